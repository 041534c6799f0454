"""Frame structures of the blind benchmark and the two ways their decks are written.

A :class:`Frame` is the structure itself: grids (basic positions and displacement systems),
CBAR members with their sections (PBARL library sections, or a plain PBAR), CROD bracing,
supports (by set), masses (CONM2: no effect on statics) and flexible joints (coincident branch
grids tied by an RBE2 CM=123). :meth:`Frame.deck` is the parsed model, built directly;
:func:`plain_text` writes it with the project's own writer (``write_deck``: every grid in basic,
systems as CORD2R in basic, sections as PBAR, one SPC1 set); :func:`user_text` writes the same
structure as users' decks are written (CORD2R/CORD1R chains with grids given in CP systems,
GRDSET defaults, PBARL, CBAR vectors and offsets in the grids' CD systems, CONM2, SPC1 sets
combined by an SPCADD, small, large and free field mixed), optionally as a whole input file
whose case control selects the SPCADD and whose FORCE/MOMENT cards give the load cases.

The families (:data:`FAMILIES`) build frames of realistic size: ``ladder`` (chassis rails and
cross members), ``truss`` (a space-truss girder: bar chords and cross frames, CROD diagonals),
``storey`` (multi-storey frames of PBARL I sections, some bays braced by rods), ``tube`` (a
body of tubes, ``blackbox.structures.tube_body``), ``imported`` (the 216-member transmission
tower of a public deck, ``decks/``: legs and horizontals as bars, diagonals as rods), ``hall``
(an industrial hall: portal frames with haunched rafters, purlins, wind-bracing rods, column
bases pinned in a rotated coordinate system), the small frames of the first benchmark
(``portal``, ``box``, ``star``), ``bus`` (a bus body: floor ladder, side walls of pillars,
waist and cant rails, roof bows, end frames; on its suspension mounts, loaded as on a body test
rig) and ``jacket`` (an offshore jacket platform: battered tubular legs, X- or K-braced faces,
horizontal frames, a deck frame of I or box girders on deck legs; on its piles at the mudline,
loaded by waves, wind, deck loads, torsion and a boat impact), the family held out of all tuning
(:data:`HELD_OUT`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from blackbox.structures import FrameBuilder, star_joint_frame, tube_body
from solver_adapters.bdf import parse_real, pbarl_section, read_deck
from solver_adapters.bdf_write import cbar_in_cd, format_card, print_float_8, write_deck
from solver_adapters.deck import CBar, Coord, Deck, Grid, Mat1, PBar, Prod, Rbe2, Rod, Spc1

DECKS = Path(__file__).resolve().parent / "decks"
STEEL = (2.1e11, 8.1e10, 0.3)                # E, G, NU (each exact in an 8-character field)
TUBE_STEEL = dict(E=206.85e9, G=82.7e9, A=2.99e-4, I1=77.42e-8, I2=16.65e-8, J=35.40e-8)  # first benchmark


@dataclass(frozen=True)
class Section:
    """A member section: a PBARL library section (``kind`` its TYPE, ``dims`` DIM1...) or, with
    ``kind == "PBAR"``, ``dims = (A, I1, I2, J)`` given directly."""
    kind: str
    dims: tuple[float, ...]

    def values(self) -> tuple:
        """``(A, I1, I2, J, K1, K2, I12)`` as the reader makes them (``pbarl_section``)."""
        if self.kind == "PBAR":
            a, i1, i2, j = self.dims
            return a, i1, i2, j, None, None, 0.0
        return pbarl_section(self.kind, self.dims)


@dataclass
class CoordDef:
    """A coordinate system as the user's deck defines it: ``CORD2R`` by three points given in
    system ``rid`` or ``CORD1R`` through three grids; ``coord`` is the resolved system."""
    card: str
    coord: Coord
    rid: int = 0
    points: tuple = ()             # CORD2R: A, B, C in system rid
    grids: tuple[int, ...] = ()    # CORD1R: origin, z-axis, x-z-plane grids


def coord_from_points(cid: int, pts, card: str = "CORD2R") -> Coord:
    """The rectangular system with origin ``pts[0]``, z axis towards ``pts[1]`` and x-z plane
    through ``pts[2]`` (basic positions), as NASTRAN (and the reader) resolves it."""
    a, b, c = (np.asarray(p, float) for p in pts)
    ez = (b - a) / np.linalg.norm(b - a)
    ey = np.cross(ez, c - a)
    ey /= np.linalg.norm(ey)
    ex = np.cross(ey, ez)
    return Coord(cid, "R", tuple(a.tolist()), (tuple(ex.tolist()), tuple(ey.tolist()), tuple(ez.tolist())), card)


def rotation(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Rows: the x, y, z axes (in basic) of a system turned by ``yaw`` about z, then ``pitch``
    about the new y and ``roll`` about the new x (radians)."""
    cz, sz, cy, sy, cx, sx = (math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch),
                              math.cos(roll), math.sin(roll))
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return (Rz @ Ry @ Rx).T


@dataclass
class Frame:
    """A frame structure (module docstring). Member and grid ids start at 1; supports are given
    per grid (components in the grid's CD system) with the SPC1 set each belongs to."""
    family: str
    mats: dict[int, tuple[float, float, float]] = field(default_factory=lambda: {1: STEEL})
    grids: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    cd: dict[int, int] = field(default_factory=dict)
    coords: dict[int, CoordDef] = field(default_factory=dict)
    sections: dict[int, tuple[int, Section]] = field(default_factory=dict)     # pid -> (mid, section)
    bars: dict[int, list] = field(default_factory=dict)      # eid -> [ga, gb, pid, v, wa, wb] (basic)
    prods: dict[int, tuple[int, float, float]] = field(default_factory=dict)   # pid -> (mid, A, J)
    rods: dict[int, tuple[int, int, int]] = field(default_factory=dict)        # eid -> (ga, gb, pid)
    spcs: dict[int, str] = field(default_factory=dict)
    spc_set: dict[int, int] = field(default_factory=dict)
    rbe2: dict[int, tuple[int, tuple[int, ...]]] = field(default_factory=dict)  # eid -> (gn, gm)
    joints: list[tuple[str, tuple[int, ...]]] = field(default_factory=list)
    masses: list[tuple[int, float]] = field(default_factory=list)
    groups: dict[str, list[int]] = field(default_factory=dict)   # named member groups (for reports)
    force: float = 1000.0         # load magnitudes of the random cases (N, N m)
    moment: float = 500.0
    # a test rig's (or a design analysis's) load cases instead of random ones: ``rig_case(rng,
    # avoid)`` draws one case as {grid: force vector in basic (N)} on grids not in ``avoid`` (the
    # joints' and the supports')
    rig_case: Callable[[np.random.Generator, set[int]], dict[int, np.ndarray]] | None = None

    # ---- building ------------------------------------------------------------------------
    def grid(self, xyz, gid: int | None = None) -> int:
        g = gid if gid is not None else max(self.grids, default=0) + 1
        self.grids[g] = tuple(float(v) for v in xyz)
        return g

    def section(self, sec: Section, mid: int = 1) -> int:
        for pid, (m, s) in self.sections.items():
            if s == sec and m == mid:
                return pid
        pid = max([*self.sections, *self.prods], default=0) + 1
        self.sections[pid] = (mid, sec)
        return pid

    def next_eid(self) -> int:
        return max([*self.bars, *self.rods], default=0) + 1

    def prune(self) -> None:
        """Drop the grids no member connects (a source deck's unused grids)."""
        used = {g for b in self.bars.values() for g in b[:2]} | {g for r in self.rods.values() for g in r[:2]}
        for g in [g for g in self.grids if g not in used]:
            del self.grids[g]
            self.cd.pop(g, None)
            self.spcs.pop(g, None)
            self.spc_set.pop(g, None)

    def bar(self, ga: int, gb: int, pid: int, v=None, group: str | None = None) -> int:
        d = np.subtract(self.grids[gb], self.grids[ga])
        if v is None:
            v = (0.0, 0.0, 1.0)
            if np.linalg.norm(np.cross(d, v)) < 1e-3 * np.linalg.norm(d):
                v = (1.0, 0.0, 0.0)
        e = self.next_eid()
        self.bars[e] = [ga, gb, pid, tuple(float(x) for x in v), None, None]
        if group:
            self.groups.setdefault(group, []).append(e)
        return e

    def chain(self, ga: int, gb: int, n: int, pid: int, v=None, group: str | None = None) -> list[int]:
        """``n`` bars from ``ga`` to ``gb`` through ``n - 1`` new equally spaced grids; returns the
        grids, ``ga`` and ``gb`` included."""
        a, b = np.array(self.grids[ga]), np.array(self.grids[gb])
        pts = [ga] + [self.grid(a + (b - a) * k / n) for k in range(1, n)] + [gb]
        for p, q in zip(pts, pts[1:]):
            self.bar(p, q, pid, v, group)
        return pts

    def rod(self, ga: int, gb: int, area: float, mid: int = 1, group: str | None = None) -> int:
        pid = next((p for p, v in self.prods.items() if v == (mid, area, 0.0)), None)
        if pid is None:
            pid = max([*self.sections, *self.prods], default=0) + 1
            self.prods[pid] = (mid, area, 0.0)
        e = self.next_eid()
        self.rods[e] = (ga, gb, pid)
        if group:
            self.groups.setdefault(group, []).append(e)
        return e

    def fix(self, g: int, comps: str = "123456", sid: int = 1) -> None:
        self.spcs[g] = "".join(sorted(set(self.spcs.get(g, "") + comps)))
        self.spc_set[g] = sid

    def members_at(self) -> dict[int, list[int]]:
        """Grid -> the CBARs ending there."""
        at: dict[int, list[int]] = {}
        for e, (a, b, *_) in self.bars.items():
            at.setdefault(a, []).append(e)
            at.setdefault(b, []).append(e)
        return at

    def neighbours(self, g: int) -> set[int]:
        """Grids joined to ``g`` by one member (bar or rod)."""
        out = {b if a == g else a for a, b, *_ in self.bars.values() if g in (a, b)}
        return out | {b if a == g else a for a, b, _ in self.rods.values() if g in (a, b)}

    def flexible_joint(self, name: str, node: int, eids: list[int]) -> tuple[int, ...]:
        """Split ``node`` into one coincident grid per member of ``eids`` (the first keeps
        ``node``; the new grids take its displacement system), tied by an RBE2 CM=123."""
        grids = [node]
        for e in eids[1:]:
            g = self.grid(self.grids[node])
            if node in self.cd:
                self.cd[g] = self.cd[node]
            bar = self.bars[e]
            if bar[0] == node:
                bar[0] = g
            else:
                bar[1] = g
            grids.append(g)
        self.rbe2[9_000_001 + len(self.rbe2)] = (node, tuple(grids[1:]))
        self.joints.append((name, tuple(grids)))
        return tuple(grids)

    # ---- the parsed model ----------------------------------------------------------------
    def deck(self) -> Deck:
        """The structure as the reader would hold it (positions in basic, vectors and offsets in
        basic, sections as the equivalent PBAR)."""
        d = Deck()
        for cid, c in self.coords.items():
            d.coords[cid] = c.coord
        for g, xyz in self.grids.items():
            d.grids[g] = Grid(g, xyz, "", "", 0, self.cd.get(g, 0))
        for mid, (e, gg, nu) in self.mats.items():
            d.mat1s[mid] = Mat1(mid, e, gg, nu)
        for pid, (mid, sec) in self.sections.items():
            a, i1, i2, j, k1, k2, i12 = sec.values()
            d.pbars[pid] = PBar(pid, mid, a, i1, i2, j, "", k1, k2, i12,
                                card="PBAR" if sec.kind == "PBAR" else "PBARL")
        for e, (ga, gb, pid, v, wa, wb) in self.bars.items():
            d.cbars[e] = CBar(e, pid, ga, gb, tuple(v), None, "", "", "", wa, wb)
        for pid, (mid, a, j) in self.prods.items():
            d.prods[pid] = Prod(pid, mid, a, j)
        for e, (ga, gb, pid) in self.rods.items():
            d.rods[e] = Rod(e, ga, gb, pid)
        by: dict[tuple[int, str], list[int]] = {}
        for g in sorted(self.spcs):
            by.setdefault((self.spc_set.get(g, 1), self.spcs[g]), []).append(g)
        d.spc1s = [Spc1(sid, comps, tuple(gs)) for (sid, comps), gs in sorted(by.items())]
        for e, (gn, gm) in self.rbe2.items():
            d.rbe2s[e] = Rbe2(e, gn, "123", gm)
        return d

    def n_members(self) -> int:
        return len(self.bars) + len(self.rods)


