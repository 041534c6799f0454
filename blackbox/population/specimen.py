"""One specimen: its estimate and, per parameter, its likelihood of ``log k`` (no solver run).

Everything here works on the specimen's condensed model (the one batched solver run of
:func:`blackbox.condensation.condense`): a prediction costs a ``n_B x n_B`` solve.

1. The maximum-likelihood estimate, as ``blackbox identify`` makes it
   (:func:`blackbox.identification.identify` without its profiles), with the covariance and the
   identifiability of every parameter.
2. Per parameter ``j`` the likelihood of ``theta_j = log k_j`` (:mod:`blackbox.population.likelihood`):

   * not identifiable from the specimen's data (a null-space direction of the Jacobian): no
     information, said so, and left out of that parameter's population;
   * otherwise the quadratic approximation ``(theta_hat_j, c_j)`` (``c_j`` the linearised
     standard deviation of ``log k_j``) is *checked* against the exact ``chi2`` along the
     linearised profile path ``theta_hat + t c_j C_{.j} / C_jj`` at ``t = +-1.5, +-3`` (4
     predictions): when the exact rise is ``t^2`` within :data:`QUADRATIC_RTOL` (as a signed
     root) the Gaussian form is kept;
   * else the exact **profile likelihood** is tabulated: ``chi2`` minimised over the other
     parameters (warm-started Gauss-Newton, :func:`blackbox.identification.newton._newton`) at
     offsets ``0.5 ... 7.5 c_j`` on each side and, where the profile stays low, at doubling
     distances up to the springs' floor or :data:`~blackbox.identification.uncertainty.PROFILE_SPAN`
     times the joint's stiffest spring. A side whose signed root never reaches
     :data:`R_TAIL` is *open* (the likelihood stays flat beyond it: the data do not bound the
     spring there). A profile that never reaches ``|r| = 1`` on either side carries no
     information either.

The specimen also keeps what the pooled test of :mod:`blackbox.population.fit` needs: its
``chi2``, the rank of its Jacobian and its problem (the condensed model and the observations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import interpolate

from blackbox.condensation import CondensedModel
from blackbox.errors import PopulationError
from blackbox.identification import Observations, identify
from blackbox.fitting.lm import MAX_LOG_STEP, solve_damped
from blackbox.identification.problem import SPRING_FLOOR, _Problem
from blackbox.identification.uncertainty import PROFILE_SPAN
from blackbox.population.likelihood import GaussianLikelihood, SpecimenLikelihood, TabulatedLikelihood

__all__ = ["SpecimenFit", "fit_specimen", "QUADRATIC_RTOL", "R_TAIL"]

QUADRATIC_RTOL = 0.05
"""The quadratic approximation is kept when the exact signed root at ``t = +-1.5, +-3`` linearised
standard deviations is ``|t|`` within 5 % (an interval end moves by at most ~5 % of its width)."""

R_TAIL = 6.0
"""A profile side is tabulated until its signed root reaches 6 (a likelihood ratio of e^-18);
beyond, it continues as a Gaussian tail with the last slope."""

_OFFSETS = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.5, 8.0)   # in linearised standard deviations, then doubling
_REFIT_ITERATIONS = 8
_CHECK_T = (-3.0, -1.5, 1.5, 3.0)
TABLE_NODES = 81
"""Nodes of a tabulated likelihood (equally spaced over its profile points; linear between)."""


@dataclass(frozen=True, eq=False)
class SpecimenFit:
    """A specimen's estimate and its likelihood of every parameter (``log k``)."""
    k: np.ndarray
    std_log: np.ndarray                 # linearised std of log k; inf where not identifiable
    identifiable: np.ndarray
    likelihoods: tuple[SpecimenLikelihood, ...]
    chi2: float
    n_obs: int
    rank: int
    converged: bool
    iterations: int
    reduced_chi2: float
    warnings: tuple[str, ...]
    refits: int                         # constrained refits of the tabulated profiles
    problem: _Problem = field(repr=False)

    @property
    def n_params(self) -> int:
        return int(self.k.size)

    def interval(self, j: int, z: float = 1.959963984540054) -> tuple[float, float]:
        """The specimen's own interval of ``k_j`` (its likelihood alone: ``|r| <= z``); ``nan``
        without information, ``0``/``inf`` for a side the data leave open."""
        L = self.likelihoods[j]
        if not L.informative:
            return (math.nan, math.nan)
        if isinstance(L, GaussianLikelihood):
            return (math.exp(L.m - z * L.c), math.exp(L.m + z * L.c))
        return tuple(_level_crossings(L, z))


