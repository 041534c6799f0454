"""Design optimisation decks (SOL 200) imported as the linear static analysis of their initial
design (docs/import.md, "Design optimisation decks"; ``solver_adapters/bdf/design.py``).

References: NASTRAN's design model gives a designed property as P = C0 + sum COEFi X(DVIDi)
(MSC QRG DVPREL1 and DVMREL1 remark 1; COEF1 = PVAL: the property card's value, remark 7), the
first analysis is at the design variables' initial values XINIT (MSC QRG DESVAR), a DLINK's
dependent variable is C0 + CMULT sum Ci X(IDVi) (MSC QRG DLINK remark 1). The displacements are
checked against the closed forms of a cantilever (tip force P: axial P L / (E A), bending
P L^3 / (3 E I), end rotation P L^2 / (2 E I); a rod P L / (E A); a spring P / K) and against
MYSTRAN 18 (which does not run SOL 200) running the SOL 101 deck with the designed values
written on the property cards, and running the imported study through the mystran adapter
(whose run deck is written from the parsed model, so it carries the designed values).

Tolerances: closed forms 1e-12 relative (a few operations on exact element matrices);
MYSTRAN prints 7 significant digits: 1e-6 of each subcase's largest translation (rotation).
"""

from __future__ import annotations

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.bdf_write import print_float_16
from solver_adapters.protocol import DeckFormatError

from conftest import needs_mystran
from test_deck_tail import _agree, _import, _mystran, _solve
from test_deck_tail_elements import _study_against_mystran

CLOSED = 1e-12
RTOL = 1e-6
L = 2.0
P = (1000.0, -2000.0, 3000.0)

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

# the initial design: X1 = 2, X2 = 4, X3 = 0.5 + 2 (1.0 X2) = 8.5 (DLINK)
X1, X2, X3 = 2.0, 4.0, 0.5 + 2.0 * 4.0
A_D = 1.0e-4 + 5.0e-4 * X1            # DVPREL1 10: C0 + COEF X1, by name
I1_D = 1.0e-6 * X2                    # DVPREL1 11: PVAL (the card's I1) times X2, by FID 5
I2_D = 1.0e-6 * X3                    # DVPREL1 12: X3 (dependent, DLINK) times 1e-6
E_D = 1.0e11 * X1                     # DVMREL1 20: E = 1e11 X1 (the card says 2.1e11)

CANTILEVER = f"""SOL 200
CEND
SPC = 1
DESOBJ(MIN) = 100
DISP = ALL
SUBCASE 1
  ANALYSIS = STATICS
  LOAD = 5
SUBCASE 2
  ANALYSIS = MODES
  METHOD = 9
  LOAD = 5
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,{L},0.,0.
CBAR,1,7,1,2,0.,1.,0.
PBAR,7,1,1.E-3,1.E-6,2.E-6,3.E-6
MAT1,1,2.1E11,,0.3
SPC1,1,123456,1
FORCE,5,2,,1000.,1.,-2.,3.
DESVAR,1,AREA,{X1},0.1,10.
DESVAR,2,INER,{X2},1.,10.
DESVAR,3,DEP,1.,0.1,100.
DLINK,1,3,0.5,2.,2,1.
DVPREL1,10,PBAR,7,A,,,1.E-4
,1,5.E-4
DVPREL1,11,PBAR,7,5
,2,PVAL
DVPREL1,12,PBAR,7,I2
,3,1.E-6
DVMREL1,20,MAT1,1,E
,1,1.E11
DRESP1,100,W,WEIGHT
DCONSTR,1,100,,1.E5
EIGRL,9,,,3
ENDDATA
"""


