"""The check of a diagnosis's additions against data they were not fitted to
(``blackbox.diagnosis.validation``).

Reference: for a model linear in its parameters the one-step K-fold of ``cv_chi2`` is exact (the
leave-fold-out least-squares solution is one Gauss-Newton step from the full solution), so it is
compared with K explicit refits (``numpy.linalg.lstsq`` on the other folds' rows) to round-off
(1e-9 relative: a few hundred rows, condition number ~10).
"""

from __future__ import annotations

import numpy as np
import pytest

from blackbox.diagnosis.validation import cv_chi2, kfold


def _problem(seed=0, n_cases=10, rows=12, p=3):
    rng = np.random.default_rng(seed)
    case = np.repeat(np.arange(n_cases), rows)
    J = rng.standard_normal((len(case), p))
    y = J @ rng.standard_normal(p) + rng.standard_normal(len(case))
    return case, J, y


def _explicit(J, y, case, folds, fixed=None):
    """K refits; ``fixed``: {column: value} for columns held at a value when their fold is out."""
    total = 0.0
    for fold in folds:
        out = np.isin(case, fold)
        cols = [q for q in range(J.shape[1]) if np.linalg.norm(J[~out, q]) > 0]
        x = np.zeros(J.shape[1])
        x[cols] = np.linalg.lstsq(J[~out][:, cols], y[~out], rcond=None)[0]
        for q, v in (fixed or {}).items():
            if q not in cols:
                x[q] = v
        e = y[out] - J[out] @ x
        total += e @ e
    return total


def test_folds_deal_the_cases_in_order():
    v = kfold([0, 1, 2, 3, 4, 5, 6])
    assert v.kind == "kfold" and v.k == 5
    assert v.folds == ((0, 5), (1, 6), (2,), (3,), (4,))
    assert kfold([3, 4]).folds == ((3,), (4,))
    assert kfold([2]).kind == "none"


def test_linear_model_equals_explicit_refits():
    case, J, y = _problem()
    x = np.linalg.lstsq(J, y, rcond=None)[0]
    r = y - J @ x
    folds = kfold(range(10)).folds
    inf = np.full(3, np.inf)
    cv, _ = cv_chi2(J, r, x, -inf, inf, np.full(3, np.nan), case, folds)
    assert cv == pytest.approx(_explicit(J, y, case, folds), rel=1e-9)
    assert cv > r @ r          # predicting unseen cases is worse than fitting them


def test_a_parameter_of_one_case_goes_back_to_its_nested_value():
    """A factor acting on case 3 alone (a load scale): when case 3 is left out nothing else tells
    its value, so it is predicted at its nested value (here 0, the model without it); and no fold
    can both learn and predict with it, so the effect is not checkable by prediction."""
    case, J, y = _problem(seed=1)
    extra = np.where(case == 3, 1.0, 0.0)[:, None] * np.random.default_rng(2).standard_normal((len(case), 1))
    J2 = np.hstack([J, extra])
    y2 = y + 3.0 * extra[:, 0]
    x = np.linalg.lstsq(J2, y2, rcond=None)[0]
    r = y2 - J2 @ x
    folds = kfold(range(10)).folds
    inf = np.full(4, np.inf)
    nominal = np.array([np.nan, np.nan, np.nan, 0.0])
    cv, checkable = cv_chi2(J2, r, x, -inf, inf, nominal, case, folds, owners=[slice(3, 4)])
    assert cv == pytest.approx(_explicit(J2, y2, case, folds, fixed={3: 0.0}), rel=1e-9)
    assert checkable == [False]
    # a parameter on two cases in different folds is learnt from one and predicts the other
    both = np.where(np.isin(case, [3, 4]), 1.0, 0.0)
    J3 = np.hstack([J, both[:, None]])
    x3 = np.linalg.lstsq(J3, y + 2.0 * both, rcond=None)[0]
    _, checkable = cv_chi2(J3, y + 2.0 * both - J3 @ x3, x3, -inf, inf, nominal, case, folds, owners=[slice(3, 4)])
    assert checkable == [True]


def test_a_parameter_at_its_bound_stays_there():
    """A bounded parameter at its bound (a spring the data want below 0) is held in every fold's
    refit, as the bounded fit would hold it: the explicit refits without that column."""
    case, J, y = _problem(seed=3)
    lo = np.array([-np.inf, -np.inf, 0.0])
    x = np.linalg.lstsq(J[:, :2], y, rcond=None)[0]
    x = np.append(x, 0.0)
    r = y - J @ x
    folds = kfold(range(10)).folds
    cv, _ = cv_chi2(J, r, x, lo, np.full(3, np.inf), np.full(3, np.nan), case, folds)
    assert cv == pytest.approx(_explicit(J[:, :2], y, case, folds), rel=1e-9)


