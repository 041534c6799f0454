"""Defects of the test data, and a joint with play, as effects the diagnosis finds.

Planted on the cube fixture (Section 3.7.1: 20 load cases, grids 5, 6, 8 and the joint's DOFs
measured with 5 % noise; Table 3.1 structure), the way a rig produces them: the reading is wrong,
and the sigma the user declares follows the reading (a swapped or misplaced channel carries its
reading's noise and declared sigma along). Each is found at its place, as what it is, with an
interval around the planted size; the report calls it the data, not the structure. A joint gap
is planted from ``blackbox.structures.gap_response`` (the truth solved case by case), which the
augmented model reproduces to rounding.
"""

from __future__ import annotations

import csv
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

from blackbox import diagnosis as dg
from blackbox.commands import diagnose as diagnose_command
from blackbox.diagnosis.effects import JointGap
from blackbox.structures import gap_response
from solver_adapters.reference import ReferenceAdapter

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"


def _copy(tmp: Path, name: str) -> Path:
    dst = tmp / name
    shutil.copytree(FIXTURES / "cube", dst, ignore=shutil.ignore_patterns(".blackbox_cache", "*.png", "truth*"))
    return dst


def _rows(study: Path) -> list[dict]:
    return list(csv.DictReader(open(study / "measurements.csv")))


def _write(study: Path, rows: list[dict]) -> None:
    with open(study / "measurements.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _channel(rows, g, c):
    return {r["case"]: r for r in rows if int(r["grid"]) == g and int(r["component"]) == c}


def _diagnose(study: Path) -> dict:
    return diagnose_command.run(study, plots=False).document


def _only(doc: dict, kind: str) -> dict:
    assert doc["verdict"] == "explained", doc["verdict_detail"]
    added = [a for a in doc["added"] if a["effect"] == kind]
    assert len(added) == 1 and doc["added"][0]["effect"] == kind, [(a["effect"], a["where"]) for a in doc["added"]]
    assert len(doc["added"]) <= 2
    return added[0]


def _within(p: dict, truth: float, n_std: float = 4.0) -> None:
    """The planted value within ``n_std`` standard errors (a 4-sigma band: a false failure once
    in ~16,000 runs of a correct method)."""
    assert abs(p["value"] - truth) <= n_std * p["std"], (p, truth)


TRUTH_K = 1.0e4         # the cube fixture's joint springs (Table 5.12 setting)


def _truth_adapter(pr, k):
    """The reference solver on the cube's deck with its joint's springs at ``k``."""
    from blackbox.structures import make_joint, spring_network
    j = pr.joints[0]
    return ReferenceAdapter(pr.deck).with_springs(spring_network(make_joint(j.name, j.grids, "simple"), k))


def _measure(study: Path, cases, response, seed: int) -> None:
    """The study's readings rewritten as a truth, ``response(o)`` (displacements at the measured
    DOFs ``o``, one column per case of ``cases``), plus fresh noise at each reading's declared
    sigma (``seed``)."""
    rows = _rows(study)
    o = list(dict.fromkeys((int(r["grid"]), int(r["component"])) for r in rows))
    U = response(o)
    cases = list(cases)
    oi = {d: i for i, d in enumerate(o)}
    rng = np.random.default_rng(seed)
    for r in rows:
        u = U[oi[(int(r["grid"]), int(r["component"]))], cases.index(r["case"])]
        r["value"] = repr(float(u + rng.normal() * float(r["sigma"])))
    _write(study, rows)


@pytest.fixture(scope="module")
def tmp_module():
    with tempfile.TemporaryDirectory() as t:
        yield Path(t)


def test_sign_flip(tmp_module):
    study = _copy(tmp_module, "flip")
    rows = _rows(study)
    for r in _channel(rows, 5, 2).values():
        r["value"] = repr(-float(r["value"]))
    _write(study, rows)
    doc = _diagnose(study)
    a = _only(doc, "sign_flip")
    assert a["where"] == [5] and a["component"] == 2 and a["of"] == "data"
    _within(a["parameters"][0], -1.0)
    assert "test data" in doc["verdict_detail"]


def test_channel_swap(tmp_module):
    study = _copy(tmp_module, "swap")
    rows = _rows(study)
    a_, b_ = _channel(rows, 5, 3), _channel(rows, 8, 3)
    for case in a_:
        for k in ("value", "sigma"):
            a_[case][k], b_[case][k] = b_[case][k], a_[case][k]
    _write(study, rows)
    a = _only(_diagnose(study), "channel_swap")
    assert a["where"] == [5, 8] and a["component"] == 3
    _within(a["parameters"][0], 1.0)


def test_case_swap(tmp_module):
    """Every reading of cases L3 and L8 exchanged, values and sigmas (two files saved under each
    other's names): one effect names both cases, its fraction 1 within 4 std, the data."""
    study = _copy(tmp_module, "case_swap")
    rows = _rows(study)
    by = {(r["case"], r["grid"], r["component"]): r for r in rows}
    for (case, g, c), r in by.items():
        if case == "L3":
            o = by[("L8", g, c)]
            for k in ("value", "sigma"):
                r[k], o[k] = o[k], r[k]
    _write(study, rows)
    doc = _diagnose(study)
    a = _only(doc, "case_swap")
    assert len(doc["added"]) == 1 and a["where"] == ["L3", "L8"] and a["of"] == "data"
    assert a["pattern"] == "exchanged" and "cases L3 and L8 are each other's" in a["pattern_detail"]
    _within(a["parameters"][0], 1.0)


def test_case_swap_model_is_the_exchange(cube_prepared):
    """At fraction 1 the augmented model predicts each of the two cases' rows as the declared
    model's response to the other case's load (the columns of ``U`` exchanged), at 1/2 their
    mean, to rounding; the score column the search batches (``sparse_columns``) is the
    Jacobian's column (the model is linear in the fraction: both are ``u_B - u_A``)."""
    from blackbox.diagnosis.effects import CaseSwap
    pr = cube_prepared
    swap = next(e for e in pr.candidates if isinstance(e, CaseSwap) and e.where == ("L3", "L8"))
    assert sum(isinstance(e, CaseSwap) for e in pr.candidates) == 45           # 10 fitted cases, pairs
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(swap, pr.ident.k)
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    model = dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, o)
    om = dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)})
    U = model.state(x).U_O
    a, b = (list(pr.study.loads.cases).index(c) for c in ("L3", "L8"))
    swapped = U.copy()
    swapped[:, [a, b]] = U[:, [b, a]]
    scale = np.max(np.abs(U))
    for t, want in ((1.0, om.pick(swapped)), (0.5, 0.5 * (om.pick(U) + om.pick(swapped)))):
        x[-1] = t
        assert np.max(np.abs(model.predict(x, om) - want)) < 1e-13 * scale
    x[-1] = 0.0
    base = dg.AugmentedModel(pr.base, dg.ModelSpec(tuple(pr.joints)), pr.boundary, pr.K_deck, o)
    (rows, vals), = CaseSwap.sparse_columns(base, base.state(x[:-1]), x[:-1], om, [swap])
    col = np.zeros(len(om.y))
    col[rows] = vals
    J = model.jacobian(x, om)[:, -1]
    assert np.max(np.abs(col - J)) < 1e-13 * scale and np.count_nonzero(J) == 2 * 30      # 30 channels a case


