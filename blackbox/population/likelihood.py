"""One specimen's likelihood for one joint parameter, and its integral against the population.

For a spring ``k`` the coordinate is ``theta = log k``. A specimen's evidence about ``theta`` is
its *profile likelihood* ``L(theta) = exp(-r(theta)^2 / 2)`` (``r``: the signed root of
``chi2_profile(theta) - chi2_min``, the other parameters of the specimen re-optimised), scaled to
1 at the specimen's own estimate. Two forms:

* :class:`GaussianLikelihood` ``(m, c)``: ``r = (theta - m) / c``, the quadratic approximation at
  the estimate (``c`` = the linearised standard deviation of ``log k``), used where the exact
  profile is quadratic (checked, :mod:`blackbox.population.specimen`);
* :class:`TabulatedLikelihood`: the exact profile tabulated at nodes, ``L`` linear between the
  nodes; beyond the last node on each side ``|r|`` continues linearly with the last slope
  (a Gaussian tail) or stays at its last value (a side the data leave open: a flat likelihood).

The hierarchical model draws ``theta`` of every specimen from ``N(mu, tau^2)``; what the
population fit needs of a specimen is

    I(mu, tau) = integral L(theta) phi(theta; mu, tau^2) d theta

(the specimen's marginal likelihood of the population parameters, up to a constant). Both forms
give it in closed form for any ``tau >= 0``: the Gaussian form directly, the tabulated one as a
sum over the nodes' intervals of ``(a + b theta) phi`` integrals and two Gaussian-tail integrals.
:meth:`log_integral` takes arrays of ``mu`` and ``tau`` (broadcast) and returns ``log I``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

__all__ = ["GaussianLikelihood", "TabulatedLikelihood", "TabulatedStack", "SpecimenLikelihood", "TAU_MIN"]

TAU_MIN = 1e-9
"""``tau`` below this is taken as this (a point mass, to far below any spread of interest)."""

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def _tail_log_integral(r0: float, slope: float, mu_local: np.ndarray, tau: np.ndarray, side: int) -> np.ndarray:
    """``log integral exp(-(r0 + slope * side * x)^2 / 2) phi(x; mu_local, tau^2) dx`` over
    ``x <= 0`` (``side = -1``, the left tail) or ``x >= 0`` (``side = +1``): ``|r|`` grows by
    ``slope`` per unit of distance from the tail's anchor (0 here). The exponent
    ``alpha + beta x`` with ``alpha = r0``, ``beta = side * slope``; the product with the Gaussian
    is a Gaussian of precision ``P = beta^2 + 1/tau^2``."""
    beta = side * slope
    q = 1.0 + beta * beta * tau * tau
    M = (mu_local - r0 * beta * tau * tau) / q
    sdP = tau / np.sqrt(q)                         # 1 / sqrt(P)
    z = side * M / sdP                             # P(x >= 0) = Phi(M sqrt P); P(x <= 0) = Phi(-M sqrt P)
    return -0.5 * (r0 + beta * mu_local) ** 2 / q - 0.5 * np.log(q) + special.log_ndtr(z)


class SpecimenLikelihood:
    """A specimen's likelihood of one parameter ``theta = log k`` (scaled to 1 at its maximum)."""
    m: float                # where it is largest (the specimen's estimate)
    c: float                # a Gaussian-equivalent standard deviation (inf: no information)
    exact: bool             # True: the tabulated profile; False: the quadratic approximation

    def log_integral(self, mu, tau) -> np.ndarray:
        raise NotImplementedError

    def log_value(self, theta) -> np.ndarray:
        """``log L(theta)``."""
        raise NotImplementedError

    @property
    def informative(self) -> bool:
        return bool(np.isfinite(self.c))


@dataclass(frozen=True)
class GaussianLikelihood(SpecimenLikelihood):
    """``L = exp(-(theta - m)^2 / (2 c^2))``."""
    m: float
    c: float
    exact: bool = False

    def log_integral(self, mu, tau) -> np.ndarray:
        tau = np.maximum(np.asarray(tau, float), TAU_MIN)
        v = self.c * self.c + tau * tau
        return math.log(self.c) - 0.5 * np.log(v) - 0.5 * (self.m - np.asarray(mu, float)) ** 2 / v

    def log_value(self, theta) -> np.ndarray:
        return -0.5 * ((np.asarray(theta, float) - self.m) / self.c) ** 2