def test_cantilever_is_the_initial_design(tmp_path):
    """The designed A, I1 (PVAL), I2 (through a DLINK) and E replace the cards' values: the tip
    moves as the closed forms of the designed bar say; the MODES subcase is not imported."""
    result = _import(tmp_path, CANTILEVER)
    assert result.cases == ("1",)
    assert any("subcase 2 is ANALYSIS = MODES" in n for n in result.notes)
    assert any("design model (DESVAR x3, DLINK x1, DVPREL1 x3, DVMREL1 x1)" in n and "PBAR 7" in n
               for n in result.notes)
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    p, m = deck.pbars[7], deck.mat1s[1]
    assert (p.a, p.i1, p.i2, p.j) == pytest.approx((A_D, I1_D, I2_D, 3.0e-6), rel=1e-15)
    assert (m.e, m.nu, m.g) == pytest.approx((E_D, 0.3, E_D / 2.6), rel=1e-15)
    _, report, u = _solve(result)
    tip = {c: u[report.index((2, c)), 0] for c in range(1, 7)}
    fx, fy, fz = P
    expect = {1: fx * L / (E_D * A_D), 2: fy * L**3 / (3 * E_D * I1_D), 3: fz * L**3 / (3 * E_D * I2_D),
              4: 0.0, 5: -fz * L**2 / (2 * E_D * I2_D), 6: fy * L**2 / (2 * E_D * I1_D)}
    for c, value in expect.items():
        assert tip[c] == pytest.approx(value, rel=CLOSED, abs=1e-18), c


def test_the_same_cards_outside_sol_200_are_dropped(tmp_path):
    """SOL 101 does not read a design model: the cards' own values are the model."""
    text = CANTILEVER.replace("SOL 200", "SOL 101").replace("DESOBJ(MIN) = 100\n", "").replace(
        "  ANALYSIS = STATICS\n", "").replace("SUBCASE 2\n  ANALYSIS = MODES\n  METHOD = 9\n  LOAD = 5\n", "")
    result = _import(tmp_path, text)
    assert any("dropped the design model" in n and "SOL 101" in n for n in result.notes)
    assert "DVPREL1" not in result.model_bdf and "DESVAR" not in result.model_bdf
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    assert (deck.pbars[7].a, deck.mat1s[1].e) == (1.0e-3, 2.1e11)


def test_misspelled_design_command_is_read_by_its_first_four_letters(tmp_path):
    """DESOPJ (pyNastran's degvcn03.bdf, an MSC test deck) is DESOBJ to NASTRAN."""
    result = _import(tmp_path, CANTILEVER.replace("DESOBJ(MIN)", "DESOPJ(MIN)"))
    assert any("DESOBJ (written DESOPJ)" in n for n in result.notes)


ROD_SPRING = """SOL 200
CEND
SPC = 1
SUBCASE 1
  LOAD = 5
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,3.,0.,0.
GRID,3,,3.,2.,0.
GRID,4,,6.,0.,0.
GRID,5,,9.,0.,0.
CROD,1,8,1,2
PROD,8,1,1.E-3,1.E-6
CONROD,2,2,4,1,1.E-3,1.E-6
CBAR,3,9,4,5,0.,1.,0.
PBARL,9,1,,BAR
,0.1,0.2
CTUBE,5,6,2,3
PTUBE,6,1,0.05,0.01
CELAS1,4,12,3,2,0,0
PELAS,11,5.E4,,,12,1.E5
MAT1,1,7.E10,,0.33
SPC1,1,123456,1
SPC1,1,23456,2,4,5
SPC1,1,13456,3
FORCE,5,5,,1000.,1.,0.,0.
FORCE,5,3,,500.,0.,1.,0.
DESVAR,1,X1,2.,1.,4.
DESVAR,2,X2,0.5,0.1,1.
DVPREL1,1,PROD,8,A,1.E-4,1.E-2
,1,1.E-3
DVPREL1,2,PBARL,9,DIM2,,,0.05
,2,0.2
DVPREL1,3,PELAS,12,K1
,1,4.E4
DVPREL1,4,PTUBE,6,OD
,2,0.2
DVPREL1,5,PMASS,33,3
,1,1.
ENDDATA
"""


