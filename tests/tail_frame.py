"""A frame deck that uses every card of the deck tail (docs/import.md), and the same structure
and loads as a deck MYSTRAN 18 runs, for tests/test_deck_tail.py.

The frame (``FRAME``): columns, beams and a brace between seven grids, clamped at grids 1 and 4:

* CBAR with PBAR (NSM for the gravity load) and with the OFFT options GGO, BGO, GOG, BOG,
  GOO, BOO (offsets given in the offset system: x from GA to GB, y in the plane of x and the
  orientation vector, z = x cross v), a CBEAM with a PBEAM that has a warping coefficient CW,
  a neutral axis offset N1 N2, an end B with its area A left blank and I1 printed with fewer
  digits than at end A, a CROD, and a pin flag;
* masses: MAT1 RHO, PBAR NSM, CONM2 with an offset, CONM1 (diagonal), CMASS2 to ground, CMASS1
  with PMASS; cards with no effect on a linear static solution: MDLPRM, EIGRL, EIGR, DEBUG,
  PARAM, PLOTEL;
* loads: subcase 1 the PLOAD1 of every TYPE and SCALE (concentrated and distributed, uniform
  and linear, on part of a bar and on a whole one, on a bar with offsets and with a pin flag),
  subcase 2 GRAV (in a rectangular system CID) with PARAM,WTMASS, subcase 3 a LOAD combination
  of those and a FORCE set, its first line's trailing fields left blank.

:func:`mystran_deck` writes the same structure as MYSTRAN runs it, each step a definition of
the card it replaces, computed here independently of the reader: offsets in the basic system
(the offset system built from the grids), the CBEAM as two CBARs (the axial stiffness on the
neutral axis through rigid offsets, bending, torsion and mass on the shear-centre axis; its PBEAM has
K1 = K2 = 0.0, no shear flexibility, which a bending bar of negligible area then reproduces),
every PLOAD1 as point loads (FORCE, MOMENT) on grids added along its bar (a distributed load
on its three Gauss points: exact for a linear load on a bar whose end loads are cubic in the
load's position), CONM1 as the CONM2 of its diagonal, the scalar masses (CMASS1, CMASS2, which
MYSTRAN 18 cannot run here: it stops in SPARSE_MGG with any CMASS2 in this model) as their
gravity load, the force m a_C on their component (with PARAM,WTMASS), and the cards MYSTRAN
does not read but have no effect left out.
"""

from __future__ import annotations

import numpy as np

E, G_MOD, RHO = 2.1e11, 8.1e10, 7800.0
GRIDS = {1: (0.0, 0.0, 0.0), 2: (0.0, 0.0, 3.0), 3: (4.0, 0.0, 3.0), 4: (4.0, 0.0, 0.0),
         5: (0.0, 3.0, 3.0), 6: (4.0, 3.0, 3.0), 7: (2.0, 3.0, 0.5)}
