"""Fit statistics of a weighted least-squares estimate with declared errors (Sec. 4.3-4.4).

The estimation model (eq. 21, 31) is ``y = f(k) + e``, ``e ~ N(0, V_m)``, ``V_m = diag(sigma^2)`` with
``sigma`` the declared, absolute measurement errors. At the estimate ``k^``:

* ``chi2 = sum r_i^2``, ``r = (y - f(k^)) / sigma`` (the standardized residuals); for a correct
  model and correct ``sigma``, ``chi2 ~ chi2(n - p)``, so the reduced chi-square
  ``chi2 / (n - p)`` is ~1 within :func:`chi2_band` and :func:`plausibility_warning` flags a value
  the declared ``sigma`` cannot explain;
* the log-likelihood ``-2 log L = chi2 + sum log(2 pi sigma_i^2)`` (the second term is constant
  for given data, so it cancels in every comparison of models on the same rows but makes the
  numbers comparable with other software's Gaussian likelihoods);
* ``AIC = -2 log L + 2 p`` and ``BIC = -2 log L + p log n`` (Akaike 1974; Schwarz 1978), the one
  definition used by the identification and the diagnosis;
* the covariance of the estimate ``(J^T V_m^-1 J)^-1`` (``J = df/dk``: the matrix of the weighted
  regression, eq. 28, at the optimum, from which Sec. 4.4 builds the confidence intervals) from a
  pivoted QR of the whitened Jacobian (:func:`covariance`), with its numerical rank and the
  parameters that are not identifiable (a component in the null space: standard deviation ``inf``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from blackbox.distributions import chi2_ppf, chi2_sf

__all__ = ["FitStatistics", "HoldoutStats", "Covariance", "covariance", "chi2_band", "plausibility_warning"]

NULL_TOL = 1e-6          # a null-space component above this makes a parameter unidentifiable
PLAUSIBLE_P = 1e-3       # chi2 with an upper-tail probability below this is implausible


@dataclass(frozen=True)
class FitStatistics:
    """lmfit's ``[[Fit Statistics]]`` for a Gaussian likelihood with known ``sigma``."""
    n_obs: int
    n_params: int
    chi2: float
    reduced_chi2: float          # nan without degrees of freedom
    rms_residual: float          # unweighted, measurement units
    aic: float
    bic: float

    @property
    def dof(self) -> int:
        return self.n_obs - self.n_params

    @classmethod
    def of(cls, y: np.ndarray, f: np.ndarray, sigma: np.ndarray, n_params: int,
           weights: np.ndarray | None = None) -> "FitStatistics":
        """From the data ``y``, the prediction ``f``, ``sigma`` (``weights = 1 / sigma`` if
        given, to reuse the exact array the fit used) and the number of fitted parameters."""
        w = 1.0 / sigma if weights is None else weights
        res = (y - f) * w
        chi2 = float(res @ res)
        n, p = len(y), int(n_params)
        dof = n - p
        red = chi2 / dof if dof > 0 else float("nan")
        m2logL = chi2 + float(np.sum(np.log(2.0 * np.pi * sigma ** 2)))
        rms = float(np.sqrt(np.mean((y - f) ** 2)))
        return cls(n, p, chi2, red, rms, m2logL + 2 * p, m2logL + p * math.log(n))


@dataclass(frozen=True, eq=False)
class HoldoutStats:
    """Prediction of held-out cases with the fitted parameters."""
    cases: tuple[str, ...]
    n_obs: int
    rms_error: float            # unweighted, measurement units
    chi2: float
    residuals: np.ndarray       # standardized, (measured - predicted) / sigma

    @classmethod
    def of(cls, cases, y: np.ndarray, f: np.ndarray, weights: np.ndarray) -> "HoldoutStats":
        rh = (y - f) * weights
        return cls(tuple(cases), len(y), float(np.sqrt(np.mean((y - f) ** 2))), float(rh @ rh), rh)


