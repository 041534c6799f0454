"""Generated frame structures, written as NASTRAN bulk data (free field, full precision).

Used by the tests (cases beyond the fixtures: other frames, joints with 2-6 branches, several
joints) and by the benchmark (car-body-like frames of 1e5-1e6 DOFs). A generated structure is
just a deck plus a description of its flexible joints: exactly what a user brings.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from blackbox.diagnosis.decks import prune_spcadds
from blackbox.joints import frame_element_stiffness, make_joint, spring_network
from blackbox.reference_tables import TABLE_3_1
from solver_adapters.bdf_write import print_float_free
from solver_adapters.deck import Deck, Grid, Rbe2, Spring


@dataclass
class FrameBuilder:
    """Collects grids, bars, supports and joints; :meth:`bdf` renders the deck. Every member has
    the same section, by default the cube's (Table 3.1)."""
    E: float = TABLE_3_1["E"]
    G: float = TABLE_3_1["G"]
    A: float = TABLE_3_1["A"]
    I1: float = TABLE_3_1["Iz"]
    I2: float = TABLE_3_1["Iy"]
    J: float = TABLE_3_1["J"]
    grids: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    bars: list[tuple[int, int, int, tuple[float, float, float]]] = field(default_factory=list)
    spcs: dict[int, str] = field(default_factory=dict)
    rbe2: list[tuple[int, int, tuple[int, ...], str]] = field(default_factory=list)
    springs: list[tuple[int, int, int, int, float]] = field(default_factory=list)
    joints: list[tuple[str, tuple[int, ...]]] = field(default_factory=list)

    def grid(self, gid: int, xyz) -> int:
        self.grids[gid] = tuple(float(v) for v in xyz)
        return gid

    def bar(self, ga: int, gb: int, v=None) -> int:
        eid = len(self.bars) + 1
        d = np.subtract(self.grids[gb], self.grids[ga])
        if v is None:
            v = (0.0, 0.0, 1.0)
            if np.linalg.norm(np.cross(d, v)) < 1e-6 * np.linalg.norm(d):
                v = (1.0, 0.0, 0.0)
        self.bars.append((eid, ga, gb, tuple(float(x) for x in v)))
        return eid

    def fix(self, gid: int, comps: str = "123456") -> None:
        self.spcs[gid] = "".join(sorted(set(self.spcs.get(gid, "") + comps)))

    def flexible_joint(self, name: str, node: int, bar_ids: list[int], first_new_id: int) -> tuple[int, ...]:
        """Split ``node`` into one coincident grid per bar in ``bar_ids`` (branch 1 keeps ``node``),
        tie them with an RBE2 CM=123 and record the joint."""
        grids = [node]
        for b, eid in enumerate(bar_ids[1:]):
            gid = self.grid(first_new_id + b, self.grids[node])
            grids.append(gid)
            i = eid - 1
            e, ga, gb, v = self.bars[i]
            self.bars[i] = (e, gid if ga == node else ga, gid if gb == node else gb, v)
        self.rbe2.append((10_000_000 + len(self.rbe2) + 1, node, tuple(grids[1:]), "123"))
        self.joints.append((name, tuple(grids)))
        return tuple(grids)

    def bdf(self, title: str = "generated frame") -> str:
        def r(x: float) -> str:       # <= 16 characters per field, as NASTRAN free field allows
            return print_float_free(x, max_width=16)

        out = [f"$ {title}", "BEGIN BULK",
               f"MAT1,1,{r(self.E)},{r(self.G)}",
               f"PBAR,1,1,{r(self.A)},{r(self.I1)},{r(self.I2)},{r(self.J)}"]
        out += [f"GRID,{g},,{r(x)},{r(y)},{r(z)}" for g, (x, y, z) in sorted(self.grids.items())]
        out += [f"CBAR,{e},1,{a},{b},{r(v[0])},{r(v[1])},{r(v[2])}" for e, a, b, v in self.bars]
        out += [f"SPC1,1,{c},{g}" for g, c in sorted(self.spcs.items())]
        for eid, gn, gm, cm in self.rbe2:
            out.append(f"RBE2,{eid},{gn},{cm}," + ",".join(str(g) for g in gm))
        for i, (g1, c1, g2, c2, k) in enumerate(self.springs):
            out.append(f"CELAS2,{20_000_000 + i + 1},{r(k)},{g1},{c1},{g2 or ''},{c2 or ''}")
        out.append("ENDDATA")
        return "\n".join(out) + "\n"