def _level_crossings(L: TabulatedLikelihood, z: float) -> list[float]:
    """Where ``|r| = z`` on each side of the tabulated likelihood's maximum (as ``k``)."""
    level = -0.5 * z * z
    t, g = L.nodes, L.log_L
    i0 = int(np.argmax(g))
    out = []
    for side in (-1, 1):
        idx = range(i0, -1, -1) if side < 0 else range(i0, t.size)
        prev = None
        end = None
        for i in idx:
            if g[i] <= level:
                if prev is None:
                    end = t[i]
                else:                           # linear in log L between the two nodes
                    a, b = g[prev], g[i]
                    end = t[prev] + (t[i] - t[prev]) * (a - level) / (a - b)
                break
            prev = i
        if end is None:                         # beyond the nodes: the tail
            slope = L.left_slope if side < 0 else L.right_slope
            r_end = math.sqrt(-2.0 * g[0 if side < 0 else -1])
            if slope <= 0.0:
                out.append(0.0 if side < 0 else math.inf)
                continue
            end = (t[0] - (z - r_end) / slope) if side < 0 else (t[-1] + (z - r_end) / slope)
        out.append(math.exp(end))
    return out


def fit_specimen(model: CondensedModel, obs: Observations, k0, *, max_iterations: int = 50,
                 quadratic_rtol: float = QUADRATIC_RTOL) -> SpecimenFit:
    """The specimen's estimate and its likelihood of every parameter (module docstring).
    Every parameter must be a simple-model spring (``PopulationError`` names the one that is not)."""
    prob = _Problem(model, obs)
    if not np.all(prob.log_mask):
        bad = [f"{j}.{n}" for j, n, lg in zip(model.assembly.param_joint, model.assembly.param_names,
                                               prob.log_mask) if not lg]
        raise PopulationError(f"parameter(s) {bad[:6]} are not springs: the population models "
                              "simple-model springs (log-normal); declare model = \"simple\"")
    res = identify(model, obs, k0, profile=False, max_iterations=max_iterations)
    k = np.asarray(res.k, float)
    ident = np.asarray(res.identifiable, bool)
    p = k.size
    with np.errstate(invalid="ignore", divide="ignore"):
        C = res.covariance / np.outer(k, k)                     # covariance of log k
    std_log = np.where(ident, np.sqrt(np.abs(np.diag(C))), np.inf)
    theta = np.log(k)
    at_floor = prob.at_floor(k, 2.0 * SPRING_FLOOR)
    chi2_min = float(res.chi2)
    phi_fit = prob.to_phi(k)
    liks: list[SpecimenLikelihood] = []
    warnings = list(res.warnings)
    refits = 0
    Cs = np.where(np.isfinite(C), C, 0.0)
    for j in range(p):
        if not ident[j] and not at_floor[j]:
            liks.append(GaussianLikelihood(float(theta[j]), math.inf))
            continue
        c = float(std_log[j]) if np.isfinite(std_log[j]) and std_log[j] > 0 else 1.0
        if ident[j] and not at_floor[j] and _quadratic(prob, phi_fit, chi2_min, Cs, j, c, ident, quadratic_rtol):
            liks.append(GaussianLikelihood(float(theta[j]), c))
            continue
        path = np.where(ident, Cs[:, j] / Cs[j, j], 0.0) if ident[j] and Cs[j, j] > 0 else np.zeros(p)
        path[j] = 1.0
        L, n, failed = _tabulate(prob, phi_fit, k, chi2_min, j, c, path)
        refits += n
        if failed:
            warnings.append(f"{failed} profile refit(s) of {model.assembly.param_names[j]} did not converge; "
                            "their chi2 (an upper bound of the profile) is used")
        liks.append(L)
    return SpecimenFit(k, std_log, ident, tuple(liks), chi2_min, int(res.n_obs), int(res.rank),
                       bool(res.converged), int(res.iterations), float(res.reduced_chi2), tuple(warnings),
                       refits, prob)