def test_rod_section_and_spring_designs(tmp_path):
    """A PROD's A, a PBARL's DIM2 (the equivalent section is made again from it), the second
    PELAS of a card, a PTUBE's OD: grid 5 moves P (L1 / (E A1) + 0 + L3 / (E A3)) along x
    (the CONROD between 2 and 4 is undesigned), grid 3 P2 / (K + E A_tube / L) along y (the
    grounded spring beside the tube)."""
    result = _import(tmp_path, ROD_SPRING)
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    a_rod = 1.0e-3 * 2.0
    a_bar = 0.1 * (0.05 + 0.2 * 0.5)
    k = 4.0e4 * 2.0
    od = 0.2 * 0.5
    a_tube = np.pi * (od**2 - (od - 0.02) ** 2) / 4
    assert deck.prods[8].a == pytest.approx(a_rod, rel=1e-15)
    assert deck.pbars[9].a == pytest.approx(a_bar, rel=1e-15)
    assert deck.pelas[12].k == k and deck.pelas[11].k == 5.0e4
    assert deck.prods[6].a == pytest.approx(a_tube, rel=1e-14)
    _, report, u = _solve(result)
    e = 7.0e10
    ux5 = 1000.0 * (3.0 / (e * a_rod) + 3.0 / (e * 1.0e-3) + 3.0 / (e * a_bar))
    uy3 = 500.0 / (k + e * a_tube / 2.0)
    assert u[report.index((5, 1)), 0] == pytest.approx(ux5, rel=CLOSED)
    assert u[report.index((3, 2)), 0] == pytest.approx(uy3, rel=CLOSED)


@pytest.mark.parametrize("edit, card, field, why", [
    (("DVPREL1,1,PROD,8,A,1.E-4,1.E-2", "DVPREL1,1,PROD,8,A,1.E-4,1.E-3"), "DVPREL1", 7,
     r"A = 0.002 at the initial design .*outside \[PMIN, PMAX\]"),
    (("DESVAR,1,X1,2.,1.,4.", "DESVAR,1,X1,5.,1.,4."), "DESVAR", 4, "XINIT = 5 is outside"),
    (("DVPREL1,3,PELAS,12,K1\n,1,4.E4", "DVPREL1,3,PELAS,12,K1\n,7,4.E4"), "DVPREL1", 10,
     "design variable 7 has no DESVAR"),
    (("DVPREL1,1,PROD,8,A", "DVPREL1,1,PROD,81,A"), "DVPREL1", 4, "PROD 81 does not exist"),
    (("DVPREL1,1,PROD,8,A", "DVPREL1,1,PROD,8,-3"), "DVPREL1", 5, "element property table"),
    (("DVPREL1,1,PROD,8,A", "DVPREL1,1,PROD,8,AREA"), "DVPREL1", 5, "not a property of PROD"),
    (("DVPREL1,2,PBARL,9,DIM2", "DVPREL1,2,PBARL,9,DIM3"), "DVPREL1", 5, "not a dimension of PBARL"),
    (("DVPREL1,4,PTUBE,6,OD", "DVPREL1,4,PTUBE,6,T"), "DVPREL1", 5,
     "PTUBE 6 with its designed value.*wall thickness"),
    (("DVPREL1,5,PMASS", "DVPREL1,3,PMASS"), "DVPREL1", 2, "duplicate DVPREL1 ID 3"),
    (("DVPREL1,5,PMASS,33,3\n,1,1.", "DVPREL2,5,PROD,8,J,,,7\n,DESVAR,1\nDEQATN  7       A(X)=FOO(X)"),
     "DEQATN", 3, "function FOO is not evaluated"),
    (("DVPREL1,5,PMASS,33,3\n,1,1.", "DVPREL2,5,PROD,8,J,,,7\n,DESVAR,1\nDEQATN  7       A(X,Y)=X"),
     "DEQATN", 3, "has 2 argument"),
    (("DVPREL1,5,PMASS,33,3\n,1,1.", "DVPREL2,5,PROD,8,J,,,7\n,DESVAR,1\n,DTABLE,C9\nDEQATN  7       A(X,C)=X"),
     "DVPREL2", 19, "DTABLE label C9 is not defined"),
    (("DVPREL1,5,PMASS,33,3\n,1,1.", "DVPREL2,5,PROD,8,J,,,8\n,DESVAR,1"), "DVPREL2", 8,
     "DEQATN 8 does not exist"),
    (("DVPREL1,5,PMASS,33,3\n,1,1.", "DVCREL1,5,CONROD,2,A\n,1,1."), "DVCREL1", 3,
     "connectivity value of CONROD 2"),
    (("DVPREL1,5,PMASS,33,3\n,1,1.", "DVPREL1,5,PROD,8,4\n,2,1."), "DVPREL1", 5,
     "PROD 8 A is designed twice"),
])
def test_bad_design_fields_are_located(edit, card, field, why, tmp_path):
    with pytest.raises(DeckFormatError, match=why) as info:
        _import(tmp_path, ROD_SPRING.replace(*edit))
    assert (info.value.card, info.value.field) == (card, field)