def test_a_spring_in_a_flat_valley_stays_at_the_full_fit():
    """A spring (a joint parameter bounded at 0) that a fold's linearised step would move by more
    than its own value (a spring running rigid or free, where one step predicts nonsense) stays
    at the full fit's value in that fold: here a spring at 1e-6 of what the data alone would give
    it, which every fold would move a millionfold, so every fold's refit holds it (the explicit
    refits with that column held). A free (complex-joint) parameter is never held: for it the
    one-step K-fold stays exact (the refits without a hold)."""
    case, J, y = _problem(seed=5)
    x = np.linalg.lstsq(J, y, rcond=None)[0]
    folds = kfold(range(10)).folds
    nan = np.full(3, np.nan)
    lo = np.array([-np.inf, -np.inf, 0.0])
    x_spring = x.copy()
    x_spring[2] = abs(x[2]) * 1e-6
    x_spring[:2] = np.linalg.lstsq(J[:, :2], y - J[:, 2] * x_spring[2], rcond=None)[0]
    r_spring = y - J @ x_spring
    cv, _ = cv_chi2(J, r_spring, x_spring, lo, np.full(3, np.inf), nan, case, folds)
    expect = _explicit(J[:, :2], y - J[:, 2] * x_spring[2], case, folds)
    assert cv == pytest.approx(expect, rel=1e-9)
    inf = np.full(3, np.inf)
    r = y - J @ x
    cv_free, _ = cv_chi2(J, r, x, -inf, inf, nan, case, folds)
    assert cv_free == pytest.approx(_explicit(J, y, case, folds), rel=1e-9)


def test_a_parameter_the_other_cases_barely_see_is_not_learnt_from_them():
    """A misplaced sensor whose neighbour reads nearly the same except in one case: its column is
    large in case 3 and 1 % of that elsewhere. Left out, case 3 would be predicted from one step
    on what the other cases see of it (noncentrality ~0.1: noise), which extrapolates their noise
    by 100x into case 3; below ``LEARNABLE_NC`` the parameter goes back to its nested value
    there (exactly the explicit refit with it held), and since the folds that learn it predict
    cases where it is noise, the effect is not checkable by prediction (the LR test and BIC
    judge it, as they judge an outlier). The same column at full size in two cases stays
    checkable."""
    from blackbox.diagnosis.validation import LEARNABLE_NC
    case, J, y = _problem(seed=3)
    rng = np.random.default_rng(4)
    col = np.where(case == 3, 1.0, 0.01) * rng.standard_normal(len(case))
    J2 = np.hstack([J, col[:, None]])
    y2 = y + 5.0 * col
    x = np.linalg.lstsq(J2, y2, rcond=None)[0]
    r = y2 - J2 @ x
    folds = kfold(range(10)).folds
    inf = np.full(4, np.inf)
    nominal = np.array([np.nan, np.nan, np.nan, 0.0])
    seen_elsewhere = x[3] ** 2 * np.sum(col[case != 3] ** 2)
    assert seen_elsewhere < LEARNABLE_NC < x[3] ** 2 * np.sum(col[case == 3] ** 2)
    cv, checkable = cv_chi2(J2, r, x, -inf, inf, nominal, case, folds, owners=[slice(3, 4)])
    explicit = 0.0                      # K refits, the column held at 0 in the fold that leaves case 3 out
    for fold in folds:
        out = np.isin(case, fold)
        cols = [0, 1, 2] if 3 in fold else [0, 1, 2, 3]
        b = np.zeros(4)
        b[cols] = np.linalg.lstsq(J2[~out][:, cols], y2[~out], rcond=None)[0]
        explicit += float(np.sum((y2[out] - J2[out] @ b) ** 2))
    assert cv == pytest.approx(explicit, rel=1e-9)
    assert checkable == [False]
    both = np.where(np.isin(case, [3, 4]), 1.0, 0.01) * rng.standard_normal(len(case))
    J3 = np.hstack([J, both[:, None]])
    x3 = np.linalg.lstsq(J3, y + 5.0 * both, rcond=None)[0]
    _, checkable = cv_chi2(J3, y + 5.0 * both - J3 @ x3, x3, -inf, inf, nominal, case, folds, owners=[slice(3, 4)])
    assert checkable == [True]


def test_no_fold_learns_a_direction_the_full_data_do_not_determine():
    """Two parameters whose columns differ by 1e-9 of their size (a joint coupling matrix's
    entries that only a combination of is seen): the full data determine their sum, not their
    difference (below the fit's rank cut, 1e-6). A fold's step along the difference fits its
    noise there and carries it into the left-out case (here a random direction: 0.1 % of the
    K-fold chi2; in a blind study's coupling matrix, whose undetermined directions are not
    random, +8000, vetoing the right load scale). Restricted to what the full data determine,
    the K-fold is exactly that of the model with the one combined column (1e-6: rounding and
    the difference column's 1e-9 share of the full fit)."""
    case, J, y = _problem(seed=5)
    twin = J[:, 2] + 1e-9 * np.random.default_rng(6).standard_normal(len(case))
    J2 = np.hstack([J, twin[:, None]])
    x = np.linalg.lstsq(J2, y, rcond=1e-6)[0]          # the full fit, with the fit's rank cut
    r = y - J2 @ x
    folds = kfold(range(10)).folds
    inf = np.full(4, np.inf)
    cv, _ = cv_chi2(J2, r, x, -inf, inf, np.full(4, np.nan), case, folds)
    assert cv == pytest.approx(_explicit(J, y, case, folds), rel=1e-6)
