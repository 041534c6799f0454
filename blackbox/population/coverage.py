"""Coverage of the population's intervals over repeated simulated populations (no solver run).

One condensed model (the one solver run of the structure) serves every specimen of every
replicate: the specimens of a population share the deck and the test; what differs is their
joints. Replicate ``r`` (``numpy.random.default_rng([seed, r])``):

1. every specimen's ``log k`` drawn from ``N(log centre, tau^2)``, ``tau`` from the spread (the
   coefficient of variation: ``tau = sqrt(log(1 + cv^2))``), independently per parameter;
2. its measurements simulated at those ``k`` with the noise model of ``blackbox simulate``
   (:func:`blackbox.simulation.noise_sigma`: ``relative`` of each quantity, floored), the sigma
   declared to the estimator;
3. every specimen fitted (:func:`~blackbox.population.specimen.fit_specimen`) from ``k0``, then the
   population (:func:`~blackbox.population.fit.fit_population`);
4. per parameter: does the centre's interval hold the true median, the spread's interval the
   true coefficient of variation, each shrunk specimen interval the specimen's true ``k``?

Replicates run in chunks through an executor (``--workers``), each depending only on its seed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import stats

from blackbox.condensation import CondensedModel
from blackbox.identification import Observations
from blackbox.population.fit import fit_population
from blackbox.population.likelihood import TabulatedLikelihood
from blackbox.population.specimen import QUADRATIC_RTOL, fit_specimen
from blackbox.simulation import NoiseConfig, noise_sigma

__all__ = ["CoverageTable", "population_coverage", "simulate_specimen", "binomial_band"]


def binomial_band(n: int, level: float = 0.95, band: float = 0.99) -> tuple[float, float]:
    """Where the observed coverage of ``n`` independent intervals of nominal ``level`` falls with
    probability ``band`` (binomial quantiles, as fractions)."""
    lo = stats.binom.ppf((1.0 - band) / 2.0, n, level) / n
    hi = stats.binom.ppf(1.0 - (1.0 - band) / 2.0, n, level) / n
    return float(lo), float(hi)


def simulate_specimen(model: CondensedModel, k: np.ndarray, dofs: Sequence[tuple[int, int]], cases: Sequence[int],
                      noise: NoiseConfig, rng: np.random.Generator) -> Observations:
    """Every DOF of ``dofs`` measured in every case index of ``cases`` at the joint parameters
    ``k``, case-major, noise as ``blackbox simulate`` makes it."""
    dofs = [tuple(map(int, d)) for d in dofs]
    cases = list(cases)
    U = model.pick(model.response(np.asarray(k, float)), dofs)[:, cases]        # (rows, cases)
    true = U.T.ravel()
    ci = np.repeat(np.asarray(cases), len(dofs))
    kinds = np.tile([1 if c >= 4 else 0 for _, c in dofs], len(cases))
    sigma = noise_sigma(true, kinds, ci, noise)
    values = true + sigma * rng.standard_normal(true.size)
    return Observations(tuple(d for _ in cases for d in dofs), ci, values, sigma, tuple(model.c.cases))


@dataclass(frozen=True, eq=False)
class CoverageTable:
    """Per replicate and parameter: hits of the centre's and the spread's interval, the share of
    specimens whose shrunk interval holds their truth; per replicate the pooled test's p-value."""
    centre_hit: np.ndarray          # (R, p) bool
    spread_hit: np.ndarray          # (R, p) bool
    specimen_cover: np.ndarray      # (R, p) fraction (nan without shrinkage)
    differ_p: np.ndarray            # (R,) (nan without the pooled test)
    centre_width: np.ndarray        # (R, p) relative width (high / low of the centre)
    spread_high: np.ndarray         # (R, p) upper end of the spread interval
    exact_share: float              # share of specimen likelihoods tabulated exactly
    n_specimens: int
    wall_s: float
    executor: str

    @property
    def replicates(self) -> int:
        return int(self.centre_hit.shape[0])

    def centre_coverage(self) -> np.ndarray:
        return self.centre_hit.mean(axis=0)

    def spread_coverage(self) -> np.ndarray:
        return self.spread_hit.mean(axis=0)


