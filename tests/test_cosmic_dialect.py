"""COSMIC NASTRAN (NASTRAN-95) input that MSC's reads otherwise or not at all: the CBAR/BAROR flag
F in field 9, ``SOL n,m`` (rigid format n, subset m), ``STRESSES`` (docs/import.md).

References: the NASTRAN-95 User's Manual's CBAR (F = 1: X1 X2 X3 a vector; F = 2: X1 the grid
G0; both in GA's displacement system, offsets in each end's: OFFT GGG) and its rigid formats
(1: static analysis; DSCOEFFICIENT selects rigid formats 4 and 13's differential stiffness
coefficients). Results are compared with the same deck written with MSC's fields, which
must give the same numbers bit for bit (the same cards after the flag is read).
"""

from __future__ import annotations

import numpy as np
import pytest

from blackbox.commands import import_deck
from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import DeckFormatError, LoadMatrix
from solver_adapters.reference import ReferenceAdapter

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

FRAME = """CORD2R,5,,0.,0.,0.,0.3,0.4,1.,+C5
+C5,1.,0.2,0.
GRID,1,,0.,0.,0.,5,123456
GRID,2,,1.,0.,0.,5
GRID,3,,1.,1.,0.
GRID,9,,0.,0.,5.
MAT1,1,2.1E11,,.3
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
{bars}
"""
"""Grids 1 and 2 in a turned displacement system (CD 5), so that an orientation vector and
offsets read in GA's system (G) differ from the same numbers read in basic (B)."""
MSC = "CBAR,1,7,1,2,0.,1.,1.,GGG,+A\n+A,,,0.,0.,0.,0.,0.,.1\nCBAR,2,7,2,3,9,,,GGG"
COSMIC = "CBAR,1,7,1,2,0.,1.,1.,1,+A\n+A,,,0.,0.,0.,0.,0.,.1\nCBAR,2,7,2,3,9,,,2"


def _tip(bulk: str) -> np.ndarray:
    deck = read_deck_text(bulk)
    adapter = ReferenceAdapter(deck)
    loads = LoadMatrix.from_dense([(3, c) for c in range(1, 7)], np.eye(6) * 1e3, [f"c{c}" for c in range(1, 7)])
    return adapter.solve(loads, [(3, c) for c in range(1, 7)]).values


def test_cbar_flag_f_is_offt_ggg():
    """F = 1 (a vector, with an offset at end B) and F = 2 (a grid G0) give the MSC deck's
    solution exactly; BAROR's F alike."""
    np.testing.assert_array_equal(_tip(FRAME.format(bars=COSMIC)), _tip(FRAME.format(bars=MSC)))
    basic = _tip(FRAME.format(bars=MSC.replace("GGG", "BGG", 1)))
    assert np.abs(basic - _tip(FRAME.format(bars=MSC))).max() > 1e-3 * np.abs(basic).max()   # G is not B
    baror = "BAROR,,7,,,0.,1.,1.,1\nCBAR,1,,1,2\nCBAR,2,,2,3,0.,1.,1."
    plain = "CBAR,1,7,1,2,0.,1.,1.\nCBAR,2,7,2,3,0.,1.,1."
    np.testing.assert_array_equal(_tip(FRAME.format(bars=baror)), _tip(FRAME.format(bars=plain)))


@pytest.mark.parametrize("bars, says", [("CBAR,1,7,1,2,9,,,1", "as a vector"),
                                         ("CBAR,1,7,1,2,0.,1.,1.,2", "as a grid G0"),
                                         ("CBAR,1,7,1,2,0.,1.,1.,3", "OFFT must be one of")])
def test_cbar_flag_f_that_contradicts_its_fields_is_a_located_error(bars, says):
    with pytest.raises(DeckFormatError) as e:
        read_deck_text(FRAME.format(bars=bars))
    assert "field 9" in str(e.value) and says in str(e.value)


