"""An addition's degrees of freedom are the parameters the data determine (the rise of the
whitened Jacobian's rank), not its nominal count: a joint turned complex adds the 12 entries of
``K_C`` a simple joint lacks, of which the measured readings may see only some, and charging
BIC for the unseen ones let a one-parameter data defect (an outlier where the coupling's effect
is largest) win the choice over the coupling (blind benchmark, seed 3, study 315)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from scipy import stats

from blackbox.diagnosis.fit import effective_rank
from blackbox.diagnosis.search import Checks
from blackbox.diagnosis.validation import Validation

N = 100


def _fit(J: np.ndarray, chi2: float) -> SimpleNamespace:
    p = J.shape[1]
    return SimpleNamespace(J=J, n_params=p, n_obs=N, chi2=chi2, reduced_chi2=chi2 / (N - p),
                           bic=chi2 + p * math.log(N), spec=SimpleNamespace(effects=()),
                           holdout_chi2=None, holdout_predicted=None)


def test_effective_rank_counts_the_columns_the_data_see():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(N, 3))
    assert effective_rank(J) == 3
    assert effective_rank(np.column_stack([J, np.zeros(N), J[:, 0] + J[:, 1]])) == 3
    assert effective_rank(np.column_stack([J, 1e3 * J[:, 2]])) == 3       # scale-free
    assert effective_rank(np.zeros((N, 0))) == 0


def test_unseen_parameters_cost_nothing():
    """Three nominal parameters, one seen: LR test and BIC count one, so the addition competes
    with a one-parameter alternative on its chi2 drop alone; a full-rank addition is judged as
    before (nominal count, f2.bic - fit.bic)."""
    rng = np.random.default_rng(1)
    J0 = rng.normal(size=(N, 2))
    checks = Checks(SimpleNamespace(), None, Validation("none"))
    fit = _fit(J0, 130.0)
    seen = rng.normal(size=N)
    coupled = _fit(np.column_stack([J0, seen, np.zeros(N), 1e-9 * J0[:, 0]]), 110.0)   # LR 20, 1 seen
    other = _fit(np.column_stack([J0, rng.normal(size=N)]), 115.0)                     # LR 15, 1 param
    jc = checks.judge(fit, coupled, 1.0, 0.01, -1)
    jo = checks.judge(fit, other, 1.0, 0.01, -1)
    assert checks.added_dof(fit, coupled) == 1
    assert math.isclose(jc.delta_bic, -20.0 + math.log(N))                # not -20 + 3 ln N
    assert math.isclose(jc.lr_p, stats.chi2.sf(20.0 / coupled.reduced_chi2, 1))
    assert jc.evidence < jo.evidence                                      # the larger drop wins
    assert math.isclose(jo.delta_bic, other.bic - fit.bic)
    full = _fit(np.column_stack([J0, rng.normal(size=(N, 3))]), 110.0)
    assert checks.added_dof(fit, full) == 3
    assert math.isclose(checks.judge(fit, full, 1.0, 0.01, -1).delta_bic, full.bic - fit.bic)