def test_misplaced_sensor(tmp_module):
    """Grid 5's sensor block read at its neighbour 6 (one bar away): the block variant, t ~ 1."""
    study = _copy(tmp_module, "misplaced")
    rows = _rows(study)
    for c in range(1, 7):
        at5, at6 = _channel(rows, 5, c), _channel(rows, 6, c)
        for case in at5:
            at5[case]["value"], at5[case]["sigma"] = at6[case]["value"], at6[case]["sigma"]
    _write(study, rows)
    a = _only(_diagnose(study), "misplaced_sensor")
    assert a["where"] == [5] and a["read_at"] == 6 and a["components"] == [1, 2, 3, 4, 5, 6]
    _within(a["parameters"][0], 1.0)


def test_outlier(tmp_module):
    """One reading 12 sigma off (grid 8, component 1, case L7): the effect sits on that reading,
    and its size is the offset planted."""
    study = _copy(tmp_module, "outlier")
    rows = _rows(study)
    r = _channel(rows, 8, 1)["L7"]
    b = 12.0 * float(r["sigma"])
    r["value"] = repr(float(r["value"]) + b)
    _write(study, rows)
    a = _only(_diagnose(study), "outlier")
    assert a["where"] == [8] and a["component"] == 1 and a["case"] == "L7"
    _within(a["parameters"][0], b)


# Defects no one-parameter kind describes: the channel (or case) is set aside as a whole and
# the report says what its readings look like. Grid 5, component 2 (the channel of
# test_sign_flip, read clearly in every case); the cube has 10 cases in loads.csv order
# L1..L10. A drift and a jump are in the channel's largest sigma ``m`` (a zero moves by a
# length, whatever the reading; the cube's sigma is 5 % of each reading), noise in each
# reading's own sigma ``s``.
_CHANNEL_DEFECTS = {
    "drift": lambda i, v, s, m, rng: v + 1.5 * m * i,                  # 0 .. 13.5 sigma over the test
    "step": lambda i, v, s, m, rng: v + 10.0 * m * (i >= 5),           # a jump at case L6
    "scatter": lambda i, v, s, m, rng: v + float(rng.normal(0.0, 6.0 * s)),
    "dead": lambda i, v, s, m, rng: float(rng.normal(0.0, s)),
}


@pytest.mark.parametrize("pattern", list(_CHANNEL_DEFECTS))
def test_bad_channel(tmp_module, pattern):
    """A drifting zero, a jump, noise 6x the declared sigma, a dead transducer on one channel:
    one ``bad_channel`` at that channel (not an offset and a string of outliers), reported as the
    data, with the pattern that the module's tests name (``channel_pattern``)."""
    study = _copy(tmp_module, f"bad_channel_{pattern}")
    rows = _rows(study)
    rng = np.random.default_rng(5)
    chan = _channel(rows, 5, 2)
    m = float(max(float(r["sigma"]) for r in chan.values()))
    for r in chan.values():
        i = int(r["case"][1:]) - 1
        r["value"] = repr(_CHANNEL_DEFECTS[pattern](i, float(r["value"]), float(r["sigma"]), m, rng))
    _write(study, rows)
    doc = _diagnose(study)
    a = _only(doc, "bad_channel")
    assert len(doc["added"]) == 1
    assert a["where"] == [5] and a["component"] == 2 and a["of"] == "data"
    assert a["pattern"] == pattern, a["pattern_detail"]
    if pattern == "step":
        assert "from case L6" in a["pattern_detail"]


def test_bad_case(tmp_module):
    """Case L9's file in millimetres (every reading and its sigma x 1000): beyond any load-cell
    factor (0.2..5), so the case is set aside, and the report finds the factor 1000 and names
    the likely cause."""
    study = _copy(tmp_module, "bad_case")
    rows = _rows(study)
    for r in rows:
        if r["case"] == "L9":
            r["value"] = repr(1000.0 * float(r["value"]))
    _write(study, rows)
    doc = _diagnose(study)
    a = _only(doc, "bad_case")
    assert len(doc["added"]) == 1 and a["where"] == ["L9"] and a["of"] == "data"
    assert a["pattern"] == "scale" and "millimetres read as metres" in a["pattern_detail"], a["pattern_detail"]
    from blackbox.reports.diagnose import diagnosis_report
    from blackbox.study import load_study
    report = diagnosis_report(load_study(study), doc, [])
    assert f"What the readings show: {a['pattern_detail']}." in report


def test_rigid_motion(tmp_module):
    """Case L4 read while the whole cube moved as a rigid body (a translation and a rotation
    about the measured grids' centre, planted by ``benchmarks/unlisted_defects.py``'s rig slip
    at a noncentrality of 485): found as ``rigid_motion`` at L4, of the data, with each
    planted translation and rotation within 4 standard errors of the fitted one. The
    structure's effects cannot mimic it: a motion in one case only."""
    import sys
    sys.path.insert(0, str(FIXTURES.parent / "benchmarks"))
    import unlisted_defects as ud

    study = _copy(tmp_module, "rigid_motion")
    fields, rows = ud._read(study / "measurements.csv")
    where = ud._rig_slip(study, rows, "L4", np.random.default_rng(5))
    ud._write(study / "measurements.csv", fields, rows)
    assert where["noncentrality"] == pytest.approx(485.0, abs=1.0)
    doc = _diagnose(study)
    a = _only(doc, "rigid_motion")
    assert len(doc["added"]) == 1 and a["where"] == ["L4"] and a["of"] == "data"
    np.testing.assert_allclose(a["about"], where["about"], rtol=1e-12)
    p = {q["name"]: q for q in a["parameters"]}
    for k in range(3):
        _within(p[f"t{k + 1}_L4"], where["translation"][k])
        # r_k is the rotation times the effect's length scale: its std scales alike
        r = p[f"r{k + 1}_L4"]
        length = r["value"] / a["rotation_rad"][k]
        _within({"value": a["rotation_rad"][k], "std": r["std"] / length}, where["rotation_rad"][k])