def _quadratic(prob: _Problem, phi: np.ndarray, chi2_min: float, C: np.ndarray, j: int, c: float,
               ident: np.ndarray, rtol: float) -> bool:
    """Whether the exact ``chi2`` rises as ``t^2`` along the linearised profile path of ``j``."""
    d = np.where(ident, C[:, j] / C[j, j], 0.0) * c
    for t in _CHECK_T:
        ph = phi + t * d
        k = prob.to_k(ph)
        if not prob.admissible(k):
            return False
        f, _ = prob.predict(k)
        if not np.all(np.isfinite(f)):
            return False
        rise = prob.chi2(f) - chi2_min
        if not rise > 0.0 or abs(math.sqrt(rise) / abs(t) - 1.0) > rtol:
            return False
    return True


def _refit(prob: _Problem, phi: np.ndarray, free: np.ndarray, chi2_min: float) -> tuple[np.ndarray, float, bool]:
    """``chi2`` minimised over the ``free`` coordinates from ``phi`` (a point on the linearised
    profile path): Gauss-Newton with step halving, the minimum-norm step of
    :func:`blackbox.fitting.lm.solve_damped`, steps capped at a factor 100 per spring. It stops
    when a step lowers ``chi2`` by less than 1e-3 of its rise above ``chi2_min`` (the signed
    root is then right to ~1e-3 of itself: from the path one step usually suffices, the path
    being the profile to first order). Returns the end point, its ``chi2`` and whether it
    converged."""
    phi = phi.copy()
    k = prob.to_k(phi)
    f, resp = prob.predict(k)
    F = prob.chi2(f)
    w = prob.w
    for _ in range(_REFIT_ITERATIONS):
        J = prob.chain(prob.jacobian_k(k, resp), k)[:, free] * w[:, None]
        step = solve_damped(J, (prob.y - f) * w)
        big = float(np.max(np.abs(step), initial=0.0))
        if big > MAX_LOG_STEP:
            step *= MAX_LOG_STEP / big
        for alpha in (1.0, 0.5, 0.25, 0.125):
            trial = phi.copy()
            trial[free] += alpha * step
            k_t = prob.to_k(trial)
            if not prob.admissible(k_t):
                continue
            f_t, resp_t = prob.predict(k_t)
            F_t = prob.chi2(f_t) if np.all(np.isfinite(f_t)) else math.inf
            if F_t <= F:
                break
        else:
            return phi, F, True                 # no step lowers chi2: at the minimum to rounding
        done = F - F_t <= max(1e-3 * (F_t - chi2_min), 1e-9 * max(F_t, 1.0))
        phi, k, f, resp, F = trial, k_t, f_t, resp_t, F_t
        if done:
            return phi, F, True
    return phi, F, False