# --------------------------------------------------------------------------------------------
# against MYSTRAN
# --------------------------------------------------------------------------------------------
FRAME = """SOL {sol}
CEND
SPC = 1
DISP = ALL
SUBCASE 1
  LOAD = 5
SUBCASE 2
  LOAD = 6
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
GRID,3,,2.,1.5,0.
GRID,4,,0.,1.5,1.
GRID,5,,2.,0.,2.
CBAR,1,7,1,2,0.,0.,1.
CBAR,2,8,2,3,0.,0.,1.
CBAR,3,7,3,4,1.,0.,0.
CROD,4,11,4,1
CBAR,6,8,2,5,1.,0.,0.
CELAS1,7,12,3,2,4,2
PBAR,7,1,{a7},{i17},2.E-6,4.E-6
PBAR,8,2,{a8},1.8E-6,{i28},2.E-6
PROD,11,2,{a11},1.E-6
PELAS,12,{k12}
MAT1,1,{e1},8.1E10
MAT1,2,7.E10,,.33
SPC1,1,123456,1,5
FORCE,5,3,,1000.,0.,0.,-1.
FORCE,6,4,,800.,1.,1.,0.
MOMENT,6,2,,50.,0.,1.,0.
{design}ENDDATA
"""
DESIGN = """DESVAR,1,T,1.5,1.,3.
DESVAR,2,W,0.8,0.5,1.
DLINK,1,3,0.,1.,1,0.5,2,1.
DESVAR,3,D,1.,0.1,10.
DVPREL1,1,PBAR,7,A,,,5.E-4
,1,1.E-3
DVPREL1,2,PBAR,7,I1
,1,PVAL
DVPREL1,3,PBAR,8,I2,,,1.E-7
,3,1.E-6,2,5.E-7
DVPREL1,4,PROD,11,A
,2,1.E-3
DVPREL1,5,PELAS,12,K1
,3,2.E5
DVMREL1,6,MAT1,1,E
,1,1.4E11
DVPREL2,7,PBAR,8,A,,,70
,DESVAR,1,2
,DTABLE,CA
DTABLE,CA,1.E-3
DEQATN  70      A(T,W,C)=C*T*W**2
"""
X = {1: 1.5, 2: 0.8}
X[3] = 0.5 * X[1] + X[2]
VALUES = {"a7": 5.0e-4 + 1.0e-3 * X[1], "i17": 3.0e-6 * X[1], "i28": 1.0e-7 + 1.0e-6 * X[3] + 5.0e-7 * X[2],
          "a11": 1.0e-3 * X[2], "k12": 2.0e5 * X[3], "e1": 1.4e11 * X[1], "a8": 1.0e-3 * X[1] * X[2]**2}