def test_patterns_of_set_aside_readings():
    """``channel_pattern`` and ``case_pattern`` on exact data (noise 1, 12 cases): each pattern
    is recognised, and the simplest one that leaves a chi2 within its 99 % band is named (a
    drift is not called a step)."""
    from blackbox.diagnosis.effects.bad_case import case_pattern
    from blackbox.diagnosis.effects.bad_channel import channel_pattern
    rng = np.random.default_rng(2)
    n = 12
    u = rng.uniform(5.0, 40.0, n) * rng.choice([-1.0, 1.0], n)
    s = np.ones(n)
    e = rng.normal(0.0, 1.0, n)
    cases = [f"L{i + 1}" for i in range(n)]
    t = np.arange(n)
    assert channel_pattern(e, u, s, cases)["pattern"] == "dead"
    assert channel_pattern(u + 7.0 + e, u, s, cases)["pattern"] == "offset"
    assert channel_pattern(u + 2.0 * t + e, u, s, cases)["pattern"] == "drift"
    assert channel_pattern(u + 20.0 * (t >= 5) + e, u, s, cases)["pattern"] == "step"
    assert "from case L6" in channel_pattern(u + 20.0 * (t >= 5) + e, u, s, cases)["pattern_detail"]
    assert channel_pattern(1000.0 * (u + e), u, s, cases)["pattern"] == "gain"
    assert channel_pattern(u + 8.0 * rng.normal(0.0, 1.0, n), u, s, cases)["pattern"] == "scatter"
    assert case_pattern(e, u, s)["pattern"] == "zero"
    assert case_pattern(-(u + e), u, s)["pattern_detail"].endswith("(the load applied in the opposite direction?)")
    assert case_pattern(u[::-1] + e, u, s)["pattern"] == "other"


def test_two_cases_set_aside_that_read_as_each_other_are_called_exchanged():
    """Two set-aside cases whose readings are each other's model response (the exchanged
    readings with the sigma of their new label: 1 where the reading's own noise is 3, the
    exchange then scatters beyond the noise and both cases are set aside) are named
    ``exchanged``, judged with the larger sigma of each channel; readings that are neither
    case's response stay ``other``."""
    from types import SimpleNamespace
    from blackbox.diagnosis.effects.bad_case import BadCase
    rng = np.random.default_rng(4)
    n = 40
    chans = tuple((g, 1) for g in range(1, n + 1))
    u_a, u_b = rng.uniform(20.0, 60.0, n), rng.uniform(-60.0, -20.0, n)
    s_a, s_b = np.full(n, 1.0), np.full(n, 3.0)
    y_a, y_b = u_b + rng.normal(0.0, 3.0, n), u_a + rng.normal(0.0, 1.0, n)      # exchanged

    def fit_of(ya, yb):
        a = BadCase(("L1",), tuple(f"c_L1_{g}_1" for g, _ in chans), case="L1", channels=chans,
                    readings=tuple(ya), sigmas=tuple(s_a))
        # the other case lists its channels in another order
        b = BadCase(("L2",), tuple(f"c_L2_{g}_1" for g, _ in chans[::-1]), case="L2", channels=chans[::-1],
                    readings=tuple(yb[::-1]), sigmas=tuple(s_b[::-1]))
        spec = dg.ModelSpec((), (a, b))
        # the offsets set each case's readings to the model's response (reading - offset = u)
        return a, b, SimpleNamespace(spec=spec, x=np.concatenate([ya - u_a, (yb - u_b)[::-1]]))

    a, b, fit = fit_of(y_a, y_b)
    assert a.findings(fit)["pattern"] == b.findings(fit)["pattern"] == "exchanged"
    assert "cases L1 and L2 exchanged" in a.findings(fit)["pattern_detail"]
    a, b, fit = fit_of(u_a[::-1] + rng.normal(0.0, 1.0, n), y_b)                # L1 reads neither
    assert a.findings(fit)["pattern"] == b.findings(fit)["pattern"] == "other"


@pytest.fixture(scope="module")
def cube_prepared(tmp_module):
    (tmp_module / "decks").mkdir()
    return diagnose_command.prepare(FIXTURES / "cube", tmp_module / "decks")


def test_joint_gap_model_is_the_case_by_case_truth(cube_prepared):
    """At r = 0.3 the augmented model (each case with its own joint stiffness, sides iterated)
    predicts what the reference solver gives case by case with the springs on their sides
    (``gap_response``), to 1e-10 of the largest response (both double precision; the augmented
    system's cond ~1e3); its Jacobian matches central differences (h = 1e-6 of the parameter:
    truncation ~1e-12, rounding ~1e-10 relative), the sides held where they are."""
    pr = cube_prepared
    j = pr.joints[0]
    gap = next(e for e in pr.candidates if isinstance(e, JointGap))
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(gap, pr.ident.k)
    x[-1] = 0.3
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    model = dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, o)
    om = dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)})
    f = model.predict(x, om)
    U = gap_response(ReferenceAdapter(pr.deck), j.name, j.grids, pr.ident.k, 0.3, pr.study.loads, o)
    f_true = om.pick(U)
    assert np.max(np.abs(f - f_true)) < 1e-10 * np.max(np.abs(f_true))
    st = model.state(x)
    assert st.groups is not None and len(st.groups) > 1           # the cases do take both sides
    J = model.jacobian(x, om)
    for i in (0, len(x) - 1):
        h = 1e-6 * abs(x[i])
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fd = (model.predict(xp, om) - model.predict(xm, om)) / (2 * h)
        assert np.max(np.abs(J[:, i] - fd)) < 1e-6 * np.max(np.abs(fd))


