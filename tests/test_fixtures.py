"""The cube and car study folders: counts from the dissertation, `blackbox solve`, and a
cross-check of both decks against the real MYSTRAN executable (an independent FE code).

MYSTRAN prints 7 significant digits (docs/mystran.md), so agreement is checked to 1e-6 relative to
the largest displacement of each case (the issue's figure); the reference solver is exact to
~1e-13 on these models.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from blackbox.cli import main
from blackbox.reference_tables import TABLE_3_1, TABLE_3_1_LENGTH
from blackbox.study import load_study
from solver_adapters.bdf import read_deck
from solver_adapters.reference import ReferenceAdapter

from conftest import FIXTURES, needs_mystran


def test_car_counts_match_the_dissertation():
    """Section 3.7.2: 63 nodes, 115 elements, 384 DOFs including the joint's 12."""
    deck = read_deck(FIXTURES / "car" / "model.bdf")
    assert len(deck.grids) == 65 and len(deck.cbars) == 115
    study = load_study(FIXTURES / "car")
    a = ReferenceAdapter(study.deck_path)
    assert len(a.dofs()) == 390
    _, f_labels, T = a.stiffness()
    constrained = sum(1 for i in range(T.shape[0]) if T[i].nnz == 0)
    assert T.shape[1] + constrained == 384          # 62*6 + 12 after the RBE2 ties
    assert len(study.config.joints) == 1 and len(study.config.joints[0].grids) == 3


def test_cube_matches_table_3_1():
    deck = read_deck(FIXTURES / "cube" / "model.bdf")
    assert len(deck.cbars) == 12 and len(deck.grids) == 10
    (p,) = deck.pbars.values()
    (m,) = deck.mat1s.values()
    t = TABLE_3_1
    assert (m.e, m.g, p.a, p.i1, p.i2, p.j) == (t["E"], t["G"], t["A"], t["Iz"], t["Iy"], t["J"])
    lengths = {round(float(np.linalg.norm(np.subtract(deck.grids[b.ga].xyz, deck.grids[b.gb].xyz))), 12)
               for b in deck.cbars.values()}
    assert lengths == {TABLE_3_1_LENGTH}


def read_displacements(path: Path) -> dict:
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    return {(r["case"], int(r["grid"]), int(r["component"])): float(r["value"]) for r in rows}


@pytest.mark.parametrize("name", ["cube", "car"])
def test_blackbox_solve_writes_every_grid_and_case(name, tmp_path):
    assert main(["solve", str(FIXTURES / name), "--out", str(tmp_path), "--no-cache"]) == 0   # fixtures/ stays as is
    d = read_displacements(tmp_path / "displacements.csv")
    study = load_study(FIXTURES / name)
    n_grids = len(read_deck(study.deck_path).grids)
    assert len(d) == len(study.loads.cases) * n_grids * 6


@needs_mystran
@pytest.mark.parametrize("name", ["cube", "car"])
def test_fixture_decks_agree_with_mystran(name, tmp_path):
    assert main(["solve", str(FIXTURES / name), "--out", str(tmp_path / "ref"), "--no-cache"]) == 0
    assert main(["solve", str(FIXTURES / name), "--adapter", "mystran", "--out", str(tmp_path / "mys"),
                 "--no-cache"]) == 0
    ref = read_displacements(tmp_path / "ref" / "displacements.csv")
    mys = read_displacements(tmp_path / "mys" / "displacements.csv")
    assert ref.keys() == mys.keys()
    for case in {k[0] for k in ref}:
        keys = [k for k in ref if k[0] == case]
        a = np.array([ref[k] for k in keys])
        b = np.array([mys[k] for k in keys])
        assert np.max(np.abs(a - b)) <= 1e-6 * np.max(np.abs(a)), case


def test_solve_bad_input_is_one_paragraph(tmp_path, capsys):
    bad = tmp_path / "study"
    bad.mkdir()
    for f in ("study.toml", "model.bdf"):
        (bad / f).write_text((FIXTURES / "cube" / f).read_text())
    (bad / "loads.csv").write_text("case,grid,component,value\nL1,999,6,0.5\n")
    assert main(["solve", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "loads.csv:2" in err and "grid 999" in err and "Traceback" not in err


def test_the_study_deck_is_parsed_once():
    """load_study parses model.bdf; the reference adapter built for the study reuses that parse
    (a 1e6-DOF deck takes ~23 s to read) while keeping the path the run cache hashes."""
    from blackbox.adapters import make_adapter_for

    study = load_study(FIXTURES / "cube")
    adapter = make_adapter_for(study, cache=False)
    assert adapter.deck is study.deck and adapter.deck_path == study.deck_path
    cached = make_adapter_for(study, cache=True)
    assert cached.inner.deck is study.deck
