"""The search's hold-out comparison reads the hold-out residuals with the prediction's own
uncertainty (``search.prediction_metric``): a hold-out case that loads a parameter the fit rows
leave loose does not decide an addition by where that parameter lands."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from blackbox.diagnosis.fit import Fit
from blackbox.diagnosis.model import ModelSpec
from blackbox.diagnosis.search import Checks, prediction_metric
from blackbox.diagnosis.validation import Validation

N_FIT = 1000
N_CASE = 40


def _fit(chi2: float, p: int, y: np.ndarray, residual: np.ndarray, basis: np.ndarray | None) -> Fit:
    """A fit of ``p`` parameters with chi2 ``chi2`` on ``N_FIT`` rows whose hold-out residual
    (sigma 1) is ``residual``."""
    bic = chi2 + p * np.log(N_FIT)
    J, Jh, free = _jacobians_of(p, len(y), basis)
    return Fit(ModelSpec(()), np.zeros(p), np.zeros(p), N_FIT, p, chi2, chi2 / (N_FIT - p), 1.0, bic,
               np.zeros(N_FIT), np.zeros(N_FIT), 1.0, float(residual @ residual), len(y), True, "",
               J, y - residual, Jh, free)


def _jacobians_of(p: int, n: int, basis: np.ndarray | None):
    """``(J, holdout_J, free)`` whose prediction basis is ``basis`` (one column, or ``None``: no
    basis): the first parameter alone moves, seen by the fit rows with unit norm, so that its
    hold-out column is the basis itself."""
    J = np.zeros((N_FIT, p))
    if basis is None:
        return J, None, None
    J[0, 0] = 1.0
    Jh = np.zeros((n, p))
    Jh[:, 0] = basis[:, 0]
    free = np.zeros(p, bool)
    free[0] = True
    return J, Jh, free


def _case(rng, loose_off: tuple[float, float], spoiled: float = 0.0):
    """Hold-out case 0 carries an effect ``s`` (10 sigma) the addition predicts; case 1 loads a
    direction ``u`` the fitted parameters leave loose (the addition's prediction uncertain by
    300 sigma along it), off by ``loose_off`` (before, after) along it, and by ``spoiled``
    along a direction ``v`` outside it after the addition."""
    n = 2 * N_CASE
    case = np.repeat([0, 1], N_CASE)
    s = np.zeros(n)
    s[:N_CASE] = rng.normal(size=N_CASE)
    s *= 10.0 / np.linalg.norm(s)
    u, v = np.zeros(n), np.zeros(n)
    u[N_CASE:] = rng.normal(size=N_CASE)
    u /= np.linalg.norm(u)
    v[N_CASE:] = rng.normal(size=N_CASE)
    v -= (v @ u) * u
    v /= np.linalg.norm(v)
    noise = rng.normal(size=n)
    y = noise + s
    r1 = noise + s + loose_off[0] * u
    r2 = noise + loose_off[1] * u + spoiled * v
    basis = 300.0 * u[:, None]
    hold = SimpleNamespace(sigma=np.ones(n), y=y, case=case)
    return hold, _fit(2000.0, 1, y, r1, None), _fit(1000.0, 2, y, r2, basis)


def test_loose_parameter_case_does_not_veto_an_addition():
    """Both fits miss case 1 by many times its noise along the loose direction, the addition by
    more: read plainly that vetoes the addition (it predicts case 0 to its noise, a chi2 drop
    of ~100, and improves the fit by ~1000); in the addition's predictive metric case 1 is at
    its noise for both and the addition passes."""
    rng = np.random.default_rng(7)
    hold, fit, f2 = _case(rng, (60.0, 150.0))
    j = Checks(None, hold, Validation("holdout")).judge(fit, f2, 1.0, 0.01, -1)
    assert j.accepted, j.reasons
    assert j.holdout_delta_chi2 < -50.0
    # the plain reading of the same fits (no prediction basis) vetoes it
    plain = Checks(None, hold, Validation("holdout")).judge(fit, _without_basis(f2), 1.0, 0.01, -1)
    assert not plain.accepted
    assert plain.holdout_delta_chi2 > 10_000.0


def test_case_spoiled_outside_the_loose_direction_still_vetoes():
    """The metric discounts only what the fitted parameters' error can carry: an addition that
    spoils case 1 along another direction (150 sigma) is vetoed as before."""
    rng = np.random.default_rng(7)
    hold, fit, f2 = _case(rng, (60.0, 150.0), spoiled=150.0)
    j = Checks(None, hold, Validation("holdout")).judge(fit, f2, 1.0, 0.01, -1)
    assert not j.accepted


def test_metric_is_the_predictive_chi2():
    """Each case's ``z^T z`` is ``r^T (I + A A^T)^-1 r`` for both fits; rows outside ``keep`` are
    left as they are."""
    rng = np.random.default_rng(1)
    hold, fit, f2 = _case(rng, (60.0, 150.0))
    A = f2.holdout_basis.copy()
    A[:N_CASE, 0] = rng.normal(size=N_CASE)
    f2 = _with_basis(f2, A)
    a, b, _ = prediction_metric(fit, f2, hold)
    for f, g in ((fit, a), (f2, b)):
        r = (hold.y - f.holdout_predicted) / hold.sigma
        z = (hold.y - g.holdout_predicted) / hold.sigma
        for k in (0, 1):
            rows = hold.case == k
            Ak = A[rows]
            want = r[rows] @ np.linalg.solve(np.eye(int(rows.sum())) + Ak @ Ak.T, r[rows])
            assert np.isclose(z[rows] @ z[rows], want, rtol=1e-9)
        assert np.isclose(g.holdout_chi2, z @ z)
    keep = hold.case == 0
    a, _, _ = prediction_metric(fit, f2, hold, keep)
    assert np.array_equal(a.holdout_predicted[~keep], fit.holdout_predicted[~keep])


def _without_basis(f: Fit) -> Fit:
    return _with_basis(f, None)


def _with_basis(f: Fit, basis) -> Fit:
    from dataclasses import replace

    J, Jh, free = _jacobians_of(f.n_params, len(f.holdout_predicted), basis)
    return replace(f, J=J, holdout_J=Jh, free=free)