def test_joint_gap_found(tmp_module, cube_prepared):
    """The cube's joint with play r = 0.3 (its springs a third as stiff when they open), the
    measurements that truth plus the fixture's own noise draws (the declared sigma of each
    reading): found as joint_gap at J7 with r within 4 std, the structure (not the data)."""
    pr = cube_prepared
    j = pr.joints[0]
    study = _copy(tmp_module, "gap")
    k = np.full(j.n_params, TRUTH_K)
    _measure(study, pr.study.loads.cases,
             lambda o: gap_response(ReferenceAdapter(pr.deck), j.name, j.grids, k, 0.3, pr.study.loads, o), 11)
    a = _only(_diagnose(study), "joint_gap")
    assert a["where"] == ["J7"] and a["of"] == "structure"
    _within(a["parameters"][0], 0.3)


def test_clean_data_raise_no_data_defect(tmp_module):
    """The cube fixture as simulated (no defect): nothing added, whatever the hundreds of
    outlier (one per reading: 300) and channel-pair candidates (each kind's share of alpha,
    Bonferroni within it)."""
    study = _copy(tmp_module, "clean")
    doc = _diagnose(study)
    assert doc["verdict"] == "adequate" and not doc["added"]
    kinds = doc["settings"]["candidates_by_effect"]
    assert kinds["outlier"] == 300 and kinds["channel_swap"] > 20 and kinds["joint_gap"] == 1
    assert kinds["case_swap"] == 45             # every pair of the 10 fitted cases
    assert kinds["load_tilt"] == 38             # every force and moment of the 10 fitted cases
    assert kinds["misplaced_load"] == 71        # every grid they load, with each free neighbour


def test_holdout_veto_is_calibrated():
    """``holdout_worse``: an addition that is right (it moves the hold-out prediction by exactly
    the effect the hold-out data carry, |d| from 0.1 to 10 sigma) is vetoed with the chance a
    3-sigma rule gives (one-sided, 0.13 %: 1.3 expected in 1,000 draws, at most 7 allowed, a
    Poisson tail of 5e-5);
    one the hold-out does not carry (an effect the fit invented, |d| = 5 sigma) is vetoed nearly
    always (its chi2 rises by |d|^2 = 25 against a limit of -25 + 30 = 5: 99.4 %, >= 97 % here)."""
    from types import SimpleNamespace

    from blackbox.diagnosis.search import holdout_worse
    rng = np.random.default_rng(3)
    n = 40
    for size in (0.1, 1.0, 3.0, 10.0):
        s = rng.normal(size=n)
        s *= size / np.linalg.norm(s)
        vetoed = 0
        for _ in range(1000):
            y = s + rng.normal(size=n)
            hold = SimpleNamespace(sigma=np.ones(n), y=y, case=np.zeros(n, int))
            fit = SimpleNamespace(holdout_predicted=np.zeros(n), holdout_chi2=float(y @ y))
            f2 = SimpleNamespace(holdout_predicted=s, holdout_chi2=float((y - s) @ (y - s)), holdout_basis=None)
            vetoed += holdout_worse(fit, f2, hold) is not None
        assert vetoed <= 7, (size, vetoed)
    d = rng.normal(size=n)
    d *= 5.0 / np.linalg.norm(d)
    vetoed = 0
    for _ in range(1000):
        y = rng.normal(size=n)
        hold = SimpleNamespace(sigma=np.ones(n), y=y, case=np.zeros(n, int))
        fit = SimpleNamespace(holdout_predicted=np.zeros(n), holdout_chi2=float(y @ y))
        f2 = SimpleNamespace(holdout_predicted=d, holdout_chi2=float((y - d) @ (y - d)), holdout_basis=None)
        vetoed += holdout_worse(fit, f2, hold) is not None
    assert vetoed >= 970


def _nested_ls_draws(rng, right: bool, loose: float, size: float, draws: int, with_basis: bool,
                     in_metric: bool = False) -> int:
    """How many of ``draws`` additions ``holdout_worse`` vetoes, in a linear model where every
    term of the rule is exact: 80 fitted and 40 hold-out readings of unit noise, 3 declared
    parameters, and an addition of 4 parameters that the fitted readings see ``loose`` times as
    strongly as the declared ones and the hold-out readings as strongly, moving the hold-out
    prediction by ``size`` sigma. ``right``: the hold-out readings carry the addition too (else
    only the fitted ones do: a defect of the fitted data that the addition absorbs). Both fits
    are least squares; the fits keep their prediction bases (``with_basis``) or not; with
    ``in_metric`` both hold-out residuals are read in the addition's predictive metric first,
    as the search reads them (:func:`blackbox.diagnosis.search.prediction_metric`)."""
    from types import SimpleNamespace

    from blackbox.diagnosis.fit import prediction_basis
    from blackbox.diagnosis.search import case_metric, holdout_worse
    m, n, p1, px = 80, 40, 3, 4
    J1, Jx = rng.normal(size=(m, p1)), loose * rng.normal(size=(m, px))
    Jh1, Jhx = rng.normal(size=(n, p1)), rng.normal(size=(n, px))
    J2, Jh2 = np.hstack([J1, Jx]), np.hstack([Jh1, Jhx])
    bx = rng.normal(size=px)
    bx *= size / np.linalg.norm(Jhx @ bx)
    b1 = rng.normal(size=p1)
    A1 = prediction_basis(J1, Jh1, np.ones(p1, bool))
    A2 = prediction_basis(J2, Jh2, np.ones(p1 + px, bool))
    vetoed = 0
    for _ in range(draws):
        y = J1 @ b1 + Jx @ bx + rng.normal(size=m)
        yh = Jh1 @ b1 + (Jhx @ bx if right else 0.0) + rng.normal(size=n)
        u1 = Jh1 @ np.linalg.lstsq(J1, y, rcond=None)[0]
        u2 = Jh2 @ np.linalg.lstsq(J2, y, rcond=None)[0]
        hold = SimpleNamespace(sigma=np.ones(n), y=yh, case=np.zeros(n, int))
        metric = case_metric(A2, hold) if in_metric else None
        if metric is not None:
            u1, u2 = yh - metric(yh - u1), yh - metric(yh - u2)
        fit = SimpleNamespace(holdout_predicted=u1, holdout_chi2=float((yh - u1) @ (yh - u1)),
                              holdout_basis=A1 if with_basis else None)
        f2 = SimpleNamespace(holdout_predicted=u2, holdout_chi2=float((yh - u2) @ (yh - u2)),
                             holdout_basis=A2 if with_basis else None)
        vetoed += holdout_worse(fit, f2, hold, metric=metric) is not None
    return vetoed


