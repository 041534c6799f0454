"""Uncertainty of the identified parameters (Sec. 4.4).

The covariance is ``(J^T V_m^-1 J)^-1`` in the natural parameters at the optimum, from the pivoted
QR of :func:`blackbox.fitting.statistics.covariance` on the whitened Jacobian with every column
scaled by its parameter's size: its numerical rank and null space decide identifiability (a
parameter with a component in the null space is *not identifiable*: std ``inf``, interval
``nan``). ``sigma`` is absolute, so the covariance is *not* scaled by the reduced chi-square by
default (normal quantile); ``scale_covariance=True`` multiplies it by ``max(1, reduced_chi2)``
(only ever widening) and uses Student's t with ``n_obs - n_params`` degrees of freedom, for a
sigma known only up to a factor.

Intervals at ``confidence``. By default the reported intervals are **profile-likelihood**
intervals (:func:`_profile_ci`): ``{k_i : min_others chi2 <= chi2_min + z^2}``, found on the
profile-t scale (Bates & Watts 1988) from the linearised end points, a few re-optimisations each.
The linearised intervals (:func:`linear_intervals`: ``k exp(+-z std/k)`` for springs,
``k +- z std`` otherwise) are always reported too, but they under-cover when a spring is weakly
determined: on the cube of Chapter 5 with 5 % noise and 10 load cases the y-plane springs have
20-40 % relative uncertainty and the estimator is far from normal (curved valleys, the bound at
0); over 400 replicates the log-space linearised interval covered ``ky12`` 88 % of the time
(outside the binomial band), the profile interval 94-95 % for every spring
(``tests/test_identification.py``; 92-94 % with another seed set: the profile likelihood ratio
of one spring has a mean of ~1.1 instead of 1 there, a small-sample effect). ``bootstrap=N``
(:func:`parametric_bootstrap`) adds a seeded parametric bootstrap (refits of data simulated from
the estimate with the declared sigma) with percentile intervals.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from blackbox.condensation import Response
from blackbox.fitting.statistics import covariance
from blackbox.identification.newton import _Fit, _newton
from blackbox.identification.problem import SPRING_FLOOR, _Problem

PROFILE_WIDTHS = 50.0               # other parameters: up to 50 linearised half-widths
PROFILE_SPAN = 1e6                  # a spring's profile is searched up to 1e6 x its joint's stiffest
PROFILE_TAU_RTOL = 1e-2             # end points to 1% of the profile-t level (coverage +-0.001)


def _covariance(prob: _Problem, k: np.ndarray, resp: Response, rank_rtol: float):
    """``(J^T V_m^-1 J)^+`` in the natural parameters (columns scaled by :meth:`_Problem.scale`);
    returns ``(cov, identifiable, rank)``."""
    c = covariance(prob.jacobian_k(k, resp) * prob.w[:, None], prob.scale(k), rank_rtol)
    return c.cov, c.identifiable, c.rank


def linear_intervals(k: np.ndarray, std: np.ndarray, z: float, log_mask: np.ndarray,
                     ident: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linearised intervals ``(n_params, 2)`` (``k exp(+-z std/k)`` for springs, in log k;
    ``k +- z std`` otherwise; ``nan`` where not identifiable) and the half-widths ``z std / k``
    (springs) or ``z std`` (others), the profile search's first trial."""
    lin = np.full((k.size, 2), np.nan)
    lg = log_mask
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        half = z * std / np.where(lg, k, 1.0)                # in log k for springs, else in k
        lin[lg & ident] = k[lg & ident, None] * np.exp(np.outer(half[lg & ident], [-1.0, 1.0]))
        lin[~lg & ident] = k[~lg & ident, None] + np.outer(half[~lg & ident], [-1.0, 1.0])
    return lin, half


def _bootstrap_refits(ys: Sequence[np.ndarray], shared: tuple) -> list[np.ndarray | None]:
    """Refits of the bootstrap data ``ys`` from the estimate (``shared = (prob, phi,
    max_iterations, xtol, ftol)``), where the task runs; ``None``: that refit did not converge."""
    prob, phi, max_iterations, xtol, ftol = shared
    out = []
    for y in ys:
        b = _newton(prob, phi, y=y, max_iterations=int(max_iterations), xtol=xtol, ftol=ftol)
        out.append(b.k if b.status in (1, 2, 3) else None)
    return out


def parametric_bootstrap(prob: _Problem, fit: _Fit, f: np.ndarray, n: int, seed: int, max_iterations: int,
                         xtol: float, ftol: float, executor=None) -> np.ndarray:
    """``n`` refits (from the estimate) of data simulated from the prediction ``f`` with the
    declared sigma (``numpy.random.default_rng(seed)``, one draw per replicate in order); the
    converged estimates, one per row, in replicate order. ``executor`` (an object with
    ``workers``, ``share`` and ``map_shared``, e.g. :class:`blackbox.parallel.DaskExecutor`):
    the refits in contiguous chunks (4 per worker), the problem and the estimate sent to each
    worker once; every refit is the serial one from the same start and data, so the samples
    are the serial ones."""
    rng = np.random.default_rng(seed)
    ys = [f + prob.sigma * rng.standard_normal(len(f)) for _ in range(int(n))]
    shared = (prob, fit.phi, int(max_iterations), xtol, ftol)
    workers = getattr(executor, "workers", 1) if executor is not None else 1
    if workers <= 1 or len(ys) < 2:
        ks = _bootstrap_refits(ys, shared)
    else:
        parts = np.array_split(np.arange(len(ys)), min(len(ys), 4 * workers))
        with executor.share(shared) as handle:
            done = executor.map_shared(_bootstrap_refits, handle, [[ys[i] for i in idx] for idx in parts])
        ks = [k for part in done for k in part]
    samples = [k for k in ks if k is not None]
    return np.array(samples).reshape(-1, prob.p)


