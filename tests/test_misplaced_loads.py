"""Several loads of one case each at a neighbouring grid: ``misplaced_load``'s richer variant
``loads`` (``blackbox.diagnosis.effects.misplaced_load.MisplacedLoads``).

The study is ``benchmarks/unlisted_defects.py``'s misplaced-load study of seed 54, index 3 (a
bus frame): case L6 loads grids 4, 20 and 28, and the benchmark put each load in at a
neighbour (4 at 10, 20 at 8, 28 at 34; noncentrality 1611). Before the variant: one load found,
at the wrong neighbour (28 at 16, share 0.87), then three outliers of L6 (4 effects, reduced chi2
1.109)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import unlisted_defects as ud
from benchmarks.blind.generate import NONE, generate_study
from blackbox.commands import diagnose as dc
from blackbox.diagnosis.effects.misplaced_load import MisplacedLoad, MisplacedLoads


def _single(g, h, at_g, at_h, others=()):
    return MisplacedLoad((g,), (f"t_L1_{g}_to_{h}",), case="L1", moved_to=h, at_g=at_g, at_h=at_h, others=others)


def test_loads_moved_into_one_grid_add_up_and_the_variant_is_nested():
    """Two loads moved into the same grid 3 (1 -> 3 and 2 -> 3): their changes at 3 add up; at
    the nested point the variant changes nothing, and it equals the single misplacement where
    its new share is 0."""
    a = _single(1, 3, ((2, -10.0),), ((2, -10.0),))
    b = (2, 3, ((2, -4.0),), ((2, -4.0),))
    (v, xv), = MisplacedLoads(a.where, a.names, case="L1", members=(a,), others=(b,)).richer(np.array([0.7]))
    assert v.variant == "loads" and v.where == (1, 2) and v.n_params == 2
    np.testing.assert_array_equal(xv, [0.7, 0.0])
    cases = ("L0", "L1")
    assert len(v.load_dofs) == len(set(v.load_dofs)) == 3           # (1, 2), (3, 2), (2, 2)
    row = {d: i for i, d in enumerate(v.load_dofs)}
    dF = v.load_change(np.array([1.0, 1.0]), cases)
    assert dF[row[(3, 2)], 1] == -14.0 and dF[row[(1, 2)], 1] == 10.0 and dF[row[(2, 2)], 1] == 4.0
    assert not dF[:, 0].any()
    np.testing.assert_array_equal(v.load_change(np.zeros(2), cases), 0.0)
    single = a.load_change(np.array([0.7]), cases)
    np.testing.assert_array_equal(v.load_change(xv, cases)[[row[d] for d in a.load_dofs]], single)
    # no further grid to add; a share below one half is no misplacement of that load
    assert v.richer(np.array([1.0, 1.0])) == []
    assert "grid 2" in v.rejection(np.array([1.0, 0.3]))
    assert v.rejection(np.array([1.0, 0.9])) is None


def test_a_misplacement_of_a_load_blocks_another_of_the_same_load():
    a = _single(1, 3, ((2, -10.0),), ((2, -10.0),))
    other = _single(1, 4, ((2, -10.0),), ((2, -10.0),))

    class Spec:
        effects = (a,)
    assert not other.applicable(Spec())


@pytest.fixture(scope="module")
def moved(tmp_path_factory):
    out = tmp_path_factory.mktemp("moved")
    st = generate_study(3, 54, out, kind=NONE, shape="bus", style="plain")
    where = ud.plant_load(st, "misplaced_load", np.random.default_rng([54, 3, ud.DEFECTS.index("misplaced_load")]))
    assert where["case"] == "L6" and where["moved"] == [[4, 10], [20, 8], [28, 34]]
    return st.folder, where


def test_two_of_three_misplaced_loads_are_one_effect_at_their_neighbours(moved):
    folder, where = moved
    d = dc.run(folder, plots=False).diagnosis
    assert len(d.added) == 1
    e = d.final.spec.effects[0]
    assert e.kind == "misplaced_load" and e.variant == "loads" and e.case == "L6"
    found = sorted([m.grid, m.moved_to] for m in e.members)
    # every load found at its true neighbour; 4 -> 10 moves the readings least (LR 23 once the
    # other two are in, not significant at the kind's level), so it may stay unnamed
    assert {(20, 8), (28, 34)} <= {tuple(p) for p in found} and all(p in where["moved"] for p in found)
    assert d.verdict == "explained" and d.band[0] <= d.final.reduced_chi2 <= d.band[1]


def test_misplaced_loads_of_a_holdout_case_are_chosen_grid_by_grid(tmp_path):
    """Seed 55's hall s0002 with ``--in-holdout``: hold-out case L5's three loads each put in at
    a neighbour (18 at 16, 32 at 30, 96 at 94; noncentrality 8242). Each grid's best single
    neighbour, fitted together, was rejected and the case left "not predicted"; chosen grid by
    grid, each with those before, two moves predict it (chi2 14200 -> 67 over 75 readings), both
    at their true neighbours, and the verdict is "explained" with the data named."""
    st = generate_study(2, 55, tmp_path, kind=NONE, shape="hall", style="plain")
    where = ud.plant_load(st, "misplaced_load", np.random.default_rng([55, 2, ud.DEFECTS.index("misplaced_load")]),
                          in_holdout=True)
    assert where["case"] == "L5" and where["moved"] == [[18, 16], [32, 30], [96, 94]]
    r = dc.run(st.folder, plots=False)
    hc = r.document["holdout_check"]
    (case,) = hc["cases"]
    assert case["case"] == "L5" and case["reads_as"] == "misplaced_load" and case["of"] == "data"
    moved = sorted([x["grid"], x["moved_to"]] for x in case["load"]["loads"])
    assert len(moved) >= 2 and all(m in where["moved"] for m in moved)
    assert r.diagnosis.verdict == "explained" and not r.diagnosis.added