def _tabulate(prob: _Problem, phi_fit: np.ndarray, k: np.ndarray, chi2_min: float, j: int,
              c: float, path: np.ndarray) -> tuple[SpecimenLikelihood, int, int]:
    """The exact profile likelihood of ``log k_j``, tabulated (module docstring). Returns the
    likelihood, the number of refits and how many did not converge."""
    free = np.ones(prob.p, dtype=bool)
    free[j] = False
    floor = float(prob.floor_value(k)[j])
    top = floor / SPRING_FLOOR                                   # the joint's stiffest spring
    th0 = float(phi_fit[j])
    limits = {-1: th0 - math.log(max(floor, 1e-300)) if floor > 0 else 30.0,
              +1: math.log(PROFILE_SPAN * top) - th0}
    pts = {0.0: 0.0}
    n = failed = 0
    open_side = {}
    for side in (-1, 1):
        prev = phi_fit.copy()
        limit = limits[side]
        offsets = [h * c for h in _OFFSETS]
        h = offsets[-1]
        i = 0
        reached = False
        while True:
            if i < len(offsets):
                h = offsets[i]
            else:
                h *= 2.0
            i += 1
            h = min(h, limit)
            phi = phi_fit + side * h * path                 # the linearised profile path ...
            if not prob.admissible(prob.to_k(phi)):
                phi = prev.copy()                           # ... or the last profile point moved
                phi[j] = th0 + side * h
                if not prob.admissible(prob.to_k(phi)):
                    break
            phi, chi2, ok = _refit(prob, phi, free, chi2_min)
            n += 1
            failed += not ok
            prev = phi
            r = math.sqrt(max(chi2 - chi2_min, 0.0))
            pts[side * h] = side * r
            if r >= R_TAIL:
                reached = True
                break
            if h >= limit:
                break
        open_side[side] = not reached
    hs = np.array(sorted(pts))
    rs = np.array([pts[h] for h in hs])
    # |r| never falls going outward (a profile only rises away from its minimum; a refit that
    # stopped early could break that by a little)
    i0 = int(np.flatnonzero(hs == 0.0)[0])
    rs[i0:] = np.maximum.accumulate(np.maximum(rs[i0:], 0.0))
    rs[:i0 + 1] = -np.maximum.accumulate(np.maximum(-rs[:i0 + 1][::-1], 0.0))[::-1]
    thetas = th0 + hs
    if max(abs(rs[0]), abs(rs[-1])) < 1.0:
        return GaussianLikelihood(th0, math.inf), n, failed                 # flat: no information
    # r is smooth and monotone in theta: a cubic spline through the points, or the monotone cubic
    # (PCHIP) where the spline would not be monotone; the table's nodes go where L changes: equally spaced in r on each side (24 each), and equally spaced in
    # theta over the whole table (the rest), so a long open side does not thin out the peak
    fine = np.linspace(thetas[0], thetas[-1], 4001)
    r_fine = interpolate.CubicSpline(thetas, rs)(fine)
    if np.any(np.diff(r_fine) < 0.0):
        r_fine = interpolate.PchipInterpolator(thetas, rs)(fine)
    n_side = 24
    at_r = np.concatenate([np.interp(np.linspace(rs[0], 0.0, n_side + 1)[:-1], r_fine, fine), [th0],
                           np.interp(np.linspace(0.0, rs[-1], n_side + 1)[1:], r_fine, fine)])
    dense = np.sort(np.concatenate([at_r, np.linspace(thetas[0], thetas[-1], TABLE_NODES - at_r.size)]))
    gap = 1e-9 * max(thetas[-1] - thetas[0], 1e-12)
    dense = dense[0] + np.maximum.accumulate(dense - dense[0] + gap * np.arange(dense.size))
    r_dense = np.interp(dense, fine, r_fine)
    log_L = -0.5 * r_dense ** 2
    slopes = []
    for side, (a, b) in ((-1, (0, 1)), (1, (-1, -2))):
        if open_side[side]:
            slopes.append(0.0)
        else:
            slopes.append(abs(rs[a] - rs[b]) / abs(thetas[a] - thetas[b]))
    # a Gaussian-equivalent width (for scales and the effective number of specimens): half the
    # |r| <= 1 interval; a side open at |r| = 1 counts twice the other side's half
    lo = th0 - float(np.interp(-1.0, rs, thetas)) if rs[0] <= -1.0 else math.inf
    hi = float(np.interp(1.0, rs, thetas)) - th0 if rs[-1] >= 1.0 else math.inf
    c_eq = 0.5 * (lo + hi) if math.isfinite(lo) and math.isfinite(hi) else 2.0 * min(lo, hi)
    L = TabulatedLikelihood(dense, log_L, slopes[0], slopes[1], th0, float(c_eq))
    return L, n, failed