def test_holdout_veto_counts_the_prediction_error():
    """``holdout_worse`` when the fit leaves loose the parameters of a right addition that the
    hold-out cases see (fitted readings 10x less sensitive to them): the refit's hold-out
    prediction error adds its variance to the chi2 change's mean (``2 tr(A2 A2^T - A1 A1^T)``)
    and spread, which the rule counts from the fits' hold-out Jacobians. Right additions are
    then vetoed at the 3-sigma rule's rate (0.13 %: at most 7 of 1,000, as above) at 0.5 and
    3 sigma; counting the noise alone, 3-5 % are (measured 41-50 of 1,000: more than 20 here)
    -- the blind benchmark's seed 3, tube s0242: a 16-sigma outlier vetoed although its refit
    moved the hold-out prediction by 0.074 sigma along parameters the fit left loose. Where the
    fit determines the addition (``loose`` 1), a wrong one that moves the hold-out prediction
    by 10 sigma is still always vetoed (its chi2 rises by about 100). The same holds with the
    residuals read in the addition's predictive metric, as the search reads them."""
    rng = np.random.default_rng(11)
    for size in (0.5, 3.0):
        assert _nested_ls_draws(rng, True, 0.1, size, 1000, True) <= 7
        assert _nested_ls_draws(rng, True, 0.1, size, 1000, True, in_metric=True) <= 7
    assert _nested_ls_draws(rng, True, 0.1, 3.0, 1000, False) > 20
    assert _nested_ls_draws(rng, False, 1.0, 10.0, 200, True) == 200
    assert _nested_ls_draws(rng, False, 1.0, 10.0, 200, True, in_metric=True) == 200


def test_separating_measurements(cube_prepared):
    """Two explanations of the same support (its springs, or the stiffness of member 1 that ends
    there), each refitted: the sensors and loads ``separating_measurements`` proposes are the
    DOFs where the two fitted models differ most, best first, in units of the measured channels'
    median sigma of that kind; checked against the two models evaluated directly at the top
    sensor (every case) and under the top load (a unit load's response scaled to the study's
    size; the study's sensors), to 1e-10 relative (the same arithmetic in another order)."""
    from blackbox.commands.diagnose import load_magnitudes
    from blackbox.diagnosis.effects import MemberStiffness, SupportFlexibility
    from blackbox.diagnosis.search import refit_candidate
    from blackbox.diagnosis.separation import separating_measurements, unit_load_view

    pr = cube_prepared
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    om = dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)})
    declared = dg.fit_model(dg.AugmentedModel(pr.base, dg.ModelSpec(tuple(pr.joints)), pr.boundary, pr.K_deck, o),
                            om, None, pr.ident.k)
    sup = next(e for e in pr.candidates if isinstance(e, SupportFlexibility) and e.where == (1,))
    mem = next(e for e in pr.candidates if isinstance(e, MemberStiffness) and 1 in (pr.deck.cbars[e.eid].ga,
                                                                                   pr.deck.cbars[e.eid].gb))
    pr.base.ensure_columns(mem.refit_columns(), "test")
    fa, _ = refit_candidate(pr.base, declared, sup, om, None, pr.boundary, pr.K_deck, o, np.zeros(sup.n_params))
    fb, _ = refit_candidate(pr.base, declared, mem, om, None, pr.boundary, pr.K_deck, o, np.zeros(mem.n_params))
    mags = load_magnitudes(pr.study.loads)
    sep = separating_measurements(pr.base, fa, fb, pr.boundary, pr.K_deck, om, mags)
    s = sep["sensors"]
    assert len(s) == 3 and s[0]["separation_sigma"] >= s[1]["separation_sigma"] >= s[2]["separation_sigma"] > 0
    sig_t = float(np.median(om.sigma[om.comp <= 3]))
    sig_r = float(np.median(om.sigma[om.comp >= 4]))
    d = (s[0]["grid"], s[0]["component"])
    Ua = dg.AugmentedModel(pr.base, fa.spec, pr.boundary, pr.K_deck, [d]).state(fa.x).U_O[0]
    Ub = dg.AugmentedModel(pr.base, fb.spec, pr.boundary, pr.K_deck, [d]).state(fb.x).U_O[0]
    want = np.sqrt(np.mean(((Ua - Ub) / (sig_t if d[1] <= 3 else sig_r)) ** 2))
    assert s[0]["separation_sigma"] == pytest.approx(want, rel=1e-10)
    ld = sep["loads"][0]
    dl = (ld["grid"], ld["component"])
    view = unit_load_view(pr.base, [dl])
    chan = list(dict.fromkeys(zip(om.grid.tolist(), om.comp.tolist())))
    Va = dg.AugmentedModel(view, fa.spec, pr.boundary, pr.K_deck, chan).state(fa.x).U_O[:, 0]
    Vb = dg.AugmentedModel(view, fb.spec, pr.boundary, pr.K_deck, chan).state(fb.x).U_O[:, 0]
    csig = np.array([sig_t if c <= 3 else sig_r for _, c in chan])
    size = mags[0] if dl[1] <= 3 else mags[1]
    assert ld["value"] == size
    assert ld["separation_sigma"] == pytest.approx(np.linalg.norm((Va - Vb) / csig) * size, rel=1e-10)


