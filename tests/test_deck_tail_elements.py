"""Elements of the long tail of real decks (issue 20): RBAR (a rigid bar), CTUBE/PTUBE (a rod
of tube section), CBUSH with its spring off the line GA-GB (OCID, S1-S3) and MPC/MPCADD (linear
multipoint constraints selected by MPC = in the case control).

References:

* closed forms. Cantilever of length L, tip force P and moment M (Timoshenko & Gere, *Mechanics
  of Materials*): deflection P L^3 / (3 E I) + M L^2 / (2 E I), rotation P L^2 / (2 E I) + M L / (E I);
  a rigid arm of length a from the tip carries the load P there as P and M = P a at the tip and
  moves as u + theta x a. Rod: axial P L / (E A), torsion T L / (G J), with the tube's
  A = pi (OD^2 - D^2) / 4 and J = pi (OD^4 - D^4) / 32, D = OD - 2 T (MSC QRG PTUBE). A spring
  k between two points rigidly attached to two grids (MSC QRG CBUSH): the grid forces are
  C^T k C u, C the rigid-body map of each grid to the spring point. A constraint u_a = 2 u_b
  between two axial springs: the minimum of the energy K1 (2 u_b)^2 / 2 + K2 u_b^2 / 2 - P u_b.
* MYSTRAN 18 run as a subprocess: on the original deck where it solves every card (CBUSH with
  OCID and S1-S3, MPC), else on the study written by the mystran adapter (CTUBE, which MYSTRAN
  does not have, as the CROD/PROD of the same A and J; RBAR, which it reads but does not solve,
  as its RBE2).

Tolerances: closed forms to CLOSED = 1e-9 relative (a direct solve of a few DOFs in double
precision; any wrong term is of order 1e-2 or more); MYSTRAN, which prints 7 significant digits,
to RTOL = 1e-6 of each subcase's largest translation (rotation), as in tests/test_deck_tail.py.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import DeckFormatError, LoadMatrix, ModelError
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran
from test_deck_tail import CLOSED, RTOL, _agree, _import, _mystran, _solve

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

E, NU = 2.0e11, 0.3
G = E / (2.0 * (1.0 + NU))
A, I, J = 1.0e-3, 2.0e-6, 3.0e-6


def _static(bulk: str, loads: str, cases: int = 1) -> str:
    """A SOL 101 input file: ``cases`` subcases, subcase i with LOAD = i, every grid printed."""
    cc = "".join(f"SUBCASE {i}\n  LOAD = {i}\n" for i in range(1, cases + 1))
    return (f"SOL 101\nCEND\nDISPLACEMENT = ALL\nSPC = 1\n{cc}BEGIN BULK\n{bulk}{loads}"
            "ENDDATA\n")


def _by_grid(report, u, j: int, grids) -> np.ndarray:
    return np.array([[u[report.index((g, c)), j] if (g, c) in report else 0.0 for c in range(1, 7)]
                     for g in grids])


def _against_mystran(tmp_path: Path, text: str, n_cases: int) -> float:
    """The input file imported and solved by the reference solver against MYSTRAN running the
    file itself: the worst relative difference over every subcase and printed grid."""
    cases, report, u = _solve(_import(tmp_path, text))
    tables = _mystran(tmp_path / "mystran", text)
    assert len(cases) == n_cases and sorted(tables) == list(range(1, n_cases + 1))
    worst = 0.0
    for j, case in enumerate(cases):
        grids = sorted(tables[int(case)])
        ref = np.array([tables[int(case)][g] for g in grids])
        worst = max(worst, _agree(_by_grid(report, u, j, grids), ref, f"subcase {case}"))
    return worst


def _study_against_mystran(tmp_path: Path, text: str, n_cases: int) -> float:
    """The input file imported, its study solved by the reference solver and by the mystran
    adapter (which writes the run deck from the parsed model): the worst relative difference
    over every subcase and grid."""
    from blackbox.commands.output import write_output
    from blackbox.study import load_study
    from solver_adapters.nastran import MystranAdapter
    result = _import(tmp_path, text)
    cases, report, u = _solve(result)
    out = tmp_path / "study"
    write_output(out, "import", result.write)
    study = load_study(out)
    assert list(study.loads.cases) == cases and len(cases) == n_cases
    mys = MystranAdapter(out / "model.bdf").solve(study.loads, report).values
    grids = sorted({g for g, _ in report})
    return max(_agree(_by_grid(report, u, j, grids), _by_grid(report, mys, j, grids), f"case {c}")
               for j, c in enumerate(cases))


# --------------------------------------------------------------------------------------------
# RBAR
# --------------------------------------------------------------------------------------------
L, ARM = 2.0, 0.5
CANTILEVER = (f"GRID,1,,0.,0.,0.\nGRID,2,,{L},0.,0.\nGRID,3,,{L + ARM},0.,0.\n"
              f"CBAR,1,1,1,2,0.,1.,0.\nPBAR,1,1,{A},{I},{I},{J}\nMAT1,1,{E},,{NU}\nSPC1,1,123456,1\n")


def _tip_of_arm(p: float) -> tuple[float, float]:
    """Deflection and rotation at the end of a rigid arm ARM long on the cantilever's tip,
    force p there across the arm: the tip carries p and the moment p ARM."""
    m = p * ARM
    w2 = p * L ** 3 / (3 * E * I) + m * L ** 2 / (2 * E * I)
    t2 = p * L ** 2 / (2 * E * I) + m * L / (E * I)
    return w2 + t2 * ARM, t2


@pytest.mark.parametrize("rbar", ["RBAR,5,2,3,123456", "RBAR,5,3,2,0,123456,0,0",
                                  "RBAR,5,2,3,123456,,,123456", "RBAR,5,2,3,123456,,,3"])
def test_rbar_rigid_arm_closed_form(rbar, tmp_path):
    """A rigid arm at the cantilever's tip, as RBAR with CNA = 123456 (CMA, CMB blank: every
    component of GB dependent), the same with GA and GB swapped (CNB = 123456; 0 for blank, as
    NASTRAN allows), with CMB given,
    and with CMB = 3 (only the deflection tied; grid 3's other components have no stiffness and
    AUTOSPC takes them)."""
    p = -1500.0
    text = _static(CANTILEVER + rbar + "\n", "FORCE,1,3,,1.,0.,0.,1.\n".replace("1.\n", f"{p}\n"))
    result = _import(tmp_path, text)
    assert 'adapter = "reference"' in result.study_toml
    cases, report, u = _solve(result)
    w3, t3 = _tip_of_arm(p)
    assert u[report.index((3, 3)), 0] == pytest.approx(w3, rel=CLOSED)
    assert u[report.index((2, 5)), 0] == pytest.approx(-t3, rel=CLOSED)   # +z force: -theta_y
    if rbar.endswith(",3"):
        assert (3, 5) not in report or abs(u[report.index((3, 5)), 0]) == 0.0
    else:
        assert u[report.index((3, 5)), 0] == pytest.approx(-t3, rel=CLOSED)


def test_rbar_held_as_the_rbe2_it_is():
    deck = read_deck_text(CANTILEVER + "RBAR,5,3,2,,123456,12,,1.2-5\n", name="m.bdf")
    e = deck.rbe2s[5]
    assert (e.card, e.gn, e.cm, e.gm) == ("RBAR", 2, "12", (3,))


@pytest.mark.parametrize("card, field, why", [
    ("RBAR,5,2,3,1236,45", 6, "independent components at both grids"),
    ("RBAR,5,2,3,123", 5, "six independent components in all"),
    ("RBAR,5,2,3,123456,,1", 7, "CMA component(s) 1 are also independent"),
    ("RBAR,5,2,3,123456,,,17", 8, "digits 1-6"),
    ("RBAR,5,2,2,123456", 2, "GA and GB are the same grid 2"),
])
def test_rbar_errors_are_located(card, field, why):
    with pytest.raises((DeckFormatError, ModelError), match=re.escape(why)) as info:
        read_deck_text(CANTILEVER + card + "\n", name="m.bdf")
    if isinstance(info.value, DeckFormatError):
        assert (info.value.file, info.value.line, info.value.card, info.value.field) == \
            ("m.bdf", 8, "RBAR", field)
    else:
        assert "m.bdf:8" in str(info.value) and "RBAR 5" in str(info.value)


RBAR_FRAME = """GRID,1,,0.,0.,0.
GRID,2,,0.,0.,3.
GRID,3,,0.6,0.2,3.4
GRID,4,,2.5,0.4,3.4
GRID,5,,3.1,0.4,3.
GRID,6,,3.1,0.4,0.
GRID,7,,1.2,-0.8,3.2,9
CORD2R,9,,0.,0.,0.,0.,0.,1.,
,1.,1.,0.
CBAR,1,1,1,2,1.,0.,0.
CBAR,2,1,3,4,0.,0.,1.
CBAR,3,1,5,6,1.,0.,0.
PBAR,1,1,2.E-3,3.E-6,2.E-6,4.E-6
MAT1,1,2.1E11,,.3
RBAR,11,2,3,123456
RBAR,12,5,4,,123456
RBAR,13,3,7,123456,,,1346
SPC1,1,123456,1,6
"""
"""A portal whose beam is tied to its columns by rigid bars (one each way round: CNA, CNB) and
a grid 7 in a rotated CD system on a partial RBAR (CMB = 1346, its CD components)."""


@needs_mystran
@pytest.mark.filterwarnings("ignore:load on 2 component")   # round-off of CID 9 -> basic -> CD 9
def test_rbar_frame_agrees_with_mystran(tmp_path):
    """MYSTRAN 18 reads RBAR but does not solve it ("Code for RBAR processing not written yet"):
    the mystran adapter writes each RBAR as the RBE2 it is, and solves the imported study."""
    loads = ("FORCE,1,4,,1000.,0.3,-0.2,-1.\nMOMENT,1,3,,200.,1.,0.,0.\n"
             "FORCE,2,7,9,800.,1.,0.,0.5\nMOMENT,2,7,9,300.,1.,0.,0.\n")
    assert _study_against_mystran(tmp_path, _static(RBAR_FRAME, loads, 2), 2) <= RTOL


# --------------------------------------------------------------------------------------------
# CTUBE / PTUBE
# --------------------------------------------------------------------------------------------
def _tube(od: float, t: float | None) -> tuple[float, float]:
    d = 0.0 if t is None else od - 2 * t
    return math.pi * (od ** 2 - d ** 2) / 4, math.pi * (od ** 4 - d ** 4) / 32


@pytest.mark.parametrize("t", [0.004, None])
def test_ctube_axial_and_torsion_closed_form(t, tmp_path):
    """A tube (and, T blank, a solid round bar) pulled and twisted: u = P L / (E A),
    theta = T L / (G J), A and J of the tube section."""
    od, length, p, torque = 0.05, 1.5, 2.0e4, 300.0
    a, j = _tube(od, t)
    bulk = (f"GRID,1,,0.,0.,0.\nGRID,2,,0.,{length},0.\nCTUBE,7,3,1,2\n"
            f"PTUBE,3,1,{od},{'' if t is None else t}\nMAT1,1,{E},{G}\nSPC1,1,123456,1\n")
    text = _static(bulk, f"FORCE,1,2,,{p},0.,1.,0.\nMOMENT,1,2,,{torque},0.,1.,0.\n")
    cases, report, u = _solve(_import(tmp_path, text))
    assert u[report.index((2, 2)), 0] == pytest.approx(p * length / (E * a), rel=CLOSED)
    assert u[report.index((2, 5)), 0] == pytest.approx(torque * length / (G * j), rel=CLOSED)


@pytest.mark.parametrize("card, field, why", [
    ("PTUBE,3,1,0.05,0.03", 5, "wall thickness T must be in"),
    ("PTUBE,3,1,-0.05", 4, "outer diameter OD must be > 0"),
    ("PTUBE,3,1,0.05,0.004,,0.06", 7, "tapered tube"),
])
def test_ptube_errors_are_located(card, field, why):
    base = "GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nCTUBE,7,3,1,2\nMAT1,1,2.E11,,.3\n"
    with pytest.raises(DeckFormatError, match=why) as info:
        read_deck_text(base + card + "\n", name="t.bdf")
    assert (info.value.card, info.value.field, info.value.line) == ("PTUBE", field, 5)


def test_ctube_needs_a_ptube_and_crod_a_prod():
    base = "GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nMAT1,1,2.E11,,.3\n"
    with pytest.raises(ModelError, match="property PID 3 is a PROD; a CTUBE needs a PTUBE"):
        read_deck_text(base + "CTUBE,7,3,1,2\nPROD,3,1,1.E-4\n", name="t.bdf")
    with pytest.raises(ModelError, match="property PID 3 is a PTUBE; a CROD needs a PROD"):
        read_deck_text(base + "CROD,7,3,1,2\nPTUBE,3,1,.05\n", name="t.bdf")


TUBE_TRUSS = """GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
GRID,3,,0.,2.,0.
GRID,4,,0.7,0.6,1.5
CTUBE,11,5,1,4
CTUBE,12,5,2,4
CTUBE,13,6,3,4
CROD,14,7,1,2
PTUBE,5,1,.06,.005
PTUBE,6,1,.04
PROD,7,1,2.E-4,1.E-8
MAT1,1,2.1E11,,.3
SPC1,1,123456,1,2,3
"""
"""A tripod of tubes (one solid) over a rod: grid 4 is held by the three tubes alone."""


def test_ctube_tripod_closed_form(tmp_path):
    """Grid 4 of the tripod: its translations against K = sum EA/L n n^T, its rotations
    against sum GJ/L n n^T (direct stiffness method)."""
    xyz = {1: (0.0, 0.0, 0.0), 2: (2.0, 0.0, 0.0), 3: (0.0, 2.0, 0.0), 4: (0.7, 0.6, 1.5)}
    kt, kr = np.zeros((3, 3)), np.zeros((3, 3))
    for g, (od, t) in ((1, (0.06, 0.005)), (2, (0.06, 0.005)), (3, (0.04, None))):
        d = np.subtract(xyz[4], xyz[g])
        n, length = d / np.linalg.norm(d), np.linalg.norm(d)
        a, j = _tube(od, t)
        kt += 2.1e11 * a / length * np.outer(n, n)
        kr += 2.1e11 / 2.6 * j / length * np.outer(n, n)
    f, m = np.array([300.0, -500.0, -800.0]), np.array([20.0, 10.0, -15.0])
    text = _static(TUBE_TRUSS, "FORCE,1,4,,1.,300.,-500.,-800.\nMOMENT,1,4,,1.,20.,10.,-15.\n")
    cases, report, u = _solve(_import(tmp_path, text))
    ours = _by_grid(report, u, 0, [4])[0]
    np.testing.assert_allclose(ours[:3], np.linalg.solve(kt, f), rtol=CLOSED)
    np.testing.assert_allclose(ours[3:], np.linalg.solve(kr, m), rtol=CLOSED)


@needs_mystran
def test_ctube_study_agrees_with_mystran(tmp_path):
    """MYSTRAN 18 has no CTUBE: the mystran adapter writes each as the CROD/PROD of its A and J,
    and solves the imported study; its displacements against the reference solver's."""
    text = _static(TUBE_TRUSS, "FORCE,1,4,,1.,300.,-500.,-800.\nMOMENT,1,4,,1.,20.,10.,-15.\n")
    assert _study_against_mystran(tmp_path, text, 1) <= RTOL


