"""Sigma when nobody declares it (blackbox.noise, blackbox.identification.fit_sigma).

Statistics are tested as statistics: on data simulated with a known sigma, the parameter
intervals must cover the true stiffness as often as their level says, and the sigma estimate's
own interval must cover the true sigma, within the binomial band of the replicate count. The
structure is the planar column on a base joint (tests/test_base_joint.py): the top deflection
``u = F (L^3 / 3EI + L^2 / k)`` is linear in ``1 / k``, so profile-likelihood intervals with
Student's t and the chi-square interval of sigma are exact there -- a miss is the code's, not
the approximation's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from blackbox.cli import main
from blackbox.commands import diagnose, identify
from blackbox.identification import Observations
from blackbox.identification import identify as fit
from blackbox.identification.fit_sigma import identify_with_fit_sigma, predict_rows
from blackbox.noise import RECTANGULAR, Readings, reduce_readings, sigma_interval
from blackbox.study import load_study

from test_base_joint import TOP, TRUE, column, write_column_study

FORCES = [2.0e4, -4.0e4, 6.0e4, -8.0e4, 1.0e5, -1.2e5]      # N, one case each, at the column top
SIGMA = 2.0e-4                                             # m, the true noise of one reading
K_TRUE = TRUE["ky12"]
REPLICATES = 300
LEVEL = 0.95
BAND = 2.576 * math.sqrt(LEVEL * (1 - LEVEL) / REPLICATES)
"""Two-sided 99 % binomial band of an observed coverage over REPLICATES replicates (+-0.032)."""


def write_rows(folder, rows: list[tuple[str, float, str]], extra_toml: str = "") -> None:
    """loads.csv with FORCES, measurements.csv from ``rows`` (case, value, sigma text)."""
    (folder / "loads.csv").write_text("case,grid,component,value\n" + "".join(
        f"L{i + 1},{TOP},1,{f!r}\n" for i, f in enumerate(FORCES)))
    (folder / "measurements.csv").write_text("case,grid,component,value,sigma\n" + "".join(
        f"{c},{TOP},1,{v!r},{s}\n" for c, v, s in rows))
    if extra_toml:
        (folder / "study.toml").write_text((folder / "study.toml").read_text() + extra_toml)


@pytest.fixture(scope="module")
def column_model(tmp_path_factory):
    """The planar column, condensed once (the replicates reuse it: no solver run per replicate),
    and the exact deflections of the FORCES cases for the true spring."""
    folder = write_column_study(tmp_path_factory.mktemp("noise") / "col", column(planar=True), planar=True)
    truth = [(f"L{i + 1}", f * (1.6 ** 3 / (3 * 30e9 * 0.4 ** 4 / 12) + 1.6 ** 2 / K_TRUE), "1e-4")
             for i, f in enumerate(FORCES)]
    write_rows(folder, truth)
    res = identify.run(folder, adapter="reference", profile=False)
    obs = res.fit_obs
    exact = predict_rows(res.model, obs, np.array([K_TRUE]))
    return res.model, obs, exact, folder


def test_blank_sigma_repeats_are_averaged_and_pooled(tmp_path):
    """Three readings of each step: the row is their mean; sigma = s / sqrt(3) with s pooled
    over the channel's steps, nu = sum (n - 1); the interval is chi-square's."""
    vals = np.array([[1.0, 1.2, 1.1], [2.0, 2.3, 2.2], [3.0, 2.9, 3.4]]) * 1e-3
    keys = tuple((f"L{i + 1}", TOP, 1, 0) for i in range(3) for _ in range(3))
    r = Readings(keys, vals.ravel(), np.full(9, np.nan), tuple(range(2, 11)))
    order, values, sigma, noise = reduce_readings(r, confidence=0.9)
    np.testing.assert_allclose(values, vals.mean(axis=1), rtol=1e-15)
    s = math.sqrt(np.sum((vals - vals.mean(axis=1, keepdims=True)) ** 2) / 6)
    np.testing.assert_allclose(sigma, s / math.sqrt(3), rtol=1e-14)
    assert list(order) == [0, 3, 6] and noise.source == ("repeats",) * 3
    (ch,) = noise.channels
    assert ch.dof == 6 and ch.readings == 9 and ch.repeated_steps == 3
    lo, hi = (s * math.sqrt(6 / stats.chi2.ppf(q, 6)) for q in (0.95, 0.05))
    assert (ch.ci_low, ch.ci_high) == pytest.approx((lo, hi), rel=1e-12)
    assert noise.effective_dof() == 6


def test_accuracy_and_repeats_combine_as_gum_says(tmp_path):
    """A declared +-a is a rectangular distribution, u_B = a / sqrt 3; with repeats the two add in
    quadrature and the degrees of freedom are Welch-Satterthwaite's (GUM G.4.1)."""
    keys = (("L1", TOP, 1, 0),) * 2 + (("L2", TOP, 1, 0),) + (("L3", TOP, 5, 0),)
    r = Readings(keys, np.array([1.0e-3, 1.2e-3, 2.0e-3, 1e-4]), np.full(4, np.nan), (2, 3, 4, 5))
    _, _, sigma, noise = reduce_readings(r, translation_accuracy=3e-4, rotation_accuracy=None)
    ua2 = (0.2e-3) ** 2 / 2 / 2                   # s^2 = 2e-8 (one repeated step, nu = 1), mean of 2
    ub = 3e-4 / RECTANGULAR
    assert sigma[0] == pytest.approx(math.sqrt(ua2 + ub * ub), rel=1e-12)
    assert noise.dof[0] == pytest.approx((ua2 + ub * ub) ** 2 / (ua2 ** 2 / 1), rel=1e-12)
    assert sigma[1] == pytest.approx(math.sqrt(2 * ua2 + ub * ub), rel=1e-12)    # one reading: s, not s/sqrt2
    assert noise.source == ("repeats+accuracy", "repeats+accuracy", "fit")        # rotation: nothing declared
    assert math.isnan(sigma[2])


