"""How a diagnosis checks an addition against data it was not fitted to.

Two ways, chosen by the study:

* **hold-out cases** (the study's ``holdout_cases``): predicted, never fitted. The hold-out
  chi2 change ``dh`` of an addition is weighed with the fit's own evidence: the addition must
  lower ``delta BIC + dh`` (BIC of the fit rows plus the hold-out rows' chi2, i.e. -2 log of the
  fit's Bayes factor times the hold-out's predictive likelihood ratio). A hold-out that barely
  sees an effect (two cases against a sensor offset, or a scale confined to one fitted case) then
  cannot veto strong evidence by the chance sign of a small change, while a hold-out that the
  effect predicts clearly worse (a member factor standing in for a joint) vetoes it; the same
  sum ranks the accepted candidates, ``dh`` divided there by the hold-out's dispersion
  (:func:`blackbox.diagnosis.search.holdout_dispersion`).
* **K-fold over load cases** (no hold-out declared: every case is fitted): the fitted cases in
  study order are dealt into ``K = min(5, n_cases)`` folds (case ``i`` in fold ``i mod K``); each
  fold is predicted from the others and the chi2 of those predictions summed (``cv_chi2``). An
  addition must lower ``cv_chi2``. Each fold's fit is *one Gauss-Newton step* from the full fit
  (approximate cross-validation: the leave-fold-out optimum of the model linearised at the full
  optimum), so a K-fold check costs K small least-squares solves, no refits and no solver runs.
  Parameters at a bound stay there, and so does a spring the step would move by more than its
  own value (in the flat valley of running rigid or free, where one linearised step predicts
  nonsense); no fold steps along a direction the full data do not determine (below the fit's
  rank cut: a joint's coupling matrix has tens of them), which one step would fill with the
  fold's noise; an effect parameter that only the left-out fold informs
  (one case's load scale when that case is left out), or that the other folds see below
  :data:`LEARNABLE_NC` (a misplaced sensor whose neighbour reads nearly the same except in one
  case), goes back to its nested value, since nothing else can tell it. An effect whose
  parameters no fold can both learn and predict (confined to one case), or whose size the folds
  that learn it see below :data:`LEARNABLE_NC` in all the cases they predict together (a check
  that cannot tell the effect from noise), cannot be checked by prediction at all: it rests on
  the LR test and BIC, and the search says so in its decision.

With one fitted case neither is possible and additions rest on the LR test and BIC (a warning).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["Validation", "KFOLD_MAX", "kfold", "cv_chi2", "inside_bounds"]

KFOLD_MAX = 5               # folds at most: each fold's fit keeps >= 80 % of the cases
LEARNABLE_NC = 9.0
"""An effect parameter is learned by a fold when the fold's fitted cases alone see its fitted
size from its nested value at 3 sigma (noncentrality 9); below that, the fold's one step would
extrapolate their noise into the left-out case, so the parameter goes back to its nested value."""


@dataclass(frozen=True)
class Validation:
    """``kind``: ``"holdout"``, ``"kfold"`` or ``"none"``; ``folds``: for K-fold, the case
    indices of each fold."""
    kind: str
    folds: tuple[tuple[int, ...], ...] = ()

    @property
    def k(self) -> int:
        return len(self.folds)

    def describe(self) -> str:
        if self.kind == "holdout":
            return "hold-out cases (predicted, never fitted)"
        if self.kind == "kfold":
            return (f"{self.k}-fold cross-validation over the load cases (each fold predicted from a "
                    "one-step refit on the others)")
        return "none (one fitted case): additions rest on the LR test and BIC"


def kfold(cases: Sequence[int], k_max: int = KFOLD_MAX) -> Validation:
    """K-fold over the fitted ``cases`` (indices, in study order): case ``i`` of the list in fold
    ``i mod K``, ``K = min(k_max, len(cases))``; fewer than two cases: ``kind="none"``."""
    cases = list(dict.fromkeys(int(c) for c in cases))
    k = min(k_max, len(cases))
    if k < 2:
        return Validation("none")
    return Validation("kfold", tuple(tuple(cases[g::k]) for g in range(k)))


def inside_bounds(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Which parameters lie strictly inside their bounds (by more than 1e-9 of their size, at
    least 1e-9): the ones a fit moves; a parameter at a bound is held there."""
    tol = 1e-9 * np.maximum(np.abs(x), 1.0)
    return (x > lo + tol) & (x < hi - tol)