# --------------------------------------------------------------------------------------------
# writing: the project's plain writing and a user's
# --------------------------------------------------------------------------------------------
def plain_text(frame: Frame, title: str) -> str:
    """The deck as the project writes one (``write_deck``, free field, every bit kept), every
    support in one SPC1 set."""
    d = frame.deck()
    by: dict[str, list[int]] = {}
    for g in sorted(frame.spcs):
        by.setdefault(frame.spcs[g], []).append(g)
    d.spc1s = [Spc1(1, comps, tuple(gs)) for comps, gs in sorted(by.items())]
    return f"$ {title}\n" + write_deck(d, "free")


def _local(coords: dict[int, CoordDef], cid: int, xyz) -> np.ndarray:
    """Basic position -> coordinates in system ``cid`` (rectangular)."""
    if cid == 0:
        return np.asarray(xyz, float)
    c = coords[cid].coord
    return np.asarray(c.axes) @ (np.asarray(xyz, float) - np.asarray(c.origin))


def _exact_8(v) -> bool:
    """A field that a small (8-character) field holds exactly."""
    if not isinstance(v, float):
        return True
    return parse_real(print_float_8(v)) == v


def _f(x: float) -> float:
    """A real for a free or large field: the shortest digits, and no ``-0.0``."""
    x = float(x)
    return 0.0 if x == 0.0 else x


@dataclass
class UserStyle:
    """The choices of a users'-style writing (drawn by :func:`user_style`)."""
    grdset_cp: int
    grdset_cd: int
    cp: dict[int, int]             # grid -> CP system its position is given in
    spc_sets: dict[int, int]       # grid -> the SPC1 set of its support
    spcadd: int
    masses: list[tuple[int, float]]


