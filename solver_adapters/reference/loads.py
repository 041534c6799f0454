"""Equivalent nodal loads of loads applied to elements, as NASTRAN applies them: PLOAD1 on bars
and beams, GRAV on the structure's lumped mass. ``blackbox import`` writes them into loads.csv;
the reference solver then solves them exactly as the element loads.

PLOAD1 (MSC QRG): a concentrated load (X2 blank or equal to X1) or a linearly varying
distributed load (P1 at X1 to P2 at X2) along the bar between its ends (the offset ends, end A
the origin), a force or moment along a basic axis (FX..MZ) or an element axis (FXE..MZE). SCALE
LE gives X in length, FR as a fraction of the bar's length; LEPR and FRPR the same, with a
distributed load given per unit of the bar's length projected on the plane normal to the load
(the load per unit length is P |sin(angle between the bar and the load)|; a concentrated load
is not projected). The equivalent nodal loads are the bar's fixed-end forces: the bar is cut at
the load's points into sub-bars of its own (exact) stiffness, the load put on those points and
the points condensed out, as pin flags are (a released end component is condensed too). A
distributed load is put on the three Gauss points of its span: the loads at the grids are the
integral of the shape functions times the load, a polynomial of degree 4 at most (cubic
shape functions, linear load), which three Gauss points integrate exactly. So the grids'
displacements are those of the bar under the load itself (Euler-Bernoulli or Timoshenko bending,
product of inertia, neutral axis, pin flags; offsets carry the end loads rigidly to the grids).

GRAV (MSC QRG): the acceleration A (N1, N2, N3) in system CID applied to the mass: NASTRAN's
default lumped mass (PARAM,COUPMASS off): half of a bar's or rod's mass (rho A + NSM) L at each
of its ends (a bar's offset ends, the force then carried to the grid with its moment), a
CONM2's mass at its centre of gravity (offset X from the grid), all mass times PARAM,WTMASS.

Thermal loads (MSC QRG TEMP, TEMPD, TEMPRB, MAT1; MYSTRAN's BAR1 and ROD1 compute the same): a
bar's or rod's free thermal strain alpha (T - TREF), T the element's mean temperature (TEMPRB's
TA and TB, or the mean of its two grids' temperatures), and for a bar the curvatures of the
effective linear gradients TP1 (element y) and TP2 (element z), varying linearly from end A to
end B. TEMPRB defines TP1 and TP2 by the thermal moments they give, int T y dA = I1 TP1 and
int T z dA = I2 TP2, so the free curvatures solve [I1 I12; I12 I2] (v'', w'') = -alpha (I1 TP1,
I2 TP2) (plane 1: v'' with theta_z = v'; plane 2: w'' with theta_y = -w'). The equivalent nodal
loads are the fixed-end forces of that free deformation: with d the free displacements of end B
of the bar clamped at end A, K [0; d] (K the bar's exact element stiffness), pin flags condensed
and offsets carried to the grids as for PLOAD1. So a bar clamped at both ends gets no
displacement and the reaction E A alpha (T - TREF), and a free end moves alpha (T - TREF) L.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver_adapters.errors import ElementLoadError as LoadError  # args: (field, message)
from solver_adapters.reference import frame

TYPES = ("FX", "FY", "FZ", "MX", "MY", "MZ", "FXE", "FYE", "FZE", "MXE", "MYE", "MZE")
SCALES = ("LE", "FR", "LEPR", "FRPR")
_GAUSS = (np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)]), np.array([5.0, 8.0, 5.0]) / 9.0)


@dataclass(frozen=True)
class Pload1:
    """PLOAD1 SID EID TYPE SCALE X1 P1 X2 P2 (``x2`` None: a concentrated load)."""
    eid: int
    type: str
    scale: str
    x1: float
    p1: float
    x2: float | None
    p2: float


def bar_frame(deck, b) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """``(R, L, wa, wb)`` of a bar: rows of R its element axes in basic, L its length between its
    ends (the grids moved by the offsets), the offsets in basic (zero when none)."""
    xa, xb = np.array(deck.grids[b.ga].xyz), np.array(deck.grids[b.gb].xyz)
    wa, wb = np.array(b.wa or (0.0, 0.0, 0.0)), np.array(b.wb or (0.0, 0.0, 0.0))
    v = np.array(deck.grids[b.g0].xyz) - xa if b.g0 is not None else np.array(b.x, float)
    R, L = frame.rotation_matrices((xa + wa)[None], (xb + wb)[None], v[None])
    return R[0], float(L[0]), wa, wb


def _local_stiffness(deck, b, lengths: np.ndarray) -> np.ndarray:
    """Local stiffnesses ``(n, 12, 12)`` of pieces of bar ``b`` with the given lengths;
    :class:`LoadError` for a tapered beam (the loads NASTRAN puts on its ends from a load along
    it, or from a temperature, were not measured)."""
    p = deck.pbars[b.pid]
    if p.taper is not None:
        raise LoadError(1, f"a load along bar {b.eid} or a temperature on it, whose {p.card} {p.pid} is "
                           f"tapered: its end loads are not modelled (only loads at its ends)")
    m = deck.mat1s[p.mid]
    n = len(lengths)
    full = lambda v: np.full(n, float(v))
    as1 = full(p.k1 * p.a if p.k1 else np.inf)
    as2 = full(p.k2 * p.a if p.k2 else np.inf)
    k = frame.local_stiffness(np.asarray(lengths, float), full(m.e), full(m.g), full(p.a), full(p.i1),
                              full(p.i2), full(p.j), as1, as2, full(p.i12))
    if p.n1 or p.n2:
        k = frame.neutral_axis(k, np.tile([p.n1, p.n2], (n, 1)))
    return k


def fixed_end_loads(deck, b, L: float, points: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """The 12 end loads (element axes, ends A then B: forces then moments) equivalent to the
    loads ``points`` ``[(x, (Fx, Fy, Fz, Mx, My, Mz) in element axes), ...]`` on bar ``b``."""
    tol = 1e-12 * L
    inner = sorted({x for x, _ in points if tol < x < L - tol})
    nodes = [0.0, *inner, L]
    n = len(nodes)
    f = np.zeros(6 * n)
    for x, load in points:
        i = 0 if x <= tol else n - 1 if x >= L - tol else 1 + inner.index(x)
        f[6 * i:6 * i + 6] += load
    released = [int(ch) - 1 for ch in b.pa] + [6 * (n - 1) + int(ch) - 1 for ch in b.pb]
    if n == 2 and not released:
        return f
    K = np.zeros((6 * n, 6 * n))
    for i, k in enumerate(_local_stiffness(deck, b, np.diff(nodes))):
        K[6 * i:6 * i + 12, 6 * i:6 * i + 12] += k
    ends = [d for d in (*range(6), *range(6 * (n - 1), 6 * n)) if d not in released]
    inside = [d for d in range(6 * n) if d not in ends]
    Kbi, Kii = K[np.ix_(ends, inside)], K[np.ix_(inside, inside)]
    f_end = f[ends] - Kbi @ np.linalg.solve(Kii, f[inside])
    out = np.zeros(12)
    out[[d if d < 6 else d - 6 * (n - 2) for d in ends]] = f_end
    return out


def pload1_points(load: Pload1, R: np.ndarray, L: float) -> list[tuple[float, np.ndarray]]:
    """The point loads (element axes) that stand for one PLOAD1 on a bar (see the module
    docstring); :class:`LoadError` for positions off the bar or a projection with no meaning."""
    k = TYPES.index(load.type)
    axis = k % 3
    elem = k >= 6
    moment = (k % 6) >= 3
    d_local = np.eye(3)[axis] if elem else R[:, axis]          # the load's unit direction
    fraction = load.scale in ("FR", "FRPR")
    x1 = load.x1 * (L if fraction else 1.0)
    x2 = None if load.x2 is None else load.x2 * (L if fraction else 1.0)
    top = 1.0 if fraction else L
    for value, field in ((load.x1, 6), (load.x2, 8)):
        if value is not None and not (0.0 <= value <= top * (1 + 1e-12)):
            raise LoadError(field, f"position {value:g} is off the bar (0 to {top:g}"
                                   f"{' as a fraction of its length' if fraction else f', its length between its ends'})")
    if x2 is not None and x2 < x1:
        raise LoadError(8, "X2 must not be less than X1")

    def vec(magnitude: float) -> np.ndarray:
        out = np.zeros(6)
        out[3 * moment:3 * moment + 3] = magnitude * d_local
        return out

    if x2 is None or x2 == x1:
        return [(x1, vec(load.p1))]
    factor = 1.0
    if load.scale in ("LEPR", "FRPR"):
        along = abs(float(d_local[0]))                           # cosine to the bar's axis
        if along > 1.0 - 1e-12:
            raise LoadError(4, f"a projected distributed load ({load.scale}) along the bar's axis "
                               f"has no projected length")
        factor = float(np.sqrt(max(0.0, 1.0 - along * along)))
    half, mid = 0.5 * (x2 - x1), 0.5 * (x1 + x2)
    out = []
    for xi, wi in zip(*_GAUSS):
        x = mid + half * xi
        p = load.p1 + (load.p2 - load.p1) * (x - x1) / (x2 - x1)
        out.append((x, vec(wi * half * p * factor)))
    return out


def _to_grids(b, R: np.ndarray, wa: np.ndarray, wb: np.ndarray, f12: np.ndarray) -> dict:
    """End loads in element axes -> ``{(grid, component): value}`` in basic at the grids (an
    offset carries its end's force to the grid with the moment w x F)."""
    out: dict[tuple[int, int], float] = {}
    for grid, w, f in ((b.ga, wa, f12[:6]), (b.gb, wb, f12[6:])):
        force, moment = R.T @ f[:3], R.T @ f[3:]
        moment = moment + np.cross(w, force)
        for c, v in enumerate((*force, *moment), start=1):
            if v != 0.0:
                out[(grid, c)] = out.get((grid, c), 0.0) + float(v)
    return out


def pload1_loads(deck, b, load: Pload1) -> dict[tuple[int, int], float]:
    """The nodal loads (basic) NASTRAN applies for one PLOAD1 on bar ``b``."""
    R, L, wa, wb = bar_frame(deck, b)
    f12 = fixed_end_loads(deck, b, L, pload1_points(load, R, L))
    return _to_grids(b, R, wa, wb, f12)


def thermal_bar_loads(deck, b, alpha: float, strain: float, tp1: tuple[float, float],
                      tp2: tuple[float, float]) -> dict[tuple[int, int], float]:
    """The nodal loads (basic) of bar ``b``'s free thermal deformation: axial ``strain`` (alpha
    (T - TREF)), gradients ``tp1`` = (TP1A, TP1B), ``tp2`` = (TP2A, TP2B) (see the module
    docstring). :class:`LoadError` for gradients on a PBEAM with a neutral-axis offset."""
    R, L, wa, wb = bar_frame(deck, b)
    p = deck.pbars[b.pid]
    d = np.zeros(12)
    d[6] = strain * L
    if any(tp1) or any(tp2):
        if p.n1 or p.n2:
            raise LoadError(1, f"a temperature gradient on bar {b.eid}, whose {p.card} {p.pid} has "
                               f"a neutral-axis offset (N1, N2): its thermal curvature about the "
                               f"offset axis is not modelled")
        inertia = np.array([[p.i1, p.i12], [p.i12, p.i2]])
        moments = -alpha * np.array([[p.i1 * tp1[0], p.i1 * tp1[1]], [p.i2 * tp2[0], p.i2 * tp2[1]]])
        (va, vb), (wa_, wb_) = np.linalg.solve(inertia, moments)    # curvatures at A and B
        d[7] = L * L * (va / 3.0 + vb / 6.0)                       # v(L), v'' linear in x
        d[8] = L * L * (wa_ / 3.0 + wb_ / 6.0)                     # w(L)
        d[10] = -0.5 * L * (wa_ + wb_)                             # theta_y = -w'(L)
        d[11] = 0.5 * L * (va + vb)                                # theta_z = v'(L)
    f = _local_stiffness(deck, b, np.array([L]))[0] @ d
    f12 = fixed_end_loads(deck, b, L, [(0.0, f[:6]), (L, f[6:])])
    return _to_grids(b, R, wa, wb, f12)


def thermal_rod_loads(deck, r, strain: float) -> dict[tuple[int, int], float]:
    """The nodal loads (basic) of rod ``r``'s free axial thermal ``strain``: E A strain along
    the rod, pulling its ends apart."""
    mid, a, _ = deck.rod_section(r)
    xa, xb = np.array(deck.grids[r.ga].xyz), np.array(deck.grids[r.gb].xyz)
    e = (xb - xa) / np.linalg.norm(xb - xa)
    n = deck.mat1s[mid].e * a * strain
    out: dict[tuple[int, int], float] = {}
    for grid, sign in ((r.ga, -1.0), (r.gb, 1.0)):
        for c in range(3):
            v = float(sign * n * e[c])
            if v != 0.0:
                out[(grid, c + 1)] = out.get((grid, c + 1), 0.0) + v
    return out


@dataclass
class Masses:
    """The mass a GRAV load acts on, from the deck's cards: mass per unit length of each bar
    property and rod (``rho A + NSM``; a CONROD by its EID; a bar property whose mass varies
    along it, end A's and end B's, :func:`bar_end_masses`), the CONM2 masses ``(grid, mass,
    offset in basic)`` and their inertia about the centre of gravity (``conm2_inertia``: no part
    of a GRAV load), the CONM1 mass matrices ``(grid, 6x6 in basic)``, the scalar masses to
    ground ``(grid, component, mass)`` (CMASS1, CMASS2; the component in the grid's CD system)
    and PARAM,WTMASS."""
    bar_pid: dict[int, float]
    rod_pid: dict[int, float]
    conrod: dict[int, float]
    conm2: list[tuple[int, float, tuple[float, float, float]]]
    wtmass: float = 1.0
    conm1: list[tuple[int, np.ndarray]] = None
    scalar: list[tuple[int, int, float]] = None
    conm2_inertia: list[tuple[int, np.ndarray]] = None   # (grid, 3x3 about the CG, basic)


def bar_end_masses(mpl, L: float) -> tuple[float, float]:
    """The lumped masses at a bar's two ends from its mass per length ``mpl`` (one value, or end
    A's and end B's of a tapered beam): half each, or ``L (2 a + b) / 6`` and ``L (a + 2 b) / 6``
    when it varies linearly from ``a`` to ``b`` (NASTRAN's lumped CBEAM mass: pyNastran's
    ``model_200`` GRAV case, NSM tapered, matched to NX NASTRAN's single-precision OP2)."""
    if isinstance(mpl, tuple):
        a, b = mpl
        return L * (2.0 * a + b) / 6.0, L * (a + 2.0 * b) / 6.0
    return 0.5 * mpl * L, 0.5 * mpl * L


def gravity_loads(deck, masses: Masses, accel) -> dict[tuple[int, int], float]:
    """The nodal loads (basic) of the acceleration field ``accel`` (basic) on the lumped mass:
    a 3-vector (GRAV: the same at every grid) or a function of the grid ID (RFORCE: the field of a
    rotation, at each grid). As NASTRAN's load ``M a`` with the lumped mass matrix M and the
    field's translational acceleration a at each grid (its rotational one zero): a mass off its
    grid (a CONM2's offset, a bar's offset end) is loaded by its grid's acceleration, its moment
    about the grid by the offset."""
    out: dict[tuple[int, int], float] = {}

    def add(key, v: float) -> None:
        if v != 0.0:
            out[key] = out.get(key, 0.0) + v

    field = accel if callable(accel) else (lambda grid, a=np.asarray(accel, float): a)

    def g(grid: int) -> np.ndarray:
        return np.asarray(field(grid), float) * masses.wtmass

    for b in deck.cbars.values():
        mpl = masses.bar_pid.get(b.pid, 0.0)
        if mpl:
            R, L, wa, wb = bar_frame(deck, b)
            ma, mb = bar_end_masses(mpl, L)
            ha, hb = R @ (ma * g(b.ga)), R @ (mb * g(b.gb))
            for key, v in _to_grids(b, R, wa, wb, np.concatenate([ha, np.zeros(3), hb, np.zeros(3)])).items():
                add(key, v)
    for r in deck.rods.values():
        mpl = masses.conrod.get(r.eid, 0.0) if r.pid is None else masses.rod_pid.get(r.pid, 0.0)
        if mpl:
            L = float(np.linalg.norm(np.subtract(deck.grids[r.gb].xyz, deck.grids[r.ga].xyz)))
            for grid in (r.ga, r.gb):
                gg = g(grid)
                for c in range(3):
                    add((grid, c + 1), float(0.5 * mpl * L * gg[c]))
    for grid, m, offset in masses.conm2:
        force = m * g(grid)
        moment = np.cross(np.asarray(offset, float), force)
        for c, v in enumerate((*force, *moment), start=1):
            add((grid, c), float(v))
    for grid, matrix in masses.conm1 or ():
        for c, v in enumerate(matrix[:, :3] @ g(grid), start=1):
            add((grid, c), float(v))
    for grid, comp, m in masses.scalar or ():
        if comp <= 3:                               # a rigid translation turns no grid
            d = deck.displacement_frames([grid])[0][comp - 1]
            for c, v in enumerate(d * (m * float(d @ g(grid))), start=1):
                add((grid, c), float(v))
    return out