def test_a_share_of_another_reading_is_judged_alike_for_a_swap_and_a_misplaced_sensor():
    """``channel_swap`` and ``misplaced_sensor`` share one rule (``ReadsAnother``): the refit
    also starts at the whole defect (share 1), and a share below 1/2 or above 3/2 is refused
    with a message that says how the channels read; 1/2 to 3/2 is accepted."""
    from blackbox.diagnosis.effects import ChannelSwap, MisplacedSensor
    swap = ChannelSwap((3, 7), ("swap_3_7_1",), component=1)
    moved = MisplacedSensor((3,), ("t_3_9",), read_at=9, components=(1,), weights=((1.0, 0.0, 0.0),))
    x2, step = np.array([5.0, 0.0]), np.array([0.2])
    lo, hi = np.array([0.0, 0.0]), np.array([10.0, 2.0])
    for e in (swap, moved):
        starts = e.refit_starts(x2, step, lo, hi, 1)
        assert [s[1] for s in starts] == [0.0, 0.2, 1.0] and all(s[0] == 5.0 for s in starts)
        assert e.rejection(np.array([0.5])) is None and e.rejection(np.array([1.5])) is None
    assert swap.rejection(np.array([0.3])) == "the channels mix by 0.3: mostly their own grids, not a swap"
    assert swap.rejection(np.array([1.7])) == "the channels mix by 1.7: more than a swap can explain"
    assert moved.rejection(np.array([0.3])) == "the channels read 0.3 of grid 9: mostly their own grid, not misplaced"
    assert moved.rejection(np.array([1.7])) == "the channels read 1.7 of grid 9: more than a misplacement can explain"


def _turned_loads(loads, case: str, grid: int, first: int, t: np.ndarray):
    """``loads`` with the vector (force: ``first`` 1, moment: 4) at ``grid`` in ``case`` turned by
    the tilt angles ``t`` about :func:`perpendicular_axes` of it (the planted truth)."""
    import scipy.sparse as sp
    from blackbox.diagnosis.effects.load_tilt import perpendicular_axes, tilt
    from solver_adapters.protocol import LoadMatrix
    V = loads.values.toarray()
    dofs = list(loads.dofs)
    j = list(loads.cases).index(case)
    for k in range(3):
        if (grid, first + k) not in dofs:
            dofs.append((grid, first + k))
            V = np.vstack([V, np.zeros((1, V.shape[1]))])
    rows = [dofs.index((grid, first + k)) for k in range(3)]
    v = V[rows, j].copy()
    V[rows, j] += tilt(v, perpendicular_axes(v), t)
    return LoadMatrix(tuple(dofs), sp.csc_matrix(V), loads.cases)


def _load_model(pr, e):
    """``(x, o, om, model)``: the cube's augmented model with the load effect ``e`` added at its
    nominal parameters (the springs at the declared fit's estimate), the measured DOFs ``o`` and
    the fitted cases' rows ``om``; checked to be the declared model exactly there."""
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(e, pr.ident.k)
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    om = dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)})
    model = dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, o)
    declared = dg.AugmentedModel(pr.base, dg.ModelSpec(tuple(pr.joints)), pr.boundary, pr.K_deck, o)
    assert np.array_equal(model.predict(x, om), declared.predict(x[:-e.n_params], om))
    return x, o, om, model


def test_load_tilt_model_is_the_turned_load(cube_prepared):
    """With the force at grid 5 in case L3 turned by t = (0.2, -0.15) rad, the augmented model
    predicts what the reference solver gives for the declared structure (springs at the
    declared fit's estimate) under the turned loads, to 1e-12 of the largest response (both
    double precision, one linear solve each); at t = 0 it is the declared model exactly; its
    Jacobian matches central differences (h = 1e-6 rad: truncation ~1e-12, rounding ~1e-10
    relative, 1e-7 allowed); the rotation's own derivatives (``tilt_derivatives``) match
    differences of ``tilt`` to 1e-8, and a turn keeps the vector's length."""
    from blackbox.diagnosis.effects import LoadTilt
    from blackbox.diagnosis.effects.load_tilt import tilt, tilt_derivatives
    pr = cube_prepared
    tilts = [e for e in pr.candidates if isinstance(e, LoadTilt)]
    e = next(e for e in tilts if e.case == "L3" and e.grid == 5 and e.first == 1)
    x, o, om, model = _load_model(pr, e)
    t = np.array([0.2, -0.15])
    x[-2:] = t
    adapter = _truth_adapter(pr, pr.ident.k)
    want = om.pick(adapter.solve(_turned_loads(pr.study.loads, "L3", 5, 1, t), o).values)
    assert np.max(np.abs(model.predict(x, om) - want)) < 1e-12 * np.max(np.abs(want))
    J = model.jacobian(x, om)
    h = 1e-6
    for q in (-2, -1):
        xp, xm = x.copy(), x.copy()
        xp[q] += h
        xm[q] -= h
        fd = (model.predict(xp, om) - model.predict(xm, om)) / (2 * h)
        assert np.max(np.abs(fd - J[:, q])) < 1e-7 * np.max(np.abs(J[:, q]))
    v, axes = np.array(e.v), np.array(e.axes)
    for tt in (np.zeros(2), t, np.array([1e-6, 2e-6]), np.array([2.0, -1.0])):
        assert abs(np.linalg.norm(v + tilt(v, axes, tt)) - np.linalg.norm(v)) < 1e-12 * np.linalg.norm(v)
        D = tilt_derivatives(v, axes, tt)
        for k in range(2):
            dt = np.zeros(2)
            dt[k] = 1e-6
            fd = (tilt(v, axes, tt + dt) - tilt(v, axes, tt - dt)) / 2e-6
            assert np.max(np.abs(fd - D[k])) < 1e-8 * np.linalg.norm(v)


def test_load_tilt_found(tmp_module, cube_prepared):
    """Case L3's force at grid 5 went in turned 15 degrees (the cube's truth, springs 1e4, and
    fresh noise at each reading's declared sigma): found as load_tilt at grid 5 in L3, alone,
    a defect of the data, its angle within 4 std of 15 degrees."""
    pr = cube_prepared
    study = _copy(tmp_module, "tilt")
    adapter = _truth_adapter(pr, np.full(pr.joints[0].n_params, TRUTH_K))
    loads = _turned_loads(pr.study.loads, "L3", 5, 1, np.radians(15.0) * np.array([np.cos(0.7), np.sin(0.7)]))
    _measure(study, pr.study.loads.cases, lambda o: adapter.solve(loads, o).values, 12)
    a = _only(_diagnose(study), "load_tilt")
    assert a["where"] == [5] and a["case"] == "L3" and a["vector"] == "force" and a["of"] == "data"
    std = np.degrees(max(p["std"] for p in a["parameters"]))
    assert abs(a["angle_deg"] - 15.0) <= 4.0 * std, (a["angle_deg"], std)
    assert "turned" in a["pattern_detail"]


# case L3 of the cube: the force (y) and moment at grid 3 and the force at grid 5, each turned
# its own way (radians, about each vector's perpendicular_axes)
_L3_TURNS = {(3, 1): np.array([0.2, -0.1]), (3, 4): np.array([-0.3, 0.25]), (5, 1): np.array([0.15, 0.1])}