def test_measurements_csv_without_sigma(tmp_path, column_model):
    """A blank cell, or no sigma column at all, is read as "estimate it"; repeated rows of one
    step are readings (averaged); a repeated row with a sigma is still a located error."""
    _, _, _, folder = column_model
    import shutil
    f = tmp_path / "s"
    shutil.copytree(folder, f, ignore=shutil.ignore_patterns(".blackbox_cache"))
    (f / "measurements.csv").write_text(f"case,grid,component,value\nL1,{TOP},1,1e-3\nL1,{TOP},1,1.2e-3\n"
                                        f"L2,{TOP},1,-2e-3\n")
    m = load_study(f).measurements
    assert m.cases == ("L1", "L2") and m.values[0] == pytest.approx(1.1e-3)
    assert m.noise.source == ("repeats", "repeats") and m.sigma[1] == pytest.approx(math.sqrt(2e-8))
    (f / "measurements.csv").write_text(f"case,grid,component,value,sigma\nL1,{TOP},1,1e-3,\nL1,{TOP},1,1.2e-3,1e-4\n")
    from blackbox.errors import StudyError
    with pytest.raises(StudyError, match=r"measurements.csv:3 column 'sigma'.*repeated readings"):
        load_study(f)


def test_intervals_cover_with_sigma_from_repeats(column_model):
    """Three readings per step, sigma unknown: pooled over the 6 steps (nu = 12), the mean's
    sigma s / sqrt 3, Student t with 12 dof. Coverage of k and of sigma within the band."""
    model, obs, exact, _ = column_model
    rng = np.random.default_rng(20261)
    hit_k = hit_s = 0
    keys = tuple((c, TOP, 1, 0) for c in ("L1", "L2", "L3", "L4", "L5", "L6") for _ in range(3))
    for _ in range(REPLICATES):
        readings = np.repeat(exact, 3) + SIGMA * rng.standard_normal(18)
        _, values, sigma, noise = reduce_readings(Readings(keys, readings, np.full(18, np.nan), tuple(range(18))))
        o = Observations(obs.dofs, obs.case_index, values, sigma, obs.case_labels)
        r = fit(model, o, [1e8], sigma_dof=noise.effective_dof())
        hit_k += r.ci_low[0] <= K_TRUE <= r.ci_high[0]
        ch = noise.channels[0]
        hit_s += ch.ci_low <= SIGMA <= ch.ci_high
    assert abs(hit_k / REPLICATES - LEVEL) <= BAND, hit_k
    assert abs(hit_s / REPLICATES - LEVEL) <= BAND, hit_s


