"""``load_scale``: the structure felt scaled loads (all cases, a group of cases, or one case), Sec. 5.3.1.

A factor ``s`` on every response of its cases (linearity: exact, no run). Candidates: one factor
for all cases (``s_all``); when ``loads.csv`` names groups (the set-up a case was run in: a test
day, a rig, a load cell) and there are at least two, one factor per group with a fitted case
(``s_group_G``, a miscalibrated load cell of one set-up); with more than one fitted case, one
per fitted case (``s_L``). ``where`` lists the cases scaled.

Without a ``group`` column, groups are *found from the data*: each fitted case's own scale of its
responses in the declared fit (``1 + sum(u r / sigma^2) / sum(u^2 / sigma^2)``, ``u`` the
predicted responses, ``r`` the residuals) orders the fitted cases, and every run of ``k`` cases at
either end of that order (``2 <= k <= n - 1``: the ``k`` most over- or under-scaled) is a
candidate ``s_found_<first>_<k>`` -- the cases of a test day whose load cell read low share one
factor and sit together at one end. The groups are found again from each round's fit
(:meth:`LoadScale.refresh`): with a support spring still missing, the declared fit's case scales
mix both effects, and the day stands out only once the support is in the model. The order is read from the same data the candidates are
then tested on, so a found group's likelihood ratio is not a chi2_1 variable: the best of the
groups a noise-only data set offers has a chi2 drop near 0.3 n, not 1. Its test accounts for
the choice (:func:`found_group_log_sf`): with ``z_i`` the fitted cases' standardized scales
(independent N(0, 1) with no load scaled, when the cases outnumber the joint parameters), any
group's drop is at most the sum of the squares of its members of one sign (Cauchy-Schwarz),
hence at most ``A = sum z_i^2 [z_i > 0]`` or ``B`` (the same for ``z_i < 0``); ``A`` is a
mixture of chi2_j with binomial(n, 1/2) weights, so ``P(best drop > t) <= 2 sum_j C(n, j)
2^-n P(chi2_j > t)`` whichever groups are offered. That bound is each found group's p-value,
and the found groups together count as one hypothesis of their round
(:attr:`LoadScale.hypothesis`); where they compete with a group fixed in advance (all cases,
a ``loads.csv`` group, one case) their chi2 drop counts as the drop a fixed group would need
for the same p-value (:meth:`blackbox.diagnosis.search.Checks.judge`), so a group that fits
the noise of a few cases better does not displace the one that explains them all. One case's
own factor stays a candidate beside them. Hold-out cases are never in a found group (their
residuals are not looked at).

A scale of fitted cases only moves the hold-out prediction through the structure's refit alone,
and a hold-out case may share the group's defect unseen (a test day's load cell read low in a
hold-out case too): the hold-out cases then judge it with each case's own scale taken out
(:meth:`holdout_scale_free`), by the shape of their responses. Otherwise a right group, which
unbiases the structure, reads as predicting such hold-out cases worse and is vetoed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special, stats

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.registry import register

__all__ = ["LoadScale", "case_scales", "found_group_log_sf"]


def case_scales(case: np.ndarray, y: np.ndarray, sigma: np.ndarray, predicted: np.ndarray,
                labels) -> dict[str, tuple[float, float]]:
    """Each case's least-squares scale of its predicted responses, minus 1, and its standard
    deviation: ``(sum(u r / s^2) / sum(u^2 / s^2), 1 / sqrt(sum(u^2 / s^2)))`` over the case's
    rows (``u`` predicted, ``r = y - u``); ``case`` indexes ``labels``."""
    u = np.asarray(predicted, float)
    w = 1.0 / np.asarray(sigma, float) ** 2
    r = np.asarray(y, float) - u
    case = np.asarray(case)
    out = {}
    for c in dict.fromkeys(case.tolist()):
        rows = case == c
        uu = float(np.sum(w[rows] * u[rows] ** 2))
        if uu > 0:
            out[labels[c]] = (float(np.sum(w[rows] * u[rows] * r[rows]) / uu), 1.0 / np.sqrt(uu))
    return out


def found_group_log_sf(t: float, n: int) -> float:
    """The natural log of the bound of the module docstring on the chance that, with no load
    scaled, the best group found among ``n`` fitted cases drops the chi2 by ``t`` or more:
    ``log min(1, 2 sum_{j=1..n} C(n, j) 2^-n P(chi2_j > t))``."""
    if t <= 0:
        return 0.0
    j = np.arange(1, n + 1)
    terms = special.gammaln(n + 1) - special.gammaln(j + 1) - special.gammaln(n - j + 1) - n * np.log(2.0) \
        + stats.chi2.logsf(t, j)
    return float(min(0.0, np.log(2.0) + special.logsumexp(terms)))


@register
@dataclass(frozen=True, eq=False)
class LoadScale(Effect):
    """``cases``: indices of the scaled cases among the study's load cases; ``group``: the
    ``loads.csv`` group they form (a group candidate), else ``None``."""
    kind = "load_scale"
    of_data = True
    summary = "the loads of some cases were scaled (a factor on their responses)"

    cases: tuple[int, ...] = ()
    group: str | None = None
    among: int = 0          # a found group: how many fitted cases it was chosen among

    @property
    def hypothesis(self) -> object:
        return (self.kind, "found from the data") if self.found else self.key

    def selection_log_sf(self, t: float) -> float | None:
        return found_group_log_sf(t, self.among) if self.found else None

    def details_json(self) -> dict:
        return {} if self.group is None else {"group": self.group}

    def label(self) -> str:
        return f"{self.kind} @ group {self.group}" if self.group is not None else super().label()

    @classmethod
    def candidates(cls, ctx, split) -> list["LoadScale"]:
        cases = list(ctx.cases)
        fitted = [ctx.fit_obs.case_labels[c] for c in ctx.fit_obs.cases]
        out = [cls(tuple(cases), ("s_all",), cases=tuple(range(len(cases))))]
        groups = ctx.groups or {}
        names = list(dict.fromkeys(groups[c] for c in cases if c in groups))
        if len(names) > 1:
            for g in names:
                members = [c for c in cases if groups.get(c) == g]
                if len(members) > 1 and any(c in fitted for c in members):
                    out.append(cls(tuple(members), (f"s_group_{g}",), cases=tuple(cases.index(c) for c in members),
                                   group=g))
        if len(fitted) > 1:
            out += [cls((c,), (f"s_{c}",), cases=(cases.index(c),)) for c in fitted]
        if len(names) <= 1 and ctx.case_scales:
            out += cls.found_groups(cases, ctx.case_scales)
        return out

    def holdout_scale_free(self, hold) -> bool:
        """A scale of fitted cases only: the hold-out cases may be in its group unseen (found
        groups never take them in), so each hold-out case's own scale is taken out before it
        judges the addition; a group with a hold-out case in it is judged as it predicts them."""
        held = {hold.labels[int(c)] for c in np.unique(hold.case)} if hold is not None and hold.labels else set()
        return bool(held) and not (set(self.where) & held)

    @property
    def found(self) -> bool:
        """A group found from the data (not named in ``loads.csv``)."""
        return self.group is not None and self.group.startswith("found")

    @classmethod
    def refresh(cls, pool, fit, om, labels):
        if not any(isinstance(e, cls) and e.found for e in pool):
            return pool
        scales = case_scales(om.case, om.y, om.sigma, fit.predicted, labels)
        keep = [e for e in pool if not (isinstance(e, cls) and e.found)]
        return keep + cls.found_groups(list(labels), scales)

    @classmethod
    def found_groups(cls, cases: list[str], case_scales: dict[str, tuple[float, float]]) -> list["LoadScale"]:
        """The groups found from the data (module docstring): the ``k`` fitted cases with the
        largest, and those with the smallest, own scale, ``2 <= k <= n - 1``."""
        order = sorted((c for c in cases if c in case_scales), key=lambda c: (case_scales[c][0], cases.index(c)))
        n = len(order)
        out, seen = [], set()
        for k in range(2, n):
            for members in (order[:k], order[n - k:]):
                idx = tuple(sorted(cases.index(c) for c in members))
                if idx in seen:
                    continue
                seen.add(idx)
                first = cases[idx[0]]
                out.append(cls(tuple(cases[i] for i in idx), (f"s_found_{first}_{k}",), cases=idx,
                               group=f"found from the data ({k} cases)", among=n))
        return out

    @property
    def acts_on_output(self) -> bool:
        return True

    def output_rows(self, om):
        return [(0, np.isin(om.case, self.cases))]