# --------------------------------------------------------------------------------------------
# CBUSH with its spring point off the line GA-GB (OCID, S1-S3)
# --------------------------------------------------------------------------------------------
K_BUSH = (2.0e6, 3.0e6, 4.0e6, 5.0e4, 6.0e4, 7.0e4)


def _skew(r) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


@pytest.mark.parametrize("ocid, offset, basic", [
    ("0", (0.0, 0.5, 0.2), (0.0, 0.5, 0.2)),
    ("8", (0.3, -0.4, 0.1), (0.4, 0.3, 0.1)),         # CORD2R 8: x8 = y, y8 = -x, z8 = z
])
def test_cbush_offset_closed_form(ocid, offset, basic, tmp_path):
    """A CBUSH from the clamped grid 1 to grid 2, element axes basic (CID 0), its springs at
    grid 1 plus the offset (in basic, or in a rotated system OCID): grid 2 is held by the six
    springs alone through the rigid arm r = p - x_2, so its stiffness is T^T diag(K) T with
    T = [[I, -S(r)], [0, I]] (u_p = u_2 + theta_2 x r; MSC QRG CBUSH, Figure 2: the offset is
    measured from GA)."""
    bulk = ("GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nCORD2R,8,,0.,0.,0.,0.,0.,1.,\n,0.,1.,0.\n"
            f"CBUSH,5,6,1,2,,,,0\n,,{ocid},{offset[0]},{offset[1]},{offset[2]}\n"
            f"PBUSH,6,K,{','.join(map(str, K_BUSH))}\nSPC1,1,123456,1\n")
    f = np.array([100.0, -200.0, 300.0, 40.0, -50.0, 60.0])
    loads = f"FORCE,1,2,,1.,{f[0]},{f[1]},{f[2]}\nMOMENT,1,2,,1.,{f[3]},{f[4]},{f[5]}\n"
    cases, report, u = _solve(_import(tmp_path, _static(bulk, loads)))
    T = np.eye(6)
    T[:3, 3:] = -_skew(np.array(basic) - np.array([1.0, 0.0, 0.0]))
    expect = np.linalg.solve(T.T @ np.diag(K_BUSH) @ T, f)
    np.testing.assert_allclose(_by_grid(report, u, 0, [2])[0], expect, rtol=CLOSED,
                               atol=CLOSED * np.abs(expect).max())