def cube(edge: float = 0.2) -> FrameBuilder:
    """The cube of Section 3.7.1 (Table 3.1): nodes 1-4 bottom, i+4 above i, node 1 fixed,
    a 3-branch flexible joint at node 7: grid 7 on member 7-3, 71 on 7-8, 72 on 7-6 (the branch
    order with which the stub joint reproduces Table 5.12; branch 3, the clamped one of the
    complex model, is the member to node 6)."""
    f = FrameBuilder()
    pts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    for i, (x, y, _) in enumerate(pts):
        f.grid(i + 1, (x * edge, y * edge, 0.0))
        f.grid(i + 5, (x * edge, y * edge, edge))
    for a, b in [(1, 2), (2, 3), (3, 4), (4, 1), (5, 6), (6, 7), (7, 8), (8, 5),
                 (1, 5), (2, 6), (3, 7), (4, 8)]:
        f.bar(a, b)
    f.fix(1)
    bars_at_7 = [e for e, a, b, _ in f.bars if 7 in (a, b)]
    order = sorted(bars_at_7, key=lambda e: {3: 0, 8: 1, 6: 2}[
        [g for g in f.bars[e - 1][1:3] if g != 7][0]])
    f.flexible_joint("J7", 7, order, 71)
    return f


def star_joint_frame(n_branches: int, seed: int = 0, arm: float = 0.5) -> FrameBuilder:
    """A frame with one flexible joint of ``n_branches`` branches (2..6 and more).

    The joint sits at the origin; each branch is a bar to an outer node in a random direction;
    outer nodes are chained into a ring of bars and each has a short leg to a clamped base,
    so the structure is stable even with every joint parameter at zero.
    """
    rng = np.random.default_rng(seed)
    f = FrameBuilder(E=206.85e9, G=82.7e9, A=2.99e-4, I1=77.42e-8, I2=16.65e-8, J=35.40e-8)
    f.grid(1, (0.0, 0.0, 0.0))
    dirs = []
    while len(dirs) < n_branches:
        d = rng.standard_normal(3)
        d /= np.linalg.norm(d)
        if all(abs(d @ e) < 0.9 for e in dirs):
            dirs.append(d)
    bar_ids = []
    for b, d in enumerate(dirs):
        outer = f.grid(100 + b, arm * (1.0 + 0.3 * rng.random()) * d)
        bar_ids.append(f.bar(1, outer))
        base = f.grid(200 + b, np.add(f.grids[outer], (0.0, 0.0, -0.3)))
        f.bar(outer, base)
        f.fix(base)
    for b in range(n_branches):
        if n_branches > 2 or b == 0:
            f.bar(100 + b, 100 + (b + 1) % n_branches)
    f.flexible_joint("J1", 1, bar_ids, 11)
    return f