CLAMPED = (1, 4)
PBAR = {1: (2.0e-3, 3.0e-6, 2.0e-6, 4.0e-6, 2.5), 2: (1.5e-3, 1.8e-6, 1.2e-6, 2.0e-6, 0.0)}
"""PID -> A, I1, I2, J, NSM."""
# EID -> (GA, GB, PID, orientation vector, OFFT, WA, WB in basic, PA, PB)
BARS = {
    11: (1, 2, 1, (1.0, 0.0, 0.0), "GGO", (0.0, 0.0, 0.0), (0.05, 0.02, 0.0), "", ""),
    12: (2, 3, 1, (0.0, 0.0, 1.0), "GOO", (0.0, 0.1, 0.0), (0.0, 0.1, -0.05), "", ""),
    13: (4, 3, 2, (0.0, 1.0, 0.0), "BGO", (0.0, 0.0, 0.0), (0.03, 0.0, 0.0), "", ""),
    15: (5, 6, 2, (0.0, 0.0, 1.0), "GOG", (0.0, 0.0, -0.04), (0.0, 0.0, 0.0), "", "5"),
    16: (3, 6, 2, (0.0, 0.0, 1.0), "BOG", (0.0, 0.02, 0.03), (0.0, 0.0, 0.0), "", ""),
    17: (6, 7, 1, (0.0, 0.0, 1.0), "BOO", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), "", ""),
}
BEAM = (14, 2, 5, (0.0, 0.0, 1.0))           # CBEAM EID GA GB v, PBEAM 3 below
PBEAM = dict(a=2.5e-3, i1=4.0e-6, i2=3.0e-6, j=5.0e-6, cw=1.3e-9, n1=0.012, n2=-0.02)
ROD = (18, 4, 7, 4.0e-4, 0.0)                # CROD EID GA GB (PROD A J)
# PLOAD1 set 100: (EID, TYPE, SCALE, X1, P1, X2, P2); X2 None: concentrated
PLOAD1 = [
    (12, "FZ", "FR", 0.2, -1500.0, 0.8, -900.0),      # linear, part of the bar, offsets
    (12, "MZE", "LE", 1.5, 300.0, None, None),        # concentrated moment, element axes
    (11, "FX", "LE", 0.0, 800.0, 3.0, 800.0),         # uniform over the whole column
    (13, "FYE", "FR", 0.5, 2000.0, None, None),       # concentrated, element y
    (14, "FZ", "LE", 0.5, -1200.0, 2.5, -600.0),      # on the beam with a neutral axis
    (15, "FXE", "FR", 0.25, 500.0, None, None),       # axial, on a bar with a pin flag
    (15, "MYE", "FR", 0.0, -100.0, 1.0, 200.0),       # distributed moment
    (16, "MX", "FR", 0.5, 150.0, None, None),         # concentrated moment, basic x
    (16, "FYE", "LE", 0.5, 700.0, 2.0, 700.0),        # uniform, part of the bar
    (17, "FZ", "LEPR", 0.0, -1000.0, 2.0, -400.0),    # projected, linear, on the brace
    (17, "FY", "FRPR", 0.3, 600.0, 0.9, 600.0),       # projected, uniform
    (17, "MY", "FRPR", 0.6, 250.0, None, None),       # projected concentrated: not projected
]
GRAV = (200, 9, 9.81, (0.2, -0.3, -1.0))      # GRAV SID CID A N, in CORD2R 9
CORD9 = ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0))    # A, B, C: x9 = y, y9 = -x, z9 = z
WTMASS = 0.8
CONM2 = (21, 7, 35.0, (0.1, -0.2, 0.15))      # EID G M offset (basic)
CONM1 = (22, 5, 12.0)                         # EID G m (diagonal translational mass)
CMASS2 = (23, 6, 3, 8.0)                      # EID G C M, to ground
CMASS1 = (24, 3, 1, 31, 5.0)                  # EID G C PID M (PMASS)
FORCE = (300, 6, (1000.0, -500.0, 250.0))     # FORCE set 300 at grid 6


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def offset_axes(ga: int, gb: int, v) -> np.ndarray:
    """Rows x, y, z of the offset system: x from GA to GB (the grids), z = x cross v, y = z x x."""
    x = _unit(np.subtract(GRIDS[gb], GRIDS[ga]))
    z = _unit(np.cross(x, v))
    return np.array([x, np.cross(z, x), z])


def _f(x: float) -> str:
    """A real in at most 16 characters (MYSTRAN reads no more of a free field)."""
    from solver_adapters.bdf_write import print_float_16
    return print_float_16(float(x))


def _card(name: str, *fields) -> str:
    """A free-field card, 8 fields a line (continuation lines start with a comma)."""
    items = ["" if f is None else (_f(f) if isinstance(f, float) else str(f)) for f in fields]
    lines = [name + "," + ",".join(items[:8])]
    for k in range(8, len(items), 8):
        lines.append("," + ",".join(items[k:k + 8]))
    return "\n".join(lines) + "\n"


def _mass_cards() -> str:
    eid, g, m, off = CONM2
    out = _card("CONM2", eid, g, None, m, *map(float, off))
    return out + "".join(_card("MAT1", mid, E, G_MOD, None, RHO) for mid in (1,))