def test_intervals_cover_with_sigma_from_the_fit(column_model):
    """One reading per step, nothing declared: sigma from the fit's residuals (nu = n - p = 5),
    Student t. Coverage of k and of sigma within the band; the normal quantile would cover ~88 %
    (t(5) = 2.57 against 1.96), so the test tells the two apart."""
    model, obs, exact, _ = column_model
    rng = np.random.default_rng(20262)
    hit_k = hit_s = hit_normal = 0
    for _ in range(REPLICATES):
        o = obs.with_values(exact + SIGMA * rng.standard_normal(len(exact)))
        r, fs, _, _ = identify_with_fit_sigma(model, o, [1e8], np.ones(len(o), dtype=bool))
        # nu = n - (sum of the leverages, p = 1 to rounding)
        assert fs.dof == pytest.approx((5.0,), rel=1e-12) and r.reduced_chi2 == pytest.approx(1.0, rel=1e-6)
        hit_k += r.ci_low[0] <= K_TRUE <= r.ci_high[0]
        hit_s += fs.ci_low[0] <= SIGMA <= fs.ci_high[0]
        z, t = stats.norm.ppf(0.975), stats.t.ppf(0.975, 5)
        lo, hi = r.linear_ci[0]          # log-space linearised, rescaled from t to z
        hit_normal += math.exp(math.log(r.k[0]) - (math.log(r.k[0]) - math.log(lo)) * z / t) <= K_TRUE \
            <= math.exp(math.log(r.k[0]) + (math.log(hi) - math.log(r.k[0])) * z / t)
    assert abs(hit_k / REPLICATES - LEVEL) <= BAND, hit_k
    assert abs(hit_s / REPLICATES - LEVEL) <= BAND, hit_s
    assert hit_normal / REPLICATES < LEVEL - BAND, hit_normal      # the t quantile matters here


def test_identify_says_sigma_came_from_the_fit(column_model, tmp_path):
    """End to end: blank sigma, nothing declared. result.json and the report say the chi-square
    test is off; diagnose refuses (its noise must not come from the model), exit 2."""
    _, _, exact, folder = column_model
    import json
    import shutil
    f = tmp_path / "blank"
    shutil.copytree(folder, f, ignore=shutil.ignore_patterns(".blackbox_cache"))
    rng = np.random.default_rng(3)
    write_rows(f, [(f"L{i + 1}", float(v + SIGMA * rng.standard_normal()), "") for i, v in enumerate(exact)])
    assert main(["identify", str(f), "--out", str(tmp_path / "out")]) == 0
    doc = json.loads((tmp_path / "out" / "result.json").read_text())
    assert doc["sigma"]["chi2_test"] is False and doc["sigma"]["fit"][0]["dof"] == 5.0
    assert "Student t, sigma estimated with 5 dof" in doc["ci_method"]
    assert "chi-square test of the model is off" in (tmp_path / "out" / "report.md").read_text()
    assert main(["diagnose", str(f), "--out", str(tmp_path / "d")]) == 2
    with pytest.raises(Exception, match="must not come from the model's own fit"):
        diagnose.run(f, adapter="reference")