@dataclass(frozen=True, eq=False)
class Covariance:
    """``cov`` (nan rows and columns for a parameter that is not identifiable), ``std`` (``inf``
    there), the numerical ``rank`` of the whitened Jacobian and the ``identifiable`` mask."""
    cov: np.ndarray
    std: np.ndarray
    rank: int
    identifiable: np.ndarray


def covariance(J: np.ndarray, scale: np.ndarray | None = None, rank_rtol: float = 1e-8,
               null_tol: float = NULL_TOL) -> Covariance:
    """``(J^T J)^+`` of the whitened Jacobian ``J = V_m^-1/2 df/dk`` (Sec. 4.4).

    The columns are scaled by each parameter's size ``scale`` (default 1), then a pivoted QR
    ``J_s P = Q R`` (``scipy.linalg.qr(pivoting=True)``) gives the numerical rank
    (``|R_ii| > rank_rtol |R_00|``). With ``R_1`` the leading ``rank`` rows, a complete
    orthogonal decomposition ``R_1^T = Q_2 T`` gives ``pinv(R_1^T R_1) = Q_2 T^-1 T^-T Q_2^T``
    and the null space (the remaining columns of ``Q_2``): a parameter with a component above
    ``null_tol`` in it is *not identifiable* (only combinations with others are determined); the
    others get the pseudo-inverse variance, exact for estimable quantities.
    """
    J = np.asarray(J, dtype=float)
    p = J.shape[1]
    s = np.ones(p) if scale is None else np.asarray(scale, dtype=float)
    Js = J * s                                                  # scaled columns
    _, R, P = sla.qr(Js, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > rank_rtol * d[0])) if d.size and d[0] > 0 else 0
    cov = np.full((p, p), np.nan)
    ident = np.zeros(p, dtype=bool)
    if rank:
        Q2, T = sla.qr(R[:rank, :].T, mode="full")             # R1 = T^T Q2^T: complete orthogonal
        Ti = np.linalg.inv(T[:rank, :rank])
        C = Q2[:, :rank] @ (Ti.T @ Ti) @ Q2[:, :rank].T          # pinv(R1^T R1) in pivoted order
        null = np.zeros((p, p - rank))
        null[P] = Q2[:, rank:]
        ident = np.linalg.norm(null, axis=1) < null_tol if p > rank else np.ones(p, dtype=bool)
        cov_s = np.empty((p, p))
        cov_s[np.ix_(P, P)] = C
        cov = cov_s * np.outer(s, s)                           # k = s * (k / s)
        cov[~ident, :] = np.nan
        cov[:, ~ident] = np.nan
    std = np.where(ident, np.sqrt(np.abs(np.diag(cov))), np.inf)
    return Covariance(cov, std, rank, ident)


def chi2_band(dof: int, level: float = 0.99) -> tuple[float, float]:
    """The central ``level`` band of ``chi2(dof) / dof`` (where the reduced chi-square of a
    correct model with correct ``sigma`` falls with probability ``level``)."""
    if dof <= 0:
        return float("nan"), float("nan")
    a = (1.0 - level) / 2.0
    return float(chi2_ppf(a, dof) / dof), float(chi2_ppf(1.0 - a, dof) / dof)


def plausibility_warning(chi2: float, dof: int, p_min: float = PLAUSIBLE_P) -> str | None:
    """A warning when ``chi2`` is implausibly large for ``dof`` degrees of freedom (upper-tail
    probability below ``p_min``): the declared ``sigma`` does not explain the residuals."""
    if dof <= 0:
        return None
    pval = float(chi2_sf(chi2, dof))
    if pval >= p_min:
        return None
    return (f"chi2 = {chi2:.4g} for {dof} degrees of freedom (p = {pval:.2g}): the residuals are "
            f"larger than the declared sigma explains (model error or underestimated sigma); "
            f"the intervals assume sigma is right unless scale_covariance=True")
