"""A study whose deck uses every card of the supported subset the way users' decks do.

A two-bay, one-storey space frame (six columns, top beams in x and y, a midspan grid on two
beams) written with: a CORD2R, a CORD2R defined in it (RID chain), a CORD1R on three grids, a
CORD2C; GRDSET giving every grid a default CD; grids positioned in CP systems; MAT1 with E and
NU only (G completed); PBAR, PBARL (I, BOX, TUBE), PBEAM with CBEAM; CBAR offsets WA/WB and a pin
flag; CROD/PROD and CONROD bracing; an RBE2 tie of the flexible joint (CM=123) and a rigid link
RBE2 (CM=123456); an RBE3 load-introduction grid; a CBUSH with PBUSH; CELAS2 between two grids
and CELAS1/PELAS to ground; CONM2 masses; SPC1 and SPC sets combined by an SPCADD; PARAM cards.
Small, large and free field lines are mixed.

The flexible joint ``J`` (4 branches: a column, two x beams, a y beam) sits at top grid 12,
whose grids have CD 3 (the CORD1R) and CD 1. Loads and measurements are in the grids' CD components, as the contract says.
:func:`write_rich_study` writes ``study.toml``, ``model.bdf``, ``loads.csv`` and the simulated
``measurements.csv`` (truth: the joint's springs at ``joint_k``; noise ``noise`` relative with a
floor) -- nothing planted: the declared model is the truth.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["rich_deck_text", "write_rich_study", "JOINT_GRIDS", "MEASURED", "SUPPORTS"]

JOINT_GRIDS = (12, 121, 122, 123)   # column top (branch 1), x beam from 11, x beam to 30, y beam
MEASURED = (12, 121, 122, 123, 13, 14, 16, 30, 40, 60)
SUPPORTS = (1, 2, 3, 4, 5, 6)


def _rot(axis: str, deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    if axis == "z":
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


# coordinate systems: rows of R are the system's axes in basic
O1, R1 = np.array([1.0, 0.5, 0.0]), _rot("z", 30.0)
O2_IN_1, R2_IN_1 = np.array([0.0, 0.0, 3.0]), _rot("x", 20.0)
O2, R2 = O1 + O2_IN_1 @ R1, R2_IN_1 @ R1
O4 = np.array([3.0, 1.0, 0.0])          # CORD2C axis along basic z through (3, 1)

H, BAY, DEPTH = 3.0, 3.0, 2.0


def _positions() -> dict[int, np.ndarray]:
    p = {}
    for i, (x, y) in enumerate([(0, 0), (BAY, 0), (2 * BAY, 0), (0, DEPTH), (BAY, DEPTH), (2 * BAY, DEPTH)]):
        p[1 + i] = np.array([x, y, 0.0])            # bases 1..6
        p[11 + i] = np.array([x, y, H])             # tops 11..16
    for g in (121, 122, 123):                       # joint branches at grid 12
        p[g] = p[12].copy()
    p[30] = np.array([1.5 * BAY, 0.0, H])           # midspan of beam 12-13
    p[40] = np.array([1.5 * BAY, DEPTH, H])         # midspan of beam 15-16
    p[50] = np.array([0.5 * BAY, DEPTH, H])         # splice of beam 14-15 (CBUSH 50-51)
    p[51] = p[50].copy()
    p[60] = np.array([BAY, 0.5 * DEPTH, H + 0.4])   # RBE3 load-introduction grid above 12/15
    p[70] = np.array([0.0, 0.0, H + 0.4])           # rigid bracket above 11 (RBE2 123456)
    return p


def _f(v: float) -> str:
    """A free-field real that reads back exactly."""
    s = repr(float(v))
    return s if ("." in s or "e" in s) else s + "."


def _cord2(card: str, cid: int, rid: int, a, b, c) -> list[str]:
    """A CORD2x in free field: A and B on the first line, C on a continuation."""
    return [f"{card},{cid},{rid}," + ",".join(_f(v) for v in (*a, *b)) + ",+C" + str(cid),
            f"+C{cid}," + ",".join(_f(v) for v in c)]


def _large_real(v: float) -> str:
    s = f"{v:.12g}"
    return s if ("." in s or "e" in s) else s + "."


def _small(name: str, fields: list) -> str:
    """One small-field card (8-character fields, continuation lines as needed)."""
    def fmt(v):
        if v is None:
            return " " * 8
        if isinstance(v, float):
            s = f"{v:.6g}"
            if "." not in s and "e" not in s:
                s += "."
            s = s.replace("e", "E")
            if len(s) > 8:
                s = f"{v:.2E}"
            return f"{s:<8}"[:8]
        return f"{str(v):<8}"[:8]
    lines, row = [], f"{name:<8}"
    for i, v in enumerate(fields):
        if i and i % 8 == 0:
            lines.append(row + "+")
            row = "+       "
        row += fmt(v)
    lines.append(row.rstrip())
    return "\n".join(lines)


def rich_deck_text() -> str:
    p = _positions()
    out = ["$ a users'-style deck: every supported card (tests/rich_deck.py)", "BEGIN BULK",
           "PARAM,POST,-1", "PARAM   AUTOSPC YES",
           # coordinate systems: CORD2R 1 in basic, CORD2R 2 in 1 (RID chain), CORD1R 3 on grids
           # 1, 11, 2 (origin at grid 1, z up, x toward grid 2), CORD2C 4 in basic
           *_cord2("CORD2R", 1, 0, O1, O1 + R1[2], O1 + R1[0]),
           *_cord2("CORD2R", 2, 1, O2_IN_1, O2_IN_1 + R2_IN_1[2], O2_IN_1 + R2_IN_1[0]),
           "CORD1R  3       1       11      2",
           *_cord2("CORD2C", 4, 0, O4, O4 + [0, 0, 1.0], O4 + [1.0, 0, 0]),
           "GRDSET,,,,,,1",                          # default CD 1 for every grid
           ]
    cp = {13: 2, 16: 2, 40: 2, 60: 1}               # grids positioned in another system
    # RBE3 403 (grid 60 on 13, 15, 16) is all in basic: MYSTRAN 18 weighs RBE3 grids in
    # another CD system differently from NASTRAN (docs/mystran.md), and the deck must solve alike
    # in both solvers
    cd = {12: 3, 121: 3, 122: 3, 123: 3, 1: 0, 4: 4, 14: 4, 30: 2, 40: 0, 50: 2, 51: 2, 70: 0,
          13: 0, 15: 0, 16: 0, 60: 0}
    origin = {1: O1, 2: O2}
    rot = {1: R1, 2: R2}
    for g in sorted(p):
        x = p[g]
        if g in cp:
            x = (x - origin[cp[g]]) @ rot[cp[g]].T
        c = cd.get(g)
        fields = [g, cp.get(g), *map(float, x), c if c is not None else None]
        if g % 3 == 0:
            out.append("GRID," + ",".join("" if v is None else (_f(v) if isinstance(v, float) else str(v))
                                          for v in fields))
        elif g % 3 == 1:
            out.append(f"GRID*   {g:<16}{'' if cp.get(g) is None else cp[g]:<16}{_large_real(x[0]):<16}"
                       f"{_large_real(x[1]):<16}+\n*       {_large_real(x[2]):<16}{'' if c is None else c:<16}")
        else:
            out.append("GRID," + ",".join("" if v is None else (_f(v) if isinstance(v, float) else str(v))
                                          for v in fields))
    # material: E and NU (G = E / (2 (1 + NU)) completed), RHO (no effect in statics)
    out.append("MAT1,1,2.1E11,,0.3,7850.")
    out += ["PBAR,1,1,4.0E-3,8.0E-6,6.0E-6,1.2E-5",                     # columns
            "PBARL,2,1,,I", "+,0.24,0.12,0.12,0.01,0.012,0.012",          # beams in x: I section
            "PBARL,3,1,,BOX", "+,0.16,0.12,0.008,0.008",                  # beams in y: box
            "PBARL,4,1,,TUBE", "+,0.05,0.04",                             # secondary
            "PBEAM,5,1,3.0E-3,5.0E-6,4.0E-6,0.,8.0E-6",                   # CBEAM member
            "PROD,6,1,5.0E-4,1.0E-8",
            "PBUSH,7,K,1.0E9,1.0E9,1.0E9,1.0E7,1.0E7,1.0E7",
            "PELAS,8,5.0E6"]
    eid = 100

    def bar(ga, gb, pid, v, card="CBAR", pa="", pb="", wa=None, wb=None):
        nonlocal eid
        eid += 1
        f = [eid, pid, ga, gb, *map(float, v)]
        if pa or pb or wa is not None or wb is not None:
            f += [None, pa or None, pb or None, *(wa or (None,) * 3), *(wb or (None,) * 3)]
        out.append(_small(card, f))

    for i in range(6):                       # columns (orientation vector in GA's CD system)
        bar(1 + i, 11 + i, 1, (1.0, 0.0, 0.0))
    bar(11, 121, 2, (0.0, 0.0, 1.0))                                # joint branch 121: x beam from 11
    bar(122, 30, 2, (0.0, 0.0, 1.0), wb=(0.0, 0.0, 0.05))           # branch 122: x beam, offset at 30
    bar(30, 13, 2, (0.0, 0.0, 1.0), wa=(0.0, 0.0, 0.05))
    bar(123, 15, 3, (0.0, 0.0, 1.0))                                # branch 123: y beam (box)
    bar(11, 14, 3, (0.0, 0.0, 1.0))
    bar(13, 16, 3, (0.0, 0.0, 1.0))
    bar(14, 50, 3, (0.0, 0.0, 1.0))                                 # to the splice (CBUSH 50-51)
    bar(51, 15, 3, (0.0, 0.0, 1.0))
    bar(15, 40, 5, (0.0, 0.0, 1.0), card="CBEAM")                   # PBEAM 5
    bar(40, 16, 2, (0.0, 0.0, 1.0), pb="6")                         # pin flag at end B (16)
    bar(70, 14, 4, (0.0, 0.0, 1.0))                                 # tube from the rigid bracket
    out.append("CROD,201,6,2,13")                                   # bracing diagonals
    out.append("CONROD,202,6,15,1,6.0E-4,1.0E-8")
    out.append("CBUSH,301,7,50,51,,,,0")                            # CID 0: coincident grids
    out.append("RBE2,401,12,123,121,122,123")                       # the joint's translation tie
    out.append("RBE2,402,11,123456,70")                             # a rigid bracket
    out.append("RBE3,403,,60,123456,1.0,123,13,15,+R3\n+R3,16")      # load introduction at 60
    out.append("CELAS2,501,2.0E7,51,3,70,3")                        # a spring between two grids
    out.append("CELAS1,502,8,6,4")                                  # rotation spring to ground
    out.append("CONM2,601,15,,120.")
    out.append("CONM2,602,30,,80.")
    out += ["SPC1,1,123456,1,2,3", "SPC1    2       123456  4       5",
            "SPC,3,6,123,0.", "SPCADD,10,1,2,3"]
    out.append("ENDDATA")
    return "\n".join(out) + "\n"


def write_rich_study(folder: Path, *, n_cases: int = 12, seed: int = 3, joint_k: float = 2.0e6,
                     noise: float = 0.02, holdout: int = 2, adapter: str = "reference") -> Path:
    """The study folder (module docstring), measurements simulated with ``blackbox simulate``
    from the joint's springs at ``joint_k``; ``holdout`` of the cases declared hold-out."""
    from blackbox.commands import simulate as simulate_cmd

    folder = Path(folder)
    src = folder.parent / (folder.name + "_src")
    src.mkdir(parents=True)
    (src / "model.bdf").write_text(rich_deck_text())
    rng = np.random.default_rng(seed)
    loaded = [12, 13, 14, 16, 30, 40, 60, 121, 123]
    rows = []
    for c in range(n_cases):
        for g in rng.choice(loaded, size=3, replace=False):
            comp = int(rng.integers(1, 7))
            val = float(rng.normal()) * (2.0e3 if comp <= 3 else 5.0e2)
            rows.append(f"L{c + 1},{g},{comp},{val!r}")
    (src / "loads.csv").write_text("case,grid,component,value\n" + "\n".join(rows) + "\n")
    hold = ", ".join(f'"L{n_cases - i}"' for i in range(holdout))
    (src / "study.toml").write_text(
        f'name = "rich"\n\n[solver]\nadapter = "{adapter}"\ndeck = "model.bdf"\n\n'
        f'[[joints]]\nname = "J"\ngrids = [{", ".join(map(str, JOINT_GRIDS))}]\nmodel = "simple"\n'
        f"initial = 1.0e5\n\n[identification]\nholdout_cases = [{hold}]\n")
    truth = src / "truth.toml"
    truth.write_text(f"seed = {seed}\n[[joints]]\nname = \"J\"\nmodel = \"simple\"\nvalue = {joint_k!r}\n"
                     f"[noise]\nrelative = {noise!r}\nfloor = 0.05\n[measure]\njoint = true\n"
                     f"away_grids = [{', '.join(str(g) for g in MEASURED if g not in JOINT_GRIDS)}]\n")
    res = simulate_cmd.run(src, truth)
    folder.mkdir()
    res.write(folder)
    return folder