def tube_body(n_long: int, n_around: int, length: float = 4.5, width: float = 1.5,
              height: float = 1.4, with_joint: bool = True) -> FrameBuilder:
    """A car-body-like frame: members on a closed elliptic tube (a shell-like surface, as a
    body-in-white), rings around the long axis, longitudinals, and one diagonal per panel;
    supported at four "suspension points" of the floor: front-left 123, front-right 13, rear
    left 3, rear right 3 (the six rigid-body motions removed, plus one redundant vertical
    support, as a body standing on four wheel pads).

    DOFs = 6 * n_long * n_around (plus the joint's branch grids). With ``with_joint`` one
    roof node becomes a flexible joint whose branches are all its members (4-5 branches).
    """
    f = FrameBuilder(E=206.85e9, G=82.7e9, A=2.99e-4, I1=77.42e-8, I2=16.65e-8, J=35.40e-8)

    def gid(i: int, j: int) -> int:
        return 1 + i * n_around + (j % n_around)

    for i in range(n_long):
        x = length * i / (n_long - 1)
        for j in range(n_around):
            t = 2 * math.pi * j / n_around
            f.grid(gid(i, j), (x, 0.5 * width * math.cos(t), 0.5 * height * (1 + math.sin(t))))
    for i in range(n_long):
        for j in range(n_around):
            f.bar(gid(i, j), gid(i, j + 1), v=(1.0, 0.0, 0.0))
            if i + 1 < n_long:
                f.bar(gid(i, j), gid(i + 1, j))
                if (i + j) % 2 == 0:
                    f.bar(gid(i, j), gid(i + 1, j + 1))
    bottom = 3 * n_around // 4
    left, right = bottom - max(1, n_around // 8), (bottom + max(1, n_around // 8)) % n_around
    front, rear = max(1, n_long // 6), n_long - 1 - max(1, n_long // 6)
    for g, c in [(gid(front, left), "123"), (gid(front, right), "13"),
                 (gid(rear, left), "3"), (gid(rear, right), "3")]:
        f.fix(g, c)
    if with_joint:
        node = gid(n_long // 2, n_around // 4)
        bars = [e for e, a, b, _ in f.bars if node in (a, b)]
        f.flexible_joint("JR", node, bars, 10 * n_long * n_around + 1)
    return f


def write_study(folder: Path, builder: FrameBuilder, loads: list[tuple[str, int, int, float]],
                name: str, model: str = "simple", initial: float = 1.0e3) -> Path:
    """Write a study folder (``docs/study-format.md``) for a generated structure."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "model.bdf").write_text(builder.bdf(name))
    with (folder / "loads.csv").open("w") as fh:
        fh.write("case,grid,component,value\n")
        for case, g, c, v in loads:
            fh.write(f"{case},{g},{c},{v!r}\n")
    lines = [f'name = "{name}"', "", "[solver]", 'adapter = "reference"', 'deck = "model.bdf"', ""]
    for jname, grids in builder.joints:
        lines += ["[[joints]]", f'name = "{jname}"', f"grids = {list(grids)}", f'model = "{model}"',
                  f"initial = {initial!r}", ""]
    (folder / "study.toml").write_text("\n".join(lines))
    return folder


def random_loads(builder: FrameBuilder, n_cases: int, seed: int = 1, per_case: int = 3,
                 force: float = 100.0, moment: float = 10.0) -> list[tuple[str, int, int, float]]:
    """Seeded load cases on unsupported, non-joint grids: forces and moments mixed."""
    rng = np.random.default_rng(seed)
    joint_grids = {g for _, gs in builder.joints for g in gs}
    free = [g for g in sorted(builder.grids) if g not in builder.spcs and g not in joint_grids]
    rows = []
    for c in range(n_cases):
        for g in rng.choice(free, size=min(per_case, len(free)), replace=False):
            comp = int(rng.integers(1, 7))
            mag = force if comp <= 3 else moment
            rows.append((f"L{c + 1}", int(g), comp, float(mag * rng.uniform(-1, 1))))
    return rows


class TruthDeck:
    """A truth deck under construction: a copy of the declared deck with effects planted in it
    (springs, joints), new grid and element ids above the deck's own. Used by the generators of
    studies with undeclared effects (``fixtures/undeclared/generate.py``, ``benchmarks/blind``)."""

    def __init__(self, deck: Deck):
        self.deck = copy.deepcopy(deck)
        self.next_grid = max(self.deck.grids) + 1
        self.next_eid = self.deck.max_element_id() + 1

    def eid(self) -> int:
        self.next_eid += 1
        return self.next_eid - 1

    def spring(self, k: float, g1: int, c1: int, g2: int = 0, c2: int = 0) -> None:
        e = self.eid()
        self.deck.springs[e] = Spring(e, g1, c1, g2, c2, k=float(k), card="CELAS2")

    def members_at(self, grid: int) -> list[int]:
        return sorted(e for e, b in self.deck.cbars.items() if grid in (b.ga, b.gb))

    def unclamp(self, grid: int) -> str:
        """Take ``grid`` out of every SPC1 set (a set left empty goes, and with it its name in
        an SPCADD) and clear its GRID PS; returns the components those constrained there (in
        the grid's CD system), for the springs that replace them."""
        comps, spcs = self.deck.grids[grid].ps, []
        if comps:
            self.deck.grids[grid] = replace(self.deck.grids[grid], ps="")
        for s in self.deck.spc1s:
            if grid in s.grids:
                comps += s.components
                rest = tuple(x for x in s.grids if x != grid)
                if rest:
                    spcs.append(replace(s, grids=rest))
            else:
                spcs.append(s)
        self.deck.spc1s = spcs
        prune_spcadds(self.deck)
        return "".join(sorted(set(comps)))

    def split_grid(self, grid: int) -> list[int]:
        """Make ``grid`` a joint of its members: one new coincident grid per member after the
        first, each member moved to its own grid, their translations tied to ``grid`` by an RBE2
        CM=123 (as a study's joints). Returns the branch grids, ``grid`` first."""
        d = self.deck
        branches = [grid]
        for e in self.members_at(grid)[1:]:
            g = self.next_grid
            self.next_grid += 1
            d.grids[g] = Grid(g, d.grids[grid].xyz, cd=d.grids[grid].cd)
            b = d.cbars[e]
            d.cbars[e] = replace(b, ga=g if b.ga == grid else b.ga, gb=g if b.gb == grid else b.gb)
            branches.append(g)
        e = self.eid()
        d.rbe2s[e] = Rbe2(e, grid, "123", tuple(branches[1:]))
        return branches

    def untie_translations(self, grids) -> None:
        """Remove the other branch grids of a joint from the RBE2 that ties their translations to
        the first (an RBE2 left with none goes)."""
        g1, others = grids[0], set(grids[1:])
        for r in list(self.deck.rbe2s.values()):
            if r.gn == g1 and others & set(r.gm):
                gm = tuple(g for g in r.gm if g not in others)
                if gm:
                    self.deck.rbe2s[r.eid] = replace(r, gm=gm)
                else:
                    del self.deck.rbe2s[r.eid]

    def k_diag(self, eid: int, grid: int) -> np.ndarray:
        """The diagonal (6) of member ``eid``'s stiffness at its end ``grid``, in the components
        of the grid's displacement system (CD)."""
        d = self.deck
        b = d.cbars[eid]
        p = d.pbars[b.pid]
        m = d.mat1s[p.mid]
        x = b.x if b.g0 is None else np.subtract(d.grids[b.g0].xyz, d.grids[b.ga].xyz)
        K = frame_element_stiffness(d.grids[b.ga].xyz, d.grids[b.gb].xyz, m.e, m.g, p.a, p.i2, p.i1, p.j, x)
        end = 0 if b.ga == grid else 1
        R = d.displacement_frames([grid])[0]
        blk = K[6 * end:6 * end + 6, 6 * end:6 * end + 6]
        return np.concatenate([np.diag(R @ blk[:3, :3] @ R.T), np.diag(R @ blk[3:, 3:] @ R.T)])

    def joint(self, name: str, grids, model: str, params) -> None:
        for s in spring_network(make_joint(name, grids, model), params):
            self.spring(s.k, s.a[0], s.a[1], *(s.b if s.b is not None else (0, 0)))


def coupled_kc(grids, simple_values, rho: np.ndarray, t: float) -> np.ndarray:
    """``K_C = S^1/2 (I + t rho) S^1/2``: the simple model's ``K_C`` (``S``) coupled by the
    symmetric zero-diagonal ``rho`` of spectral norm 1; positive definite for ``t < 1``."""


def gap_response(adapter, name: str, grids, k, r: float, loads, report, max_iterations: int = 30):
    """The displacements at ``report`` (``(len(report), cases)``) of the structure of ``adapter``
    with the simple-model joint ``name`` (branch ``grids``, springs ``k`` in the model's
    parameter order) given play: in each case each spring acts as ``k`` when its relative
    rotation (branch ``i`` minus branch ``j`` about its axis) is ``>= 0`` and as ``r k`` when it
    is ``< 0``, the sides found by solving the case again until they settle. The definition of
    the ``joint_gap`` effect (``blackbox.diagnosis.effects.joint_gap``), simulated without the
    diagnosis: one solver run per case and iteration through ``adapter.with_springs``. Raises
    ``RuntimeError`` when the sides keep changing (a gap that chatters between two states)."""
    springs = spring_network(make_joint(name, grids, "simple"), k)
    ends = [d for s in springs for d in (s.a, s.b) if d is not None]
    rows = list(dict.fromkeys(list(report) + ends))
    idx = {d: i for i, d in enumerate(rows)}
    out = np.zeros((len(report), loads.n_cases))
    for c in range(loads.n_cases):
        case = loads.select([c])
        side = np.ones(len(springs), bool)
        for _ in range(max_iterations):
            net = [replace(s, k=s.k * (1.0 if up else r)) for s, up in zip(springs, side)]
            u = adapter.with_springs(net).solve(case, rows).values[:, 0]
            rel = np.array([u[idx[s.a]] - (u[idx[s.b]] if s.b is not None else 0.0) for s in springs])
            new = rel >= 0.0
            if np.array_equal(new, side):
                break
            side = new
        else:
            raise RuntimeError(f"joint {name}: the gap's sides do not settle in case {loads.cases[c]}")
        out[:, c] = u[[idx[d] for d in report]]
    return out