def test_cbush_s1_s3_without_ocid_are_ignored_with_a_note():
    base = "GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nPBUSH,6,K,1.,1.,1.,1.,1.,1.\n"
    deck = read_deck_text(base + "CBUSH,5,6,1,2,,,,0\n,.3,-1,.1,.2,.3\n", name="b.bdf")
    assert deck.bushes[5].offset is None and deck.bushes[5].s == 0.3
    assert any("S1-S3 with OCID blank or -1 are ignored" in n and "CBUSH 5 at b.bdf:4" in n
               for n in deck.notes)


BUSH_OFFSETS = """GRID,1,,0.,0.,0.
GRID,2,,1.,0.,0.
GRID,3,,1.,1.,0.5
GRID,4,,2.,1.,0.5
GRID,5,,2.,1.,0.5
GRID,6,,1.,1.,-0.5
CORD2R,8,,0.,0.,0.,0.,0.,1.,
,0.,1.,0.
CORD2C,9,,0.,0.,0.,0.,0.,1.,
,1.,0.,0.
CBAR,1,1,1,2,0.,1.,0.
CBAR,2,1,3,4,0.,0.,1.
PBAR,1,1,2.E-3,3.E-6,2.E-6,4.E-6
MAT1,1,2.1E11,,.3
CBUSH,11,6,2,3,,,,0
,,0,0.2,0.3,0.1
CBUSH,12,6,4,5,,,,8
,,8,0.1,-0.2,0.3
CBUSH,13,7,3,6,,,,8
,,9,0.4,10.,-0.2
PBUSH,6,K,2.E6,3.E6,4.E6,5.E4,6.E4,7.E4
PBUSH,7,K,1.E5,2.E5,3.E5,4.E3,5.E3,6.E3
SPC1,1,123456,1,6
"""
"""A bar, two CBUSHes with their springs offset in basic and in a rotated system, a second bar,
a CBUSH between coincident grids 4, 5 (CID 8) offset in system 8, and a CBUSH to the clamped
grid 6 offset in a cylindrical system (its axes at GA). MYSTRAN 18 stops without a message on a
grounded CBUSH with an offset (GB blank), and takes a cylindrical CID (element axes) as its
defining axes rather than its axes at GA (MSC QRG CBUSH remark 3): neither is in this deck."""


