"""CBARAO (MSC QRG CBARAO: the stations along a CBAR where its forces and stresses are printed)
has no effect on a linear static solution: recognised, named in the one summary line of cards
with no effect, kept in model.bdf, never a reason for another adapter, and never handed to
MYSTRAN, which matches entry names on a prefix and would read it as a CBAR.

Reference: the same cantilever solved with and without the card (identical displacements), and
MYSTRAN 18 running the deck with it through the mystran adapter (1e-6 of the largest value:
MYSTRAN prints 7 digits)."""

from __future__ import annotations

import numpy as np
import pytest

from solver_adapters.bdf import NO_EFFECT, read_deck_text
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran
from test_deck_tail import CANTILEVER, _import, mystran_matches_reference

CBARAO = "CBARAO,1,SCALE,.5\nCBARAO,1,FR,3,.25,.5,.75\n"

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _tip(deck) -> np.ndarray:
    loads = LoadMatrix.from_dense([(2, 3)], np.array([[-100.0]]), ["1"])
    report = [(2, c) for c in range(1, 7)]
    return ReferenceAdapter(deck).solve(loads, report).values


def test_cbarao_has_no_effect_and_is_named_once(tmp_path):
    deck = read_deck_text(CANTILEVER + CBARAO, name="m.bdf")
    assert "CBARAO" in NO_EFFECT and deck.no_effect["CBARAO"][0] == 2 and not deck.unmodelled
    assert "CBARAO x2 (first at m.bdf:7)" in deck.summary()
    np.testing.assert_array_equal(_tip(deck), _tip(read_deck_text(CANTILEVER, name="m.bdf")))
    text = ("SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\n" + CANTILEVER + CBARAO +
            "FORCE,5,2,,1.,0.,0.,-1.\nENDDATA\n")
    result = _import(tmp_path, text)
    assert 'adapter = "reference"' in result.study_toml and CBARAO.splitlines()[0] in result.model_bdf
    line = [n for n in result.notes if n.startswith("accepted with no effect")]
    assert len(line) == 1 and "CBARAO x2" in line[0]


def test_cbarao_never_reaches_mystran(tmp_path):
    from solver_adapters.nastran import passthrough_cards
    p = tmp_path / "m.bdf"
    p.write_text(CANTILEVER + CBARAO)
    assert [c.name for c in passthrough_cards(p)] == []


@needs_mystran
def test_mystran_adapter_runs_a_deck_with_cbarao(tmp_path):
    mystran_matches_reference(tmp_path, CBARAO)
