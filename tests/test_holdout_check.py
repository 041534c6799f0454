"""The hold-out cases read against the final model (blackbox.diagnosis.holdout).

The statistics are checked on a linear model, where the distribution of a hold-out residual is
known exactly: ``y = X b + e``, ``e ~ N(0, 1)``, ``b`` fitted by least squares on the fit rows;
a hold-out residual ``y_h - X_h b_hat`` then has covariance ``I + X_h (X^T X)^-1 X_h^T``, which
``prediction_basis`` must reproduce. Then on a study of the blind benchmark's generator whose
one clipped reading sits in a hold-out case, the defect the search cannot see.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from blackbox.diagnosis.holdout import TESTS, prediction_basis, read_holdout
from blackbox.diagnosis.model import ObsMap

ALPHA = 0.01
N_FIT, N_CASES, PER_CASE, P = 24, 3, 12, 6


def _design(rng):
    X = rng.normal(size=(N_FIT, P))
    # hold-out rows beyond the fit rows' range (leverage ~ 1): there the prediction's own
    # error is as large as the noise, and a check that left it out would see misfits everywhere
    Xh = 2.5 * rng.normal(size=(N_CASES * PER_CASE, P))
    return X, Xh


def _hold(y: np.ndarray) -> ObsMap:
    n = len(y)
    case = np.repeat(np.arange(N_CASES), PER_CASE)
    return ObsMap(np.arange(n), np.full(n, -1), case, 100 + np.arange(n) % PER_CASE, y, np.ones(n),
                  np.ones(n, int), tuple(f"H{i + 1}" for i in range(N_CASES)))


def _draw(rng, X, Xh, b):
    y = X @ b + rng.normal(size=len(X))
    bh = np.linalg.lstsq(X, y, rcond=None)[0]
    yh = Xh @ b + rng.normal(size=len(Xh))
    return yh, Xh @ bh


def test_prediction_basis_is_the_least_squares_prediction_covariance():
    rng = np.random.default_rng(1)
    X, Xh = _design(rng)
    exact = Xh @ np.linalg.inv(X.T @ X) @ Xh.T
    A = prediction_basis(X, Xh, np.ones(P, bool))
    assert np.allclose(A @ A.T, exact, rtol=1e-9, atol=1e-12)
    # parameters in other units (columns of X and X_h scaled alike) predict the same
    d = rng.uniform(0.1, 10.0, P)
    A = prediction_basis(X * d, Xh * d, np.ones(P, bool))
    assert np.allclose(A @ A.T, exact, rtol=1e-9, atol=1e-12)
    # a parameter held at a bound carries no error
    free = np.ones(P, bool)
    free[2] = False
    A2 = prediction_basis(X, Xh, free)
    Xf, Xhf = X[:, free], Xh[:, free]
    assert np.allclose(A2 @ A2.T, Xhf @ np.linalg.inv(Xf.T @ Xf) @ Xhf.T, rtol=1e-9, atol=1e-12)


def test_clean_hold_out_rarely_flagged_and_z_is_standard():
    """Over 2,000 draws the three tests together fire in at most alpha of them (binomial: 20
    expected at alpha = 0.01; 35 is beyond its 3-sigma end), and the standardized residuals have
    unit variance (within 3 % = 3 sigma of the sample variance of 72,000 of them)."""
    rng = np.random.default_rng(7)
    X, Xh = _design(rng)
    b = rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    fired, r2 = 0, []
    for _ in range(2000):
        yh, f = _draw(rng, X, Xh, b)
        hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA)
        fired += bool(hc.readings or hc.cases or not hc.predicted)
        r2.append((yh - f) ** 2)
    r2 = np.array(r2)
    assert fired <= 35
    assert abs(np.mean(r2 / (1.0 + np.sum(A ** 2, axis=1))) - 1.0) < 0.03
    # the residuals themselves are well above the noise here: without the prediction's error
    # the check would flag clean data
    assert np.mean(r2) > 1.3


def test_one_gross_reading_is_an_outlier_of_the_data():
    rng = np.random.default_rng(3)
    X, Xh = _design(rng)
    b = rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    sd = np.sqrt(1.0 + np.sum(A ** 2, axis=1))
    yh[15] += 12.0 * sd[15]                     # case H2, a clipped transducer's reading
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA)
    assert [(r.case, r.grid) for r in hc.readings] == [("H2", 100 + 15 % PER_CASE)]
    assert not hc.cases and hc.predicted and hc.findings == 1


def test_reversed_case_reads_as_loaded_the_other_way():
    rng = np.random.default_rng(4)
    X, Xh = _design(rng)
    b = 20.0 * rng.normal(size=P)               # readings many sigma: a reversal is plain
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    yh[2 * PER_CASE:] *= -1.0                   # case H3
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA)
    assert [c.case for c in hc.cases] == ["H3"] and not hc.readings
    (c,) = hc.cases
    assert c.explained and abs(c.scale + 1.0) < 3.0 * c.scale_std
    assert "loaded the other way" in c.sentence()
    assert hc.predicted


def test_a_case_no_factor_fits_is_not_predicted():
    rng = np.random.default_rng(5)
    X, Xh = _design(rng)
    b = 20.0 * rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    yh[:PER_CASE] = yh[:PER_CASE][::-1]         # case H1's readings shuffled: no scale fits
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA)
    assert [c.case for c in hc.cases] == ["H1"]
    assert not hc.cases[0].explained and not hc.predicted
    assert "not predicted" in hc.sentences()[0]


def test_a_case_predicted_with_loose_parameters_is_a_note_not_a_finding():
    """The same shuffled case, offered a refit with the fitted cases (``loose``): when the fitted
    chi2 rises within its limit and the case is then within its level, it is a note and the cases
    are predicted; when the rise is beyond its limit (or the case still beyond its level) it stays
    "not predicted". The refit itself is what check_holdout runs (next test, on a real study)."""
    rng = np.random.default_rng(5)
    X, Xh = _design(rng)
    b = 20.0 * rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    yh[:PER_CASE] = yh[:PER_CASE][::-1]
    asked = []
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA,
                      loose=lambda rows: asked.append(len(rows)) or (5.0, 12.0, 10.0))
    assert asked == [PER_CASE] and hc.cases == () and hc.predicted and not hc.findings
    assert [c for c, *_ in hc.loose] == ["H1"] and "leave loose" in hc.notes()[0]
    for rise, chi2 in ((13.0, 10.0), (5.0, 1e4)):
        hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA, loose=lambda rows: (rise, 12.0, chi2))
        assert [c.case for c in hc.cases] == ["H1"] and not hc.predicted and hc.loose == ()


def test_hold_out_case_on_parameters_the_fitted_cases_leave_loose(tmp_path):
    """Blind benchmark study s0579 (storey, a sign flip at grid 102): hold-out case L3 (a moment
    at grid 60) is 308 chi2 over 63 readings off the final model's linear prediction, with the
    joint's springs kz12, kz23, kz34 far from the truth and undetermined (no standard error). Fitted
    with the fitted cases it raises their chi2 by 8 (limit chi2(19) at 0.01: 36) and is within its
    level: a note. Before: "not predicted" and the verdict "unexplained" on the true model."""
    from benchmarks.blind.generate import generate_study
    from blackbox.commands.diagnose import run

    st = generate_study(579, 1, tmp_path / "s579")
    doc = json.loads(json.dumps(run(st.folder, plots=False).document, default=float))
    assert [(a["effect"], a["where"]) for a in doc["added"]] == [("sign_flip", [102])]
    hc = doc["holdout_check"]
    assert hc["predicted"] and not hc["findings"] and [x["case"] for x in hc["loose"]] == ["L3"]
    assert doc["verdict"] == "explained"
    shutil.rmtree(tmp_path / "s579", ignore_errors=True)


def test_misfit_spread_over_every_case_is_not_predicted():
    """Every reading off by 1.5 sigma of noise more than declared: no case alone is beyond its
    Bonferroni level by much, the rest is."""
    rng = np.random.default_rng(6)
    X, Xh = _design(rng)
    b = rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    yh = yh + 1.5 * np.sqrt(1.0 + np.sum(A ** 2, axis=1)) * rng.normal(size=len(yh))
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA)
    assert not hc.predicted
    assert TESTS == 3


@pytest.mark.slow
def test_clipped_reading_in_a_hold_out_case_is_found(tmp_path):
    """The unlisted data-defect benchmark's seed 13, hall s0000 (``benchmarks/unlisted_defects.py
    --n 3 --seed 13 --defects saturated``): channel 48/1 clipped at 60 % of its largest reading,
    which is in hold-out case L1 (z 12.4 there). Before the hold-out check the diagnosis said
    "adequate"; the fitted cases are within their band."""
    ud = pytest.importorskip("benchmarks.unlisted_defects")
    from benchmarks.blind.generate import NONE, generate_study
    from blackbox.commands.diagnose import run

    st = generate_study(0, 13, tmp_path / "saturated", kind=NONE, shape="hall", style="plain")
    rng = np.random.default_rng([13, 0, ud.DEFECTS.index("saturated")])
    where = ud.plant(st.folder, "saturated", rng)
    assert where == {"grid": 48, "component": 1}
    doc = json.loads(json.dumps(run(st.folder, plots=False).document, default=float))
    hc = doc["holdout_check"]
    assert doc["added"] == []
    assert [(o["grid"], o["component"], o["case"]) for o in hc["outliers"]] == [(48, 1, "L1")]
    assert hc["cases"] == [] and hc["predicted"]
    assert doc["verdict"] == "explained" and "defects of the data, not of the structure" in doc["verdict_detail"]
    shutil.rmtree(tmp_path / "saturated", ignore_errors=True)


def test_case_in_another_unit_reads_as_its_readings_scaled():
    """A hold-out case written in millimetres (x 1000, noise and all): no load of any size gives
    readings whose noise is 1000 sigma, readings scaled by 1000 do."""
    rng = np.random.default_rng(8)
    X, Xh = _design(rng)
    b = 20.0 * rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    yh[PER_CASE:2 * PER_CASE] *= 1000.0
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA)
    (c,) = hc.cases
    assert c.case == "H2" and c.reads_as == "readings_scale" and abs(c.scale / 1000.0 - 1.0) < 3.0 * c.scale_std / 1000.0
    assert "another unit" in c.sentence() and hc.predicted


def test_a_case_that_is_another_cases_readings_reads_as_that_case():
    """Hold-out case H3's readings are H1's (a file saved twice): with the other cases'
    predictions at its channels offered, it reads as H1's, with no parameter."""
    rng = np.random.default_rng(9)
    X, Xh = _design(rng)
    b = 20.0 * rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    hold = _hold(yh)
    # the model's prediction of case k at the channels of the rows asked for: here each case's
    # channels are the same twelve, in the same order
    by_case = [(lab, f[k * PER_CASE:(k + 1) * PER_CASE], np.ones(PER_CASE), False) for k, lab in enumerate(hold.labels)]
    yh[2 * PER_CASE:] = yh[:PER_CASE] + 0.0
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA, other_cases=lambda rows: by_case)
    (c,) = hc.cases
    assert c.case == "H3" and c.reads_as == "other_case" and c.other == "H1" and hc.predicted
    assert "H1's readings" in c.sentence()


