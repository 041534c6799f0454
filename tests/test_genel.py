"""GENEL, NASTRAN's general element: a stiffness or flexibility matrix over UI components, with
UD components and the rigid-body matrix S (solver_adapters/bdf/matrices.py).

References: NASA's NASTRAN-95 demonstration problem D01-14-1A (tests/data/decks/d01141a.inp), a
cantilever of six unit segments (EA = 6, EI = 0.5), five of them GENELs in each of the card's
forms and one a CBAR; its published displacements (NASTRAN-95 ``demoout/d01141a.out``, 7 printed
digits) are those of beam theory: axial load 1 at the tip, u(x) = x / EA; transverse load 1,
v(x) = x^2 (3 L - x) / (6 EI) and theta(x) = x (2 L - x) / (2 EI), L = 6.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from blackbox.commands import import_deck
from solver_adapters.bdf import read_deck_text
from solver_adapters.bdf_write import write_deck
from solver_adapters.protocol import DeckFormatError
from test_deck_tail import _solve

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

D01141A = Path(__file__).parent / "data" / "decks" / "d01141a.inp"

# NASTRAN-95's printed displacements of D01-14-1A, grids 1-7: T1 in subcase 1; T2 and R3 in 2
PRINTED_T1 = [0.0, 1.666667e-01, 3.333334e-01, 5.000001e-01, 6.666667e-01, 8.333327e-01, 9.999993e-01]
PRINTED_T2 = [0.0, 5.666667, 21.33333, 45.0, 74.66666, 108.3333, 144.0]
PRINTED_R3 = [0.0, 11.0, 20.0, 27.0, 32.0, 35.0, 36.0]


def _displacements(result):
    cases, report, u = _solve(result)
    index = {d: i for i, d in enumerate(report)}
    return {(g, c, case): u[index[(g, c)], j] for j, case in enumerate(cases) for g in range(1, 8)
            for c in (1, 2, 6) if (g, c) in index} | {(1, c, case): 0.0 for c in (1, 2, 6) for case in cases}


def test_nasas_general_elements_give_nastrans_published_cantilever():
    """Every GENEL form of D01-14-1A: the displacements NASTRAN-95 printed, to 2e-6 of the
    largest (7 printed digits, and one Z term the deck prints as .166666 for 1/6), and beam
    theory to the same."""
    result = import_deck.run(D01141A)
    assert result.cases == ("1", "2")
    u = _displacements(result)
    x = np.arange(7.0)
    for name, got, printed, exact in (
            ("T1", [u[(g, 1, "1")] for g in range(1, 8)], PRINTED_T1, x / 6.0),
            ("T2", [u[(g, 2, "2")] for g in range(1, 8)], PRINTED_T2, x ** 2 * (18.0 - x) / 3.0),
            ("R3", [u[(g, 6, "2")] for g in range(1, 8)], PRINTED_R3, x * (12.0 - x))):
        scale = np.abs(exact).max()
        assert np.abs(np.array(got) - printed).max() <= 2e-6 * scale, name
        assert np.abs(np.array(got) - exact).max() <= 2e-6 * scale, name


def test_a_written_deck_reads_back_as_the_same_element():
    """write_deck (diagnose's edited decks) writes each GENEL as the stiffness form over all its
    components; read back, the structure solves to the same displacements to round-off."""
    result = import_deck.run(D01141A)
    deck = read_deck_text(result.model_bdf)
    assert sorted(m.label for m in deck.dmigs.values()) == [f"GENEL {i}" for i in range(1, 6)]
    again = write_deck(deck, "large")
    assert again.count("GENEL*") == 5 and "DMIG" not in again
    back = read_deck_text(again)
    for name in deck.dmigs:
        a = {(r, c): v for r, c, v in deck.dmigs[name].terms}
        b = {(r, c): v for r, c, v in back.dmigs[name].terms}
        assert a.keys() == b.keys()
        assert max(abs(a[k] - b[k]) for k in a) <= 1e-9 * max(abs(v) for v in a.values())


BASE = """GRID,1,,0.,0.,0.,,123456
GRID,2,,1.,0.,0.,,345
GRID,3,,2.,0.,0.,,345
GRID,4,,3.,0.,0.,,345
"""


@pytest.mark.parametrize("genel, field, says", [
    ("GENEL,7,,2,1,2,2\n,K,1.,0.", 10, "needs the lower triangle of an 2 x 2 matrix"),
    ("GENEL,7,,2,1,2,2,2,6\n,UD,,3,1,4,2,3,6\n,K,6.,0.,0.,6.,3.,2.", 4, "the UD components are on 2 points"),
    ("GENEL,7,,2,1,2,2\n,Z,1.,1.,1.", 4, "its flexibility Z is singular"),
    ("GENEL,7,,2,1,2,2", 9, "needs its matrix"),
    ("GENEL,7,,2,1,2,2\n,S,1.,0.", 10, "needs its matrix"),
])
def test_a_bad_general_element_is_a_located_error(genel, field, says):
    with pytest.raises(DeckFormatError, match=says) as err:
        read_deck_text(BASE + genel + "\n")
    assert (err.value.card, err.value.field) == ("GENEL", field)


def test_the_mystran_adapter_refuses_a_general_element(tmp_path):
    """MYSTRAN 18 has no GENEL: the mystran adapter says so, naming the element, before any run."""
    from solver_adapters.nastran import check_writable
    deck = read_deck_text(import_deck.run(D01141A).model_bdf, name="model.bdf")
    with pytest.raises(DeckFormatError, match="cannot run GENEL 1 .*has no GENEL") as err:
        check_writable(deck)
    assert err.value.card == "GENEL"


def test_a_grid_a_general_element_couples_is_no_undeclared_joint_candidate():
    """The undeclared-joint cut splits a grid's bars and would leave a GENEL on one side: where two
    bars meet a GENEL the grid is not cut, and the diagnosis's notes say why."""
    from blackbox.diagnosis.decks import cards_at, unmodelled_notes, unsplittable_grids
    deck = read_deck_text(BASE.replace(",,345", "") + "MAT1,1,1.,,.3\nPBAR,1,1,1.,1.,1.,1.\nCBAR,1,1,2,3,0.,1.,0.\n"
                          "CBAR,2,1,3,4,0.,1.,0.\nGENEL,7,,3,2,3,6\n,K,1.,0.,1.\n")
    assert unsplittable_grids(deck) == {3: ["GENEL 7"]}
    assert "GENEL 7" in cards_at(deck, 3)
    assert any("GENEL elements are not candidates (3)" in n for n in unmodelled_notes(deck))