def _cord9_axes() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The axes of CORD2R 9 in basic (MSC QRG CORD2R: z towards B, x-z plane through C)."""
    a, b, c = (np.asarray(p, float) for p in CORD9)
    z = _unit(b - a)
    y = _unit(np.cross(z, c - a))
    return np.cross(y, z), y, z


def nastran_deck() -> str:
    """The frame as a whole NASTRAN input file with every card of the deck tail."""
    case = ["SOL 101", "CEND", "TITLE = deck tail frame", "SPC = 1", "DISPLACEMENT = ALL",
            "SUBCASE 1", "  LOAD = 100", "SUBCASE 2", "  LOAD = 200", "SUBCASE 3", "  LOAD = 400",
            "BEGIN BULK"]
    b = ["MDLPRM,HDF5,1\n", "EIGRL,900,,,6\n", "EIGR,901,MGIV,0.,100.,,4\n", "DEBUG,10,1\n",
         "PARAM,POST,-1\n", f"PARAM,WTMASS,{_f(WTMASS)}\n", "PLOTEL,99,1,3\n"]
    b += [_card("GRID", g, None, *map(float, xyz)) for g, xyz in GRIDS.items()]
    b.append(_card("SPC1", 1, 123456, *CLAMPED))
    a, bb, c = CORD9
    b.append(_card("CORD2R", 9, 0, *map(float, a), *map(float, bb), *map(float, c)))
    for pid, (area, i1, i2, j, nsm) in PBAR.items():
        b.append(_card("PBAR", pid, 1, area, i1, i2, j, nsm))
    for eid, (ga, gb, pid, v, offt, wa, wb, pa, pb) in BARS.items():
        axes = offset_axes(ga, gb, v)
        ends = []
        for letter, w in zip(offt[1:], (wa, wb)):
            ends += list(axes @ np.asarray(w, float)) if letter == "O" else list(w)
        b.append(_card("CBAR", eid, pid, ga, gb, *map(float, v), offt, pa or None, pb or None,
                       *map(float, ends)))
    eid, ga, gb, v = BEAM
    p = PBEAM
    b.append(_card("CBEAM", eid, 3, ga, gb, *map(float, v)))
    i1_b = float(f"{p['i1']:.5e}") + 2.0e-11              # end B: I1 printed with fewer digits
    b.append(_card("PBEAM", 3, 1, p["a"], p["i1"], p["i2"], 0.0, p["j"], None,
                   *[None] * 8,
                   "YESA", 1.0, None, f"{i1_b:.6g}", None, None, None, None,
                   0.0, 0.0, None, None, None, None, p["cw"], p["cw"],
                   None, None, None, None, p["n1"], p["n2"], p["n1"], p["n2"]))
    eid, ga, gb, area, j = ROD
    b += [_card("CROD", eid, 5, ga, gb), _card("PROD", 5, 1, area, j)]
    b.append(_mass_cards())
    eid, g, m = CONM1
    b.append(_card("CONM1", eid, g, None, m, None, m, None, None, m))
    eid, g, c, m = CMASS2
    b.append(_card("CMASS2", eid, m, g, c))
    eid, g, c, pid, m = CMASS1
    b += [_card("CMASS1", eid, pid, g, c), _card("PMASS", pid, m)]
    for eid_, kind, scale, x1, p1, x2, p2 in PLOAD1:
        b.append(_card("PLOAD1", 100, eid_, kind, scale, x1, p1, x2, p2))
    sid, cid, acc, n = GRAV
    b.append(_card("GRAV", sid, cid, acc, *map(float, n)))
    sid, g, f = FORCE
    b.append(_card("FORCE", sid, g, None, 1.0, *map(float, f)))
    # LOAD 400: the first line ends with a pair left blank, the continuation holds the last pair
    b.append("LOAD,400,1.5,1.,100,-0.5,200,,\n,2.,300\n")
    return "\n".join(case) + "\n" + "".join(b) + "ENDDATA\n"


# --------------------------------------------------------------------------------------------
# the same structure and loads as MYSTRAN runs them
# --------------------------------------------------------------------------------------------
_GAUSS = ((-np.sqrt(0.6), 5.0 / 9.0), (0.0, 8.0 / 9.0), (np.sqrt(0.6), 5.0 / 9.0))


def _bar_line(eid: int):
    """(end A point, end B point, element axes rows, pid, v, pa, pb, wa, wb) in basic."""
    if eid == BEAM[0]:
        _, ga, gb, v = BEAM
        wa = wb = np.zeros(3)
        pa = pb = ""
        pid = 3
    else:
        ga, gb, pid, v, _, wa, wb, pa, pb = BARS[eid]
        wa, wb = np.asarray(wa, float), np.asarray(wb, float)
    a, b = np.asarray(GRIDS[ga]) + wa, np.asarray(GRIDS[gb]) + wb
    x = _unit(b - a)
    z = _unit(np.cross(x, v))
    return a, b, np.array([x, np.cross(z, x), z]), pid, v, pa, pb, wa, wb, ga, gb


def _point_loads(eid: int) -> list[tuple[float, np.ndarray]]:
    """The PLOAD1 of bar ``eid`` as point loads ``(x along the bar, 6-vector in basic)``."""
    a, b, axes, *_ = _bar_line(eid)
    L = float(np.linalg.norm(b - a))
    out = []
    for e, kind, scale, x1, p1, x2, p2 in PLOAD1:
        if e != eid:
            continue
        k = ["FX", "FY", "FZ", "MX", "MY", "MZ", "FXE", "FYE", "FZE", "MXE", "MYE", "MZE"].index(kind)
        d = axes[k % 3] if k >= 6 else np.eye(3)[k % 3]
        moment = (k % 6) >= 3
        frac = scale in ("FR", "FRPR")
        s1 = x1 * L if frac else x1

        def vec(mag):
            v6 = np.zeros(6)
            v6[3 * moment:3 * moment + 3] = mag * d
            return v6

        if x2 is None:
            out.append((s1, vec(p1)))
            continue
        s2 = x2 * L if frac else x2
        proj = np.sqrt(1.0 - float(np.dot(axes[0], d)) ** 2) if scale.endswith("PR") else 1.0
        for xi, w in _GAUSS:
            s = 0.5 * (s1 + s2) + 0.5 * (s2 - s1) * xi
            p = p1 + (p2 - p1) * (s - s1) / (s2 - s1)
            out.append((s, vec(w * 0.5 * (s2 - s1) * p * proj)))
    return out


def mystran_deck(subcases: tuple[int, ...], refine: bool) -> str:
    """The frame as MYSTRAN runs it (see the module docstring), one subcase per load set of
    ``subcases`` (100 PLOAD1, 200 GRAV, 300 FORCE). ``refine``: the bars cut at the PLOAD1's
    points (for set 100); without, the bars are whole, as a GRAV needs them (a lumped mass
    matrix depends on where the bars end)."""
    case = ["SOL 101", "CEND", "ECHO = NONE", "SPC = 1", "DISPLACEMENT = ALL"]
    for k, sid in enumerate(subcases, start=1):
        case += [f"SUBCASE {k}", f"  LOAD = {sid}"]
    case.append("BEGIN BULK")
    b = [f"PARAM,WTMASS,{_f(WTMASS)}\n", "PARAM,AUTOSPC,YES\n"]
    b += [_card("GRID", g, None, *map(float, xyz)) for g, xyz in GRIDS.items()]
    b.append(_card("SPC1", 1, 123456, *CLAMPED))
    a9, b9, c9 = CORD9
    b.append(_card("CORD2R", 9, 0, *map(float, a9), *map(float, b9), *map(float, c9)))
    for pid, (area, i1, i2, j, nsm) in PBAR.items():
        b.append(_card("PBAR", pid, 1, area, i1, i2, j, nsm))
    p = PBEAM
    # bending and torsion (with the beam's mass on its axis), and the axial part (massless)
    b.append(_card("PBAR", 3, 1, 1e-12 * p["a"], p["i1"], p["i2"], p["j"], RHO * p["a"]))
    b.append(_card("PBAR", 4, 2, p["a"] * (1 - 1e-12), 0.0, 0.0, 0.0))
    b.append(_card("MAT1", 2, E, G_MOD, None, 0.0))
    next_grid, next_eid = 1000, 1000
    forces: dict[int, list[str]] = {100: [], 200: [], 300: [], 400: []}
    for eid in (*BARS, BEAM[0]):
        a, b_, axes, pid, v, pa, pb, wa, wb, ga, gb = _bar_line(eid)
        L = float(np.linalg.norm(b_ - a))
        points = sorted(_point_loads(eid), key=lambda t: t[0]) if refine else []
        stations = sorted({s for s, _ in points if 1e-12 * L < s < L * (1 - 1e-12)})
        ids = {}
        nodes = [ga]
        for s in stations:
            ids[s] = next_grid
            b.append(_card("GRID", next_grid, None, *map(float, a + s * axes[0])))
            nodes.append(next_grid)
            next_grid += 1
        nodes.append(gb)
        for s, v6 in points:
            g = ga if s <= 1e-12 * L else gb if s >= L * (1 - 1e-12) else ids[s]
            # a load at a bar end sits on the offset end: carried to the grid by the offset
            w = wa if g == ga else wb if g == gb else np.zeros(3)
            force, moment = v6[:3], v6[3:] + np.cross(w, v6[:3])
            if force.any():
                forces[100].append(_card("FORCE", 100, g, None, 1.0, *map(float, force)))
            if moment.any():
                forces[100].append(_card("MOMENT", 100, g, None, 1.0, *map(float, moment)))
        for k in range(len(nodes) - 1):
            first, last = k == 0, k == len(nodes) - 2
            ends = [*(wa if first else (0.0, 0.0, 0.0)), *(wb if last else (0.0, 0.0, 0.0))]
            pins = (pa if first else "", pb if last else "")
            e = eid if k == 0 else next_eid
            if k:
                next_eid += 1
            if eid == BEAM[0]:
                # axial part on the neutral axis: rigid offsets n (element y, z) at both ends
                n = p["n1"] * axes[1] + p["n2"] * axes[2]
                b.append(_card("CBAR", e, 3, nodes[k], nodes[k + 1], *map(float, v)))
                b.append(_card("CBAR", next_eid, 4, nodes[k], nodes[k + 1], *map(float, v), None,
                               None, None, *map(float, n), *map(float, n)))
                next_eid += 1
            else:
                b.append(_card("CBAR", e, pid, nodes[k], nodes[k + 1], *map(float, v), None,
                               pins[0] or None, pins[1] or None, *map(float, ends)))
    eid, ga, gb, area, j = ROD
    b += [_card("CROD", eid, 5, ga, gb), _card("PROD", 5, 1, area, j)]
    b.append(_mass_cards())
    eid, g, m = CONM1
    b.append(_card("CONM2", eid, g, None, m))
    sid, cid, acc, n = GRAV
    b.append(_card("GRAV", 201, cid, acc, *map(float, n)))
    x9, y9, z9 = _cord9_axes()
    a_basic = acc * (n[0] * x9 + n[1] * y9 + n[2] * z9)
    for _, g, c, m in (CMASS2, CMASS1[:3] + (CMASS1[4],)):
        f = np.zeros(3)
        f[c - 1] = WTMASS * m * a_basic[c - 1]             # grids without CD: basic components
        b.append(_card("FORCE", 202, g, None, 1.0, *map(float, f)))
    b.append("LOAD,200,1.,1.,201,1.,202\n")
    sid, g, f = FORCE
    b.append(_card("FORCE", sid, g, None, 1.0, *map(float, f)))
    b += forces[100]

    return "\n".join(case) + "\n" + "".join(b) + "ENDDATA\n"