def test_case_tilt_model_is_the_turned_loads(cube_prepared):
    """With every load of case L3 turned its own way (_L3_TURNS), the augmented model predicts
    what the reference solver gives for the declared structure under those loads, to 1e-12 of
    the largest response (as for one turned load); at zero it is the declared model exactly; its
    Jacobian matches central differences (h = 1e-6 rad, as above)."""
    from blackbox.diagnosis.effects import CaseTilt
    pr = cube_prepared
    e = next(e for e in pr.candidates if isinstance(e, CaseTilt) and e.case == "L3")
    assert [(m.grid, m.first) for m in e.members] == list(_L3_TURNS) and len(e.names) == 6
    assert not any(isinstance(h, CaseTilt) for h in pr.holdout_candidates)
    x, o, om, model = _load_model(pr, e)
    x[-6:] = np.concatenate(list(_L3_TURNS.values()))
    loads = pr.study.loads
    for (g, first), t in _L3_TURNS.items():
        loads = _turned_loads(loads, "L3", g, first, t)
    want = om.pick(_truth_adapter(pr, pr.ident.k).solve(loads, o).values)
    assert np.max(np.abs(model.predict(x, om) - want)) < 1e-12 * np.max(np.abs(want))
    J = model.jacobian(x, om)
    for q in range(-6, 0):
        xp, xm = x.copy(), x.copy()
        xp[q] += 1e-6
        xm[q] -= 1e-6
        fd = (model.predict(xp, om) - model.predict(xm, om)) / 2e-6
        assert np.max(np.abs(fd - J[:, q])) < 1e-7 * np.max(np.abs(J[:, q]))


def test_tilt_beyond_135_degrees_reads_as_reversed(cube_prepared):
    """A load turned by more than 135 degrees acts more against its declared direction than
    across it: the report reads it as applied the other way (pattern ``reversed``), for one load
    (load_tilt) and for a case whose every load turned so (case_tilt); a case with one load
    turned 177 degrees and the others a few degrees stays ``turned``. The turned directions are
    checked against the angle: their dot product with the declared one is its cosine."""
    from types import SimpleNamespace
    from blackbox.diagnosis.effects import CaseTilt, LoadTilt
    pr = cube_prepared
    e = next(e for e in pr.candidates if isinstance(e, CaseTilt) and e.case == "L3")
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(e, pr.ident.k)
    back = np.array([np.pi - 0.05, 0.0])                      # 177.1 degrees
    x[-6:] = np.concatenate([back, -back, back])
    a = e.findings(SimpleNamespace(spec=spec, x=x))
    assert a["pattern"] == "reversed" and "loaded reversed" in a["pattern_detail"]
    for t in a["turns"]:
        assert abs(t["angle_deg"] - np.degrees(np.pi - 0.05)) < 1e-9
        assert abs(np.dot(t["declared_direction"], t["turned_direction"]) - np.cos(np.pi - 0.05)) < 1e-12
    x[-4:] = np.concatenate([[0.05, 0.0], [0.0, -0.1]])
    assert e.findings(SimpleNamespace(spec=spec, x=x))["pattern"] == "turned"
    one = next(c for c in pr.candidates if isinstance(c, LoadTilt) and c.case == "L3" and c.grid == 5)
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(one, pr.ident.k)
    for t, pattern in ((np.radians(136.0), "reversed"), (np.radians(134.0), "turned")):
        x[-2:] = [0.0, t]
        b = one.findings(SimpleNamespace(spec=spec, x=x))
        assert b["pattern"] == pattern and abs(b["angle_deg"] - np.degrees(t)) < 1e-9


def test_case_tilt_found(tmp_module, cube_prepared):
    """Every load of case L3 turned its own way (_L3_TURNS: 8 to 22 degrees; the cube's truth,
    springs 1e4, fresh noise at each reading's declared sigma): found as case_tilt of L3, alone, a
    defect of the data, each vector's turn within 4 std of the planted one."""
    pr = cube_prepared
    study = _copy(tmp_module, "case_tilt")
    adapter = _truth_adapter(pr, np.full(pr.joints[0].n_params, TRUTH_K))
    loads = pr.study.loads
    for (g, first), t in _L3_TURNS.items():
        loads = _turned_loads(loads, "L3", g, first, t)
    _measure(study, pr.study.loads.cases, lambda o: adapter.solve(loads, o).values, 14)
    a = _only(_diagnose(study), "case_tilt")
    assert a["case"] == "L3" and a["of"] == "data" and sorted(a["where"]) == [3, 5]
    for p, truth in zip(a["parameters"], np.concatenate(list(_L3_TURNS.values()))):
        _within(p, truth)
    assert "loads of case L3 went in turned" in a["pattern_detail"]


def _moved_loads(loads, case: str, e, t: float):
    """``loads`` with the share ``t`` of ``case``'s load at ``e.grid`` moved to ``e.moved_to``,
    as the candidate ``e`` carries it over (the planted truth)."""
    import scipy.sparse as sp
    from solver_adapters.protocol import LoadMatrix
    V = loads.values.toarray()
    dofs = list(loads.dofs)
    j = list(loads.cases).index(case)
    for g, sign, part in ((e.grid, -1.0, e.at_g), (e.moved_to, 1.0, e.at_h)):
        for c, v in part:
            if (g, c) not in dofs:
                dofs.append((g, c))
                V = np.vstack([V, np.zeros((1, V.shape[1]))])
            V[dofs.index((g, c)), j] += sign * t * v
    return LoadMatrix(tuple(dofs), sp.csc_matrix(V), loads.cases)