@dataclass(frozen=True, eq=False)
class TabulatedLikelihood(SpecimenLikelihood):
    """``L`` at ascending ``nodes`` (``log_L`` <= 0), linear between them; outside, ``|r|``
    continues from the end value with ``left_slope`` / ``right_slope`` per unit of ``theta`` (0:
    flat, the data leave that side open)."""
    nodes: np.ndarray
    log_L: np.ndarray
    left_slope: float
    right_slope: float
    m: float
    c: float
    exact: bool = True

    @property
    def informative(self) -> bool:
        return True                     # a flat profile is not tabulated (no information)

    def __post_init__(self):
        t = np.asarray(self.nodes, float)
        g = np.asarray(self.log_L, float)
        if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0) or g.shape != t.shape:
            raise ValueError("a tabulated likelihood needs >= 2 ascending nodes and one value each")
        object.__setattr__(self, "nodes", t)
        object.__setattr__(self, "log_L", np.minimum(g, 0.0))
        L = np.exp(self.log_L)
        object.__setattr__(self, "_L", L)
        object.__setattr__(self, "_b", np.diff(L) / np.diff(t))          # slope of L per interval
        object.__setattr__(self, "_r_ends", (math.sqrt(-2.0 * self.log_L[0]), math.sqrt(-2.0 * self.log_L[-1])))

    def log_value(self, theta) -> np.ndarray:
        th = np.asarray(theta, float)
        t = self.nodes
        inside = np.interp(th, t, self._L)
        r0, rn = self._r_ends
        left = -0.5 * (r0 + self.left_slope * (t[0] - th)) ** 2
        right = -0.5 * (rn + self.right_slope * (th - t[-1])) ** 2
        with np.errstate(divide="ignore"):
            return np.where(th < t[0], left, np.where(th > t[-1], right, np.log(inside)))

    def log_integral(self, mu, tau) -> np.ndarray:
        mu, tau = np.broadcast_arrays(np.asarray(mu, float), np.maximum(np.asarray(tau, float), TAU_MIN))
        shape = mu.shape
        mu, tau = mu.reshape(-1), tau.reshape(-1)
        t = self.nodes
        z = (t[:, None] - mu[None, :]) / tau[None, :]                     # (n, P)
        Phi = special.ndtr(z)
        phi = np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
        dPhi = np.diff(Phi, axis=0)
        dphi = np.diff(phi, axis=0)
        # interval i: L = L_i + b_i (theta - t_i); integral of theta phi = mu dPhi - tau dphi
        inner = (self._L[:-1, None] * dPhi
                 + self._b[:, None] * ((mu[None, :] - t[:-1, None]) * dPhi - tau[None, :] * dphi)).sum(axis=0)
        r0, rn = self._r_ends
        left = _tail_log_integral(r0, self.left_slope, mu - t[0], tau, -1)
        right = _tail_log_integral(rn, self.right_slope, mu - t[-1], tau, +1)
        with np.errstate(divide="ignore"):
            out = np.logaddexp(np.log(np.maximum(inner, 0.0)), np.logaddexp(left, right))
        return out.reshape(shape)


class TabulatedStack:
    """Several tabulated likelihoods with the same number of nodes, evaluated together (one set
    of array operations for all of them): :meth:`log_integral` takes ``mu`` and ``tau`` of shape
    ``(n_likelihoods, P)`` (or broadcastable) and returns ``log I`` of each at each pair."""

    def __init__(self, liks: "list[TabulatedLikelihood]"):
        self.t = np.stack([L.nodes for L in liks])                         # (T, n)
        self.L = np.stack([L._L for L in liks])
        self.b = np.stack([L._b for L in liks])
        self.r0 = np.array([L._r_ends[0] for L in liks])[:, None]
        self.rn = np.array([L._r_ends[1] for L in liks])[:, None]
        self.sl = np.array([L.left_slope for L in liks])[:, None]
        self.sr = np.array([L.right_slope for L in liks])[:, None]

    def log_integral(self, mu, tau) -> np.ndarray:
        T = self.t.shape[0]
        mu = np.broadcast_to(np.asarray(mu, float), (T,) + np.shape(mu)[-1:]) if np.ndim(mu) <= 1 \
            else np.asarray(mu, float)
        tau = np.maximum(np.broadcast_to(np.asarray(tau, float), mu.shape), TAU_MIN)
        t = self.t
        z = (t[:, :, None] - mu[:, None, :]) / tau[:, None, :]            # (T, n, P)
        Phi = special.ndtr(z)
        phi = np.exp(-0.5 * z * z)
        dPhi = np.diff(Phi, axis=1)
        dphi = np.diff(phi, axis=1) / math.sqrt(2.0 * math.pi)
        inner = (self.L[:, :-1, None] * dPhi
                 + self.b[:, :, None] * ((mu[:, None, :] - t[:, :-1, None]) * dPhi - tau[:, None, :] * dphi)).sum(axis=1)
        left = _tail_log_integral(self.r0, self.sl, mu - t[:, :1], tau, -1)
        right = _tail_log_integral(self.rn, self.sr, mu - t[:, -1:], tau, +1)
        with np.errstate(divide="ignore"):
            return np.logaddexp(np.log(np.maximum(inner, 0.0)), np.logaddexp(left, right))