def test_readings_swapped_between_a_fitted_and_a_hold_out_case(tmp_path):
    """Seed 43's portal (unlisted_defects --in-holdout): the readings of fitted case L12 and
    hold-out case L4 exchanged. The search sets L12 aside, which the corrupted hold-out case
    used to veto (its chi2, 1e7 under either fit, moved by 3.5e4: the hold-out cases are now
    weighed by their misfit, search.holdout_case_weights), and the hold-out check reads L4 as
    the model's response to L12's load, its own readings set aside. Before: a member factor
    added and "unexplained" at reduced chi2 123."""
    import benchmarks.unlisted_defects as ud
    from benchmarks.blind.generate import NONE, generate_study
    from blackbox.commands.diagnose import run

    st = generate_study(0, 43, tmp_path / "swapped", kind=NONE, shape="portal", style="plain")
    rng = np.random.default_rng([43, 0, ud.DEFECTS.index("swapped_cases")])
    assert ud.plant(st.folder, "swapped_cases", rng, in_holdout=True) == {"cases": ["L12", "L4"]}
    doc = json.loads(json.dumps(run(st.folder, plots=False).document, default=float))
    assert [(a["effect"], a["where"]) for a in doc["added"]] == [("bad_case", ["L12"])]
    (c,) = doc["holdout_check"]["cases"]
    assert (c["case"], c["reads_as"], c["other"], c["other_response"]) == ("L4", "other_case", "L12", True)
    assert doc["verdict"] == "explained"
    shutil.rmtree(tmp_path / "swapped", ignore_errors=True)


def test_a_case_the_specimen_slid_in_reads_as_a_rigid_motion():
    """Case H2 carries one rigid translation (3 sigma at every translation reading along x,
    the rows' direction); offered the rigid-body readings, the check names it."""
    rng = np.random.default_rng(10)
    X, Xh = _design(rng)
    b = rng.normal(size=P)
    A = prediction_basis(X, Xh, np.ones(P, bool))
    yh, f = _draw(rng, X, Xh, b)
    W = np.zeros((len(yh), 6))
    W[:, 0] = 1.0                               # every reading along basic x: sees t1 only
    yh[PER_CASE:2 * PER_CASE] += 3.0 * np.sqrt(1.0 + np.sum(A[PER_CASE:2 * PER_CASE] ** 2, axis=1)) + 2.0
    hc = read_holdout(_hold(yh), f, A, np.ones(len(yh), bool), ALPHA, rigid=lambda rows: W[rows])
    (c,) = hc.cases
    assert c.case == "H2" and c.reads_as == "rigid_motion" and c.motion[0] > 4.0 and hc.predicted
