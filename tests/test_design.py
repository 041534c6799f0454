"""``blackbox design`` (:mod:`blackbox.experiment_design`, :mod:`blackbox.commands.design`).

Reference values: the fixtures' truths (``fixtures/*/truth.toml``: cube springs 1e4 N*m/rad, car
springs 1e5 N*m/rad, car complex model Table 5.18) with their noise model (5 % of each reading,
floor 0.02). The goals at full scale are printed by ``benchmarks/design.py``; here they are
checked on smaller plans.
"""

from __future__ import annotations

import json
import re
from functools import lru_cache

import numpy as np
import pytest

from blackbox import experiment_design as D
from blackbox.commands import design as cmd
from blackbox.commands.common import study_adapter
from blackbox.commands.output import write_output
from blackbox.condensation import CondensedModel, condense
from blackbox.declared import declared_model, read_truth, truth_joints
from blackbox.errors import StudyError
from blackbox.fitting.statistics import covariance
from blackbox.identification.problem import _Problem
from blackbox.joints import joint_dofs
from blackbox.simulation import NoiseConfig
from blackbox.study import load_study
from conftest import FIXTURES, ROOT, copy_fixture

NOISE = NoiseConfig(relative=0.05, floor=0.02)
SETUP = {"cube": ((7, 71, 72), (5, 6, 8), {1}, 5.0, 0.5),
         "car": ((11, 111, 112), (9, 10, 12, 13), {6, 36, 26, 56}, 1000.0, 100.0)}


def make_candidates(study, structure: str, reference: bool) -> D.Candidates:
    jg, away, spc, F, M = SETUP[structure]
    grids = sorted(g for g in study.deck.grids if g not in spc | set(jg))
    loads = tuple(D.CandidateLoad(g, c, F if c <= 3 else M) for g in grids for c in range(1, 7))
    ref = jg[0] if reference else None
    sens = [D.CandidateSensor(g, c, None, None if ref is None or g == ref else ref) for g, c in joint_dofs(jg)]
    sens += [D.CandidateSensor(g, c, None, ref) for g in away for c in range(1, 7)]
    return D.Candidates(loads, tuple(sens))


@lru_cache(maxsize=None)
def setup(fixture: str, reference: bool):
    """The fixture condensed once with every candidate (the fixture folder is only read: no cache)."""
    study = load_study(FIXTURES / fixture)
    dm = declared_model(study)
    cands = make_candidates(study, "cube" if fixture.startswith("cube") else "car", reference)
    cm = dm.condense(study_adapter(study, None, cache=False), observed=cands.observed, loads=cands.unit_loads())
    tp = study.root / "truth.toml"
    _, kt = truth_joints(study, read_truth(tp), tp)
    space = D.candidate_space(cm, cands, np.asarray(kt, float), NOISE)
    return study, dm, cands, cm, np.asarray(kt, float), space


def write_candidates(path, cands: D.Candidates):
    rows = ["kind,grid,component,value,sigma,reference_grid"]
    rows += [f"load,{ld.grid},{ld.component},{ld.value},," for ld in cands.loads]
    rows += [f"sensor,{s.grid},{s.component},,{'' if s.sigma is None else s.sigma},"
             f"{'' if s.reference_grid is None else s.reference_grid}" for s in cands.sensors]
    path.write_text("\n".join(rows) + "\n")
    return path


# ---------------------------------------------------------------------------------------------
# superposition and the information matrix
# ---------------------------------------------------------------------------------------------
def test_one_solver_run_and_plans_by_superposition_match_a_direct_condensation():
    study, dm, cands, cm, kt, space = setup("cube", True)
    assert cm.c.solver_runs == 1
    plan = [3, 17, 30]
    pc = CondensedModel(D.plan_condensed(cm.c, cands, plan), list(dm.joints), cm.K_deck)
    from solver_adapters.protocol import LoadMatrix
    ld = [cands.loads[i] for i in plan]
    V = np.zeros((len(ld), len(ld)))
    np.fill_diagonal(V, [x.value for x in ld])
    direct = CondensedModel(condense(study_adapter(study, None, cache=False),
                                     LoadMatrix.from_dense([x.dof for x in ld], V, ["a", "b", "c"]),
                                     dm.boundary, cands.observed), list(dm.joints), cm.K_deck)
    dofs = [s.dof for s in cands.sensors]
    a = pc.pick(pc.response(kt), dofs)
    b = direct.pick(direct.response(kt), dofs)
    # superposition of a linear solve: equal to rounding (1e-10 of the largest reading)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * np.abs(b).max())