def _root_through_origin(p1: tuple[float, float], p2: tuple[float, float], level: float) -> float:
    """Where ``tau(h) = level`` for ``tau = a h + b h^2`` through ``(0, 0)``, ``p1``, ``p2``
    (the secant of ``p1, p2`` when ``p1`` is the origin or the parabola has no root beyond 0)."""
    (h1, t1), (h2, t2) = p1, p2
    if not (np.isfinite(t1) and np.isfinite(t2)) or h1 == h2:
        return np.nan
    if h1 > 0.0:
        det = h1 * h2 * (h2 - h1)
        a = (t1 * h2 * h2 - t2 * h1 * h1) / det
        b = (t2 * h1 - t1 * h2) / det
        if b != 0.0:
            disc = a * a + 4.0 * b * level
            if disc >= 0.0:
                roots = [(-a + sgn * math.sqrt(disc)) / (2.0 * b) for sgn in (1.0, -1.0)]
                roots = [x for x in roots if x > 0.0]
                if roots:
                    return min(roots, key=lambda x: abs(x - h2))
    return h2 + (level - t2) * (h2 - h1) / (t2 - t1) if t2 != t1 else np.nan


def _profile_ci(prob: _Problem, fit: _Fit, i: int, delta: float, half_width: float,
                xtol: float, ftol: float) -> tuple[float, float]:
    """Profile-likelihood interval of parameter ``i``: where the profile ``min chi2`` with
    ``phi_i`` fixed (the others re-optimised, warm-started from the nearest solved point)
    reaches ``chi2_min + delta``. Searched in ``phi`` (log k for springs, the entries of ``K_C``
    for the complex model: :meth:`_Problem.natural`) on the profile-t
    scale ``tau = sqrt(chi2_profile - chi2_min)`` (Bates & Watts 1988, ch. 6), which is linear
    in ``phi`` when the model is: the first trial is the linearised end point ``half_width``
    (at most a factor 10 for a spring) and a secant on ``tau`` usually ends the search in 2-3
    profiles. A side where the profile stays below the level is unbounded: ``inf``, or ``0`` for
    the lower end of a spring (springs are searched down to the floor and up to
    :data:`PROFILE_SPAN` times the joint's stiffest spring, other parameters over
    :data:`PROFILE_WIDTHS` linearised half-widths)."""
    prob = prob.natural()                             # k_i must be a coordinate
    phi_fit = prob.to_phi(fit.k)
    free = np.ones(prob.p, dtype=bool)
    free[i] = False
    tau_star = math.sqrt(delta)
    phi_hat = float(phi_fit[i])
    ends = []
    for side in (-1.0, 1.0):
        solved = {0.0: phi_fit}

        def tau(h: float) -> float:
            near = min(solved, key=lambda u: abs(u - h))
            phi = solved[near].copy()
            phi[i] = phi_hat + side * h
            if not prob.admissible(prob.to_k(phi)):
                return np.inf
            sub = _newton(prob, phi, free=free, max_iterations=50, xtol=max(xtol, 1e-6), ftol=max(ftol, 1e-8))
            solved[h] = sub.phi
            return math.sqrt(max(sub.chi2 - fit.chi2, 0.0))

        lo, hi = 0.0, np.inf                          # tau(lo) < tau_star <= tau(hi)
        h = half_width if np.isfinite(half_width) and half_width > 0 else 1.0
        if prob.log_mask[i]:                          # springs: from the floor to 1e6 x the stiffest
            floor = prob.floor_value(fit.k)[i]
            top = floor / SPRING_FLOOR                # the stiffest spring of the joint
            limit = math.log(fit.k[i] / floor) if side < 0 else math.log(PROFILE_SPAN * top / fit.k[i])
            h = min(h, math.log(10.0))                # the first crossing, not a far one:
            max_stride = math.log(10.0)               # a decade at a time
            if limit <= 1e-9:
                ends.append(-np.inf)                  # at the floor: the lower end is 0
                continue
        else:
            limit, max_stride = PROFILE_WIDTHS * h, np.inf
        h = min(h, limit)
        result = np.inf
        prev = (0.0, 0.0)                             # the last evaluated point, for the secant
        for _ in range(30):
            t = tau(h)
            if abs(t - tau_star) <= PROFILE_TAU_RTOL * tau_star:
                result = h
                break
            if t < tau_star:
                lo = h
            else:
                hi = h
            if np.isfinite(hi) and hi - lo <= PROFILE_TAU_RTOL * min(half_width, h):
                result = 0.5 * (lo + hi)
                break
            # tau(0) = 0: the parabola through 0 and the last two points, else their secant ...
            h_new = _root_through_origin(prev, (h, t), tau_star)
            prev = (h, t)
            if np.isfinite(hi):                       # ... kept inside the bracket
                h = h_new if lo < h_new < hi else 0.5 * (lo + hi)
            else:                                     # ... or a bounded extrapolation
                if lo >= limit:
                    break                             # flat: unbounded on this side
                h_new = 1.05 * h_new if np.isfinite(h_new) else 4.0 * lo
                h = min(max(h_new, 1.1 * lo), 4.0 * lo, limit, lo + max_stride)
        ends.append(phi_hat + side * result)
    out = np.array(ends)
    if prob.log_mask[i]:
        with np.errstate(over="ignore"):
            return float(np.exp(out[0])), float(np.exp(out[1]))
    return float(out[0]), float(out[1])
