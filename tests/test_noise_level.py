"""A misfit that looks like noise larger than declared (blackbox/diagnosis/noise_level.py).

References: the whitened residuals of a least-squares fit with hat diagonal ``h`` have
``E[z_i^2] = c^2 (1 - h_i)`` under noise ``c`` times the declared sigma (Seber & Lee, Linear
Regression Analysis, 2nd ed., sec. 10.1), which the group tests take as their degrees of freedom.
"""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from blackbox.diagnosis.noise_level import leverages, noise_level

GRIDS, CASES, COMPS = 8, 10, 3


def _layout():
    g, k, c = np.meshgrid(np.arange(GRIDS), np.arange(CASES), np.arange(1, COMPS + 1), indexing="ij")
    return g.ravel(), k.ravel(), c.ravel()


def _fit_residuals(rng, y, X):
    """Whitened residuals and leverages of the least-squares fit of ``y`` on ``X``."""
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    return y - X @ beta, leverages(X)


def test_leverages_are_the_hat_diagonal():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(40, 4)) * np.array([1.0, 1e3, 1e-3, 5.0])     # columns of any scale
    H = X @ np.linalg.solve(X.T @ X, X.T)
    assert np.allclose(leverages(X), np.diag(H), atol=1e-10)          # round-off of a 4-column solve
    assert abs(leverages(X).sum() - 4.0) < 1e-9                       # the trace is the rank


def test_noise_larger_than_declared_is_said_to_be_noise_and_sized():
    """Noise twice the declared sigma on a linear fit: the factor is 2 within its standard
    error (about 2 / sqrt(2 dof) = 0.05 here, 4 of them allowed), and 500 such draws are called
    anything else at most 15 times: alpha = 0.01 over the two tests gives 5 expected, and a
    Poisson(5) count above 15 has probability 7e-5."""
    rng = np.random.default_rng(2)
    grid, case, comp = _layout()
    sigma = np.exp(rng.uniform(-1, 1, size=len(grid)))
    X = rng.normal(size=(len(grid), 5))
    X[:, 0] *= 30.0 * (grid == 0)                    # one parameter pinned by one grid's readings
    other = 0
    response = 50.0 * rng.normal(size=len(grid))
    for i in range(500):
        z, h = _fit_residuals(rng, 2.0 * rng.normal(size=len(grid)), X)
        nl = noise_level(z, h, grid, case, comp, sigma, response)
        if i == 0:
            assert nl.noise_like and abs(nl.factor - 2.0) < 4 * 2.0 / np.sqrt(2 * nl.dof), nl
            assert f"noise {nl.factor:.3g} times" in nl.sentence() and "understates the noise" in nl.sentence()
        other += not nl.noise_like
    assert other <= 15, other


def test_a_misfit_at_one_grid_is_not_noise():
    """The model wrong at one grid (every reading there off by 5 sigma, one direction per case,
    as a soft member near it would make it): the reduced chi2 is about 4 (1 + 25 / 8 grids), as
    with noise twice the declared, but that grid carries it, and the test names the grid."""
    rng = np.random.default_rng(3)
    grid, case, comp = _layout()
    y = rng.normal(size=len(grid)) + np.where(grid == 5, 5.0 * np.sign(rng.normal(size=CASES))[case], 0.0)
    X = rng.normal(size=(len(grid), 3))
    z, h = _fit_residuals(rng, y, X)
    nl = noise_level(z, h, grid, case, comp, np.ones(len(grid)))
    assert 3.0 < nl.factor ** 2 < 5.5 and not nl.noise_like
    assert ("grid", "5") in [(g, k) for g, k, *_ in nl.uneven]
    assert "not noise" in nl.sentence() and "grid 5" in nl.sentence()


def test_a_misfit_that_grows_with_the_response_is_not_noise():
    """Hysteresis (the loading and unloading branches of a record apart by 40 % of the response
    there, the response 1 to 10 sigma, one grid and component, as in the measured column on its
    base, fixtures/measured/rc_column): no grid, case or component carries it, the largest
    responses do, and the response grouping says so; without the predictions it passes."""
    rng = np.random.default_rng(5)
    n = 400
    u = np.linspace(1.0, 10.0, n) * np.sign(rng.normal(size=n))
    branch = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    z, h = _fit_residuals(rng, u + rng.normal(size=n) + 0.2 * np.abs(u) * branch, u[:, None])
    one = np.zeros(n, int)
    nl = noise_level(z, h, one, np.arange(n), one + 1, np.ones(n), u)
    assert not nl.noise_like and "response quarter" in {g for g, *_ in nl.uneven}, nl
    assert noise_level(z, h, one, np.arange(n), one + 1, np.ones(n)).noise_like


def test_hold_out_cases_not_predicted_at_that_noise_rule_it_out():
    rng = np.random.default_rng(4)
    grid, case, comp = _layout()
    z, h = _fit_residuals(rng, 2.0 * rng.normal(size=len(grid)), rng.normal(size=(len(grid), 3)))
    asked = []
    nl = noise_level(z, h, grid, case, comp, np.ones(len(grid)), holdout=lambda c: asked.append(c) or False)
    assert not nl.noise_like and asked == [nl.factor]
    assert "hold-out cases are not predicted even at that noise" in nl.sentence()


@pytest.mark.slow
def test_a_study_with_every_sigma_halved_reads_as_noise_twice_declared(tmp_path):
    """A clean portal study of the blind generator (seed 77) whose every declared sigma is halved:
    nothing is added, the verdict stays "unexplained" (the misfit is above the declared band,
    CONTRACT's definition), and the diagnosis says it looks like noise 2 times the declared
    sigma, the hold-out cases predicted at that noise. The factor: 2 times the square root of the
    reduced chi2 the study has at its true sigma, itself within about 1 +- 0.05 (790 dof):
    10 % allowed."""
    from benchmarks.blind.generate import NONE, generate_study
    from blackbox.commands.diagnose import run

    st = generate_study(0, 77, tmp_path / "ns", kind=NONE, shape="portal", style="plain")
    path = st.folder / "measurements.csv"
    rows = list(csv.DictReader(open(path, newline="")))
    for r in rows:
        r["sigma"] = repr(float(r["sigma"]) / 2.0)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    doc = json.loads(json.dumps(run(st.folder, plots=False).document, default=float))
    assert doc["added"] == [] and doc["verdict"] == "unexplained"
    nl = doc["noise_level"]
    assert nl["noise_like"] and nl["holdout_predicted"] and abs(nl["factor"] / 2.0 - 1.0) < 0.1, nl
    assert "looks like noise" in doc["verdict_detail"]
    shutil.rmtree(tmp_path / "ns", ignore_errors=True)
