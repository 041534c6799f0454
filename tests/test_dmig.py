"""DMIG matrices added to the stiffness by K2GG (docs/import.md; ``solver_adapters/bdf/matrices.py``).

References: MSC QRG DMIG (header NAME 0 IFO TIN; columns GJ CJ with terms Gi Ci Ai; IFO 6
symmetric: one of each off-diagonal pair given) and K2GG (the matrix added to the g-set
stiffness, scaled by PARAM,CK2). Closed forms: a DMIG term equal to a CELAS2's stiffness is
that spring (a grounded spring k at a DOF: P / k; between two DOFs [[k, -k], [-k, k]]); a
cantilever whose last bar is given as its 12 E I / L^3 ... stiffness terms (the layout of Vega's
test deck dmigstfs.nas) bends to P L^3 / (3 E I). MYSTRAN 18 does not read DMIG: it runs the
equivalent deck (the bar itself in place of its matrix).

Tolerances: the DMIG and CELAS2 decks give the same matrix, so 1e-12 relative (round-off of a
different summation order); the cantilever: 1e-10 (its DMIG terms to 11 digits; Vega's 6-digit
terms against the same chain solved by hand, a dense 10 x 10 solve); MYSTRAN prints 7 digits and the
matrix holds the bar's terms to 11 digits: 1e-6 of the largest translation (rotation).
"""

from __future__ import annotations

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import DeckFormatError

from conftest import needs_mystran
from test_deck_tail import _agree, _import, _mystran, _solve

CLOSED = 1e-12
pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

SPRINGS = """SOL 101
CEND
SPC = 1
K2GG = KS
SUBCASE 1
  LOAD = 5
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,1.,0.,0.
GRID,3,,2.,0.,0.
SPOINT,9
SPC1,1,123456,1
SPC1,1,3456,2,3
{springs}FORCE,5,3,,100.,1.,0.,0.
FORCE,5,2,,40.,0.,1.,0.
SLOAD,5,9,7.
ENDDATA
"""
CELAS = ("CELAS2,1,1.E4,1,1,2,1\nCELAS2,2,2.E4,2,1,3,1\nCELAS2,3,5.E3,2,2\n"
         "CELAS2,4,3.E3,3,2,2,2\nCELAS2,5,8.E2,9,0\n")
DMIG = ("DMIG,KS,0,6,1\n"
        "DMIG,KS,2,1,,2,1,3.E4,,+A\n+A,3,1,-2.E4\n"
        "DMIG,KS,3,1,,3,1,2.E4\n"
        "DMIG,KS,2,2,,2,2,8.E3,,+B\n+B,3,2,-3.E3\n"
        "DMIG,KS,3,2,,3,2,3.E3\n"
        "DMIG,KS,9,0,,9,,8.E2\n")
"""The springs of CELAS as one symmetric DMIG (lower triangle): grid 2's x-spring to the fixed
grid 1 (1e4) and to grid 3 (2e4), grid 2's y-spring to ground (5e3) and to grid 3 (3e3), and a
grounded spring on the scalar point 9."""


def test_dmig_is_the_springs_it_writes_out(tmp_path):
    """The DMIG deck and the CELAS2 deck give the same displacements; closed forms: grid 3
    moves 100 (1 / 1e4 + 1 / 2e4) along x, grid 2 40 / 5e3 along y (grid 3's y-spring carries
    nothing: its only load path is back through grid 2), the scalar point 7 / 800."""
    ours = _import(tmp_path, SPRINGS.format(springs=DMIG), "dmig.dat")
    assert any("K2GG = KS" in n and "DMIG KS kept" in n for n in ours.notes)
    _, report, u = _solve(ours)
    plain = SPRINGS.replace("K2GG = KS\n", "").format(springs=CELAS)
    _, report2, v = _solve(_import(tmp_path, plain, "celas.dat"), report)
    assert report2 == report
    np.testing.assert_allclose(u, v, rtol=CLOSED, atol=0.0)
    at = {dof: u[report.index(dof), 0] for dof in ((3, 1), (2, 2), (3, 2), (9, 1))}
    assert at[(3, 1)] == pytest.approx(100.0 * (1.0 / 1.0e4 + 1.0 / 2.0e4), rel=CLOSED)
    assert at[(2, 2)] == pytest.approx(40.0 / 5.0e3, rel=CLOSED)
    assert at[(3, 2)] == pytest.approx(40.0 / 5.0e3, rel=CLOSED)
    assert at[(9, 1)] == pytest.approx(7.0 / 800.0, rel=CLOSED)