def _chunk(args) -> list[tuple]:
    (model, dofs, cases, noise, centre, spread, k0, S, seeds, confidence, shrinkage, differ, qrtol) = args
    mu = np.log(np.asarray(centre, float))
    tau = np.sqrt(np.log1p(np.asarray(spread, float) ** 2))
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        truths = np.exp(mu[None, :] + tau[None, :] * rng.standard_normal((S, mu.size)))
        fits = [fit_specimen(model, simulate_specimen(model, k, dofs, cases, noise, rng), k0, quadratic_rtol=qrtol)
                for k in truths]
        pf = fit_population(fits, model.assembly.param_joint, model.assembly.param_names, confidence=confidence,
                            shrinkage=shrinkage, outliers=False, differ=differ)
        ch = np.array([P.mu_ci[0] <= m <= P.mu_ci[1] for P, m in zip(pf.parameters, mu)])
        sh = np.array([P.tau_ci[0] <= t <= P.tau_ci[1] for P, t in zip(pf.parameters, tau)])
        if shrinkage:
            th = np.log(truths).T                                      # (p, S)
            sc = np.mean((pf.shrunk[:, :, 1] <= th) & (th <= pf.shrunk[:, :, 2]), axis=1)
        else:
            sc = np.full(mu.size, np.nan)
        width = np.array([np.exp(P.mu_ci[1] - P.mu_ci[0]) for P in pf.parameters])
        top = np.array([P.spread_ci[1] for P in pf.parameters])
        exact = np.mean([isinstance(L, TabulatedLikelihood) for f in fits for L in f.likelihoods])
        out.append((ch, sh, sc, pf.differ.p_value if pf.differ is not None else np.nan, width, top, exact))
    return out


def population_coverage(model: CondensedModel, dofs, cases, centre, spread, n_specimens: int, *, k0=None,
                        replicates: int = 200, noise: NoiseConfig | float = 0.05, seed: int = 2024,
                        confidence: float = 0.95, shrinkage: bool = False, differ: bool = False,
                        quadratic_rtol: float = QUADRATIC_RTOL, executor=None,
                        chunks: int | None = None) -> CoverageTable:
    """The coverage study of the module docstring: ``centre`` and ``spread`` per parameter (of
    ``model.assembly``), ``n_specimens`` per population, ``replicates`` populations; ``k0`` the
    specimens' start (default: 1/10 of the centre, as a user's rough guess). ``noise``: a
    :class:`~blackbox.simulation.NoiseConfig` or its relative part. ``executor``: where the
    chunks of replicates run (default serial); the result does not depend on it.
    ``quadratic_rtol``: the check of the specimens' quadratic likelihoods (``inf``: never
    tabulate the exact profile, to see what the exact likelihood changes)."""
    noise = noise if isinstance(noise, NoiseConfig) else NoiseConfig(relative=float(noise))
    centre = np.asarray(centre, float)
    k0 = 0.1 * centre if k0 is None else np.asarray(k0, float)
    workers = executor.workers if executor is not None else 1
    n_chunks = chunks or (4 * workers if workers > 1 else 1)
    seeds = [[int(seed), r] for r in range(int(replicates))]
    tasks = [(model, tuple(tuple(d) for d in dofs), tuple(cases), noise, centre, np.asarray(spread, float), k0,
              int(n_specimens), [seeds[i] for i in idx], confidence, shrinkage, differ, float(quadratic_rtol))
             for idx in np.array_split(np.arange(len(seeds)), min(n_chunks, len(seeds))) if idx.size]
    t0 = time.perf_counter()
    parts = executor.map(_chunk, tasks) if executor is not None else [_chunk(t) for t in tasks]
    rows = [row for part in parts for row in part]
    wall = time.perf_counter() - t0
    return CoverageTable(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                         np.array([r[2] for r in rows]), np.array([r[3] for r in rows]),
                         np.array([r[4] for r in rows]), np.array([r[5] for r in rows]),
                         float(np.mean([r[6] for r in rows])), int(n_specimens), wall,
                         executor.description if executor is not None else "serial")