@needs_mystran
def test_frame_agrees_with_mystran_on_the_sol_101_deck_of_the_initial_design(tmp_path):
    """The SOL 200 frame imported (card values 3e-6, 1e-6, ... overridden by the design model)
    and solved by the reference solver, against MYSTRAN running the SOL 101 deck whose cards hold
    the designed values (printed to the 16 characters of a field, the shortest digits that
    round-trip), every grid and component of both subcases."""
    plain = {"a7": "3.E-3", "i17": "3.E-6", "i28": "1.E-6", "a11": "1.E-3", "k12": "1.E5", "e1": "2.1E11",
             "a8": "1.5E-3"}
    sol200 = FRAME.format(sol=200, design=DESIGN, **plain)
    cases, report, u = _solve(_import(tmp_path, sol200, "frame.dat"))
    sol101 = FRAME.format(sol=101, design="", **{k: print_float_16(v) for k, v in VALUES.items()})
    ref = _mystran(tmp_path, sol101)
    grids = sorted(ref[1])
    for j, case in enumerate(cases):
        theirs = np.array([ref[int(case)][g] for g in grids])
        ours = np.array([[u[report.index((g, c)), j] if (g, c) in report else 0.0 for c in range(1, 7)]
                         for g in grids])
        assert _agree(ours, theirs, f"case {case}") <= RTOL


@needs_mystran
def test_mystran_run_deck_carries_the_initial_design(tmp_path):
    """The imported SOL 200 study solved by the mystran adapter: its run deck, written from the
    parsed model, holds the designed values (and none of the design cards, which MYSTRAN does
    not read)."""
    plain = {"a7": "3.E-3", "i17": "3.E-6", "i28": "1.E-6", "a11": "1.E-3", "k12": "1.E5", "e1": "2.1E11",
             "a8": "1.5E-3"}
    assert _study_against_mystran(tmp_path, FRAME.format(sol=200, design=DESIGN, **plain), 2) <= RTOL


def test_equations_of_responses_are_read_and_have_no_effect(tmp_path):
    """A DEQATN whose equation holds commas (on its first line and on a continuation line, in
    columns 17-72 and 9-72: fixed-field text, not free-field fields), a DRESP2 that uses it, and
    a DVPREL2 on a PMASS (a mass: no static effect; its equation is not evaluated) leave the
    initial design as it was."""
    extra = ("DEQATN  1       F(A,RL,S) = 1.0-(S+39.274*A*1.0E7/\n"
             "                (RL**2,1.)/ABS(S)\n"
             "DRESP2,101,R,1\n,DESVAR,1,2\n"
             "DVPREL2,30,PMASS,4,3,,,1\n,DESVAR,1\nPMASS,4,1.\n")
    plain = _solve(_import(tmp_path, CANTILEVER, "a.dat"))[2]
    result = _import(tmp_path, CANTILEVER.replace("ENDDATA", extra + "ENDDATA"), "b.dat")
    assert np.array_equal(_solve(result)[2], plain)
    from solver_adapters.bdf import read_deck
    path = tmp_path / "model.bdf"
    path.write_text(result.model_bdf)
    deck = read_deck(path)
    assert deck.no_effect["DRESP2"][0] == 1 and deck.pbars[7].a == pytest.approx(A_D, rel=1e-15)
    from test_reader_paths import assert_same
    assert_same(result.model_bdf, tmp_path, must_read=True)


@pytest.mark.parametrize("deck", ["CANTILEVER", "ROD_SPRING"])
def test_both_reader_paths_read_the_design_alike(deck, tmp_path):
    """The bulk path and the card-by-card path give the same designed model."""
    from test_reader_paths import assert_same
    assert_same(_import(tmp_path, globals()[deck]).model_bdf, tmp_path, must_read=True)