def test_ck2_scales_and_square_form_reads_alike(tmp_path):
    """PARAM,CK2,2. doubles every DMIG term (the displacements halve where the DMIG alone
    holds); a square matrix (IFO 1) with both triangles written out is the symmetric one."""
    base = _solve(_import(tmp_path, SPRINGS.format(springs=DMIG), "a.dat"))
    doubled = _solve(_import(tmp_path, SPRINGS.format(springs=DMIG + "PARAM,CK2,2.\n"), "b.dat"), base[1])
    np.testing.assert_allclose(doubled[2], base[2] / 2.0, rtol=CLOSED)
    square = DMIG.replace("DMIG,KS,0,6,1", "DMIG,KS,0,1,1").replace(
        "DMIG,KS,3,1,,3,1,2.E4", "DMIG,KS,3,1,,3,1,2.E4,,+C\n+C,2,1,-2.E4").replace(
        "DMIG,KS,3,2,,3,2,3.E3", "DMIG,KS,3,2,,3,2,3.E3,,+D\n+D,2,2,-3.E3")
    sq = _solve(_import(tmp_path, SPRINGS.format(springs=square), "c.dat"), base[1])
    np.testing.assert_allclose(sq[2], base[2], rtol=CLOSED)


def test_unselected_matrices_are_dropped(tmp_path):
    """NASTRAN adds only the matrix K2GG selects: another DMIG is dropped with a note, and a
    deck without K2GG keeps none."""
    other = DMIG.replace("KS", "KX")
    result = _import(tmp_path, SPRINGS.format(springs=DMIG + other), "a.dat")
    assert "KX" not in result.model_bdf and any("dropped DMIG matrix(es) KX" in n for n in result.notes)
    assert set(read_deck_text(result.model_bdf, name="model.bdf").dmigs) == {"KS"}
    none = _import(tmp_path, SPRINGS.replace("K2GG = KS\n", "").format(springs=DMIG + CELAS), "b.dat")
    assert "DMIG" not in none.model_bdf and any("no K2GG selects them" in n for n in none.notes)


def _beam(ei: float, length: float) -> np.ndarray:
    """The x-z bending stiffness of a beam on (w_A, theta_A, w_B, theta_B), theta = -dw/dx
    (NASTRAN's rotation about y): EI / L^3 [[12, -6L, -12, -6L], ...]."""
    L_ = length
    return ei / L_**3 * np.array([[12, -6 * L_, -12, -6 * L_], [-6 * L_, 4 * L_**2, 6 * L_, 2 * L_**2],
                                  [-12, 6 * L_, 12, 6 * L_], [-6 * L_, 2 * L_**2, 6 * L_, 4 * L_**2]])


L, E, I = 1.0, 7.1e10, 5.869e-7
CANTILEVER = f"""SOL 101
CEND
SPC = 10
K2GG = UGSTIF
SUBCASE 1
  LOAD = 10
BEGIN BULK
CBAR    1       1       1       2       10
CBAR    2       1       2       3       10
CBAR    3       1       3       4       10
CBAR    4       1       4       5       10
{{last}}FORCE   10      6               100.    0.      0.      1.
GRID    1               0.      0.      0.              246
GRID    2               1.      0.      0.              246
GRID    3               2.      0.      0.              246
GRID    4               3.      0.      0.              246
GRID    5               4.      0.      0.              246
GRID    6               5.      0.      0.              246
GRID    10              0.      0.      10.             123456
MAT1,1,{E!r},,.33,2700.
PBAR,1,1,2.654-3,{I!r}
SPC1    10      123456  1
ENDDATA
"""
def _small(*cards) -> str:
    """Small-field lines, 8 columns a field (``None``: blank)."""
    return "".join("".join(("" if f is None else str(f)).ljust(8) for f in c).rstrip() + "\n"
                   for c in cards)


