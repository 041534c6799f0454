"""The population of one joint parameter: centre, spread and their intervals (a random-effects model).

Every specimen ``s`` has its own ``theta_s = log k_s``, drawn from ``N(mu, tau^2)``: a log-normal
population of ``k`` whose median ``exp(mu)`` is the *centre* and whose coefficient of variation
``sqrt(exp(tau^2) - 1)`` is the *spread*. What specimen ``s`` measured enters through its
likelihood of ``theta`` (:mod:`blackbox.population.likelihood`: the exact profile likelihood from
its condensed model, or its quadratic approximation where that was checked to be exact enough),
so the specimen's marginal likelihood of the population parameters is

    I_s(mu, tau) = integral L_s(theta) phi(theta; mu, tau^2) d theta,   l(mu, tau) = sum_s log I_s.

Only *informative* specimens enter: a specimen whose data say nothing about the parameter has a
constant likelihood; it is left out and not counted in ``S``, the number of specimens.

The estimator is the random-effects meta-analysis that the methods reviews recommend for few
studies (Veroniki et al. 2016, *Res. Synth. Methods* 7:55; Langan et al. 2019, *Res. Synth.
Methods* 10:83), written with each specimen's exact likelihood in place of a normal estimate:

* the **deviance** of a common centre at spread ``tau``:

      D(tau) = 2 sum_s [max_u log I_s(u, tau) - log I_s(mu_hat(tau), tau)],

  ``mu_hat(tau)`` maximising ``l(., tau)``. For Gaussian likelihoods ``D`` is Cochran's generalised
  ``Q(tau^2) = sum_s (m_s - mu_hat)^2 / (c_s^2 + tau^2)``, exactly ``chi2(S - 1)`` at the true
  ``tau`` whatever the specimens' precisions (Viechtbauer 2007, *Stat. Med.* 26:37);
* **spread**: the Paule-Mandel estimate ``D(tau) = S - 1`` (0 when ``D(0) <= S - 1``) and the
  **Q-profile interval** ``chi2_{S-1}(a/2) <= D(tau) <= chi2_{S-1}(1 - a/2)`` (exact for Gaussian
  likelihoods; its lower end is 0 when ``tau = 0`` is inside, and the whole interval is
  ``[0, 0]`` when the specimens agree even better than their noise says they should);
* **centre**: ``mu_hat(tau_hat)`` and the **Hartung-Knapp** interval, here
  ``2 (l(mu_hat, tau_hat) - l(mu, tau_hat)) <= q t_nu^2`` with ``q = D(tau_hat) / (S - 1)``:
  for Gaussian likelihoods ``mu_hat +- t_nu sqrt(q / sum_s w_s)``, ``w_s = 1 / (c_s^2 + tau^2)``
  (Hartung & Knapp 2001, *Stat. Med.* 20:3875; Sidik & Jonkman 2002). Its degrees of freedom
  are ``nu = (S - 1) n_eff / S`` with Kish's effective number of specimens
  ``n_eff = (sum w)^2 / sum w^2``: ``S - 1`` when the specimens are equally well measured (then
  the interval is exactly Student's t), fewer when a few precise specimens carry the weighted
  mean. With ``nu = S - 1`` throughout, the interval covered 89-91 % instead of 95 % when the
  specimens' standard deviations differed twentyfold (``c`` uniform on 0.02-0.4, ``tau = 0.2``,
  4-8 specimens, Gaussian likelihoods, 4000 replicates); with ``nu`` it covered 95-97 %, and 95 %
  within the binomial band wherever the precisions are equal (docs/population.md).

The exact likelihood matters where a normal approximation of a specimen's estimate would not
average out: a weakly determined spring has a skewed likelihood in ``log k`` whose maximum is a
biased estimate, and with many specimens the centre's interval becomes narrower than that bias.
Integrating the likelihood instead of using its maximum removes it.

Also here: the per-parameter test of "the specimens share one value" (``D(0)``, Cochran's ``Q``
generalised: the likelihood ratio of the common-value fit, the specimen's other parameters free,
against each specimen's own fit, ``chi2(S - 1)``), each specimen's estimate shrunk toward the
population (:func:`shrink`) and the leave-one-out test of a specimen that does not belong
(:func:`leave_one_out`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import optimize, special

from blackbox.population.likelihood import GaussianLikelihood, SpecimenLikelihood, TabulatedLikelihood, TabulatedStack

__all__ = ["ParameterPopulation", "fit_parameter", "shrink", "leave_one_out", "LeaveOneOut", "cv_of_tau",
           "TAU_CAP"]

TAU_CAP = 5.0
"""A spread beyond ``tau = 5`` (a coefficient of variation of ``e^12.5``) is "not bounded"."""


def cv_of_tau(tau):
    """Coefficient of variation of a log-normal population with log-standard deviation ``tau``."""
    tau = np.asarray(tau, float)
    with np.errstate(over="ignore"):
        return np.sqrt(np.expm1(tau * tau))


@dataclass(frozen=True, eq=False)
class ParameterPopulation:
    """The population of one parameter, in ``theta = log k`` (``nan``: not determined; an open
    end of an interval is ``-inf``/``inf``)."""
    n_specimens: int                    # informative specimens (S)
    mu: float
    mu_ci: tuple[float, float]
    tau: float                          # Paule-Mandel
    tau_ci: tuple[float, float]         # Q-profile
    q: float                            # Hartung-Knapp factor D(tau) / (S - 1)
    common_statistic: float             # D(0): do the specimens share one value?
    common_p: float
    informative: tuple[bool, ...]       # per specimen given
    notes: tuple[str, ...] = ()
    dof: float = math.nan               # of the centre's t quantile
    model: "_Model | None" = field(default=None, repr=False)

    @property
    def determined(self) -> bool:
        return self.n_specimens >= 2 and all(np.isfinite(self.mu_ci)) and np.isfinite(self.tau_ci[1])

    @property
    def centre(self) -> float:
        return math.exp(self.mu) if np.isfinite(self.mu) else math.nan

    @property
    def centre_ci(self) -> tuple[float, float]:
        return tuple(float(np.exp(v)) if not np.isnan(v) else math.nan for v in self.mu_ci)

    @property
    def spread(self) -> float:
        return float(cv_of_tau(self.tau))

    @property
    def spread_ci(self) -> tuple[float, float]:
        return tuple(float(cv_of_tau(v)) for v in self.tau_ci)


class _Model:
    """``l(mu, tau)``, ``mu_hat(tau)`` and ``D(tau)`` of the informative specimens."""

    def __init__(self, liks: Sequence[SpecimenLikelihood]):
        self.liks = list(liks)
        self.S = len(self.liks)
        self.gaussian = all(isinstance(L, GaussianLikelihood) for L in self.liks)
        self.m = np.array([L.m for L in self.liks], float)
        self.c = np.array([L.c for L in self.liks], float)
        self.logc = np.log(self.c)
        self.g = np.array([isinstance(L, GaussianLikelihood) for L in self.liks], dtype=bool)
        tab = [L for L in self.liks if isinstance(L, TabulatedLikelihood)]
        sizes = sorted({L.nodes.size for L in tab})
        self.tab = tab
        self.stacks = [TabulatedStack([L for L in tab if L.nodes.size == n]) for n in sizes]
        spread = float(np.std(self.m)) if self.S > 1 else 0.0
        self.scale = max(spread, float(np.median(self.c)), 1e-6)
        self._sat: dict[float, float] = {}
        self._dev: dict[float, float] = {}
        self._grid = None

    def loglik(self, mu, tau) -> np.ndarray:
        """``l(mu, tau)`` for arrays ``mu``, ``tau`` (broadcast)."""
        mu, tau = np.broadcast_arrays(np.asarray(mu, float), np.asarray(tau, float))
        shape = mu.shape
        mu, tau = mu.reshape(-1), np.maximum(tau.reshape(-1), 1e-9)
        g = self.g
        v = self.c[g, None] ** 2 + tau[None, :] ** 2
        out = (self.logc[g, None] - 0.5 * np.log(v) - 0.5 * (self.m[g, None] - mu[None, :]) ** 2 / v).sum(axis=0)
        for stack in self.stacks:
            out = out + stack.log_integral(mu, tau).sum(axis=0)
        return out.reshape(shape)

    def _stack_members(self):
        sizes = sorted({L.nodes.size for L in self.tab})
        return [[L for L in self.tab if L.nodes.size == n] for n in sizes]

    def weights(self, tau: float) -> np.ndarray:
        return 1.0 / (self.c ** 2 + tau * tau)

    def mu_hat(self, tau: float) -> float:
        w = self.weights(tau)
        guess = float(np.sum(w * self.m) / np.sum(w))
        if self.gaussian:
            return guess
        se = math.sqrt(1.0 / np.sum(w))
        return _grid_max(lambda u: self.loglik(u, np.full(u.shape, tau)), guess, 6.0 * se + 2.0 * self.scale)[0]

    def saturated(self, tau: float) -> float:
        """``sum_s max_u log I_s(u, tau)`` (each specimen with its own centre)."""
        if tau in self._sat:
            return self._sat[tau]
        t = max(tau, 1e-9)
        if self.gaussian:
            out = float(np.sum(self.logc - 0.5 * np.log(self.c ** 2 + t * t)))
        else:
            g = self.g
            out = float(np.sum(self.logc[g] - 0.5 * np.log(self.c[g] ** 2 + t * t)))
            for stack, tabs in zip(self.stacks, self._stack_members()):
                # every tabulated specimen's own maximum over u, all at once: a grid about its
                # estimate, a finer one about the best node, a parabola
                m = np.array([L.m for L in tabs])[:, None]
                # a likelihood open on one side (flat to the end of the spring's range) has its
                # own centre searched about its estimate only: the flat side would let it move
                # off to where no population of finite spread puts the others
                open_ = np.array([L.left_slope == 0.0 or L.right_slope == 0.0 for L in tabs])
                half = (3.0 * np.minimum([L.c for L in tabs], 10.0) + np.where(open_, 0.0, 3.0 * t))[:, None]
                u = m + half * np.linspace(-1.0, 1.0, 25)[None, :]
                v = stack.log_integral(u, t)
                i = np.clip(np.argmax(v, axis=1), 1, 23)
                h = (u[:, 1] - u[:, 0])
                u2 = u[np.arange(len(tabs)), i][:, None] + h[:, None] * np.linspace(-1.0, 1.0, 11)[None, :]
                v2 = stack.log_integral(u2, t)
                out += float(np.sum(np.max(np.concatenate([v, v2], axis=1), axis=1)))
        self._sat[tau] = out
        return out

    def deviance(self, tau: float) -> float:
        tau = float(tau)
        if tau not in self._dev:
            u = self.mu_hat(tau)
            self._dev[tau] = max(2.0 * (self.saturated(tau) - float(self.loglik(u, tau))), 0.0)
        return self._dev[tau]

    def tau_at(self, level: float, hint: float | None = None) -> float:
        """The ``tau`` where ``D(tau)`` falls to ``level`` (0 when ``D(0) <= level``; ``inf``
        when ``D`` stays above it up to :data:`TAU_CAP`): ``D`` decreases, so the root is
        bracketed -- on a grid of ``tau``, or by steps of a factor 2 from ``hint`` -- then Brent
        on ``D`` itself."""
        if self.deviance(0.0) <= level:
            return 0.0
        if hint is not None and 0.0 < hint < TAU_CAP:
            a = b = hint
            if self.deviance(hint) > level:
                while self.deviance(b) > level:
                    if b >= TAU_CAP:
                        return math.inf
                    a, b = b, min(2.0 * b, TAU_CAP)
            else:
                while a > 1e-6 * self.scale and self.deviance(a) <= level:
                    a, b = 0.5 * a, a
                if self.deviance(a) <= level:
                    a = 0.0
            return float(optimize.brentq(lambda t: self.deviance(t) - level, a, b, xtol=1e-6 * b, rtol=1e-6))
        if self._grid is None:
            taus = np.concatenate([[0.0], self.scale * np.geomspace(1e-2, 1e2, 11)])
            taus = np.unique(np.minimum(taus, TAU_CAP))
            self._grid = (taus, np.array([self.deviance(t) for t in taus]))
        taus, D = self._grid
        below = np.flatnonzero(D <= level)
        if below.size == 0:
            return math.inf
        i = int(below[0])
        return float(optimize.brentq(lambda t: self.deviance(t) - level, taus[i - 1], taus[i],
                                     xtol=1e-6 * taus[i], rtol=1e-6))


def _grid_max(f, centre: float, half: float, n: int = 25) -> tuple[float, float]:
    """``argmax, max`` of the smooth unimodal ``f`` (vectorised over an array) on
    ``centre +- half``: a grid, a finer grid about its best node, a parabola through the best
    three nodes (widened when the best node is at the edge)."""
    for _ in range(6):
        u = np.linspace(centre - half, centre + half, n)
        v = f(u)
        i = int(np.argmax(v))
        if 0 < i < n - 1:
            break
        centre, half = u[i], 2.0 * half
    step = u[1] - u[0]
    u = np.linspace(u[i] - step, u[i] + step, 9)
    v = f(u)
    i = int(np.clip(np.argmax(v), 1, 7))
    a, b, c = v[i - 1], v[i], v[i + 1]
    den = a - 2.0 * b + c
    h = u[1] - u[0]
    x = u[i] + (0.5 * h * (a - c) / den if den < 0.0 else 0.0)
    best = float(f(np.array([x]))[0])
    return (x, best) if best >= b else (float(u[i]), float(b))


def fit_parameter(liks: Sequence[SpecimenLikelihood], confidence: float = 0.95, *,
                  intervals: bool = True, tau_hint: float | None = None) -> ParameterPopulation:
    """The population of one parameter from each specimen's likelihood (``liks``, one per
    specimen, in order; the non-informative ones are left out and marked). ``intervals=False``:
    the estimates only (the intervals ``nan``), for the leave-one-out test."""
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    informative = tuple(bool(L.informative) for L in liks)
    use = [L for L, ok in zip(liks, informative) if ok]
    S = len(use)
    nan2 = (math.nan, math.nan)
    if S == 0:
        return ParameterPopulation(0, math.nan, nan2, math.nan, nan2, math.nan, math.nan, math.nan, informative,
                                   ("no specimen's data determine this parameter",))
    model = _Model(use)
    if S == 1:
        return ParameterPopulation(1, float(use[0].m), (-math.inf, math.inf), math.nan, (0.0, math.inf), math.nan,
                                   math.nan, math.nan, informative,
                                   ("only one specimen's data determine this parameter: its spread is unknown, "
                                    "so the centre has no interval",))
    notes: list[str] = []
    a = 1.0 - confidence
    D0 = model.deviance(0.0)
    common_p = float(special.chdtrc(S - 1, D0))

    # ---- spread: Paule-Mandel estimate, Q-profile interval ---------------------------------------
    tau_at = model.tau_at
    tau_hat = tau_at(S - 1.0, tau_hint)
    tau_lo = tau_at(special.chdtri(S - 1, a / 2.0)) if intervals else math.nan
    tau_hi = tau_at(special.chdtri(S - 1, 1.0 - a / 2.0)) if intervals else math.nan
    if not np.isfinite(tau_hi):
        notes.append("the data do not bound the spread from above")
    if tau_hi == 0.0:
        notes.append("the specimens agree more closely than their measurement noise explains "
                     f"(Q = {D0:.3g} for {S - 1} degrees of freedom): the spread interval is empty, "
                     "reported as [0, 0]; check the declared sigma")
    if not np.isfinite(tau_hat):
        return ParameterPopulation(S, math.nan, nan2, math.inf, (tau_lo, math.inf), math.nan, D0, common_p,
                                   informative, tuple(notes) + ("the spread is not bounded",))

    # ---- centre: maximum likelihood at tau_hat, Hartung-Knapp interval ---------------------------
    mu_hat = model.mu_hat(tau_hat)
    D_hat = model.deviance(tau_hat)
    q = D_hat / (S - 1.0)
    w = model.weights(tau_hat)
    n_eff = float(np.sum(w) ** 2 / np.sum(w * w))
    nu = max((S - 1.0) * n_eff / S, 1.0)
    t = special.stdtrit(nu, 1.0 - a / 2.0)
    level = q * t * t
    if not intervals:
        mu_ci = nan2
    elif model.gaussian:
        half = t * math.sqrt(q / float(np.sum(model.weights(tau_hat))))
        mu_ci = (mu_hat - half, mu_hat + half)
    else:
        l_hat = float(model.loglik(mu_hat, tau_hat))
        se = math.sqrt(1.0 / float(np.sum(model.weights(tau_hat))))

        def excess(u: float) -> float:
            return 2.0 * (l_hat - float(model.loglik(u, tau_hat))) - level

        ends = []
        for side in (-1.0, 1.0):
            step, prev = max(t * math.sqrt(q) * se, 1e-6), 0.0
            end = side * math.inf
            while step <= 1e3:
                if excess(mu_hat + side * step) >= 0.0:
                    lo, hi = sorted((mu_hat + side * prev, mu_hat + side * step))
                    end = float(optimize.brentq(excess, lo, hi, xtol=1e-10))
                    break
                prev, step = step, 2.0 * step
            ends.append(end)
        mu_ci = (ends[0], ends[1])
        if not all(np.isfinite(mu_ci)):
            notes.append("the data do not bound the centre on one side")
    return ParameterPopulation(S, mu_hat, mu_ci, tau_hat, (tau_lo, tau_hi), q, D0, common_p, informative,
                               tuple(notes), nu, model)


# --------------------------------------------------------------------------------------------
# each specimen under the population
# --------------------------------------------------------------------------------------------
def shrink(liks: Sequence[SpecimenLikelihood], pop: ParameterPopulation, confidence: float = 0.95,
           n_mu: int = 15, n_tau: int = 15) -> np.ndarray:
    """Each specimen's estimate shrunk toward the population: the median and the equal-tailed
    ``confidence`` interval of its ``theta`` given its own likelihood and the population
    ``N(mu, tau^2)``, averaged over ``(mu, tau)`` with the weight ``exp(l(mu, tau))`` (flat priors
    on ``mu`` and on ``tau``: the uniform prior on the spread that Gelman 2006, *Bayesian Anal.*
    1:515, recommends for a hierarchical model of a few groups) on a grid over the centre's
    interval (widened by half its width each side) and ``0 <= tau <= 1.5 x`` the upper end of the
    spread's 99 % interval. A specimen whose data say nothing about the parameter gets the
    population's prediction for a new specimen. Returns ``(n_specimens, 3)``: median, low, high
    (``nan`` when the population is not determined)."""
    out = np.full((len(liks), 3), np.nan)
    use = [L for L in liks if L.informative]
    S = len(use)
    if S < 2 or not np.isfinite(pop.tau) or not all(np.isfinite(pop.mu_ci)):
        return out
    model = pop.model if pop.model is not None else _Model(use)
    level = special.chdtri(S - 1, 0.995)
    t_top = model.tau_at(level)
    t_top = 1.5 * max(min(t_top, TAU_CAP), pop.tau, 1e-3)
    width = pop.mu_ci[1] - pop.mu_ci[0]
    mg = np.linspace(pop.mu_ci[0] - 0.5 * width, pop.mu_ci[1] + 0.5 * width, n_mu)
    tg = np.linspace(0.0, t_top, n_tau)
    MU, TA = np.meshgrid(mg, tg, indexing="ij")
    mus, taus = MU.ravel(), TA.ravel()
    ll = model.loglik(mus, taus)
    w = np.exp(ll - ll.max())
    keep = w > 1e-8 * w.max()
    mus, taus, w = mus[keep], taus[keep], w[keep] / w[keep].sum()
    tt = np.maximum(taus, 1e-9)
    a = (1.0 - confidence) / 2.0
    for i, L in enumerate(liks):
        if isinstance(L, GaussianLikelihood) or not L.informative:
            out[i] = _gaussian_mixture_quantiles(L, mus, tt, w, (0.5, a, 1.0 - a))
            continue
        c = min(L.c, 10.0)
        lo = min(L.m - 6.0 * c, float(np.min(mus - 6.0 * tt)))
        hi = max(L.m + 6.0 * c, float(np.max(mus + 6.0 * tt)))
        n = 600
        th = np.linspace(lo, hi, n)
        logL = L.log_value(th)
        # the conditional posterior of theta at every node, normalised, mixed with the weights w;
        # a node with tau below the grid step is a point mass at its mu
        lp = logL[None, :] - 0.5 * ((th[None, :] - mus[:, None]) / tt[:, None]) ** 2
        lp -= lp.max(axis=1, keepdims=True)
        p = np.exp(lp)
        point = tt < 2.0 * (th[1] - th[0])
        if np.any(point):
            p[point] = 0.0
            p[np.flatnonzero(point), np.clip(np.searchsorted(th, mus[point]), 0, n - 1)] = 1.0
        p /= p.sum(axis=1, keepdims=True)
        cdf = np.cumsum(w @ p)
        cdf /= cdf[-1]
        out[i] = np.interp([0.5, a, 1.0 - a], cdf, th)
    return out


def _gaussian_mixture_quantiles(L: SpecimenLikelihood, mus: np.ndarray, taus: np.ndarray, w: np.ndarray,
                                probs) -> np.ndarray:
    """Quantiles of ``sum_i w_i N(a_i, b_i^2)``, the posterior of a Gaussian likelihood ``(m, c)``
    (or of none) under the priors ``N(mus_i, taus_i^2)``."""
    if L.informative:
        prec = 1.0 / L.c ** 2 + 1.0 / taus ** 2
        a = (L.m / L.c ** 2 + mus / taus ** 2) / prec
        b = 1.0 / np.sqrt(prec)
    else:
        a, b = mus, taus
    x = np.linspace(float(np.min(a - 6.0 * b)), float(np.max(a + 6.0 * b)), 300)
    F = w @ special.ndtr((x[None, :] - a[:, None]) / b[:, None])
    out = []
    for p in probs:                                  # the grid bracket, then bisection
        j = int(np.clip(np.searchsorted(F, p), 1, x.size - 1))
        lo, hi = x[j - 1], x[j]
        for _ in range(12):
            mid = 0.5 * (lo + hi)
            if float(np.dot(w, special.ndtr((mid - a) / b))) < p:
                lo = mid
            else:
                hi = mid
        out.append(0.5 * (lo + hi))
    return np.array(out)


@dataclass(frozen=True)
class LeaveOneOut:
    """Specimen ``index`` against the population of the others: the signed root of its deviance
    from their centre (``statistic``, Student's t with ``S - 2`` degrees of freedom for Gaussian
    likelihoods: the externally studentised residual of a meta-analysis, Viechtbauer & Cheung
    2010, *Res. Synth. Methods* 1:112), its two-sided ``p_value``, and the others' population."""
    index: int
    statistic: float
    p_value: float
    others: ParameterPopulation