@needs_mystran
def test_cbush_offsets_agree_with_mystran(tmp_path):
    """MYSTRAN 18 runs the deck itself (it reads CBUSH OCID and S1-S3: the offset from GA, in
    OCID's axes at GA)."""
    loads = ("FORCE,1,5,,1000.,0.3,-0.2,-1.\nMOMENT,1,5,,200.,1.,0.5,0.\n"
             "FORCE,2,3,,800.,1.,0.5,0.2\nMOMENT,2,4,,300.,0.,1.,0.\n")
    assert _against_mystran(tmp_path, _static(BUSH_OFFSETS, loads, 2), 2) <= RTOL


# --------------------------------------------------------------------------------------------
# MPC: linear multipoint constraints selected by MPC = in the case control
# --------------------------------------------------------------------------------------------
K1, K2 = 2.0e5, 3.0e5          # EA/L of the two rods (E = 2e11, L = 1, A below)
LEVER = ("GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nGRID,3,,1.,1.,0.\nGRID,4,,2.,1.,0.\n"
         f"CONROD,1,1,2,1,{K1 / 2e11},1.E-9\nCONROD,2,4,3,1,{K2 / 2e11},1.E-9\n"
         "MAT1,1,2.E11,,.3\nSPC1,1,123456,1,4\n")