MATRIX = _small(
    ("DMIG", "UGSTIF", 0, 6, 1),
    ("DMIG", "UGSTIF", 5, 3, None, 5, 3, "500039.", None, "+000001"),
    ("+000001", 5, 5, "-250019.", None, 6, 3, "-500039.", None, "+000002"),
    ("+000002", 6, 5, "-250019."),
    ("DMIG", "UGSTIF", 5, 5, None, 5, 5, "166680.", None, "+000004"),
    ("+000004", 6, 3, "250019.", None, 6, 5, "83340."),
    ("DMIG", "UGSTIF", 6, 3, None, 6, 3, "500039.", None, "+000006"),
    ("+000006", 6, 5, "250019."),
    ("DMIG", "UGSTIF", 6, 5, None, 6, 5, "166680."))
"""Vega's dmigstfs.nas (testdata/nastran/irt): the bending stiffness of a bar of length 1 in the
x-z plane, 12 E I / L^3, 6 E I / L^2, 4 E I / L, 2 E I / L to 6 digits, between grids 5 and 6."""
_K = _beam(E * I, L)
_F = [f"{v:.10E}" for v in (_K[0, 0], _K[1, 0], _K[1, 1], _K[1, 3])]     # 12, -6, 4, 2 (EI = 1)
EXACT = (f"DMIG,UGSTIF,0,6,1\nDMIG,UGSTIF,5,3,,5,3,{_F[0]},,+A\n+A,5,5,{_F[1]},,6,3,-{_F[0]},,+B\n"
         f"+B,6,5,{_F[1]}\nDMIG,UGSTIF,5,5,,5,5,{_F[2]},,+C\n+C,6,3,{_F[1][1:]},,6,5,{_F[3]}\n"
         f"DMIG,UGSTIF,6,3,,6,3,{_F[0]},,+D\n+D,6,5,{_F[1][1:]}\nDMIG,UGSTIF,6,5,,6,5,{_F[2]}\n")
"""The same matrix with the bar's terms to 11 digits (free field)."""


def _cantilever_by_hand(last: np.ndarray) -> float:
    """Tip deflection of four beams and ``last`` (4 x 4) between grids 5 and 6, grid 1 clamped,
    100 along z at grid 6: a dense solve of the 2-DOF-per-grid chain."""
    K = np.zeros((12, 12))
    for e in range(5):
        k = _beam(E * I, L) if e < 4 else last
        K[2 * e:2 * e + 4, 2 * e:2 * e + 4] += k
    f = np.zeros(10)
    f[-2] = 100.0
    return float(np.linalg.solve(K[2:, 2:], f)[-2])


def test_cantilever_with_its_last_bar_as_a_matrix(tmp_path):
    """Vega's layout read term by term; the tip deflection is the chain's with those printed
    terms, solved by hand (the terms' 6-digit rounding leaves the matrix 2.6e-4 stiffer in effect
    than the bar: a single element's terms must cancel exactly on rigid-body motion). With the
    bar's exact terms the tip is the closed form P (5 L)^3 / (3 E I)."""
    result = _import(tmp_path, CANTILEVER.format(last=MATRIX), "vega.dat")
    terms = {(r, c): a for r, c, a in read_deck_text(result.model_bdf, name="m").dmigs["UGSTIF"].terms}
    assert terms[((6, 3), (5, 5))] == 250019.0 and terms[((6, 5), (5, 3))] == -250019.0 and len(terms) == 10
    _, report, u = _solve(result)
    printed = np.array([[500039., -250019., -500039., -250019.], [-250019., 166680., 250019., 83340.],
                        [-500039., 250019., 500039., 250019.], [-250019., 83340., 250019., 166680.]])
    assert u[report.index((6, 3)), 0] == pytest.approx(_cantilever_by_hand(printed), rel=1e-10)
    _, report, u = _solve(_import(tmp_path, CANTILEVER.format(last=EXACT), "exact.dat"))
    assert u[report.index((6, 3)), 0] == pytest.approx(100.0 * (5 * L) ** 3 / (3 * E * I), rel=1e-10)


@needs_mystran
def test_cantilever_agrees_with_mystran_running_the_bar(tmp_path):
    """MYSTRAN runs the deck with CBAR 5 in place of the DMIG of its terms (it does not read
    DMIG)."""
    cases, report, u = _solve(_import(tmp_path, CANTILEVER.format(last=EXACT)))
    bar = CANTILEVER.replace("K2GG = UGSTIF\n", "DISP = ALL\n").format(
        last="CBAR    5       1       5       6       10\n")
    ref = _mystran(tmp_path, bar)
    grids = [g for g in sorted(ref[1]) if g != 10]
    ours = np.array([[u[report.index((g, c)), 0] if (g, c) in report else 0.0 for c in range(1, 7)]
                     for g in grids])
    assert _agree(ours, np.array([ref[1][g] for g in grids]), "case 1") <= 1e-6


