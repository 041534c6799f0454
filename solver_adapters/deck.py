"""The parsed bulk-data model: one frozen dataclass per supported card (``docs/study-format.md``).

Every entity remembers where it came from (``src``: ``"file:line"``) so that model errors found
later (a CBAR whose PBAR is missing) can still name the file and line.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Grid:
    """GRID: ID, X1 X2 X3, PS (permanent single-point constraints), CP, CD.

    ``xyz`` is the position in the basic system (the reader converts the coordinates given in
    the CP system); ``cp`` and ``cd`` are the system numbers as given (GRDSET applied). The
    grid's six components (SPC, springs, loads, results) are in its CD system.

    ``scalar``: a scalar point (SPOINT), which has one degree of freedom and no position. It is
    held as a point at the basic origin whose component 1 is that degree of freedom and whose
    components 2-6 are held (``ps`` ``"23456"``); a reference to it with component 0 or blank
    (NASTRAN's way of naming a scalar point's one DOF) is to component 1.
    """
    id: int
    xyz: tuple[float, float, float]
    ps: str = ""
    src: str = ""
    cp: int = 0
    cd: int = 0
    scalar: bool = False


ON_AXIS_RULE = ("lies on the polar axis of its cylindrical or spherical displacement system (CD), "
                "where that system's directions are undefined: its displacements, constraints and "
                "loads are in the basic system's directions, as NASTRAN takes them there (Autodesk "
                "Nastran QRG, CORD1S remark 7; MYSTRAN solves such a grid as one with CD 0)")
"""The note on a grid on the polar axis of its CD system, and the rule the reader follows."""


@dataclass(frozen=True)
class Coord:
    """A resolved coordinate system (CORD1R/C/S, CORD2R/C/S): ``kind`` ``"R"`` (rectangular),
    ``"C"`` (cylindrical R, THETA, Z) or ``"S"`` (spherical R, THETA, PHI), angles in degrees as
    in NASTRAN. ``origin`` is in basic, ``axes`` holds the system's x, y, z unit vectors in
    basic as rows. ``card`` and ``src`` name the defining card."""
    cid: int
    kind: str
    origin: tuple[float, float, float]
    axes: tuple[tuple[float, float, float], ...]
    card: str = "CORD2R"
    src: str = ""

    def to_basic(self, x: np.ndarray) -> np.ndarray:
        """Points ``(n, 3)`` given in this system's coordinates -> basic positions ``(n, 3)``."""
        x = np.asarray(x, float).reshape(-1, 3)
        return np.asarray(self.origin) + self.local_rect(x) @ np.asarray(self.axes)

    def local_rect(self, x: np.ndarray) -> np.ndarray:
        """This system's coordinates -> rectangular coordinates along its axes (MSC QRG, CORD2C
        and CORD2S: x = R cos(theta), y = R sin(theta); x = R sin(theta) cos(phi), ...)."""
        x = np.asarray(x, float).reshape(-1, 3)
        if self.kind == "R":
            return x.copy()
        t = np.radians(x[:, 1])
        if self.kind == "C":
            return np.column_stack([x[:, 0] * np.cos(t), x[:, 0] * np.sin(t), x[:, 2]])
        p = np.radians(x[:, 2])
        return x[:, :1] * np.column_stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])

    def _polar(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(p, rho, axis)`` of basic points ``(n, 3)``: rectangular along this system's axes,
        the distance from its z axis, and which lie on that axis (to rounding; the origin
        included)."""
        p = (xyz - np.asarray(self.origin)) @ np.asarray(self.axes).T
        rho = np.hypot(p[:, 0], p[:, 1])
        scale = np.maximum(np.abs(p).max(axis=1), np.abs(np.asarray(self.origin)).max(initial=0.0))
        return p, rho, rho <= 1e-12 * np.maximum(scale, 1e-300)

    def on_axis(self, xyz: np.ndarray) -> np.ndarray:
        """Which basic points ``(n, 3)`` lie on the polar axis of this cylindrical or spherical
        system, where its directions are undefined; none for a rectangular one."""
        xyz = np.asarray(xyz, float).reshape(-1, 3)
        if self.kind == "R":
            return np.zeros(xyz.shape[0], bool)
        return self._polar(xyz)[2]

    def frames_at(self, xyz: np.ndarray, on_axis: str = "error") -> np.ndarray:
        """The displacement axes at basic points ``(n, 3)``: ``(n, 3, 3)``, rows the unit vectors
        of components 1, 2, 3 in basic (rectangular: the axes; cylindrical: radial, tangential, z;
        spherical: radial, theta, phi at the point). Points on the polar axis of a cylindrical
        or spherical system (:meth:`on_axis`), where the directions are undefined: ``on_axis``
        ``"error"`` raises ``ValueError`` with their positions, ``"basic"`` gives them the basic
        system's axes (NASTRAN's rule for a grid's displacement system there, below)."""
        xyz = np.asarray(xyz, float).reshape(-1, 3)
        ax = np.asarray(self.axes)
        n = xyz.shape[0]
        if self.kind == "R":
            return np.broadcast_to(ax, (n, 3, 3)).copy()
        p, rho, axis = self._polar(xyz)
        bad = np.flatnonzero(axis)
        if bad.size and on_axis != "basic":
            raise ValueError(bad)
        rho = np.where(axis, 1.0, rho)
        c, s = p[:, 0] / rho, p[:, 1] / rho
        zero, one = np.zeros(n), np.ones(n)
        if self.kind == "C":
            loc = np.stack([np.column_stack([c, s, zero]), np.column_stack([-s, c, zero]),
                            np.column_stack([zero, zero, one])], axis=1)
        else:
            r = np.linalg.norm(p, axis=1)
            st, ct = rho / r, p[:, 2] / r
            loc = np.stack([np.column_stack([st * c, st * s, ct]),
                            np.column_stack([ct * c, ct * s, -st]),
                            np.column_stack([-s, c, zero])], axis=1)
        out = loc @ ax
        out[bad] = np.eye(3)
        return out


@dataclass(frozen=True)
class CBar:
    """CBAR (or CBEAM): EID, PID, GA, GB, orientation vector X1 X2 X3 (basic system) or G0 (BAROR
    defaults already applied), pin flags PA, PB (element components released at end A, B) and
    offsets WA, WB (basic system, from the grid to the bar end; ``None``: no offset)."""
    eid: int
    pid: int
    ga: int
    gb: int
    x: tuple[float, float, float] | None = None
    g0: int | None = None
    src: str = ""
    pa: str = ""
    pb: str = ""
    wa: tuple[float, float, float] | None = None
    wb: tuple[float, float, float] | None = None
    card: str = "CBAR"          # "CBEAM": a prismatic beam read from CBEAM (same element)


@dataclass(frozen=True)
class PBar:
    """PBAR: PID, MID, A, I1 (plane 1, about element z), I2 (plane 2, about element y), J,
    K1, K2 (shear area factors of planes 1 and 2), I12 (product of inertia, int y z dA in the
    element axes; couples the two bending planes).

    ``k1``/``k2`` ``None`` (field blank or 0.0) is NASTRAN's default: infinite transverse shear
    stiffness (Euler-Bernoulli); a value gives the shear stiffness per unit length K*A*G.
    ``n1``/``n2``: a PBEAM's neutral axis offset from the shear-centre axis (element y, z): the
    axial strain is taken on the neutral axis, u_N = u + n2 theta_y - n1 theta_z.
    """
    pid: int
    mid: int
    a: float
    i1: float
    i2: float
    j: float
    src: str = ""
    k1: float | None = None
    k2: float | None = None
    i12: float = 0.0
    card: str = "PBAR"          # the card it was read from: PBAR, PBARL, PBEAM or PBEAML
    n1: float = 0.0             # PBEAM neutral axis (element y, z) from the shear-centre axis:
    n2: float = 0.0             # the axial force acts on it, bending and shear on the axis
    taper: tuple[float, float, float, float] | None = None
    """A tapered PBEAM: end B's A, I1, I2, J (``a``, ``i1``, ``i2``, ``j`` are end A's); the
    section varies linearly from end A to end B (``reference.frame.tapered_local_stiffness``).
    ``None``: a prismatic beam."""


@dataclass(frozen=True)
class Mat1:
    """MAT1: MID, E, G, NU as completed by the reader (NASTRAN's rule, see ``bdf.materials._mat1``)."""
    mid: int
    e: float
    g: float
    nu: float
    src: str = ""


@dataclass(frozen=True)
class Spc1:
    """SPC1: SID, C (component digits), grids (THRU already expanded). An SPC card (enforced
    value zero) is held the same way, one entry per grid and component field, and so are the
    SUPORT/SUPORT1 reference DOFs (``card``), which a linear static solution holds as NASTRAN
    does: ``sid`` is then a set ID of no other constraint set of the deck."""
    sid: int
    components: str
    grids: tuple[int, ...]
    src: str = ""
    card: str = "SPC1"


@dataclass(frozen=True)
class SpcAdd:
    """SPCADD: SID and the SPC/SPC1 set IDs it combines."""
    sid: int
    sets: tuple[int, ...]
    src: str = ""


@dataclass(frozen=True)
class Mpc:
    """MPC: SID and its equation's terms ``(grid, component, A)``, sum A u = 0; the first term's
    component is the dependent one."""
    sid: int
    terms: tuple[tuple[int, int, float], ...]
    src: str = ""
    card: str = "MPC"

    @property
    def eid(self) -> int:       # the ID errors name, as for the rigid elements
        return self.sid


@dataclass(frozen=True)
class Prod:
    """PROD: PID, MID, A, J (torsion constant; C and NSM are not stiffness); or a PTUBE
    (``card``), its A and J those of its tube section."""
    pid: int
    mid: int
    a: float
    j: float
    src: str = ""
    card: str = "PROD"


@dataclass(frozen=True)
class Rod:
    """CROD or CTUBE (``pid`` set: its PROD or PTUBE) or CONROD (``mid``, ``a``, ``j`` on the
    element): axial + torsion."""
    eid: int
    ga: int
    gb: int
    pid: int | None = None
    mid: int | None = None
    a: float = 0.0
    j: float = 0.0
    card: str = "CROD"
    src: str = ""


@dataclass(frozen=True)
class Rbe2:
    """RBE2: EID, GN (independent grid), CM (dependent component digits), GM... (dependent grids).
    ``card``: the card it was read from, RBE2 or an RBAR with all six independent components at
    one grid (GN), which is this RBE2 with the other grid as its one dependent grid."""
    eid: int
    gn: int
    cm: str
    gm: tuple[int, ...]
    src: str = ""
    card: str = "RBE2"


@dataclass(frozen=True)
class Rbe3:
    """RBE3: EID, REFGRID, REFC (dependent components of the reference grid) and the weight
    groups ``(WT, C, grids)``: the reference grid's motion is the weighted least-squares
    average of the independent grids' components C (MSC QRG, RBE3)."""
    eid: int
    refgrid: int
    refc: str
    groups: tuple[tuple[float, str, tuple[int, ...]], ...]
    src: str = ""
    card: str = "RBE3"


@dataclass(frozen=True)
class Bush:
    """CBUSH: EID, PID, GA, GB (0: grounded), the element axes from CID (``cid`` >= 0: that
    system's axes) or else from the axis GA -> GB with the orientation vector ``x`` (as given,
    in GA's CD system) or grid ``g0``, and the spring location: ``s`` (fraction of GA -> GB)
    or, ``offset`` given, GA plus ``offset`` in system ``ocid`` (its axes at GA; 0: basic)."""
    eid: int
    pid: int
    ga: int
    gb: int
    x: tuple[float, float, float] | None = None
    g0: int | None = None
    cid: int | None = None
    s: float = 0.5
    src: str = ""
    ocid: int = -1
    offset: tuple[float, float, float] | None = None


@dataclass(frozen=True)
class Gap:
    """CGAP: EID, PID, GA, GB, the orientation vector ``x`` (GA's CD system) or grid ``g0``, and
    CID (``None``: blank, the gap axis runs from GA to GB; else that system's T1 direction at GA).
    The orientation has no effect on a linear solution (the transverse stiffness is the same in y
    and z)."""
    eid: int
    pid: int
    ga: int
    gb: int
    x: tuple[float, float, float] | None = None
    g0: int | None = None
    cid: int | None = None
    src: str = ""


@dataclass(frozen=True)
class PGap:
    """PGAP: PID, U0 (initial opening), F0 (preload), KA (closed axial), KB (open axial, None:
    blank), KT (closed transverse, None: blank), MU1, MU2 (friction), as written."""
    pid: int
    u0: float
    f0: float
    ka: float
    kb: float | None
    kt: float | None
    mu1: float
    mu2: float | None
    src: str = ""

    def linear(self) -> tuple[float, float]:
        """The (axial, transverse) stiffness of a linear solution, which keeps the gap in its
        initial state (MSC QRG CGAP remark 1: linear with the initial stiffness, which U0 sets):
        closed (U0 <= 0): KA and KT (blank: MU1 KA); open (U0 > 0): KB (blank: 1e-14 KA) and no
        transverse stiffness (MSC QRG PGAP: KT acts when the gap is closed)."""
        if self.u0 > 0.0:
            return (1e-14 * self.ka if self.kb is None else self.kb), 0.0
        return self.ka, (self.mu1 * self.ka if self.kt is None else self.kt)


@dataclass(frozen=True)
class PBush:
    """PBUSH: PID and the stiffnesses K1..K6 of the element axes (blank: 0)."""
    pid: int
    k: tuple[float, float, float, float, float, float]
    src: str = ""


@dataclass(frozen=True)
class Pelas:
    """PELAS: PID, K (GE and S ignored)."""
    pid: int
    k: float
    src: str = ""


@dataclass(frozen=True)
class Spring:
    """CELAS1 or CELAS3 (``pid`` set, ``k`` None until resolved) or CELAS2 or CELAS4 (``k`` set).

    ``g2``/``c2`` are 0 for a spring to ground. An end on a scalar point has component 1 (its
    one DOF; CELAS3/CELAS4 join scalar points only).
    """
    eid: int
    g1: int
    c1: int
    g2: int
    c2: int
    k: float | None = None
    pid: int | None = None
    card: str = "CELAS2"
    src: str = ""


@dataclass(frozen=True)
class Dmig:
    """DMIG: a matrix of direct input at grid points, added to the stiffness (K2GG): ``terms``
    ``((row grid, component), (column grid, component), value)`` in the grids' displacement
    systems; ``ifo`` 6 (symmetric: each off-diagonal term stands for its mirror too) or 1
    (square, symmetric as read). A GENEL is held as the square matrix of its element stiffness
    over its UI and UD components (``card`` "GENEL", ``name`` GENEL<EID>), which PARAM,CK2 does
    not scale."""
    name: str
    ifo: int
    terms: tuple[tuple[tuple[int, int], tuple[int, int], float], ...]
    src: str = ""
    card: str = "DMIG"          # "GENEL": a general element's stiffness (``name`` GENEL<EID>)

    @property
    def label(self) -> str:
        """What messages call it: ``DMIG NAME`` or ``GENEL EID``."""
        return f"GENEL {self.name[5:]}" if self.card == "GENEL" else f"DMIG {self.name}"


@dataclass(frozen=True)
class Unmodelled:
    """A card the reader does not model (a shell, a solid, a property or material of theirs),
    kept as read so that an external solver can be given it: ``name``, ``fields`` (NASTRAN field
    2 on, continuation markers left out, each an ``int``, a ``float``, a word or ``None`` for a
    blank), ``src`` (``"file:line"``) and ``grids``, the grids the card connects: ``()`` for a
    card that connects none (a property, a material), ``None`` when the reader does not know
    the card's layout (then :meth:`Deck.unmodelled_grids` takes every integer field that names a
    grid, to be safe)."""
    name: str
    fields: tuple[int | float | str | None, ...]
    src: str = ""
    grids: tuple[int, ...] | None = None


@dataclass
class Deck:
    """All supported cards of a deck, keyed by ID. ``files`` lists every file read (INCLUDE)."""
    grids: dict[int, Grid] = field(default_factory=dict)
    cbars: dict[int, CBar] = field(default_factory=dict)
    pbars: dict[int, PBar] = field(default_factory=dict)
    mat1s: dict[int, Mat1] = field(default_factory=dict)
    spc1s: list[Spc1] = field(default_factory=list)
    rbe2s: dict[int, Rbe2] = field(default_factory=dict)
    rbe3s: dict[int, Rbe3] = field(default_factory=dict)
    bushes: dict[int, Bush] = field(default_factory=dict)
    pbushes: dict[int, PBush] = field(default_factory=dict)
    gaps: dict[int, Gap] = field(default_factory=dict)
    pgaps: dict[int, PGap] = field(default_factory=dict)
    pelas: dict[int, Pelas] = field(default_factory=dict)
    springs: dict[int, Spring] = field(default_factory=dict)
    spcadds: dict[int, SpcAdd] = field(default_factory=dict)
    mpcs: list[Mpc] = field(default_factory=list)
    mpcadds: dict[int, SpcAdd] = field(default_factory=dict)   # MPCADD: SID and its MPC sets
    prods: dict[int, Prod] = field(default_factory=dict)
    rods: dict[int, Rod] = field(default_factory=dict)
    coords: dict[int, Coord] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    # PARAM,AUTOSPC (the last one wins, as in NASTRAN). NASTRAN's SOL 101 default is YES, and so
    # is this one: only PARAM,AUTOSPC,NO turns it off. ``autospc_src`` is the PARAM's location
    # ("" when the deck has none and the default applies).
    autospc: bool = True
    autospc_src: str = ""
    epzero: float = 1e-8        # PARAM,EPZERO: AUTOSPC's singularity ratio (NASTRAN's default)
    # cards accepted with no effect on a linear static solve: name -> (count, first "file:line")
    no_effect: dict[str, tuple[int, str]] = field(default_factory=dict)
    # cards the reader does not model, kept (in the deck's order) when the deck was read with
    # ``unmodelled="keep"`` for an external solver; the reference solver refuses a deck with any
    unmodelled: list[Unmodelled] = field(default_factory=list)
    # what the reader read but did not model as written (a PBEAM's CW ignored, ends equal to
    # printing precision): one line per kind, naming the cards; not part of the model itself
    notes: list[str] = field(default_factory=list, compare=False)
    # SOL 200's designed values (bdf.design): (card, ID) -> {field: value at the initial design},
    # already in the entities above; the loads that read cards (GRAV's RHO and NSM, thermal
    # loads' MAT1 A and TREF) take the designed values from here
    designed: dict[tuple[str, int], dict[int, float]] = field(default_factory=dict)
    # DMIG matrices added to the stiffness in the g-set (NASTRAN's K2GG), times PARAM,CK2
    dmigs: dict[str, Dmig] = field(default_factory=dict)
    ck2: float = 1.0

    def unmodelled_grids(self) -> dict[int, list[str]]:
        """Grid -> the unmodelled cards joined to it (``"CQUAD4 10"``), for every grid of the
        deck that such a card connects (cards of unknown layout: every integer field that names
        a grid, to be safe)."""
        out: dict[int, list[str]] = {}
        for u in self.unmodelled:
            if u.grids is None:
                grids = [f for f in u.fields[1:] if isinstance(f, int) and f in self.grids]
            else:
                grids = list(u.grids)
            label = f"{u.name} {u.fields[0]}" if u.fields and u.fields[0] is not None else u.name
            for g in dict.fromkeys(grids):
                out.setdefault(g, []).append(label)
        return out

    def unmodelled_counts(self) -> dict[str, tuple[int, str]]:
        """Card name -> (count, first "file:line") of the unmodelled cards, in the deck's order."""
        out: dict[str, tuple[int, str]] = {}
        for u in self.unmodelled:
            n, src = out.get(u.name, (0, u.src))
            out[u.name] = (n + 1, src)
        return out

    def max_element_id(self) -> int:
        """The largest element ID of the deck (bars, rods, rigid elements, springs, bushes and
        the unmodelled cards' first field), 0 for none: new elements go above it."""
        ids = [0, *self.cbars, *self.rods, *self.rbe2s, *self.rbe3s, *self.springs, *self.bushes]
        ids += [u.fields[0] for u in self.unmodelled if u.fields and isinstance(u.fields[0], int)]
        return max(ids)

    def rod_section(self, r: Rod) -> tuple[int, float, float]:
        """``(mid, A, J)`` of a rod: its own (CONROD) or its PROD's (CROD)."""
        if r.pid is None:
            return r.mid, r.a, r.j
        p = self.prods[r.pid]  # presence checked by validate()
        return p.mid, p.a, p.j

    def summary(self) -> str:
        """One line naming the cards read and those accepted with no effect (with counts)."""
        counts = {"GRID": len(self.grids), "CBAR": len(self.cbars), "PBAR": len(self.pbars),
                  "CROD/CONROD": len(self.rods), "PROD": len(self.prods), "MAT1": len(self.mat1s),
                  "SPC/SPC1 entries": len(self.spc1s), "SPCADD": len(self.spcadds),
                  "MPC": len(self.mpcs), "MPCADD": len(self.mpcadds),
                  "RBE2": len(self.rbe2s), "RBE3": len(self.rbe3s), "CBUSH": len(self.bushes),
                  "PBUSH": len(self.pbushes), "PELAS": len(self.pelas), "CELAS1/2": len(self.springs),
                  "CORD1/2": len(self.coords),
                  "DMIG matrices": sum(m.card == "DMIG" for m in self.dmigs.values()),
                  "GENEL": sum(m.card == "GENEL" for m in self.dmigs.values())}
        text = ", ".join(f"{n} {k}" for k, n in counts.items() if n)
        if self.autospc:
            why = (f"PARAM,AUTOSPC,YES at {self.autospc_src}" if self.autospc_src
                   else "NASTRAN's SOL 101 default")
            text += (f"; AUTOSPC on ({why}): components without stiffness (ratio below EPZERO = "
                     f"{self.epzero:g} at their grid) are constrained and listed by the reference solver")
        else:
            text += f"; AUTOSPC off (PARAM,AUTOSPC,NO at {self.autospc_src})"
        if self.unmodelled:
            text += "; kept for an external solver, not modelled by the reference solver: " + ", ".join(
                f"{name} x{n} (first at {src})" for name, (n, src) in self.unmodelled_counts().items())
        if self.no_effect:
            text += "; accepted with no effect on a linear static solve: " + ", ".join(
                f"{name} x{n} (first at {src})" for name, (n, src) in sorted(self.no_effect.items()))
        if self.notes:
            text += "; notes: " + "; ".join(self.notes)
        return text

    def displacement_frames(self, grid_ids) -> np.ndarray:
        """``(n, 3, 3)``: for each grid of ``grid_ids`` the unit vectors of its displacement
        components 1-3 (and 4-6) in basic, as rows (identity for CD = 0). A grid on the polar
        axis of its cylindrical or spherical CD system, where that system's directions are
        undefined, takes the basic system's (:data:`ON_AXIS_RULE`; :meth:`grids_on_cd_axis`
        names them)."""
        out = np.broadcast_to(np.eye(3), (len(grid_ids), 3, 3)).copy()
        cds = np.array([self.grids[g].cd for g in grid_ids], dtype=np.int64)
        for cd in np.unique(cds[cds != 0]).tolist():
            idx = np.flatnonzero(cds == cd)
            xyz = np.array([self.grids[grid_ids[i]].xyz for i in idx.tolist()], float)
            out[idx] = self.coords[cd].frames_at(xyz, on_axis="basic")
        return out

    def grids_on_cd_axis(self, grid_ids) -> list[int]:
        """The grids of ``grid_ids`` on the polar axis of their cylindrical or spherical CD
        system (their displacements are in basic: :data:`ON_AXIS_RULE`)."""
        out = []
        for g in grid_ids:
            grid = self.grids[g]
            if grid.cd and self.coords[grid.cd].on_axis(np.array([grid.xyz], float))[0]:
                out.append(g)
        return out

    def scalar_points(self) -> set[int]:
        """The IDs of the deck's scalar points (SPOINT)."""
        return {g.id for g in self.grids.values() if g.scalar}

    def spring_stiffness(self, s: Spring) -> float:
        """The spring's K: its own (CELAS2) or its PELAS's (CELAS1)."""
        if s.k is not None:
            return s.k
        return self.pelas[s.pid].k  # presence checked by validate()