def test_misplaced_load_model_is_the_moved_load(cube_prepared):
    """Case L3's load at grid 5, 0.7 of it moved to grid 6: the augmented model predicts what
    the reference solver gives under the moved loads, to 1e-12 of the largest response (one
    linear solve each, double precision); at t = 0 the declared model exactly; its Jacobian
    matches central differences (linear in t: rounding only, 1e-7 allowed). The candidates are
    every grid a fitted case loads with each neighbour that is not held in all six components."""
    from blackbox.diagnosis.effects import MisplacedLoad
    pr = cube_prepared
    moves = [e for e in pr.candidates if isinstance(e, MisplacedLoad)]
    assert {(e.grid, e.moved_to) for e in moves if e.case == "L3"} == {(3, 2), (3, 4), (3, 7), (5, 6), (5, 8)}
    e = next(e for e in moves if e.case == "L3" and e.grid == 5 and e.moved_to == 6)
    x, o, om, model = _load_model(pr, e)
    x[-1] = 0.7
    adapter = _truth_adapter(pr, pr.ident.k)
    want = om.pick(adapter.solve(_moved_loads(pr.study.loads, "L3", e, 0.7), o).values)
    assert np.max(np.abs(model.predict(x, om) - want)) < 1e-12 * np.max(np.abs(want))
    J = model.jacobian(x, om)[:, -1]
    xp, xm = x.copy(), x.copy()
    xp[-1] += 1e-6
    xm[-1] -= 1e-6
    fd = (model.predict(xp, om) - model.predict(xm, om)) / 2e-6
    assert np.max(np.abs(fd - J)) < 1e-7 * np.max(np.abs(J))


def test_misplaced_load_found(tmp_module, cube_prepared):
    """Case L3's load at grid 5 went in at grid 6 (the cube's truth, springs 1e4, fresh noise at
    each reading's declared sigma): found as misplaced_load at grid 5 in L3 moved to 6, alone, a
    defect of the data, its share within 4 std of 1."""
    from blackbox.diagnosis.effects import MisplacedLoad
    pr = cube_prepared
    e = next(e for e in pr.candidates if isinstance(e, MisplacedLoad) and e.case == "L3" and e.grid == 5
             and e.moved_to == 6)
    study = _copy(tmp_module, "moved")
    adapter = _truth_adapter(pr, np.full(pr.joints[0].n_params, TRUTH_K))
    loads = _moved_loads(pr.study.loads, "L3", e, 1.0)
    _measure(study, pr.study.loads.cases, lambda o: adapter.solve(loads, o).values, 13)
    a = _only(_diagnose(study), "misplaced_load")
    assert a["where"] == [5] and a["case"] == "L3" and a["moved_to"] == 6 and a["of"] == "data"
    _within(a["parameters"][0], 1.0)
    assert "grid 6" in a["pattern_detail"]


def test_load_candidates_keep_within_their_column_budget(monkeypatch, tmp_path):
    """On a model too large for every loaded grid's unit-load columns (the budget lowered to 20
    columns on the car), each load family keeps the grids loaded in the most fitted cases whose
    columns fit, says how many it considered of how many, and every candidate kept has its
    columns in the split run."""
    from blackbox.diagnosis.effects import load_tilt
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    pr0 = diagnose_command.prepare(FIXTURES / "car", tmp_path / "a")
    n_dofs = 6 * len(pr0.deck.grids)
    monkeypatch.setattr(load_tilt, "LOAD_DOF_COLUMNS", 20.0 * n_dofs)
    pr = diagnose_command.prepare(FIXTURES / "car", tmp_path / "b")
    lim = {x.kind: x for x in pr.limits}
    for kind in ("load_tilt", "misplaced_load"):
        before = [e for e in pr0.candidates if e.kind == kind]
        kept = [e for e in pr.candidates if e.kind == kind]
        cols = {d for e in kept for d in e.load_dofs}
        assert 0 < len(kept) < len(before) and len(cols) <= 20
        assert (lim[kind].considered, lim[kind].available) == (len(kept), len(before))
        assert all(d in pr.base.col_of for d in cols)
        cases = {}
        for e in before:
            cases.setdefault(e.grid, set()).add(e.case)
        most = max(len(c) for c in cases.values())
        assert any(len(cases[e.grid]) == most for e in kept)


@pytest.mark.parametrize("defect", ["tilt", "moved"])
def test_a_load_defect_in_a_holdout_case_is_read_as_that(tmp_module, cube_prepared, defect):
    """The cube with hold-out cases L2 and L9, and hold-out case L9's force at grid 5 turned 15
    degrees (``tilt``) or its whole load at grid 5 put in at grid 6 (``moved``; the truth, springs
    1e4, fresh noise at each reading's declared sigma): the search, which never fits L9, adds
    nothing, and the hold-out check reads L9 as that load defect at its place (a defect of the
    data; before, "not predicted" and the verdict "unexplained"). No interval is reported for a
    hold-out reading: the bands, 3 degrees and 0.08, are 5 to 6 times the spread measured over
    ten noise draws (seeds 20-29: angle 15.1 +- 0.6 degrees, share 1.002 +- 0.013, 10 of 10
    read as the planted defect at grid 5 each time)."""
    from blackbox.diagnosis.effects import MisplacedLoad
    pr = cube_prepared
    study = _copy(tmp_module, f"hold_{defect}")
    toml = (study / "study.toml").read_text()
    (study / "study.toml").write_text(toml.replace("holdout_cases = []", 'holdout_cases = ["L2", "L9"]'))
    if defect == "tilt":
        loads = _turned_loads(pr.study.loads, "L9", 5, 1, np.radians(15.0) * np.array([np.cos(2.0), np.sin(2.0)]))
    else:
        e = MisplacedLoad((5,), ("t",), case="L9", moved_to=6, at_g=((3, -4.0), (4, -0.16)),
                          at_h=((3, -4.0), (4, -0.16)))        # grids 5 and 6 share the basic system
        loads = _moved_loads(pr.study.loads, "L9", e, 1.0)
    adapter = _truth_adapter(pr, np.full(pr.joints[0].n_params, TRUTH_K))
    _measure(study, pr.study.loads.cases, lambda o: adapter.solve(loads, o).values, 14)
    doc = _diagnose(study)
    assert not doc["added"] and doc["verdict"] == "explained", doc["verdict_detail"]
    (case,) = doc["holdout_check"]["cases"]
    assert case["case"] == "L9" and case["of"] == "data"
    want = "load_tilt" if defect == "tilt" else "misplaced_load"
    assert case["reads_as"] == want and case["load"]["effect"] == want, case["finding"]
    (load,) = case["load"]["loads"]
    assert load["grid"] == 5
    if defect == "tilt":
        assert load["vector"] == "force" and abs(load["angle_deg"] - 15.0) < 3.0
    else:
        assert load["moved_to"] == 6 and abs(load["parameters"]["t_L9_5_to_6"] - 1.0) < 0.08