def assign_user_systems(frame: Frame, rng: np.random.Generator) -> None:
    """Give the frame the coordinate systems of a user's deck: ``100`` a site system (turned in
    plan, off the basic origin, CORD2R in basic), ``101`` a system given in ``100`` (CORD2R with
    RID 100, tilted), ``102`` a system through three of the frame's grids (CORD1R); the grids'
    displacement systems (CD) among them: a default for most grids, others for the supports and
    a random quarter of the grids."""
    xyz = np.array(list(frame.grids.values()))
    span = float(np.ptp(xyz, axis=0).max())
    R0 = rotation(rng.uniform(-math.pi, math.pi), rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2))
    o0 = xyz.min(axis=0) - rng.uniform(0.5, 2.0, 3) * span
    frame.coords.setdefault(100, CoordDef("CORD2R", coord_from_points(100, [o0, o0 + R0[2], o0 + R0[0]]), 0,
                                          (tuple(o0), tuple(o0 + R0[2]), tuple(o0 + R0[0]))))
    c100 = frame.coords[100].coord
    R1 = rotation(rng.uniform(-math.pi, math.pi), rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6))
    o1 = rng.uniform(-1, 1, 3) * span
    # the points in system 100's coordinates, rounded as a user types them
    pts = [np.round(o1, 3), np.round(o1 + 10.0 * R1[2], 3), np.round(o1 + 10.0 * R1[0], 3)]
    basic = [c100.to_basic(p)[0] for p in pts]
    frame.coords[101] = CoordDef("CORD2R", coord_from_points(101, basic), 100, tuple(tuple(p) for p in pts))
    ids = sorted(frame.grids)
    for _ in range(100):
        g3 = [int(g) for g in rng.choice(ids, 3, replace=False)]
        p = np.array([frame.grids[g] for g in g3])
        ez = p[1] - p[0]
        if np.linalg.norm(ez) < 0.05 * span:
            continue
        s = np.linalg.norm(np.cross(ez / np.linalg.norm(ez), p[2] - p[0]))
        if s > 0.1 * np.linalg.norm(p[2] - p[0]) and s > 0.02 * span:
            frame.coords[102] = CoordDef("CORD1R", coord_from_points(102, p, "CORD1R"), grids=tuple(g3))
            break
    systems = sorted(frame.coords)
    own = dict(frame.cd)
    default = int(rng.choice([0, 100, 101]))
    for g in ids:
        frame.cd[g] = default
    for g in rng.choice(ids, size=max(1, len(ids) // 4), replace=False):
        frame.cd[int(g)] = int(rng.choice([0] + systems))
    for g in frame.spcs:      # a support in a system of the structure's own (the hall's bases) keeps it
        frame.cd[g] = own[g] if g in own else int(rng.choice(systems))
    for _, grids in frame.joints:     # a joint made already (the star's): one CD for its branch grids
        for g in grids[1:]:
            frame.cd[g] = frame.cd[grids[0]]


def user_style(frame: Frame, rng: np.random.Generator) -> UserStyle:
    """Draw how a user's deck of ``frame`` is written (after :func:`assign_user_systems`)."""
    systems = [c for c in frame.coords if frame.coords[c].card == "CORD2R"]
    grdset_cp = int(rng.choice([0] + systems))
    grdset_cd = int(np.bincount([frame.cd.get(g, 0) for g in frame.grids]).argmax())
    defining = {g for c in frame.coords.values() for g in c.grids}
    cp = {}
    for g in frame.grids:
        cp[g] = grdset_cp if rng.random() < 0.7 else int(rng.choice([0] + systems))
        if g in defining and cp[g] not in [0] + systems:
            cp[g] = 0
    # supports: the clamped ones in set 1, the others in set 2 (a user's "bases" and "bearings")
    spc_sets = {g: (1 if c == "123456" else 2) for g, c in frame.spcs.items()}
    if len(set(spc_sets.values())) == 1:
        for g in list(spc_sets)[::2]:
            spc_sets[g] = 3
    ids = sorted(frame.grids)
    masses = [(int(g), float(np.round(rng.uniform(5, 200), 1)))
              for g in rng.choice(ids, size=min(6, len(ids)), replace=False)]
    return UserStyle(grdset_cp, grdset_cd, cp, spc_sets, 100, masses)


def user_text(frame: Frame, style: UserStyle, title: str,
              loads: list[tuple[str, int, int, float]] | None = None, decoy_spc: int | None = None) -> str:
    """The frame written as a user's deck (module docstring). With ``loads`` a whole input file:
    executive and case control (one SUBCASE per case, its label the subcase id, ``SPC =`` the
    SPCADD), FORCE/MOMENT cards in each grid's CD system, and ``decoy_spc`` a grid held by a
    further SPC1 set that no subcase selects (a support used only for transport)."""
    d = frame.deck()
    out: list[str] = []
    if loads is not None:
        cases = list(dict.fromkeys(r[0] for r in loads))
        out += ["SOL 101", "TIME 600", "CEND", f"TITLE = {title}", "ECHO = NONE",
                f"SPC = {style.spcadd}", "DISPLACEMENT(PLOT) = ALL", "SPCFORCES(PLOT) = ALL"]
        for c in cases:
            out += [f"SUBCASE {c}", f"  SUBTITLE = load case {c}", f"  LOAD = {c}"]
        out.append("BEGIN BULK")
    out += [f"$ {title}", "$ units: N, m, s", "PARAM,POST,-1", "PARAM,AUTOSPC,YES"]
    fmt_cycle = ["small", "large", "free"]

    def card(name, fields, fmt="free"):
        if fmt == "small" and not all(_exact_8(v) for v in fields):
            fmt = "large"             # a real that 8 characters cannot hold: the user types 16
        out.append(format_card(name, fields, fmt).rstrip("\n"))

    out.append("$ ---- coordinate systems")
    for cid in sorted(frame.coords):
        c = frame.coords[cid]
        if c.card == "CORD2R":
            pts = [_f(v) for p in c.points for v in p]
            card("CORD2R", [cid, c.rid or None, *pts], "large")
        else:
            card("CORD1R", [cid, *c.grids], "small")
    out.append("$ ---- grids")
    card("GRDSET", [None, style.grdset_cp or None, None, None, None, style.grdset_cd or None], "small")
    for g in sorted(frame.grids):
        cp = style.cp[g]
        x = _local(frame.coords, cp, frame.grids[g])
        cd = frame.cd.get(g, 0)
        fields = [g, None if cp == style.grdset_cp else cp, *(_f(v) for v in x),
                  None if cd == style.grdset_cd else cd]
        card("GRID", fields, fmt_cycle[g % 2 + 1] if g % 5 else "large")
    out.append("$ ---- material and sections")
    for mid, (e, gg, nu) in sorted(frame.mats.items()):
        card("MAT1", [mid, e, gg, nu], "small")
    for pid, (mid, sec) in sorted(frame.sections.items()):
        if sec.kind == "PBAR":
            card("PBAR", [pid, mid, *sec.dims], "large")
        else:
            card("PBARL", [pid, mid, None, sec.kind, None, None, None, None, *sec.dims], "small")
    for pid, (mid, a, j) in sorted(frame.prods.items()):
        card("PROD", [pid, mid, a, j or None], "small")
    out.append("$ ---- members (orientation vectors and offsets in the grids' displacement systems)")
    for e in sorted(d.cbars):
        b = cbar_in_cd(d, d.cbars[e])
        fields = [e, b.pid, b.ga, b.gb, *(_f(v) for v in b.x)]
        if b.wa is not None or b.wb is not None:
            fields += [None, None, None, *((_f(v) for v in b.wa) if b.wa else (None,) * 3),
                       *((_f(v) for v in b.wb) if b.wb else (None,) * 3)]
        card("CBAR", fields, "free" if e % 3 else "large")
    for e in sorted(frame.rods):
        card("CROD", [e, frame.rods[e][2], *frame.rods[e][:2]], "small")
    out.append("$ ---- joints: branch grids tied in translation")
    for e in sorted(frame.rbe2):
        gn, gm = frame.rbe2[e]
        card("RBE2", [e, gn, "123", *gm], "small")
    out.append("$ ---- masses (no effect on a static solve)")
    base = max([*frame.bars, *frame.rods, *frame.rbe2], default=0) + 1000
    for k, (g, m) in enumerate(style.masses):
        card("CONM2", [base + k, g, None, m], "small")
    out.append("$ ---- supports")
    by: dict[tuple[int, str], list[int]] = {}
    for g in sorted(frame.spcs):
        by.setdefault((style.spc_sets[g], frame.spcs[g]), []).append(g)
    for (sid, comps), gs in sorted(by.items()):
        card("SPC1", [sid, comps, *gs], "small")
    sets = sorted({s for s, _ in by})
    if decoy_spc is not None:
        card("SPC1", [9, "123456", decoy_spc], "small")
    card("SPCADD", [style.spcadd, *sets], "small")
    if loads is not None:
        out.append("$ ---- load cases (FORCE/MOMENT in each grid's displacement system)")
        for case, g, comp, v in loads:
            vec = [0.0, 0.0, 0.0]
            vec[(comp - 1) % 3] = 1.0
            card("FORCE" if comp <= 3 else "MOMENT", [int(case), g, frame.cd.get(g, 0) or None, _f(v), *vec], "free")
    out.append("ENDDATA")
    return "\n".join(out) + "\n"


# --------------------------------------------------------------------------------------------
# sections
# --------------------------------------------------------------------------------------------
def _r3(x: float) -> float:
    """Three significant digits (a catalogue dimension, exact in a small field)."""
    return float(f"{x:.3g}")


def box(rng, h=(0.08, 0.2), ratio=(0.5, 1.0), t=(0.03, 0.08)) -> Section:
    hh = _r3(rng.uniform(*h))
    b = _r3(hh * rng.uniform(*ratio))
    tt = _r3(max(0.002, hh * rng.uniform(*t)))
    return Section("BOX", (b, hh, tt, tt))


def tube(rng, r=(0.02, 0.06), t=(0.06, 0.15)) -> Section:
    ro = _r3(rng.uniform(*r))
    return Section("TUBE", (ro, _r3(ro * (1 - rng.uniform(*t)))))


def pipe(rng, r=(0.25, 0.5), t=(0.03, 0.08), as_pbar: bool = False) -> Section:
    """A tubular member (outer radius ``r``, wall ``t`` times the radius): PBARL TUBE, or (as a
    user who works from a section table writes it) a PBAR with the tube's A, I, I, J to four
    digits."""
    sec = tube(rng, r, t)
    if not as_pbar:
        return sec
    a, i1, i2, j = (float(f"{v:.4g}") for v in sec.values()[:4])
    return Section("PBAR", (a, i1, i2, j))


def ibeam(rng, h=(0.16, 0.4), wide=False) -> Section:
    """An I section: IPE-like (narrow flanges) or HEB-like (``wide``)."""
    hh = _r3(rng.uniform(*h))
    w = _r3(hh * (rng.uniform(0.85, 1.0) if wide else rng.uniform(0.45, 0.55)))
    tf = _r3(hh * (rng.uniform(0.06, 0.08) if wide else rng.uniform(0.045, 0.06)))
    tw = _r3(hh * (rng.uniform(0.035, 0.045) if wide else rng.uniform(0.028, 0.035)))
    return Section("I", (hh, w, w, tw, tf, tf))


def channel(rng, h=(0.12, 0.3)) -> Section:
    hh = _r3(rng.uniform(*h))
    return Section("CHAN", (_r3(hh * rng.uniform(0.35, 0.45)), hh, _r3(hh * rng.uniform(0.04, 0.05)),
                            _r3(hh * rng.uniform(0.06, 0.07))))


def rod_area(rng, d=(0.012, 0.03)) -> float:
    return _r3(math.pi / 4 * rng.uniform(*d) ** 2)


# --------------------------------------------------------------------------------------------
# families
# --------------------------------------------------------------------------------------------
def ladder(rng: np.random.Generator) -> Frame:
    """A ladder (chassis) frame: two rails of channel or box section in 0.1-0.2 m segments,
    5-9 cross members (tubes or boxes, 3-6 segments), X-braces in one or two bays, a bracket at
    each end of the rails; on four spring seats (front left 123, front right 3, rear left 23,
    rear right 3)."""
    f = Frame("ladder")
    length, width = rng.uniform(4.0, 9.0), rng.uniform(0.75, 1.2)
    rail = f.section(channel(rng) if rng.random() < 0.5 else box(rng, (0.12, 0.25), (0.4, 0.6)))
    cross = f.section(tube(rng, (0.03, 0.05)) if rng.random() < 0.5 else box(rng, (0.06, 0.12)))
    brace = f.section(tube(rng, (0.015, 0.025)))
    n_cross = int(rng.integers(5, 10))
    xs = np.sort(np.concatenate([[0.0, length], rng.uniform(0.1, 0.9, n_cross - 2) * length]))
    xs = np.unique(np.round(xs, 2))
    seg = rng.uniform(0.1, 0.2)
    stations = sorted(set(np.round(np.concatenate([xs, np.linspace(0, length, int(length / seg) + 1)]), 2)))
    rails = []
    for s in (0, 1):
        ids = [f.grid((x, s * width, 0.0)) for x in stations]
        for a, b in zip(ids, ids[1:]):
            f.bar(a, b, rail, group="rail")
        rails.append(dict(zip(stations, ids)))
    n_seg = int(rng.integers(3, 7))
    crosses = []
    for x in xs:
        crosses.append(f.chain(rails[0][x], rails[1][x], n_seg, cross, group="cross"))
    for _ in range(int(rng.integers(1, 3))):
        i = int(rng.integers(0, len(xs) - 1))
        a, b = crosses[i], crosses[i + 1]
        f.bar(a[0], b[n_seg // 2], brace, group="brace")
        f.bar(a[-1], b[n_seg // 2], brace, group="brace")
    for s, y in ((0, -0.25), (1, width + 0.25)):
        for x in (stations[1], stations[-2]):
            tip = f.grid((x, y, 0.0))
            f.bar(rails[s][x], tip, cross, group="bracket")
    ax_f, ax_r = xs[1], xs[-2]
    f.fix(rails[0][ax_f], "123", 2)
    f.fix(rails[1][ax_f], "3", 2)
    f.fix(rails[0][ax_r], "23", 2)
    f.fix(rails[1][ax_r], "3", 2)
    f.force, f.moment = 2000.0, 500.0
    return f


def truss(rng: np.random.Generator) -> Frame:
    """A space-truss girder: four chords (tubes or boxes) in 10-20 panels, a cross frame of four
    bars at every panel point, rod diagonals (CROD) in the four faces and in some cross frames;
    on the bottom chords of both ends (123 and 3 at one, 23 and 3 at the other)."""
    f = Frame("truss")
    n = int(rng.integers(10, 21))
    panel, width, height = rng.uniform(0.8, 1.5), rng.uniform(1.0, 2.0), rng.uniform(1.0, 2.0)
    chord = f.section(tube(rng, (0.04, 0.07)) if rng.random() < 0.5 else box(rng, (0.08, 0.14), (0.8, 1.0)))
    post = f.section(tube(rng, (0.025, 0.045)))
    area = rod_area(rng)
    corners = [(0, 0), (1, 0), (1, 1), (0, 1)]          # (y, z) in units of width, height
    g = [[f.grid((i * panel, y * width, z * height)) for (y, z) in corners] for i in range(n + 1)]
    for i in range(n + 1):
        for k in range(4):
            if i < n:
                f.bar(g[i][k], g[i + 1][k], chord, group="chord")
            f.bar(g[i][k], g[i][(k + 1) % 4], post, v=(1.0, 0.0, 0.0), group="frame")
        if i % 3 == 0:
            f.rod(g[i][0], g[i][2], area, group="frame-diagonal")
    for i in range(n):
        for k in range(4):
            a, b = (g[i][k], g[i + 1][(k + 1) % 4]) if i % 2 == 0 else (g[i][(k + 1) % 4], g[i + 1][k])
            f.rod(a, b, area, group="diagonal")
    f.fix(g[0][0], "123", 2)
    f.fix(g[0][1], "3", 2)
    f.fix(g[n][0], "23", 2)
    f.fix(g[n][1], "3", 2)
    f.force, f.moment = 5000.0, 1000.0
    return f


def storey(rng: np.random.Generator, max_members: int = 420) -> Frame:
    """A multi-storey frame: 2-4 x 1-3 bays, 3-6 storeys, columns of a wide I section (HEB-like),
    beams of a narrow one (IPE-like, 2-4 segments), X-bracing rods in one bay of two outer
    frames; bases clamped."""
    while True:
        nx, ny, ns = int(rng.integers(2, 5)), int(rng.integers(1, 4)), int(rng.integers(3, 7))
        nseg = int(rng.integers(2, 5))
        n = (nx + 1) * (ny + 1) * ns + (nx * (ny + 1) + ny * (nx + 1)) * ns * nseg
        if n <= max_members:
            break
    f = Frame("storey")
    bx, by, hs = rng.uniform(4.0, 7.0), rng.uniform(4.0, 6.0), rng.uniform(3.0, 4.0)
    col = f.section(ibeam(rng, (0.2, 0.3), wide=True))
    beam = f.section(ibeam(rng, (0.2, 0.4)))
    area = rod_area(rng, (0.016, 0.03))
    g = {(i, j, k): f.grid((i * bx, j * by, k * hs))
         for i in range(nx + 1) for j in range(ny + 1) for k in range(ns + 1)}
    for (i, j, k), gid in g.items():
        if k == 0:
            f.fix(gid, "123456", 1)
            continue
        f.bar(g[(i, j, k - 1)], gid, col, v=(1.0, 0.0, 0.0), group="column")
        if i < nx:
            f.chain(gid, g[(i + 1, j, k)], nseg, beam, group="beam")
        if j < ny:
            f.chain(gid, g[(i, j + 1, k)], nseg, beam, group="beam")
    for j in (0, ny):
        i = int(rng.integers(0, nx))
        for k in range(ns):
            f.rod(g[(i, j, k)], g[(i + 1, j, k + 1)], area, group="bracing")
            f.rod(g[(i + 1, j, k)], g[(i, j, k + 1)], area, group="bracing")
    f.force, f.moment = 10000.0, 5000.0
    return f


def tube_family(rng: np.random.Generator) -> Frame:
    """A body of tubes (``tube_body``: rings, longitudinals, one diagonal per panel; four wheel
    pads) with 6-10 rings of 8-10 members; rings boxes, longitudinals and diagonals tubes."""
    n_long, n_around = int(rng.integers(6, 11)), int(rng.choice([8, 10]))
    fb = tube_body(n_long, n_around, length=rng.uniform(3.5, 5.0), width=rng.uniform(1.4, 1.8),
                   height=rng.uniform(1.2, 1.6), with_joint=False)
    ring, longi, diag = box(rng, (0.05, 0.1)), tube(rng, (0.02, 0.035)), tube(rng, (0.012, 0.02))

    def section(e, a, b, v):
        d = np.subtract(fb.grids[b], fb.grids[a])
        if abs(d[0]) < 1e-9:
            return ring, "ring"
        return (longi, "longitudinal") if np.linalg.norm(d[1:]) < 1e-9 else (diag, "diagonal")
    f = from_builder("tube", fb, section)
    f.force, f.moment = 1000.0, 200.0
    return f


def from_builder(family: str, fb: FrameBuilder, section=None) -> Frame:
    """A :class:`Frame` from a ``FrameBuilder`` (its one PBAR section, members grouped by direction,
    or ``section(eid, ga, gb, v) -> (Section, group)``); the builder's joints are taken over."""
    f = Frame(family, mats={1: (fb.E, fb.G, fb.E / (2 * fb.G) - 1.0)})
    for g, xyz in fb.grids.items():
        f.grid(xyz, g)
    plain = Section("PBAR", (fb.A, fb.I1, fb.I2, fb.J))
    def by_direction(e, a, b, v):
        d = np.abs(np.subtract(fb.grids[b], fb.grids[a]))
        if d.max() <= 0.9 * np.linalg.norm(d):
            return plain, "inclined"
        return plain, ("vertical", "along x", "along y")[int(np.argmax(d[[2, 0, 1]]))]
    for e, a, b, v in fb.bars:
        sec, group = (section or by_direction)(e, a, b, v)
        pid = f.section(sec)
        f.bars[e] = [a, b, pid, tuple(v), None, None]
        f.groups.setdefault(group, []).append(e)
    for g, c in fb.spcs.items():
        f.fix(g, c, 1)
    for k, (eid, gn, gm, cm) in enumerate(fb.rbe2):
        f.rbe2[eid] = (gn, tuple(gm))
    f.joints = [(n, tuple(g)) for n, g in fb.joints]
    f.force, f.moment = 100.0, 10.0
    return f


def imported(rng: np.random.Generator) -> Frame:
    """The transmission tower of a public deck (``decks/README.md``): three stacked 72-member
    truss sections (superelements in the source, joined here at their coincident grids), one to
    three of them used; inches to metres (scaled 0.6-1.4), the deck's aluminium MAT1; legs and
    horizontals become bars (tubes or boxes), diagonals stay rods of the deck's PROD area; the
    deck's clamped base."""
    parts = ["base.bdf", "second.bdf", "third.bdf"][:int(rng.integers(1, 4))]
    decks = [read_deck(DECKS / "truss216" / p) for p in parts]
    scale = 0.0254 * rng.uniform(0.6, 1.4)
    m = decks[0].mat1s[101]
    psi = 6894.757293168361
    f = Frame("imported", mats={1: (float(f"{m.e * psi:.4g}"), float(f"{m.g * psi:.4g}"), m.nu)})
    key = {}                                  # basic position (rounded) -> grid id: parts share grids
    ids: dict[tuple[int, int], int] = {}
    for k, d in enumerate(decks):
        for gid, gr in sorted(d.grids.items()):
            pos = tuple(np.round(np.array(gr.xyz) * scale, 9))
            if pos not in key:
                key[pos] = f.grid(pos)
            ids[(k, gid)] = key[pos]
    leg = f.section(tube(rng, (0.04, 0.07)) if rng.random() < 0.5 else box(rng, (0.08, 0.14), (0.8, 1.0)))
    horizontal = f.section(tube(rng, (0.025, 0.045)))
    seen = set()
    for k, d in enumerate(decks):
        for e, r in sorted(d.rods.items()):
            a, b = ids[(k, r.ga)], ids[(k, r.gb)]
            if (min(a, b), max(a, b)) in seen:
                continue
            seen.add((min(a, b), max(a, b)))
            dv = np.subtract(f.grids[b], f.grids[a])
            vertical = np.linalg.norm(dv[:2]) < 1e-9
            level = abs(dv[2]) < 1e-9 and np.count_nonzero(np.abs(dv) > 1e-9) == 1
            if vertical:
                f.bar(a, b, leg, v=(1.0, 0.0, 0.0), group="leg")
            elif level:
                f.bar(a, b, horizontal, group="horizontal")
            else:
                f.rod(a, b, _r3(d.prods[r.pid].a * scale * scale), group="diagonal")
        for s in d.spc1s:
            for g in s.grids:
                f.fix(ids[(k, g)], "123456", 1)
    f.prune()
    f.force, f.moment = 2000.0, 500.0
    return f


def hall(rng: np.random.Generator) -> Frame:
    """An industrial hall: 5-8 portal frames at 5-6.5 m, span 12-20 m,
    eaves 5-7 m; columns of a wide I section in two segments, rafters of a narrow I in four
    segments each side, the segment at the eaves a deeper haunch section; purlins (channels)
    at the rafter nodes, eave and ridge beams; X-bracing rods in both end bays of the roof and
    in the end bays of both long walls. The hall stands turned in plan on the site (basic)
    system; the column bases are pinned about the frames' plane normal, in the hall's own
    system (CORD2R 50, their CD): components 1, 2, 3, 5, 6 held, 4 free."""
    f = Frame("hall")
    nf = int(rng.integers(5, 9))
    bay, span, eave = rng.uniform(5.0, 6.5), rng.uniform(12.0, 20.0), rng.uniform(5.0, 7.0)
    rise = span / 2 * math.tan(math.radians(rng.uniform(5, 15)))
    col = f.section(ibeam(rng, (0.24, 0.36), wide=True))
    raf = ibeam(rng, (0.3, 0.45))
    rafter = f.section(raf)
    haunch = f.section(Section("I", (_r3(raf.dims[0] * rng.uniform(1.5, 1.9)),) + raf.dims[1:]))
    purlin = f.section(channel(rng, (0.14, 0.2)))
    area = rod_area(rng, (0.016, 0.024))
    yaw = rng.uniform(-math.pi, math.pi)
    R = rotation(yaw)
    origin = np.round(rng.uniform(-50, 50, 3) * np.array([1, 1, 0]), 2)

    def at(x, y, z):                           # hall coordinates -> basic
        return origin + np.array([x, y, z]) @ R
    frame_nodes = []
    n_r = 4
    for i in range(nf):
        x = i * bay
        base = [f.grid(at(x, 0.0, 0.0)), f.grid(at(x, span, 0.0))]
        knee = [f.grid(at(x, 0.0, eave)), f.grid(at(x, span, eave))]
        nodes = {}
        for s in (0, 1):
            mid = f.grid(at(x, s * span, eave * rng.uniform(0.45, 0.6)))
            f.bar(base[s], mid, col, v=tuple(R[0]), group="column")
            f.bar(mid, knee[s], col, v=tuple(R[0]), group="column")
            f.fix(base[s], "12356", 1)
        ridge = f.grid(at(x, span / 2, eave + rise))
        for s in (0, 1):
            pts = [knee[s]]
            for k in range(1, n_r):
                t = k / n_r
                y = t * span / 2 if s == 0 else span - t * span / 2
                pts.append(f.grid(at(x, y, eave + t * rise)))
            pts.append(ridge)
            for k, (a, b) in enumerate(zip(pts, pts[1:])):
                f.bar(a, b, haunch if k == 0 else rafter, v=tuple(R[0]), group="haunch" if k == 0 else "rafter")
            nodes[s] = pts
        frame_nodes.append((base, knee, nodes))
    for i in range(nf - 1):
        _, _, na = frame_nodes[i]
        _, _, nb = frame_nodes[i + 1]
        for s in (0, 1):
            for k in range(n_r + (1 if s == 0 else 0)):
                f.bar(na[s][k], nb[s][k], purlin, v=(0.0, 0.0, 1.0), group="purlin" if k else "eave beam")
    for i in (0, nf - 2):
        base_a, knee_a, na = frame_nodes[i]
        base_b, knee_b, nb = frame_nodes[i + 1]
        for s in (0, 1):
            for k in range(n_r):
                f.rod(na[s][k], nb[s][k + 1], area, group="roof bracing")
                f.rod(na[s][k + 1], nb[s][k], area, group="roof bracing")
            f.rod(base_a[s], knee_b[s], area, group="wall bracing")
            f.rod(knee_a[s], base_b[s], area, group="wall bracing")
    c = CoordDef("CORD2R", coord_from_points(50, [origin, origin + R[2], origin + R[0]]), 0,
                 (tuple(origin), tuple(origin + R[2]), tuple(origin + R[0])))
    f.coords[50] = c
    for g in f.spcs:
        f.cd[g] = 50
    f.force, f.moment = 10000.0, 5000.0
    return f


def bus(rng: np.random.Generator) -> Frame:
    """A bus or coach body frame (held out until its misses were looked at), x forward, y across, z
    up: 7-12 panels of 1.0-1.1 m (a body 7-13 m long, 2.40-2.55 m wide; 175-315 members). The floor
    is a ladder: two longitudinal rails (channels or rectangular tubes) and a cross member at every
    station running from the side sill through both rails and a centre grid to the other sill, plus
    a heavy cross beam between the rails at each axle. Each side wall: the sill, a pillar at every
    station in two segments (below and above the waist), the waist rail and the cant rail, a
    diagonal in about half of the panels below the waist; on the door side (y = 0) the front panel
    and in half of the bodies a middle panel are door openings (no waist rail, no diagonal). A roof
    bow (four segments of a shallow arch) joins the cant rails at every station, with a crown
    stringer and in half of the bodies two more stringers. The front and rear end frames
    (windscreen, rear wall): a cross beam at waist height and a centre post from the floor to the
    roof crown. Sections are thin rectangular tubes and channels. The body stands on its suspension
    mounts under the rails at two axles (three on a long coach with a tag axle): front left 123,
    front right 3, rear left 23, rear right 3, tag axle 3 and 3 (a body longer than 11 m has one in
    half of the draws). Its load cases are a test rig's (:attr:`Frame.rig_case`): vertical floor
    loads over a few seat rows, a torsion pair at one end, lateral loads along one side's waist or
    cant rail, longitudinal loads at the rail ends, a roof load."""
    f = Frame("bus")
    n = int(np.clip(round(rng.uniform(9.0, 13.0) / rng.uniform(1.0, 1.4)), 7, 12))
    length = _r3(rng.uniform(1.0, 1.1) * n)
    width = _r3(rng.uniform(2.40, 2.55))
    track = _r3(rng.uniform(0.40, 0.55))            # the rails' distance from the centre line
    zw = _r3(rng.uniform(0.9, 1.2))                 # waist rail above the floor
    zc = _r3(zw + rng.uniform(0.9, 1.2))            # cant rail
    rise = _r3(rng.uniform(0.10, 0.25))             # roof crown above the cant rails
    rail = f.section(channel(rng, (0.12, 0.2)) if rng.random() < 0.5 else box(rng, (0.1, 0.16), (0.4, 0.6), (0.03, 0.06)))
    cross = f.section(box(rng, (0.06, 0.1), (0.5, 1.0), (0.03, 0.06)) if rng.random() < 0.5 else channel(rng, (0.08, 0.12)))
    axle = f.section(box(rng, (0.12, 0.18), (0.6, 0.9), (0.04, 0.07)))
    sill = f.section(box(rng, (0.06, 0.1), (0.5, 1.0), (0.03, 0.05)))
    pillar = f.section(box(rng, (0.05, 0.08), (0.5, 1.0), (0.03, 0.06)))
    longi = f.section(box(rng, (0.04, 0.07), (0.5, 1.0), (0.03, 0.06)))
    bow = f.section(box(rng, (0.04, 0.06), (0.5, 1.0), (0.04, 0.06)) if rng.random() < 0.5 else channel(rng, (0.05, 0.08)))
    stringer = f.section(box(rng, (0.03, 0.05), (0.6, 1.0), (0.05, 0.08)))
    diagonal = f.section(box(rng, (0.04, 0.06), (0.5, 1.0), (0.04, 0.06)))
    xs = [round(length * i / n, 3) for i in range(n + 1)]
    ys, yr = (0.0, width), (_r3(width / 2 - track), _r3(width / 2 + track))
    # axles: the front one at 18-25 % of the length, the rear at 72-80 %, a tag axle 1.35 m behind
    # it on a long coach; an axle within 0.15 m of a station is at the station
    axles = [length * rng.uniform(0.18, 0.25), length * rng.uniform(0.72, 0.80)]
    if length > 11.0 and rng.random() < 0.5 and axles[1] + 1.35 < length - 0.5:
        axles.append(axles[1] + 1.35)
    axles = [min(xs, key=lambda x: abs(x - a)) if min(abs(x - a) for x in xs) < 0.15 else round(a, 3) for a in axles]
    sills, rails, waist, cant = ([{}, {}] for _ in range(4))
    centre, crown, bows = {}, {}, {}
    for i, x in enumerate(xs):
        for s in (0, 1):
            sills[s][i] = f.grid((x, ys[s], 0.0))
            rails[s][x] = f.grid((x, yr[s], 0.0))
            waist[s][i] = f.grid((x, ys[s], zw))
            cant[s][i] = f.grid((x, ys[s], zc))
        centre[i] = f.grid((x, width / 2, 0.0))
        pts = [cant[0][i]]
        for k in (1, 2, 3):
            y = width * k / 4
            pts.append(f.grid((x, y, zc + rise * (1.0 - (2 * y / width - 1.0) ** 2))))
        pts.append(cant[1][i])
        bows[i], crown[i] = pts, pts[2]
        for a, b in zip(*[[sills[0][i], rails[0][x], centre[i], rails[1][x], sills[1][i]][k:] for k in (0, 1)]):
            f.bar(a, b, cross, v=(0.0, 0.0, 1.0), group="cross member")
        for s in (0, 1):
            f.bar(sills[s][i], waist[s][i], pillar, v=(1.0, 0.0, 0.0), group="pillar")
            f.bar(waist[s][i], cant[s][i], pillar, v=(1.0, 0.0, 0.0), group="pillar")
        for a, b in zip(pts, pts[1:]):
            f.bar(a, b, bow, v=(1.0, 0.0, 0.0), group="roof bow")
    for a in axles:
        if a not in rails[0]:
            for s in (0, 1):
                rails[s][a] = f.grid((a, yr[s], 0.0))
        f.bar(rails[0][a], rails[1][a], axle, v=(0.0, 0.0, 1.0), group="axle beam")
    for s in (0, 1):
        stations = sorted(rails[s])
        for a, b in zip(stations, stations[1:]):
            f.bar(rails[s][a], rails[s][b], rail, v=(0.0, 0.0, 1.0), group="rail")
    doors = {0} | ({n // 2} if rng.random() < 0.5 else set())     # panels open on side 0
    lines = [1, 2, 3] if rng.random() < 0.5 else [2]
    for i in range(n):
        for s in (0, 1):
            f.bar(sills[s][i], sills[s][i + 1], sill, group="sill")
            f.bar(cant[s][i], cant[s][i + 1], longi, group="cant rail")
            if s == 0 and i in doors:
                continue
            f.bar(waist[s][i], waist[s][i + 1], longi, group="waist rail")
            if rng.random() < 0.5:
                a, b = (sills[s][i], waist[s][i + 1]) if i % 2 == 0 else (sills[s][i + 1], waist[s][i])
                f.bar(a, b, diagonal, v=(0.0, 1.0, 0.0), group="wall diagonal")
        for k in lines:
            f.bar(bows[i][k], bows[i + 1][k], stringer, group="roof stringer")
    for i in (0, n):                                 # the end frames
        mid = f.grid((xs[i], width / 2, zw))
        f.bar(waist[0][i], mid, pillar, v=(1.0, 0.0, 0.0), group="end frame")
        f.bar(mid, waist[1][i], pillar, v=(1.0, 0.0, 0.0), group="end frame")
        f.bar(centre[i], mid, pillar, v=(1.0, 0.0, 0.0), group="end frame")
        f.bar(mid, crown[i], pillar, v=(1.0, 0.0, 0.0), group="end frame")
    for a, comps in zip(axles, [("123", "3"), ("23", "3"), ("3", "3")]):
        for s in (0, 1):
            f.fix(rails[s][a], comps[s], 2)
    f.force, f.moment = 5000.0, 1000.0

    def rig_case(rng: np.random.Generator, avoid: set[int]) -> dict[int, np.ndarray]:
        """One load case of a body test rig (forces only, as actuators apply them)."""
        for _ in range(100):
            kind = str(rng.choice(["floor", "torsion", "lateral", "longitudinal", "roof"],
                                  p=[0.3, 0.2, 0.25, 0.1, 0.15]))
            out: dict[int, np.ndarray] = {}
            first = int(rng.integers(0, n))
            rows = range(first, min(n + 1, first + int(rng.integers(2, 5))))
            sign = float(rng.choice([-1.0, 1.0]))
            same = kind in ("torsion", "longitudinal")      # one actuator force on both sides
            u = rng.uniform(0.3, 1.0)
            if kind == "floor":                      # passengers over a few seat rows
                pts = [(g, (0.0, 0.0, -1.0)) for i in rows for g in (rails[0][xs[i]], centre[i], rails[1][xs[i]])]
            elif kind == "torsion":                  # one end's floor corners pushed up and down
                i = int(rng.choice([0, n]))
                pts = [(sills[0][i], (0.0, 0.0, sign)), (sills[1][i], (0.0, 0.0, -sign))]
            elif kind == "lateral":                  # cornering or wind along one side
                line = waist if rng.random() < 0.5 else cant
                pts = [(line[int(rng.integers(0, 2))][i], (0.0, sign, 0.0)) for i in rows]
            elif kind == "longitudinal":             # braking or towing at the rail ends
                i = int(rng.choice([0, n]))
                pts = [(rails[s][xs[i]], (sign, 0.0, 0.0)) for s in (0, 1)]
            else:                                    # a roof load over a few bows
                pts = [(crown[i], (0.0, 0.0, -1.0)) for i in rows]
            for g, d in pts:
                if g not in avoid:
                    out[g] = f.force * (u if same else rng.uniform(0.3, 1.0)) * np.asarray(d)
            if out:
                return out
        raise RuntimeError("bus: no rig load case on the grids left free")
    f.rig_case = rig_case
    return f


def jacket(rng: np.random.Generator) -> Frame:
    """An offshore jacket platform (the held-out family), x and y the platform axes, z up from mean
    sea level. Four battered legs (in 15 % of the draws three, in 15 % six or eight in two rows),
    batter 1:8 to 1:12 in each face a leg leans in (a four-leg jacket's legs lean in both plan
    directions, the rows' inner legs across the rows only, a three-leg jacket's radially); 3-6
    elevations of horizontal frames from the mudline (water about 10-100 m deep) to the top of the
    jacket 5-9 m above sea level, the bays getting taller downwards, plan bracing (an X through a
    centre node or single diagonals; a three-leg jacket's spokes to a centre node) at the mudline,
    at the top and at some elevations between. Every face between two legs (and the transverse
    frames at inner legs of six or eight) is braced bay by bay, the pattern one per jacket: X (the
    two diagonals meet at a node of four branches), K (chevron and V alternating, so that two
    braces meet at the middle of a horizontal and at a leg: K-joints), or mixed (a pattern drawn
    per bay: X, chevron, V or a single diagonal). Legs, braces, horizontals and plan members are
    tubes (PBARL TUBE; braces, horizontals and plan members in half of the draws a PBAR computed
    from the tube).
    Vertical deck legs continue the legs above the jacket to one or two deck levels (cellar and
    main deck), with a knee brace from each deck leg to the girder of the deck's cantilever; the
    deck frame is a grid of main girders along the leg rows (deep I or box sections), cross girders
    (I) at every station and a middle stringer in half of the draws, cantilevered 3-6 m beyond the
    end legs; a three-leg deck is a triangle of girders with spokes to its centre. 80-350 members.
    The legs stand on their piles at the mudline: clamped (123456), pinned (123), or pinned with
    the pile's torsion held (1236 in a system along the leg's axis, CORD2R 61...). Its load cases
    are those of a design analysis (:attr:`Frame.rig_case`): wave and current forces on the grids
    of the legs and faces near the surface, decaying with depth, from one of eight headings; wind
    on the deck levels; a deck load (equipment or laydown) over a few girder nodes; a torsion
    (tangential forces at the main deck's leg tops, no net force); a boat impact on one leg near
    sea level."""
    while True:
        f, count = _jacket_attempt(rng)
        if 80 <= count <= 350:
            return f


def _jacket_attempt(rng: np.random.Generator) -> tuple[Frame, int]:
    f = Frame("jacket")
    n_legs = int(rng.choice([4, 3, 6, 8], p=[0.7, 0.15, 0.075, 0.075]))
    n_lev = int(rng.integers(3, 7))
    batter = rng.uniform(8.0, 12.0)
    z_top = _r3(rng.uniform(5.0, 9.0))
    h_top, grow = rng.uniform(8.0, 12.0), rng.uniform(1.15, 1.35)
    heights = [h_top * grow ** k for k in range(n_lev - 1)][::-1]      # bottom bay first
    zs = [z_top - sum(heights[k:]) for k in range(n_lev - 1)] + [z_top]
    zs = [_r3(z) if abs(z) >= 1 else round(z, 2) for z in zs]
    as_pbar = bool(rng.random() < 0.5)
    leg = f.section(tube(rng, (0.6, 1.0), (0.03, 0.06)))
    deck_leg = f.section(tube(rng, (0.5, 0.8), (0.04, 0.07)))
    brace = f.section(pipe(rng, (0.25, 0.5), (0.04, 0.08), as_pbar))
    horizontal = f.section(pipe(rng, (0.2, 0.4), (0.04, 0.08), as_pbar))
    plan = f.section(pipe(rng, (0.15, 0.3), (0.05, 0.1), as_pbar))
    knee = f.section(tube(rng, (0.15, 0.25), (0.06, 0.1)))
    main = f.section(ibeam(rng, (0.8, 1.4)) if rng.random() < 0.6 else box(rng, (0.6, 1.0), (0.5, 0.8), (0.03, 0.05)))
    cross = f.section(ibeam(rng, (0.45, 0.8)))
    stringer = f.section(ibeam(rng, (0.3, 0.5)))
    # the legs: plan position at the top of the jacket and the outward batter direction
    if n_legs == 3:
        side = rng.uniform(12.0, 18.0)
        rr = side / math.sqrt(3.0)
        angles = [math.radians(a) for a in (-90.0, 30.0, 150.0)]
        tops = [np.array([rr * math.cos(a), rr * math.sin(a)]) for a in angles]
        outward = [t / np.linalg.norm(t) for t in tops]
        faces = [(0, 1), (1, 2), (2, 0)]
        m = 0
    else:
        m = n_legs // 2                           # legs per row: rows y < 0 (0..m-1) and y > 0
        sx, half_y = rng.uniform(10.0, 14.0) if m > 2 else rng.uniform(10.0, 16.0), rng.uniform(5.0, 8.0)
        xs = [_r3(sx * (c - (m - 1) / 2)) for c in range(m)]
        tops, outward = [], []
        for sy in (-1.0, 1.0):
            for c in range(m):
                tops.append(np.array([xs[c], _r3(sy * half_y)]))
                outward.append(np.array([-1.0 if c == 0 else (1.0 if c == m - 1 else 0.0), sy]))
        faces = ([(c, c + 1) for c in range(m - 1)] + [(m + c, m + c + 1) for c in range(m - 1)]
                 + [(0, m), (m - 1, 2 * m - 1)] + [(c, m + c) for c in range(1, m - 1)])
    L = [[f.grid((*np.round(tops[i] + (z_top - z) / batter * outward[i], 4), z)) for z in zs]
         for i in range(n_legs)]
    for i in range(n_legs):
        for k in range(n_lev - 1):
            d = np.subtract(f.grids[L[i][k + 1]], f.grids[L[i][k]])
            v = np.cross(d, (0.0, 0.0, 1.0)) if np.linalg.norm(d[:2]) > 1e-6 else (1.0, 0.0, 0.0)
            f.bar(L[i][k], L[i][k + 1], leg, v=tuple(np.round(v / np.linalg.norm(v), 6)), group="leg")
    # the face bracing, one pattern per bay; a horizontal gets a middle node where K-braces meet it
    style = str(rng.choice(["X", "K", "mixed"], p=[0.4, 0.3, 0.3]))
    if style == "X":
        bays = ["X"] * (n_lev - 1)
    elif style == "K":
        start = int(rng.integers(0, 2))
        bays = [("chevron", "V")[(k + start) % 2] for k in range(n_lev - 1)]
    else:
        bays = [str(rng.choice(["X", "chevron", "V", "diagonal"])) for _ in range(n_lev - 1)]
    mid_at = {k for k, b in enumerate(bays) if b == "V"} | {k + 1 for k, b in enumerate(bays) if b == "chevron"}
    mids: dict[tuple[int, int, int], int] = {}
    for a, b in faces:
        for k in range(n_lev):
            if k in mid_at:
                mid = f.grid(np.round(0.5 * (np.add(f.grids[L[a][k]], f.grids[L[b][k]])), 4))
                mids[(a, b, k)] = mid
                f.bar(L[a][k], mid, horizontal, group="horizontal")
                f.bar(mid, L[b][k], horizontal, group="horizontal")
            else:
                f.bar(L[a][k], L[b][k], horizontal, group="horizontal")
        for k, pattern in enumerate(bays):
            a0, b0, a1, b1 = L[a][k], L[b][k], L[a][k + 1], L[b][k + 1]
            if pattern == "X":
                pa, pb, qa, qb = (np.array(f.grids[g]) for g in (a0, b1, b0, a1))
                st, *_ = np.linalg.lstsq(np.column_stack([pb - pa, qa - qb]), qa - pa, rcond=None)
                x = f.grid(np.round(pa + st[0] * (pb - pa), 4))
                for g in (a0, b1, b0, a1):
                    f.bar(g, x, brace, group="face brace")
            elif pattern == "chevron":
                for g in (a0, b0):
                    f.bar(g, mids[(a, b, k + 1)], brace, group="face brace")
            elif pattern == "V":
                for g in (a1, b1):
                    f.bar(mids[(a, b, k)], g, brace, group="face brace")
            else:
                ends = (a0, b1) if (a + k) % 2 else (b0, a1)
                f.bar(*ends, brace, group="face brace")
    # plan bracing: at the mudline and the top, and at some elevations between
    for k in range(n_lev):
        kind = str(rng.choice(["X", "diagonal"])) if k in (0, n_lev - 1) or rng.random() < 0.4 else ""
        if not kind:
            continue
        if n_legs == 3:
            c = f.grid((0.0, 0.0, zs[k]))
            for i in range(3):
                f.bar(L[i][k], c, plan, group="plan brace")
            continue
        for c in range(m - 1):
            cell = (L[c][k], L[c + 1][k], L[m + c + 1][k], L[m + c][k])
            if kind == "X":
                centre = f.grid(np.round(np.mean([f.grids[g] for g in cell], axis=0), 4))
                for g in cell:
                    f.bar(g, centre, plan, group="plan brace")
            else:
                f.bar(*((cell[0], cell[2]) if c % 2 == 0 else (cell[1], cell[3])), plan, group="plan brace")
    jacket_grids = set(f.grids)                    # below the deck: where waves act
    # the deck legs and the deck levels
    n_decks = int(rng.integers(1, 3))
    z_decks = [_r3(z_top + rng.uniform(7.0, 10.0))]
    if n_decks == 2:
        z_decks.append(_r3(z_decks[0] + rng.uniform(5.0, 8.0)))
    else:
        z_decks[0] = _r3(z_decks[0] + rng.uniform(1.0, 4.0))
    over = _r3(rng.uniform(3.0, 6.0))
    with_stringer = bool(rng.random() < 0.5)
    decks: list[dict] = []          # per deck level: {(station, row): grid}
    tops_at: list[list[int]] = []   # per deck level: the deck legs' top grids
    below = [L[i][-1] for i in range(n_legs)]
    knee_at = [f.grid((*f.grids[below[i]][:2], _r3(z_top + 0.6 * (z_decks[0] - z_top)))) for i in range(n_legs)]
    for i in range(n_legs):
        f.bar(below[i], knee_at[i], deck_leg, v=(1.0, 0.0, 0.0), group="deck leg")
    below = knee_at
    for zd in z_decks:
        grid_at: dict = {}
        lt = []
        for i in range(n_legs):
            g = f.grid((*f.grids[below[i]][:2], zd))
            f.bar(below[i], g, deck_leg, v=(1.0, 0.0, 0.0), group="deck leg")
            lt.append(g)
        if n_legs == 3:
            centre = f.grid((0.0, 0.0, zd))
            for i in range(3):
                pts = f.chain(lt[i], lt[(i + 1) % 3], 3, main, v=(0.0, 0.0, 1.0), group="main girder")
                spoke = f.chain(lt[i], centre, 2, cross, v=(0.0, 0.0, 1.0), group="cross girder")
                grid_at.update({(i, 0): lt[i], (i, 1): pts[1], (i, 2): pts[2], (i, 3): spoke[1]})
                if zd == z_decks[0]:                   # a knee brace under each girder's first third
                    f.bar(knee_at[i], pts[1], knee, group="knee brace")
            grid_at[(3, 0)] = centre
        else:
            stations = sorted({*xs, *(0.5 * (a + b) for a, b in zip(xs, xs[1:])), xs[0] - over, xs[-1] + over})
            stations = [_r3(x) if abs(x) >= 1 else round(x, 3) for x in stations]
            rows = [-half_y, 0.0, half_y] if with_stringer else [-half_y, half_y]
            rows = [_r3(y) if y else 0.0 for y in rows]
            for si, x in enumerate(stations):
                for ri, y in enumerate(rows):
                    leg_here = [i for i in range(n_legs) if abs(tops[i][0] - x) < 1e-9 and abs(tops[i][1] - y) < 1e-9]
                    grid_at[(si, ri)] = lt[leg_here[0]] if leg_here else f.grid((x, y, zd))
            for si in range(len(stations)):
                for ri in range(len(rows)):
                    if si + 1 < len(stations):
                        sec, grp = (stringer, "stringer") if rows[ri] == 0.0 else (main, "main girder")
                        f.bar(grid_at[(si, ri)], grid_at[(si + 1, ri)], sec, v=(0.0, 0.0, 1.0), group=grp)
                    if ri + 1 < len(rows):
                        f.bar(grid_at[(si, ri)], grid_at[(si, ri + 1)], cross, v=(0.0, 0.0, 1.0), group="cross girder")
            if zd == z_decks[0]:                       # knee braces under the cantilevers
                for i in range(n_legs):
                    if outward[i][0]:
                        si = stations.index(xs[0] if outward[i][0] < 0 else xs[-1]) + int(outward[i][0])
                        ri = rows.index(_r3(tops[i][1]))
                        f.bar(knee_at[i], grid_at[(si, ri)], knee, group="knee brace")
        decks.append(grid_at)
        tops_at.append(lt)
        below = lt
    pile = str(rng.choice(["123456", "123", "1236"], p=[0.4, 0.3, 0.3]))
    for i in range(n_legs):
        g = L[i][0]
        f.fix(g, pile, 1)
        if pile == "1236":                             # the pile head's system: z along the leg
            o = np.array(f.grids[g])
            axis = np.subtract(f.grids[L[i][1]], o)
            axis /= np.linalg.norm(axis)
            side = np.array([*outward[i], 0.0])
            cid = 61 + i
            pts = (tuple(o), tuple(o + axis), tuple(o + side))
            f.coords[cid] = CoordDef("CORD2R", coord_from_points(cid, pts), 0, pts)
            f.cd[g] = cid
    f.force, f.moment = 2.0e5, 1.0e5
    depth = -zs[0]
    sea = min(range(n_lev), key=lambda k: abs(zs[k]))     # the elevation nearest sea level
    centroid = np.mean(tops, axis=0)

    def heading(rng: np.random.Generator) -> np.ndarray:
        """One of the eight headings 0, 45, ..., 315 degrees from the platform's x axis."""
        t = math.radians(45.0 * int(rng.integers(0, 8)))
        return np.round(np.array([math.cos(t), math.sin(t), 0.0]), 12)

    def rig_case(rng: np.random.Generator, avoid: set[int]) -> dict[int, np.ndarray]:
        """One load case of a design analysis (forces only: the environment and the deck's
        loads act as nodal forces)."""
        for _ in range(100):
            kind = str(rng.choice(["wave", "wind", "deck", "torsion", "boat"], p=[0.35, 0.15, 0.25, 0.15, 0.1]))
            u = rng.uniform(0.3, 1.0) * f.force
            pts: list[tuple[int, np.ndarray]] = []
            if kind == "wave":                       # waves and current from one heading, decaying with depth
                d = heading(rng)
                zone, decay = rng.uniform(0.3, 0.6) * depth, rng.uniform(0.15, 0.3) * depth
                pts = [(g, d * float(np.clip(math.exp(f.grids[g][2] / decay), 0.3, 1.0)))
                       for g in sorted(jacket_grids) if f.grids[g][2] >= -zone]
            elif kind == "wind":                     # wind on the modules, carried by the deck legs
                d = heading(rng) * 0.5
                pts = [(g, d) for lt in tops_at for g in lt]
            elif kind == "deck":                     # equipment or laydown over a few girder nodes
                deck = decks[int(rng.integers(0, len(decks)))]
                keys = sorted(deck)
                k0 = keys[int(rng.integers(0, len(keys)))]
                window = [k for k in keys if abs(k[0] - k0[0]) <= 1 and abs(k[1] - k0[1]) <= 1][:6]
                pts = [(deck[k], np.array([0.0, 0.0, -1.0])) for k in window]
            elif kind == "torsion":                  # tangential forces at the main deck's leg tops
                lt = tops_at[-1]
                if any(g in avoid for g in lt):
                    continue
                sign = float(rng.choice([-1.0, 1.0]))
                for g in lt:
                    r = np.array([*(np.array(f.grids[g][:2]) - centroid), 0.0])
                    t = np.cross((0.0, 0.0, sign), r)
                    pts.append((g, t / np.linalg.norm(t)))
            else:                                    # a boat against one leg near sea level
                i = int(rng.integers(0, n_legs))
                out_i = np.array([*outward[i], 0.0])
                d = heading(rng)
                while d @ out_i >= 0:
                    d = heading(rng)
                pts = [(L[i][sea], d)]
            out = {g: u * np.asarray(v, float) for g, v in pts if g not in avoid}
            if out:
                return out
        raise RuntimeError("jacket: no load case on the grids left free")
    f.rig_case = rig_case
    return f, f.n_members()


def _portal_fb(rng: np.random.Generator) -> FrameBuilder:
    """Two parallel multi-bay portal frames tied by beams at every floor; bases clamped."""
    f = FrameBuilder(**TUBE_STEEL)
    nb, ns = int(rng.integers(1, 4)), int(rng.integers(1, 3))
    bay, h, depth = rng.uniform(0.8, 1.6), rng.uniform(0.8, 1.4), rng.uniform(0.6, 1.2)
    ids: dict[tuple, int] = {}

    def node(key, xyz):
        if key not in ids:
            ids[key] = f.grid(len(ids) + 1, xyz)
        return ids[key]
    for j in (0, 1):
        for i in range(nb + 1):
            for k in range(ns + 1):
                node(("n", i, k, j), (i * bay, j * depth, k * h))
    for j in (0, 1):
        for i in range(nb + 1):
            f.fix(ids[("n", i, 0, j)])
            for k in range(ns):
                f.bar(ids[("n", i, k, j)], ids[("n", i, k + 1, j)])
        for k in range(1, ns + 1):
            for i in range(nb):
                mid = node(("m", i, k, j), ((i + 0.5) * bay, j * depth, k * h))
                f.bar(ids[("n", i, k, j)], mid)
                f.bar(mid, ids[("n", i + 1, k, j)])
    for k in range(1, ns + 1):
        for i in range(nb + 1):
            f.bar(ids[("n", i, k, 0)], ids[("n", i, k, 1)])
    return f


def _box_fb(rng: np.random.Generator) -> FrameBuilder:
    """A space-frame box of nx x ny x nz cells (at most 6), some face diagonals; the four bottom
    corners supported (two clamped, two in translation)."""
    f = FrameBuilder(**TUBE_STEEL)
    while True:
        nx, ny, nz = (int(v) for v in rng.integers(1, [4, 3, 3]))
        if 1 < nx * ny * nz <= 6:
            break
    dx, dy, dz = rng.uniform(0.3, 0.8, 3)

    def gid(i, j, k):
        return 1 + i + (nx + 1) * (j + (ny + 1) * k)
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                f.grid(gid(i, j, k), (i * dx, j * dy, k * dz))
    for k in range(nz + 1):
        for j in range(ny + 1):
            for i in range(nx + 1):
                if i < nx:
                    f.bar(gid(i, j, k), gid(i + 1, j, k))
                if j < ny:
                    f.bar(gid(i, j, k), gid(i, j + 1, k))
                if k < nz:
                    f.bar(gid(i, j, k), gid(i, j, k + 1))
                    if i < nx and rng.random() < 0.2:
                        f.bar(gid(i, j, k), gid(i + 1, j, k + 1))
    corners = [gid(0, 0, 0), gid(nx, 0, 0), gid(nx, ny, 0), gid(0, ny, 0)]
    for c, comps in zip(corners, ["123456", "123", "123456", "123"]):
        f.fix(c, comps)
    return f


def portal(rng: np.random.Generator) -> Frame:
    return from_builder("portal", _portal_fb(rng))


def box_frame(rng: np.random.Generator) -> Frame:
    return from_builder("box", _box_fb(rng))


def star(rng: np.random.Generator) -> Frame:
    """The star frame of the first benchmark (``star_joint_frame``) with its own joint."""
    n = int(rng.integers(2, 7))
    return from_builder("star", star_joint_frame(n, seed=int(rng.integers(2**31)), arm=rng.uniform(0.4, 0.8)))


FAMILIES = {"ladder": ladder, "truss": truss, "storey": storey, "tube": tube_family, "imported": imported,
            "portal": portal, "box": box_frame, "star": star, "hall": hall, "bus": bus, "jacket": jacket}
HELD_OUT = ("jacket",)
"""Families kept out of all tuning: reported apart, run only with ``--include-held-out``. (``hall``
and then ``bus`` were held out until their misses were looked at; both are tuned on since.)"""
TUNED = tuple(f for f in FAMILIES if f not in HELD_OUT)