def test_thermal_load_of_the_initial_design(tmp_path):
    """A SOL 200 static subcase's TEMPERATURE(LOAD) is SOL 101's: the cantilever 50 degrees above
    TREF stretches by alpha 50 L, alpha the DVMREL1's (2e-5 X1 at X1 = 2, the card says 1.2e-5),
    with no force: the designed E and A do not enter a free member's thermal stretch."""
    text = CANTILEVER.replace("  LOAD = 5\nSUBCASE 2", "  TEMP(LOAD) = 8\nSUBCASE 2").replace(
        "MAT1,1,2.1E11,,0.3", "MAT1,1,2.1E11,,0.3,,1.2E-5,20.").replace(
        "ENDDATA", "TEMPD,8,70.\nDVMREL1,21,MAT1,1,A\n,1,2.E-5\nENDDATA")
    result = _import(tmp_path, text)
    _, report, u = _solve(result)
    assert u[report.index((2, 1)), 0] == pytest.approx(2.0e-5 * X1 * 50.0 * L, rel=CLOSED)
    assert abs(u[report.index((2, 3)), 0]) <= 1e-12 * L


EQUATION = CANTILEVER.replace("DVPREL1,11,PBAR,7,5\n,2,PVAL\n", "DVPREL2,11,PBAR,7,I1,,,40\n,DESVAR,1,2\n"
                              ",DTABLE,SCALE\nDTABLE,SCALE,3.E-7,UNUSED,1.\n"
                              "DEQATN,40,I(W,D,S) = S*(W*D**3)/12.; I2=I+0.0\n")
"""The cantilever with I1 from an equation of two design variables and a table constant:
I1 = S W D^3 / 12 = 3e-7 2 4^3 / 12 (a second statement leaves it as it is; the DEQATN in free
field, its equation's commas kept)."""


def test_equation_relation_is_evaluated(tmp_path):
    """A DVPREL2 (DEQATN of DESVAR values and a DTABLE constant) designs I1: the tip moves as the
    closed form of the bar with that I1, and the DEQATN and DTABLE stay out of MYSTRAN's deck."""
    i1 = 3.0e-7 * X1 * X2**3 / 12.0
    result = _import(tmp_path, EQUATION)
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    assert deck.pbars[7].i1 == pytest.approx(i1, rel=1e-15)
    _, report, u = _solve(result)
    assert u[report.index((2, 2)), 0] == pytest.approx(P[1] * L**3 / (3 * E_D * i1), rel=CLOSED)
    from solver_adapters.nastran import passthrough_cards
    path = tmp_path / "model.bdf"
    path.write_text(result.model_bdf)
    assert not {c.name for c in passthrough_cards(path)} & {"DEQATN", "DTABLE", "DVPREL2"}


@pytest.mark.parametrize("text, args, value", [
    ("F(X)=-X**2", [3.0], -9.0), ("F(X,Y)=2.**X**Y", [3.0, 2.0], 512.0),
    ("F(A,B)=MAX(A,B,7.)-MIN(A,B)+ABS(-A)", [1.0, 2.0], 7.0), ("F(X)=SQRT(X)*1.D1", [4.0], 20.0),
    ("F(X)=X/4.; G=F*2.; H=G+1.E-1", [2.0], 1.1), ("F(X, Y) = ATAN2(Y, X)", [1.0, 1.0], 0.7853981633974483), ("F(A,B) = 1.-(A+39.274*B*1.0E7/(A**2))/ABS(A)",
                                                  [2.0, 1e-7], 1.0 - (2.0 + 39.274 * 1e-7 * 1.0e7 / 2.0**2) / 2.0),
])
def test_equations_evaluate_as_fortran(text, args, value):
    """FORTRAN's precedence: ** binds tighter than unary minus and to the right."""
    from solver_adapters.bdf.equations import evaluate
    assert evaluate(text, args) == pytest.approx(value, rel=1e-15)


@pytest.mark.parametrize("text, why", [("F(X)=X+", "ends too early"), ("F(X)=X)", "unexpected"),
                                       ("F(X)=__import__", "cannot read"), ("F(X)=Y", "Y has no value"),
                                       ("F(X)=X/0.", "division by zero"), ("X=1.", "first statement")])
def test_equations_refuse_what_they_cannot_read(text, why):
    from solver_adapters.bdf.equations import EquationError, evaluate
    with pytest.raises(EquationError, match=why):
        evaluate(text, [1.0])