def _mpc_deck(mpc_cards: str, select: str, load: float = 1000.0) -> str:
    return (f"SOL 101\nCEND\nDISPLACEMENT = ALL\nSPC = 1\n{select}LOAD = 1\nBEGIN BULK\n{LEVER}"
            f"{mpc_cards}FORCE,1,3,,{load},1.,0.,0.\nENDDATA\n")


def test_mpc_lever_closed_form(tmp_path):
    """u2 = 2 u3 (MPC: 1.0 u2x - 2.0 u3x = 0, u2x dependent) between two axial rods of
    stiffness K1 (grid 2) and K2 (grid 3), force P on grid 3: the energy
    K1 (2 u3)^2 / 2 + K2 u3^2 / 2 - P u3 is least at u3 = P / (4 K1 + K2), u2 = 2 u3. The set
    is selected through an MPCADD; set 8, not selected, is dropped (NASTRAN would not apply it)."""
    cards = "MPC,7,2,1,1.,3,1,-2.\nMPCADD,9,7\nMPC,8,2,1,1.,3,1,-5.\n"
    result = _import(tmp_path, _mpc_deck(cards, "MPC = 9\n"))
    assert any("MPC = 9 selected: kept MPC set(s) 7, 9; dropped set(s) 8" in n for n in result.notes)
    assert "MPC,8" not in result.model_bdf and "MPC,7" in result.model_bdf
    cases, report, u = _solve(result)
    u3 = 1000.0 / (4 * K1 + K2)
    assert u[report.index((3, 1)), 0] == pytest.approx(u3, rel=CLOSED)
    assert u[report.index((2, 1)), 0] == pytest.approx(2 * u3, rel=CLOSED)