def test_predicted_covariance_is_the_identifications_at_the_same_rows():
    """F = sum g g^T is J^T V_m^-1 J of Sec. 4.4 with J from the identification's own eq. 18
    Jacobian (`_Problem.jacobian_k`) on the plan's rows."""
    study, dm, cands, cm, kt, space = setup("car", False)
    loads, sensors = [5, 40, 77, 120], list(range(0, 36, 2))
    pc = CondensedModel(D.plan_condensed(cm.c, cands, loads), list(dm.joints), cm.K_deck)
    obs = D.plan_observations(cands, loads, sensors, space.u, space.sigma)
    prob = _Problem(pc, obs)
    f, resp = prob.predict(kt)
    np.testing.assert_allclose(f, obs.values, rtol=1e-9)          # the same readings, to rounding
    J = prob.jacobian_k(kt, resp) * prob.w[:, None]
    np.testing.assert_allclose(D.information(space, loads, sensors), J.T @ J, rtol=1e-8,
                               atol=1e-10 * np.abs(J.T @ J).max())
    pred = D.predict(space, loads, sensors)
    np.testing.assert_allclose(pred.std, covariance(J, space.size).std, rtol=1e-8)


def test_blank_sigma_follows_the_simulators_noise_model():
    """Every candidate sensor in every case, the planned sigma is blackbox.simulation's
    (5 % of the reading, floored at 5 % x 2 % of the largest reading of its kind)."""
    study, dm, cands, cm, kt, space = setup("car", False)
    u = space.u
    kinds = np.array([s.component >= 4 for s in cands.sensors])
    for i in (0, 50, 100):
        for kind in (False, True):
            m = kinds == kind
            expect = 0.05 * np.maximum(np.abs(u[i, m]), 0.02 * np.abs(u[i, m]).max())
            np.testing.assert_allclose(space.sigma[i, m], expect, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# the search
# ---------------------------------------------------------------------------------------------
def test_exchange_leaves_no_improving_single_swap():
    study, dm, cands, cm, kt, space = setup("cube", True)
    plan = D.optimise(space, 4)
    rest = [i for i in range(space.n_loads) if i not in plan.loads]
    for pos in range(4):
        for j in rest[::3]:
            L = list(plan.loads)
            L[pos] = j
            # a local optimum of the exchange (no swap better by more than rounding)
            assert D.criterion(space, plan.criterion, L, plan.sensors) >= plan.value * (1 - 1e-9)


@pytest.mark.parametrize("criterion", ["max_relative_ci_width", "d_optimal", "a_optimal"])
@pytest.mark.parametrize("n", [3, 4])
def test_greedy_and_exchange_find_the_exhaustive_optimum_on_the_cube(criterion, n):
    """Cube, absolute readings, every sensor: 7140 (n = 3) and 58905 (n = 4) plans of the 36
    candidate loads tried one by one; the search finds the same criterion value (to rounding)."""
    study, dm, cands, cm, kt, space = setup("cube", False)
    best = D.exhaustive(space, n, criterion)
    found = D.optimise(space, n, None, criterion)
    assert found.value <= best.value + 1e-9 * abs(best.value)


@pytest.mark.parametrize("fixture, reference, n, m, ratio", [
    ("cube", True, 4, 12, 2.0),       # measured x8.9 (benchmarks/design.py)
    ("car", False, 8, None, 2.0),     # measured x5.5
    ("car", True, 8, None, 2.0),      # measured x2.1
])
def test_designed_median_width_is_at_least_twice_narrower_than_random_plans(fixture, reference, n, m, ratio):
    study, dm, cands, cm, kt, space = setup(fixture, reference)
    plan = D.optimise(space, n, m)
    p = D.predict(space, plan.loads, plan.sensors)
    rnd = [D.predict(space, r.loads, r.sensors).median_relative_width
           for r in D.random_plans(space, n, m, 50, seed=n)]
    assert np.median(rnd) >= ratio * p.median_relative_width


@pytest.mark.parametrize("name", ["d_optimal", "a_optimal"])
def test_other_criteria_beat_random_plans_on_their_own_measure(name):
    study, dm, cands, cm, kt, space = setup("car", False)
    plan = D.optimise(space, 6, None, name)
    rnd = [D.criterion(space, name, r.loads, r.sensors) for r in D.random_plans(space, 6, None, 30, seed=2)]
    assert plan.value < np.min(rnd)


def test_car_complex_designed_plan_reaches_chapter5_30_cases_with_8():
    """Chapter 5 (studies/chapter5.md, car-complex): L1-L30 give a geometric mean of 2 std / size
    of 2.6 % (realised median over 10 replicates; predicted here at the truth: 2.61 %). A designed
    plan of 8 single-load cases (forces and moments) gets there (benchmark: 7 cases, d_optimal)."""
    import importlib.util
    import sys
    spec = importlib.util.spec_from_file_location("_test_design_gf", ROOT / "fixtures" / "generate_fixtures.py")
    gf = importlib.util.module_from_spec(spec)
    sys.modules["_test_design_gf"] = gf
    spec.loader.exec_module(gf)
    gf.N_EXTRA_CASES = 29
    rows = gf.build_car().loads
    from solver_adapters.protocol import LoadMatrix
    cases = list(dict.fromkeys(str(r[0]) for r in rows))
    dofs = list(dict.fromkeys((int(r[1]), int(r[2])) for r in rows))
    V = np.zeros((len(dofs), len(cases)))
    for c, g, k, v in rows:
        V[dofs.index((int(g), int(k))), cases.index(str(c))] = float(v)
    study, dm, cands, cm, kt, space = setup("car_complex", True)
    ch5 = D.candidate_space(cm, cands, kt, NOISE, cases=LoadMatrix.from_dense(dofs, V, cases))
    p30 = D.predict(ch5, range(30), range(len(cands.sensors)))
    assert p30.geometric_mean_2std == pytest.approx(0.026, rel=0.05)     # chapter5.md: 2.6 % (rounded)
    plan = D.optimise(space, 8, None, "d_optimal", restarts=1)
    p = D.predict(space, plan.loads, plan.sensors)
    assert p.geometric_mean_2std <= p30.geometric_mean_2std
    assert p.max_relative_width <= p30.max_relative_width


def test_discrimination_separates_the_models_and_one_case_cannot():
    """In one load case the joint acts on the structure only through its 6 independent moments,
    which 9 simple springs can always reproduce: the excess chi2 of the simple model is ~0 for
    every single case; with 3 designed cases it is far above random plans' (benchmark x40)."""
    study, dm, cands, cm, kt, space = setup("car_complex", True)
    simple = declared_model(study, "simple").condensed_model(cm.c)
    ds = D.discrimination_space(space, cm, kt, simple)
    total = float(np.sum(ds.discrimination[0].r ** 2))
    one = -D.optimise(ds, 1, None, "discrimination", restarts=0).value * total
    three = -D.optimise(ds, 3, None, "discrimination", restarts=1).value * total
    assert one < 1e-6 * three
    rnd = [-D.criterion(ds, "discrimination", r.loads, r.sensors) * total
           for r in D.random_plans(ds, 3, None, 30, seed=3)]
    assert three > 10 * np.median(rnd)


def test_discrimination_predicts_the_simple_models_excess_chi2():
    """lambda is the noncentrality of the simple model's chi2 when the complex model is true:
    100 simulated tests of the 2-case discrimination plan, each fitted with the simple model, give
    mean(chi2) - (n - 9) = lambda within 5 % (its standard error is ~1 % of lambda here, the
    linearisation of the simple model adds ~1-2 %; measured 418 predicted vs 424 realised)."""
    from blackbox.identification import identify
    study, dm, cands, cm, kt, space = setup("car_complex", True)
    simple = declared_model(study, "simple").condensed_model(cm.c)
    ds = D.discrimination_space(space, cm, kt, simple)
    plan = D.optimise(ds, 2, None, "discrimination", restarts=1)
    lam = -plan.value * float(np.sum(ds.discrimination[0].r ** 2))
    pm = CondensedModel(D.plan_condensed(cm.c, cands, plan.loads), list(simple.assembly.joints), simple.K_deck)
    obs = D.plan_observations(cands, plan.loads, plan.sensors, space.u, space.sigma)
    rng = np.random.default_rng(5)
    chi2 = [identify(pm, obs.with_values(obs.values + obs.sigma * rng.standard_normal(len(obs))),
                     ds.discrimination[0].k_simple, profile=False, max_iterations=100).chi2 for _ in range(100)]
    assert np.mean(chi2) - (len(obs) - 9) == pytest.approx(lam, rel=0.05)


# ---------------------------------------------------------------------------------------------
# predicted vs realised (Sec. 4.4's covariance, tested as a statistic)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("fixture, reference, n, m", [("cube", True, 8, 12), ("car", False, 6, None)])
def test_predicted_widths_match_the_realised_median_over_200_repetitions(fixture, reference, n, m):
    """200 simulated tests of the designed plan at the truth, each identified from the study's
    start in the condensed space: the median realised width of every parameter within 10 % of
    the prediction (the median of 200 widths scatters by ~1-2 % here; the linearisation at the
    estimate instead of the truth adds a few %; benchmark: 0.4 % and 0.2 %)."""
    study, dm, cands, cm, kt, space = setup(fixture, reference)
    plan = D.optimise(space, n, m)
    pred = D.predict(space, plan.loads, plan.sensors)
    est, w = D.simulate_plan(cm, cands, plan, kt, space.sigma, dm.k0, 200, seed=7)
    assert np.isnan(w[:, 0]).sum() == 0
    ratio = np.median(w, axis=0) / pred.relative_width
    assert np.all(np.abs(ratio - 1.0) < 0.10), ratio


# ---------------------------------------------------------------------------------------------
# the command
# ---------------------------------------------------------------------------------------------
def test_command_writes_the_plan(tmp_path):
    study_dir = copy_fixture("cube", tmp_path / "cube")
    study, dm, cands, cm, kt, space = setup("cube", True)
    f = write_candidates(tmp_path / "candidates.csv", cands)
    res = cmd.run(study_dir, f, n_loads=4, n_sensors=10, n_random=10)
    assert res.solver.runs == 1 and res.command == "design"
    files = write_output(tmp_path / "out", "design", res.write)
    assert {"design.json", "loads.csv", "measurements_template.csv", "report.md"} <= set(files)
    js = json.loads((tmp_path / "out" / "design.json").read_text())
    assert js["criterion"] == "max_relative_ci_width"
    assert [ld["case"] for ld in js["loads"]] == ["D1", "D2", "D3", "D4"]
    assert len(js["sensors"]) == 10 and len(js["predicted"]) == 9
    assert {"joint", "name", "value", "std", "ci_low", "ci_high"} <= set(js["predicted"][0])
    assert js["curve"]["n_cases"] == [1, 2, 3, 4]
    assert "truth.json" in js["noise"]["source"]
    lines = (tmp_path / "out" / "measurements_template.csv").read_text().splitlines()
    assert lines[0] == "case,grid,component,value,sigma,reference_grid" and len(lines) == 1 + 40
    assert all(line.split(",")[3] == "" and float(line.split(",")[4]) > 0 for line in lines[1:])
    # the template, once filled in, is a measurements.csv of the study with the designed loads
    (study_dir / "loads.csv").write_text((tmp_path / "out" / "loads.csv").read_text())
    filled = [lines[0]] + [",".join(p[:3] + ["1e-6"] + p[4:]) for p in (line.split(",") for line in lines[1:])]
    (study_dir / "measurements.csv").write_text("\n".join(filled) + "\n")
    assert len(load_study(study_dir, need_measurements=True).measurements) == 40


def test_cli_design(tmp_path, capsys):
    """``blackbox design`` end to end: --out checked, outputs written, one solver run."""
    from blackbox.cli import main

    study_dir = copy_fixture("cube", tmp_path / "cube")
    study, dm, cands, cm, kt, space = setup("cube", True)
    f = write_candidates(tmp_path / "candidates.csv", cands)
    assert main(["design", str(study_dir), "--candidates", str(f), "--loads", "3", "--sensors", "10",
                 "--out", str(tmp_path / "d"), "--no-cache"]) == 0
    assert "1 solver run(s)" in capsys.readouterr().out
    assert (tmp_path / "d" / "design.json").is_file() and (tmp_path / "d" / "loads.csv").is_file()
    with pytest.raises(SystemExit) as info:                  # a budget of 0 cases is a usage error
        main(["design", str(study_dir), "--candidates", str(f), "--loads", "0", "--out", str(tmp_path / "e")])
    assert info.value.code == 2 and not (tmp_path / "e").exists()


def test_one_random_plan_median_in_the_report_json_and_curve(tmp_path):
    """The report's yardstick (random plans of the design's size) and the curve's last point are
    one sample of random plans: the same median everywhere the report gives it."""
    study_dir = copy_fixture("cube", tmp_path / "cube")
    study, dm, cands, cm, kt, space = setup("cube", True)
    f = write_candidates(tmp_path / "candidates.csv", cands)
    res = cmd.run(study_dir, f, n_loads=3, n_sensors=10, n_random=20)
    assert res.random_median_width == res.curve.random_max[-1, 1]
    js = res.to_json()
    assert js["random_plans"]["median_max_relative_width"] == js["curve"]["random_max_relative_width"][-1][1]
    write_output(tmp_path / "out", "design", res.write)
    report = (tmp_path / "out" / "report.md").read_text()
    shown = re.search(r"random plans of the same size \(median of 20\): widest ([0-9.e+-]+ %)", report)[1]
    row = next(line for line in report.splitlines() if line.startswith("| 3 |"))
    assert row.split(" | ")[2] == shown


def test_a_start_value_prior_is_said_with_what_a_pilot_buys(tmp_path, capsys):
    """Without --prior the design predicts at the study's start value: the notes (printed as a
    warning, in design.json and report.md) say so, with the measured cost of it on the car
    fixture and what a pilot result or --robust buys; with a prior there is no such note."""
    from blackbox.cli import main

    study_dir = copy_fixture("cube", tmp_path / "cube")
    study, dm, cands, cm, kt, space = setup("cube", True)
    f = write_candidates(tmp_path / "candidates.csv", cands)
    assert main(["design", str(study_dir), "--candidates", str(f), "--loads", "2", "--sensors", "6",
                 "--out", str(tmp_path / "d"), "--no-cache"]) == 0
    out = capsys.readouterr().out
    assert "warning: the prior is only the study's start value (J7 = 1000)" in out
    assert "pilot test" in out and "--robust" in out and "docs/design.md" in out
    js = json.loads((tmp_path / "d" / "design.json").read_text())
    assert js["notes"][0].startswith("the prior is only the study's start value")
    assert "the prior is only the study's start value" in (tmp_path / "d" / "report.md").read_text()
    truth = FIXTURES / "cube" / "truth.toml"
    res = cmd.run(study_dir, f, n_loads=2, n_sensors=6, n_random=5, prior=truth)
    assert not any("start value" in n for n in res.notes)


def test_robust_design_with_prior_result(tmp_path):
    study_dir = copy_fixture("cube", tmp_path / "cube")
    study, dm, cands, cm, kt, space = setup("cube", True)
    f = write_candidates(tmp_path / "candidates.csv", cands)
    prior = {"parameters": [{"joint": "J7", "name": n, "value": 1e4, "std": 3e3, "ci_low": None, "ci_high": None}
                            for n in dm.joints[0].param_names]}
    (tmp_path / "result.json").write_text(json.dumps(prior))
    res = cmd.run(study_dir, f, n_loads=3, prior=tmp_path / "result.json", robust=True, draws=4, n_random=5)
    assert res.robust_draws == 4 and res.space.g.shape[0] == 5        # the prior point and 4 draws
    np.testing.assert_allclose(res.prediction.value, 1e4)
    assert np.all(np.isfinite(res.prediction.std))


@pytest.mark.parametrize("text, message", [
    ("kind,grid,component,value,sigma\nload,5,1,5.0,\nactuator,5,2,1,\n", "kind must be"),
    ("kind,grid,component,value,sigma\nload,5,9,5.0,\n", "component must be"),
    ("kind,grid,component,value,sigma\nload,999,1,5.0,\n", "not in the deck"),
    ("kind,grid,component,value,sigma\nload,5,1,5.0,\nsensor,7,4,,-1\n", "sigma must be positive"),
    ("kind,grid,component,value,sigma\nload,5,1,5.0,\n", "no candidate sensors"),
])
def test_bad_candidates_say_where(tmp_path, text, message):
    f = tmp_path / "c.csv"
    f.write_text(text)
    with pytest.raises(StudyError, match=message):
        cmd.run(FIXTURES / "cube", f, n_loads=1)


def test_budgets_are_checked_before_any_work(tmp_path):
    study, dm, cands, cm, kt, space = setup("cube", True)
    f = write_candidates(tmp_path / "candidates.csv", cands)
    with pytest.raises(StudyError, match="--loads must be"):
        cmd.run(FIXTURES / "cube", f, n_loads=len(cands.loads) + 1)
    with pytest.raises(StudyError, match="--criterion must be"):
        cmd.run(FIXTURES / "cube", f, n_loads=2, criterion="e_optimal")


def test_labelled_candidate_cases_are_superposed_like_the_studys_own_cases(tmp_path):
    """The cube's 20 load cases (loads.csv, several loads each) given as candidate cases (a
    ``case`` label per row): the information of all 20 equals J^T V^-1 J of a condensation with
    those cases themselves (eq. 18 at the identification's rows, same sigma)."""
    study, dm, cands0, cm0, kt, _ = setup("cube", True)
    L = study.loads
    V = L.values.toarray()
    rows = ["kind,grid,component,value,sigma,reference_grid,case"]
    rows += [f"load,{g},{c},{float(V[i, j])!r},,,{L.cases[j]}" for j in range(L.n_cases)
             for i, (g, c) in enumerate(L.dofs) if V[i, j] != 0.0]
    rows += [f"sensor,{s.grid},{s.component},,,{'' if s.reference_grid is None else s.reference_grid},"
             for s in cands0.sensors]
    f = tmp_path / "cases.csv"
    f.write_text("\n".join(rows) + "\n")
    cands = cmd.read_candidates(f, set(study.deck.grids))
    assert len(cands.cases) == 20 and cands.case_label(3) == "L4"
    cm = dm.condense(study_adapter(study, None, cache=False), observed=cands.observed, loads=cands.unit_loads())
    space = D.candidate_space(cm, cands, kt, NOISE)
    direct = dm.condense(study_adapter(study, None, cache=False), observed=cands.observed, loads=L)
    obs = D.plan_observations(cands, range(20), range(len(cands.sensors)), space.u, space.sigma)
    obs = type(obs)(obs.dofs, obs.case_index, obs.values, obs.sigma, L.cases, obs.ref_dofs)
    prob = _Problem(direct, obs)
    f_direct, resp = prob.predict(kt)
    np.testing.assert_allclose(f_direct, obs.values, rtol=1e-8, atol=1e-10 * np.abs(obs.values).max())
    J = prob.jacobian_k(kt, resp) * prob.w[:, None]
    F = D.information(space, range(20), range(len(cands.sensors)))
    np.testing.assert_allclose(F, J.T @ J, rtol=1e-7, atol=1e-9 * np.abs(F).max())
    # the command writes every load of a chosen case under the case's D label
    study_dir = copy_fixture("cube", tmp_path / "cube")
    res = cmd.run(study_dir, f, n_loads=3, n_random=5)
    chosen = res.to_json()
    assert len(chosen["candidate_cases"]) == 3
    by_case = {}
    for ld in chosen["loads"]:
        by_case.setdefault(ld["case"], []).append((ld["grid"], ld["component"], ld["value"]))
    for d, label in zip(sorted(by_case), chosen["candidate_cases"]):
        j = L.cases.index(label)
        assert sorted(by_case[d]) == sorted((g, c, V[i, j]) for i, (g, c) in enumerate(L.dofs) if V[i, j] != 0.0)
