"""The population of every joint parameter from many specimens of one design (no solver run).

Input: one :class:`~blackbox.population.specimen.SpecimenFit` per specimen (each from its own
condensed model, its own measurements and its own noise). Output: a :class:`PopulationFit`:

* per parameter, the population (:func:`blackbox.population.hierarchy.fit_parameter`), each
  specimen's shrunk estimate (:func:`~blackbox.population.hierarchy.shrink`) and the
  leave-one-out test of every specimen (:func:`~blackbox.population.hierarchy.leave_one_out`);
* **do the specimens differ?** The likelihood-ratio test of one common set of joint parameters
  for every specimen against each specimen's own: the pooled fit minimises the sum of the
  specimens' ``chi2`` over one parameter vector (every specimen's condensed model, its own
  measurements and sigma), and

      LR = chi2_pooled - sum_s chi2_s ~ chi2(df),   df = sum_s rank_s - rank_pooled

  when the specimens share their parameters (known sigma; the usual nested-model test of
  nonlinear least squares). A small p-value: the specimens differ by more than their
  measurement noise explains;
* **a specimen that does not belong**: every specimen's leave-one-out statistic of every
  parameter (Student's t with ``S - 2`` degrees of freedom for Gaussian likelihoods), with a
  Bonferroni correction over all the specimen-parameter tests made; a specimen whose corrected
  p-value is below ``alpha`` (default 0.01) is named, with the parameter, the statistic and the
  population of the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import stats

from blackbox.errors import PopulationError
from blackbox.fitting.lm import levenberg_marquardt
from blackbox.fitting.statistics import covariance
from blackbox.identification.problem import JointCoordinates, SpringFloor
from blackbox.population.hierarchy import LeaveOneOut, ParameterPopulation, fit_parameter, leave_one_out, shrink
from blackbox.population.specimen import SpecimenFit

__all__ = ["PopulationFit", "Outlier", "SpecimensDiffer", "fit_population", "pooled_test", "OUTLIER_ALPHA"]

OUTLIER_ALPHA = 0.01
"""Family-wise level of the outlier test (Bonferroni over specimens x parameters)."""


@dataclass(frozen=True)
class SpecimensDiffer:
    """The pooled likelihood-ratio test (module docstring)."""
    statistic: float
    df: int
    p_value: float
    chi2_pooled: float
    chi2_separate: float
    k_pooled: np.ndarray = field(repr=False)
    converged: bool = True


@dataclass(frozen=True)
class Outlier:
    """A specimen that does not belong, in one parameter."""
    specimen: int
    parameter: int
    statistic: float
    p_value: float
    p_adjusted: float
    others: ParameterPopulation


@dataclass(frozen=True, eq=False)
class PopulationFit:
    """Everything the population fit produced, parameters in the specimens' order."""
    param_joint: tuple[str, ...]
    param_names: tuple[str, ...]
    parameters: tuple[ParameterPopulation, ...]
    shrunk: np.ndarray                          # (n_params, n_specimens, 3) in log k
    loo: tuple[tuple[LeaveOneOut, ...], ...]    # per parameter
    differ: SpecimensDiffer | None
    outliers: tuple[Outlier, ...]
    n_outlier_tests: int
    confidence: float
    alpha: float

    @property
    def n_specimens(self) -> int:
        return int(self.shrunk.shape[1])


class _Pooled:
    """One parameter vector for every specimen: the stacked least-squares problem of their
    condensed models (:class:`blackbox.fitting.lm.LeastSquaresProblem`)."""

    def __init__(self, problems):
        self.problems = list(problems)
        first = self.problems[0]
        self.n_params = first.p
        self.y = np.concatenate([p.y for p in self.problems])
        self.weights = np.concatenate([p.w for p in self.problems])
        self.coordinates = JointCoordinates(first.model.assembly.joints)
        self.bounds = SpringFloor(self.coordinates, self.admissible)

    def admissible(self, k) -> bool:
        return all(p.admissible(k) for p in self.problems)

    def predict(self, k):
        parts = [p.predict(k) for p in self.problems]
        return np.concatenate([f for f, _ in parts]), [r for _, r in parts]

    def jacobian(self, k, state):
        return np.vstack([p.jacobian_k(k, r) for p, r in zip(self.problems, state)])


def pooled_test(fits: Sequence[SpecimenFit]) -> SpecimensDiffer:
    """The likelihood-ratio test of one common parameter vector (module docstring); the pooled
    fit starts from the geometric mean of the specimens' estimates."""
    pooled = _Pooled(f.problem for f in fits)
    x0 = np.mean([np.log(f.k) for f in fits], axis=0)
    res = levenberg_marquardt(pooled, pooled.coordinates.to_coords(np.exp(x0)), max_iterations=100,
                              xtol=1e-9, ftol=1e-12)
    J = pooled.jacobian(res.k, res.state) * pooled.weights[:, None]
    rank = covariance(J, pooled.coordinates.scale(res.k)).rank
    separate = float(sum(f.chi2 for f in fits))
    lr = max(float(res.chi2) - separate, 0.0)
    df = int(sum(f.rank for f in fits) - rank)
    p = float(stats.chi2.sf(lr, df)) if df > 0 else math.nan
    return SpecimensDiffer(lr, df, p, float(res.chi2), separate, res.k, res.converged)


def fit_population(fits: Sequence[SpecimenFit], param_joint: Sequence[str], param_names: Sequence[str], *,
                   confidence: float = 0.95, alpha: float = OUTLIER_ALPHA, shrinkage: bool = True,
                   outliers: bool = True, differ: bool = True) -> PopulationFit:
    """The population of every parameter (module docstring). ``shrinkage``, ``outliers``,
    ``differ``: compute the shrunk specimen estimates, the leave-one-out tests and the pooled
    test (a coverage study may leave them out)."""
    fits = list(fits)
    if len(fits) < 2:
        raise PopulationError(f"a population needs at least 2 specimens, got {len(fits)}")
    p = fits[0].n_params
    if any(f.n_params != p for f in fits) or len(param_names) != p:
        raise PopulationError("the specimens do not have the same parameters")
    if not 0.0 < alpha < 1.0:
        raise PopulationError(f"alpha must be in (0, 1), got {alpha!r}")
    S = len(fits)
    pops, loos = [], []
    shrunk = np.full((p, S, 3), np.nan)
    for j in range(p):
        liks = [f.likelihoods[j] for f in fits]
        pop = fit_parameter(liks, confidence)
        pops.append(pop)
        if shrinkage:
            shrunk[j] = shrink(liks, pop, confidence)
        loos.append(tuple(leave_one_out(liks, confidence, pop.tau if pop.tau > 0 else None)) if outliers else ())
    n_tests = sum(len(x) for x in loos)
    found = []
    for j, tests in enumerate(loos):
        for t in tests:
            adj = min(1.0, t.p_value * n_tests)
            if adj < alpha:                     # the others' population, now with its intervals
                others = fit_parameter([f.likelihoods[j] for i, f in enumerate(fits) if i != t.index], confidence)
                found.append(Outlier(t.index, j, t.statistic, t.p_value, adj, others))
    found.sort(key=lambda o: o.p_adjusted)
    return PopulationFit(tuple(param_joint), tuple(param_names), tuple(pops), shrunk, tuple(loos),
                         pooled_test(fits) if differ else None, tuple(found), n_tests, confidence, alpha)