def test_mpc_not_selected_is_dropped(tmp_path):
    """MPC cards but no MPC = : NASTRAN applies none, and the import drops them with a note."""
    result = _import(tmp_path, _mpc_deck("MPC,7,2,1,1.,3,1,-2.\n", ""))
    assert any("no subcase selects an MPC set" in n for n in result.notes)
    cases, report, u = _solve(result)
    assert u[report.index((3, 1)), 0] == pytest.approx(1000.0 / K2, rel=CLOSED)
    assert u[report.index((2, 1)), 0] == 0.0


@pytest.mark.parametrize("cards, select, field, line, why", [
    ("MPC,7,2,0,1.,3,1,-2.\n", "MPC = 7\n", 4, 16, "point 2 is no SPOINT"),
    ("MPC,7,2,1,0.,3,1,-2.\n", "MPC = 7\n", 5, 16, "A1, the coefficient of the dependent"),
    ("MPC,7,2,1,1.,3,1,-2.\n", "MPC = 5\n", None, 5, "MPC = 5 selects a set the bulk data"),
    ("MPC,7,2,1,1.,9,1,-2.\n", "MPC = 7\n", None, None, "grid(s) 9 does not exist"),
])
def test_mpc_errors_are_located(cards, select, field, line, why, tmp_path):
    with pytest.raises((DeckFormatError, ModelError), match=re.escape(why)) as info:
        _solve(_import(tmp_path, _mpc_deck(cards, select)))
    if field is not None:
        assert (info.value.card, info.value.field, info.value.line) == ("MPC", field, line)
    elif line is not None:
        assert info.value.line == line