def leave_one_out(liks: Sequence[SpecimenLikelihood], confidence: float = 0.95,
                  tau_hint: float | None = None) -> list[LeaveOneOut]:
    """For every informative specimen (when at least 3 are): is it one of the others' population?
    Its likelihood is compared with the others' predictive distribution ``N(mu_hat, tau_hat^2 +
    se^2)`` (``se``: the Hartung-Knapp standard error of their centre): the deviance
    ``2 (max_u log I(u, s) - log I(mu_hat, s))`` with ``s^2 = tau_hat^2 + se^2`` (for a Gaussian
    likelihood ``(m - mu_hat)^2 / (c^2 + tau_hat^2 + se^2)``), its signed root compared with
    ``t_{S-2}``."""
    idx = [i for i, L in enumerate(liks) if L.informative]
    S = len(idx)
    out: list[LeaveOneOut] = []
    if S < 3:
        return out
    for i in idx:
        others = [liks[j] for j in idx if j != i]
        pop = fit_parameter(others, confidence, intervals=False, tau_hint=tau_hint)
        if not (np.isfinite(pop.mu) and np.isfinite(pop.tau)):
            continue
        m_o = pop.model
        se = math.sqrt(pop.q / float(np.sum(m_o.weights(pop.tau))))
        s = math.sqrt(pop.tau ** 2 + se ** 2)
        single = _Model([liks[i]])
        d = max(2.0 * (single.saturated(s) - float(single.loglik(pop.mu, s))), 0.0)
        stat = math.copysign(math.sqrt(d), liks[i].m - pop.mu)
        out.append(LeaveOneOut(i, stat, float(2.0 * special.stdtr(S - 2, -abs(stat))), pop))
    return out