def test_adapters_that_cannot_run_a_dmig_refuse_it(tmp_path):
    """The mystran adapter's run deck and the legacy (FRAMESOLVE) adapter refuse it by name
    before anything runs (MYSTRAN 18 would skip the DMIG with a warning and solve without it)."""
    from solver_adapters.errors import UnsupportedFeatureError
    from solver_adapters.legacy import LegacyDialect
    from solver_adapters.nastran import check_writable
    deck = read_deck_text(_import(tmp_path, SPRINGS.format(springs=DMIG)).model_bdf, name="model.bdf")
    with pytest.raises(DeckFormatError, match="mystran adapter cannot run DMIG KS") as info:
        check_writable(deck)
    assert info.value.card == "DMIG"
    with pytest.raises(UnsupportedFeatureError, match="DMIG KS"):
        LegacyDialect().check_model(deck)


@pytest.mark.parametrize("edit, card, field, why", [
    (("DMIG,KS,0,6,1", "DMIG,KS,0,2,1"), "DMIG", 4, "IFO = 2"),
    (("DMIG,KS,0,6,1", "DMIG,KS,0,6,3"), "DMIG", 5, "TIN = 3"),
    (("DMIG,KS,0,6,1\n", ""), "DMIG", 2, "DMIG KS has no header"),
    (("DMIG,KS,3,1,,3,1,2.E4", "DMIG,KS,3,1,,3,1,2.E4,,+Z\n+Z,2,1,5."), "DMIG", 10,
     "given twice \\(with its symmetric mirror\\)"),
    (("DMIG,KS,3,2,,3,2,3.E3", "DMIG,KS,3,2,,3,2,3.E3,,+Z\n+Z,4,2,5."), "DMIG", 10, "point 4 does not exist"),
    (("DMIG,KS,9,0,,9,,8.E2", "DMIG,KS,9,0,,9,3,8.E2"), "DMIG", 7, "scalar point: component"),
    (("DMIG,KS,9,0,,9,,8.E2", "DMIG,KS,9,0,,9,,8.E2,1."), "DMIG", 9, "imaginary part"),
    (("DMIG,KS,0,6,1", "DMIG,KS,0,1,1"), "DMIG", 4, "not symmetric"),
])
def test_bad_dmig_fields_are_located(edit, card, field, why, tmp_path):
    with pytest.raises(DeckFormatError, match=why) as info:
        _import(tmp_path, SPRINGS.format(springs=DMIG.replace(*edit)))
    assert (info.value.card, info.value.field) == (card, field)


@pytest.mark.parametrize("k2gg, why", [("K2GG = KQ", "no DMIG named KQ"),
                                       ("K2GG = 2.0*KS", "one DMIG matrix name")])
def test_bad_k2gg_is_located(k2gg, why, tmp_path):
    with pytest.raises(DeckFormatError, match=why) as info:
        _import(tmp_path, SPRINGS.replace("K2GG = KS", k2gg).format(springs=DMIG))
    assert (info.value.card, info.value.line) == ("K2GG", 4)


@pytest.mark.parametrize("fmt", ["small", "large", "free"])
def test_written_deck_keeps_the_matrix(fmt, tmp_path):
    """write_deck (diagnose's edited decks) writes the DMIG and PARAM,CK2 back: the same model."""
    from solver_adapters.bdf_write import write_deck
    result = _import(tmp_path, SPRINGS.format(springs=DMIG + "PARAM,CK2,1.5\n"))
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    again = read_deck_text(write_deck(deck, fmt), name="written.bdf")
    assert again.dmigs == {k: type(v)(v.name, v.ifo, v.terms, again.dmigs[k].src) for k, v in deck.dmigs.items()}
    assert again.ck2 == 1.5


def test_both_reader_paths_read_the_matrix_alike(tmp_path):
    from test_reader_paths import assert_same
    assert_same(_import(tmp_path, SPRINGS.format(springs=DMIG)).model_bdf, tmp_path, must_read=True)
    assert_same(_import(tmp_path, CANTILEVER.format(last=MATRIX), "c.dat").model_bdf, tmp_path, must_read=True)