def test_mpc_subcases_must_agree(tmp_path):
    text = _mpc_deck("MPC,7,2,1,1.,3,1,-2.\nMPC,8,2,1,1.,3,1,-3.\n", "").replace(
        "LOAD = 1\n", "SUBCASE 1\n  MPC = 7\n  LOAD = 1\nSUBCASE 2\n  MPC = 8\n  LOAD = 1\n")
    with pytest.raises(DeckFormatError, match="the subcases select different MPC sets"):
        _import(tmp_path, text)


MPC_FRAME = RBAR_FRAME.replace("RBAR,11,2,3,123456\n", "").replace("RBAR,12,5,4,,123456\n", "") \
    .replace("RBAR,13,3,7,123456,,,1346\n", "CBAR,4,1,3,7,0.,0.,1.\n") + (
    # grid 3 rigidly on grid 2 (r = x3 - x2 = (0.6, 0.2, 0.4)): u3 = u2 + theta2 x r
    "MPC,21,3,1,1.,2,1,-1.,\n,,2,5,-0.4,2,6,0.2\n"
    "MPC,21,3,2,1.,2,2,-1.,\n,,2,6,-0.6,2,4,0.4\n"
    "MPC,21,3,3,2.,2,3,-2.,\n,,2,4,-0.4,2,5,1.2\n"              # the same equation times 2
    "MPC,21,3,4,1.,2,4,-1.\nMPC,21,3,5,1.,2,5,-1.\nMPC,21,3,6,1.,2,6,-1.\n"
    # grid 4 pinned on grid 5 (r = x4 - x5 = (-0.6, 0, 0.4)): translations only
    "MPC,22,4,1,1.,5,1,-1.,\n,,5,5,-0.4\n"
    "MPC,22,4,2,1.,5,2,-1.,\n,,5,6,0.6,5,4,0.4\n"
    "MPC,22,4,3,1.,5,3,-1.,\n,,5,5,-0.6\n"
    "MPC,22,7,6,-1.5,3,6,0.75\n"                   # grid 7's R3 in its CD 9 = theta3z / 2
    "MPCADD,30,21,22\n")
"""The portal of RBAR_FRAME with its beam tied to its columns by MPC equations instead: rigidly
at grid 3 (one equation given times 2), pinned at grid 4 (translations only), and a rotation of
grid 7 (in the rotated CD 9) tied to grid 3's; selected through an MPCADD."""


@needs_mystran
@pytest.mark.filterwarnings("ignore:load on")
def test_mpc_frame_agrees_with_mystran(tmp_path):
    """MYSTRAN 18 runs the deck itself (MPC, MPCADD and MPC = are MYSTRAN input); and the
    imported study through the mystran adapter, whose run deck selects the model's MPC sets."""
    loads = ("FORCE,1,4,,1000.,0.3,-0.2,-1.\nMOMENT,1,3,,200.,1.,0.,0.\n"
             "FORCE,2,7,,800.,1.,0.5,0.2\nMOMENT,2,6,,300.,0.,1.,0.\n")
    text = _static(MPC_FRAME, loads, 2).replace("SPC = 1\n", "SPC = 1\nMPC = 30\n")
    for sub in ("deck", "study"):
        (tmp_path / sub).mkdir()
    assert _against_mystran(tmp_path / "deck", text, 2) <= RTOL
    assert _study_against_mystran(tmp_path / "study", text, 2) <= RTOL