def test_sol_1_0_is_static_and_stresses_is_an_output_request(tmp_path):
    """``SOL 1,0`` (rigid format 1, static analysis) reads its TEMPERATURE selection as SOL 101
    does (a deck of another solution is refused there); ``STRESSES`` is the STRESS request."""
    deck = ("ID COSMIC,TEST\nAPP DISP\nSOL 1,0\nCEND\nSTRESSES = ALL\nDSCOEFFICIENT = DEFAULT\n"
            "TEMPERATURE(LOAD) = 5\nLOAD = 10\n"
            "SPC = 1\nBEGIN BULK\n" + FRAME.format(bars=COSMIC).replace("PBAR", "TEMPD,5,120.\nPBAR")
            .replace("MAT1,1,2.1E11,,.3", "MAT1,1,2.1E11,,.3,,1.2E-5,20.")
            + "SPC1,1,123456,1\nFORCE,10,3,,1000.,0.,0.,1.\nENDDATA\n")
    p = tmp_path / "cosmic.inp"
    p.write_text(deck)
    res = import_deck.run(p)
    assert res.cases == ("1",)
    assert any("STRESS" in n for n in res.notes)
    assert any("selections of other solutions (DSCOEFFICIENT)" in n for n in res.notes)
    with pytest.raises(DeckFormatError, match="not linear statics"):
        q = tmp_path / "modes.inp"
        q.write_text(deck.replace("SOL 1,0", "SOL 3,0"))
        import_deck.run(q)


ROD_FRAME = """GRID,1,,0.,0.,0.,,123456
GRID,2,,1.,0.,0.,,2345
GRID,3,,2.,0.,0.,,2345
GRID,4,,2.,1.,0.,,345
PROD,5,1,1.E-3,1.E-6
PTUBE,6,1,.05,.005
MAT1,1,2.1E11,,.3
SPC1,1,123456,4
"""


@pytest.mark.parametrize("cosmic, msc", [
    ("CROD,60,5,1,2,61,5,2,3\nCTUBE,70,6,3,4\n", "CROD,60,5,1,2\nCROD,61,5,2,3\nCTUBE,70,6,3,4\n"),
    ("CROD,60,5,1,2\nCTUBE,70,6,3,4,71,,2,3\n", "CROD,60,5,1,2\nCTUBE,70,6,3,4\nCTUBE,71,71,2,3\nPTUBE,71,1,.05,.005\n"),
])
def test_two_rods_on_one_card_are_two_rods(cosmic, msc):
    """COSMIC's CROD/CTUBE carry a second element in fields 6-9 (a blank PID is the EID, as for
    the first): the same model, and the same displacements bit for bit, as two cards."""
    extra = "PTUBE,71,1,.05,.005\n" if "71" in cosmic else ""
    a = read_deck_text(ROD_FRAME + extra + cosmic)
    b = read_deck_text(ROD_FRAME + msc)
    assert sorted(a.rods) == sorted(b.rods)
    loads = LoadMatrix.from_dense([(2, 1), (3, 1), (3, 2)], np.eye(3) * 1e3, ["x2", "x3", "y3"])
    dofs = [(g, c) for g in (2, 3) for c in (1, 2)]
    np.testing.assert_array_equal(ReferenceAdapter(a).solve(loads, dofs).values,
                                  ReferenceAdapter(b).solve(loads, dofs).values)


def test_a_second_rod_left_half_written_is_a_located_error():
    with pytest.raises(DeckFormatError) as e:
        read_deck_text(ROD_FRAME + "CROD,60,5,1,2,61,5,2\n")
    assert "card CROD" in str(e.value) and "field 9" in str(e.value) and "second CROD" in str(e.value)


def test_pressure_stiffness_elements_have_no_static_effect():
    """CPSE2/CPSE3/CPSE4 and PPSE are differential stiffness only ("no structural stiffness and
    no structural mass", User's Manual, CPSEi remark 2): accepted with no effect, the solution
    that of the frame without them, bit for bit."""
    bars = MSC + "\nCPSE2,17,2,1,2\nCPSE3,18,2,1,2,3\nPPSE,2,500."
    deck = read_deck_text(FRAME.format(bars=bars))
    assert set(deck.no_effect) == {"CPSE2", "CPSE3", "PPSE"}
    np.testing.assert_array_equal(_tip(FRAME.format(bars=bars)), _tip(FRAME.format(bars=MSC)))