def cv_chi2(J: np.ndarray, r: np.ndarray, x: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            nominal: np.ndarray, case: np.ndarray, folds: Sequence[Sequence[int]],
            owners: Sequence[slice] = ()) -> tuple[float, list[bool]]:
    """Approximate K-fold chi2 of a fit (module docstring) and, per effect slice of ``owners``,
    whether some fold both learns its parameters and predicts with them.

    ``J``, ``r``: the whitened Jacobian and residuals (``y - f``) at the optimum ``x``;
    ``lo``, ``hi``: the bounds; ``nominal``: each parameter's nested value (``nan`` for a joint
    parameter: never reset); ``case``: each row's case index."""
    x = np.asarray(x, float)
    p = len(x)
    free = inside_bounds(x, lo, hi)
    scale = np.linalg.norm(J, axis=0)
    tiny = 1e-12 * np.maximum(scale, 1e-300)
    resettable = np.isfinite(nominal)
    # the directions of the free parameters that the full data determine (the fit's rank cut):
    # no fold learns along one the full data do not see (a joint's coupling matrix has tens of
    # such), where one step would turn the fold's noise into any prediction at all
    from blackbox.diagnosis.fit import RANK_RTOL
    sc = np.where(scale > 0, scale, 1.0)
    B = np.zeros((p, 0))
    if free.any():
        _, sv, Vt = np.linalg.svd(J[:, free] / sc[free], full_matrices=False)
        keep = sv > RANK_RTOL * sv[0] if sv.size and sv[0] > 0 else np.zeros(len(sv), bool)
        B = np.zeros((p, int(keep.sum())))
        B[free] = Vt[keep].T / sc[free][:, None]
    seen = np.zeros(p, bool)
    predicted = np.zeros(p)    # an effect parameter's size (chi2) in the cases predicted by the folds that learn it
    total = 0.0
    for fold in folds:
        out = np.isin(case, np.asarray(fold, int))
        if not out.any():
            continue
        Jt, Jg = J[~out], J[out]
        norm_t = np.linalg.norm(Jt, axis=0)
        informed = norm_t > tiny
        # an effect parameter the fold's own cases could not tell from its nested value (its
        # size there below LEARNABLE_NC in chi2) is not learned from them: one step from weak
        # information extrapolates the noise into the left-out case that holds the evidence
        informed &= ~resettable | ((x - np.where(resettable, nominal, x)) ** 2 * norm_t ** 2 >= LEARNABLE_NC)
        learn = free & informed
        d = np.zeros(p)
        reset = resettable & ~informed
        d[reset] = nominal[reset] - x[reset]
        # a spring (a joint parameter bounded at 0) that the step would move by more than its own
        # value lies in a flat valley of the fold's fit (running rigid or free): the linearised
        # step means nothing there, so the fold keeps it at the full fit's value and solves again
        for _ in range(p):
            if not learn.any():
                break
            # the learnt parameters fitted with the others where the fold keeps them, along the
            # determined directions (all of them when the full fit has full rank)
            A = Jt[:, learn] @ B[learn]
            s = np.linalg.norm(A, axis=0)
            s = np.where(s > 0, s, 1.0)
            sol = np.linalg.lstsq(A / s, r[~out] - Jt[:, ~learn] @ d[~learn], rcond=1e-10)[0]
            d[learn] = B[learn] @ (sol / s)
            wild = learn & ~resettable & (lo >= 0.0) & (np.abs(d) > np.abs(x))
            if not wild.any():
                break
            learn &= ~wild
            d[wild] = 0.0
        e = r[out] - Jg @ d
        total += float(e @ e)
        norm_g = np.linalg.norm(Jg, axis=0)
        seen |= learn & ~resettable & (norm_g > tiny)
        both = learn & resettable
        predicted[both] += (x - nominal)[both] ** 2 * norm_g[both] ** 2
    seen |= resettable & (predicted >= LEARNABLE_NC)
    return total, [bool(seen[sl].any()) for sl in owners]
