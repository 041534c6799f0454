"""``load_cell``: the load at one grid off by one factor in every case that loads it.

The study is ``benchmarks/unlisted_defects.py``'s load-cell study of seed 56, index 1 (a frame
made from an imported public deck): grid 15 is loaded in cases L4, L5, L6, L7 and L15, and the
structure felt 0.85 of each of those loads (noncentrality 659). Before the kind it was read as a
member factor at 57, a turned load at 15 and all loads of another case turned: a defect of the
structure and two of the data where there is one of the data."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import unlisted_defects as ud
from benchmarks.blind.generate import NONE, generate_study
from blackbox.commands import diagnose as dc
from blackbox.diagnosis.effects.load_cell import LoadCell


def test_the_factor_scales_the_grids_load_in_every_case_that_has_one():
    e = LoadCell((7,), ("s_load_7",), comps=(2, 6), loads=(("A", (10.0, 0.0)), ("C", (-4.0, 2.0))))
    cases = ("A", "B", "C")
    np.testing.assert_array_equal(e.load_change(np.array([1.0]), cases), 0.0)      # nested at 1
    np.testing.assert_allclose(e.load_change(np.array([0.85]), cases),
                               [[-1.5, 0.0, 0.6], [0.0, 0.0, -0.3]], rtol=1e-12)
    np.testing.assert_array_equal(e.load_change_derivatives(np.array([0.85]), cases)[0],
                                  [[10.0, 0.0, -4.0], [0.0, 0.0, 2.0]])
    assert e.load_dofs == ((7, 2), (7, 6)) and e.cases == ("A", "C")


def test_a_grid_whose_cases_load_nothing_else_is_left_to_load_scale():
    """Grid 1 is loaded by cases A and B, which load nothing else: a factor there is a load scale
    of A and B (``load_scale``), so no ``load_cell`` candidate names it again. Grid 2, loaded by
    C beside grid 3, is one; so is grid 3 (its one case loads grid 2 too). Grid 4, loaded only in
    the hold-out case D, is none: its factor is the hold-out check's load factor of D."""
    from types import SimpleNamespace as NS

    from blackbox.identification import Observations
    from solver_adapters.protocol import LoadMatrix
    dofs = ((1, 2), (2, 3), (3, 3), (4, 1))
    V = np.array([[5.0, 6.0, 0.0, 0.0], [0.0, 0.0, 7.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 2.0]])
    loads = LoadMatrix(dofs, V, ("A", "B", "C", "D"))
    obs = Observations(((9, 1),) * 3, np.array([0, 1, 2]), np.zeros(3), np.ones(3), ("A", "B", "C"))
    deck = NS(grids={g: NS(id=g, ps="") for g in (1, 2, 3, 4)}, spc1s=[])
    got = LoadCell._listed(NS(loads=loads, fit_obs=obs, deck=deck))
    assert [e.grid for e in got] == [2, 3] and got[0].cases == ("C",) and got[0].comps == (3,)


@pytest.fixture(scope="module")
def scaled(tmp_path_factory):
    out = tmp_path_factory.mktemp("load_cell")
    st = generate_study(1, 56, out, kind=NONE, shape="imported", style="plain")
    where = ud.plant_load(st, "load_cell", np.random.default_rng([56, 1, ud.DEFECTS.index("load_cell")]))
    assert where["load_at"] == [15] and where["cases"] == ["L4", "L5", "L6", "L7", "L15"]
    return st.folder


def test_a_load_cell_reading_high_is_one_factor_at_its_grid(scaled):
    r = dc.run(scaled, plots=False)
    d = r.diagnosis
    assert [(a.effect.kind, tuple(a.effect.where)) for a in d.added] == [("load_cell", (15,))]
    (p,) = r.document["added"][0]["parameters"]
    # the planted 0.85 within 3 standard errors (the fit's interval, from the declared noise)
    assert abs(p["value"] - 0.85) <= 3 * p["std"] and p["std"] < 0.01
    a = r.document["added"][0]
    assert a["of"] == "data" and a["pattern"] == "scale" and a["cases"] == ["L4", "L5", "L6", "L7", "L15"]
    assert d.verdict == "explained"