def test_declared_accuracy_gives_sigma_and_keeps_the_chi2_test(column_model, tmp_path):
    _, _, exact, folder = column_model
    import shutil
    f = tmp_path / "acc"
    shutil.copytree(folder, f, ignore=shutil.ignore_patterns(".blackbox_cache"))
    a = SIGMA * RECTANGULAR
    rng = np.random.default_rng(4)
    write_rows(f, [(f"L{i + 1}", float(v + rng.uniform(-a, a)), "") for i, v in enumerate(exact)],
               f"\n[measurements]\ntranslation_accuracy = {a!r}\n")
    res = identify.run(f, adapter="reference")
    assert res.fit_sigma is None and res.noise.counts() == {"accuracy": 6}
    np.testing.assert_allclose(res.fit_obs.sigma, SIGMA, rtol=1e-12)
    assert "normal quantile" in res.result.ci_method
    assert res.result.ci_low[0] <= K_TRUE <= res.result.ci_high[0]


def test_sigma_interval_of_a_declared_value_is_the_value():
    assert sigma_interval(2.0, math.inf, 0.95) == (2.0, 2.0)
    lo, hi = sigma_interval(1.0, 10, 0.95)
    assert lo < 1.0 < hi


def test_two_kinds_and_given_rows_alternate_to_the_truth(tmp_path):
    """Translations and rotations both blank, with different true sigmas, beside rows whose sigma
    is given: one sigma per kind, fit and estimates alternated (leverage-corrected). Over 60
    replicates each kind's 95 % interval covers its true sigma within the binomial band of 60
    (99 %: +-0.073), and the stiffness's too."""
    folder = write_column_study(tmp_path / "col", column(planar=True), planar=True)
    forces = FORCES + [1.5e5, -1.8e5]
    (folder / "loads.csv").write_text("case,grid,component,value\n" + "".join(
        f"L{i + 1},{TOP},1,{f!r}\n" for i, f in enumerate(forces)))
    rows = ["case,grid,component,value,sigma"]
    for i in range(len(forces)):
        rows += [f"L{i + 1},{TOP},1,1e-3,", f"L{i + 1},{TOP},5,1e-3,", f"L{i + 1},{TOP - 1},1,1e-3,1e-4"]
    (folder / "measurements.csv").write_text("\n".join(rows) + "\n")
    res = identify.run(folder, adapter="reference", profile=False)
    model, obs = res.model, res.fit_obs
    exact = predict_rows(model, obs, np.array([K_TRUE]))
    kinds = np.array([c for _, c in obs.dofs])
    fit_rows = np.array([g == TOP for g, _ in obs.dofs])
    true = np.where(kinds == 5, 3e-4, np.where(fit_rows, 2e-4, 1e-4))     # rotation 3e-4 rad, top u 2e-4 m
    rng = np.random.default_rng(20263)
    n, hit_t, hit_r, hit_k = 60, 0, 0, 0
    given = obs.sigma.copy()
    for _ in range(n):
        o = Observations(obs.dofs, obs.case_index, exact + true * rng.standard_normal(len(exact)),
                         np.where(fit_rows, 1.0, given), obs.case_labels)
        r, fs, final, _ = identify_with_fit_sigma(model, o, [1e8], fit_rows)
        assert fs.kinds == ("translation", "rotation") and fs.passes >= 2
        lo_t, hi_t = fs.ci_low[0], fs.ci_high[0]
        lo_r, hi_r = fs.ci_low[1], fs.ci_high[1]
        hit_t += lo_t <= 2e-4 <= hi_t
        hit_r += lo_r <= 3e-4 <= hi_r
        hit_k += r.ci_low[0] <= K_TRUE <= r.ci_high[0]
    band = 2.576 * math.sqrt(LEVEL * (1 - LEVEL) / n)
    for hits in (hit_t, hit_r, hit_k):
        assert abs(hits / n - LEVEL) <= band, (hit_t, hit_r, hit_k)
