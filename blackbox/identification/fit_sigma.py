"""Sigma from the fit, the last resort of :mod:`blackbox.noise`.

Rows whose sigma nobody gives (no value, no repeated readings, no declared accuracy) get one
standard deviation per kind of quantity (translations, rotations: different units), from the
residuals of the fit itself. For a model linear in its parameters with ``E[r] = 0``, the
residual sum of squares of a group ``g`` of rows has the expectation

    E[sum_{i in g} r_i^2] = sigma_g^2 (n_g - sum_{i in g} h_ii)

with ``h_ii`` the leverages, the diagonal of the hat matrix ``J (J^T W J)^+ J^T W`` of the
weighted fit (its trace is the number of parameters). So

    s_g^2 = sum_{i in g} r_i^2 / nu_g,      nu_g = n_g - sum_{i in g} h_ii

is unbiased, and ``nu_g s_g^2 / sigma_g^2 ~ chi2(nu_g)`` gives its interval (exact for one group
of a linear model; Bates & Watts 1988, ch. 2, for the nonlinear model near its optimum). With
one group and no other rows, ``nu = n - p`` and the estimate is the familiar ``RSS / (n - p)``;
with several groups, or rows whose sigma is known, the weights depend on the estimates, so the
fit and the estimates alternate until the estimates stop changing (a few passes).

The reduced chi-square of the last fit is then 1 up to the leverage split -- by construction, so
it says nothing about the model: the chi-square test is off (``chi2_test=False``) and the
intervals take Student's t with ``min_g nu_g`` degrees of freedom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from blackbox.condensation import CondensedModel
from blackbox.errors import IdentificationError
from blackbox.identification.fitting import identify
from blackbox.identification.observations import Observations
from blackbox.identification.problem import _Problem
from blackbox.identification.result import IdentificationResult
from blackbox.noise import sigma_interval

__all__ = ["FitSigma", "identify_with_fit_sigma", "leverages", "predict_rows"]

PASSES = 20                 # alternations of fit and estimate at most
PASS_RTOL = 1e-6            # the estimates' relative change that ends them


@dataclass(frozen=True)
class FitSigma:
    """The fit's sigma per kind: value, degrees of freedom, interval at ``confidence``, rows."""
    kinds: tuple[str, ...]
    sigma: tuple[float, ...]
    dof: tuple[float, ...]
    ci_low: tuple[float, ...]
    ci_high: tuple[float, ...]
    rows: tuple[int, ...]
    passes: int
    confidence: float

    def of(self, kind: str) -> float:
        return self.sigma[self.kinds.index(kind)]

    def to_json(self) -> list[dict]:
        return [{"kind": k, "sigma": s, "dof": d, "ci_low": lo, "ci_high": hi, "rows": n}
                for k, s, d, lo, hi, n in zip(self.kinds, self.sigma, self.dof, self.ci_low, self.ci_high, self.rows)]


def _kinds(obs: Observations) -> np.ndarray:
    return np.array(["rotation" if c >= 4 else "translation" for _, c in obs.dofs])


def predict_rows(model: CondensedModel, obs: Observations, k: np.ndarray) -> np.ndarray:
    """The model's prediction of ``obs``'s rows at ``k`` (relative rows as differences)."""
    return _Problem(model, obs).predict(np.asarray(k, float))[0]


def leverages(model: CondensedModel, obs: Observations, k: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """``h_ii`` of the weighted fit at ``k``: the squared row norms of the left singular vectors
    of the whitened Jacobian (columns scaled to unit norm first), over its numerical rank."""
    prob = _Problem(model, obs)
    k = np.asarray(k, float)
    _, resp = prob.predict(k)
    Jw = prob.jacobian_k(k, resp) * prob.w[:, None]
    norms = np.linalg.norm(Jw, axis=0)
    Jw = Jw / np.where(norms > 0, norms, 1.0)
    U, s, _ = np.linalg.svd(Jw, full_matrices=False)
    rank = int(np.sum(s > rtol * (s[0] if s.size else 0.0)))
    return np.sum(U[:, :rank] ** 2, axis=1)


def identify_with_fit_sigma(model: CondensedModel, obs: Observations, k0, fit_rows: np.ndarray, *,
                            holdout: Observations | None = None, holdout_fit_rows: np.ndarray | None = None,
                            other_dof: float = math.inf,
                            **options) -> tuple[IdentificationResult, FitSigma, Observations, Observations | None]:
    """:func:`blackbox.identification.identify` with the sigma of ``fit_rows`` (their values in
    ``obs`` are placeholders) estimated from the fit (module docstring). ``other_dof``: the
    fewest degrees of freedom among the other rows' sigmas (repeats; ``inf``: known).
    ``options`` go to every fit (the last one runs the profiles and the bootstrap asked for).
    Returns the last fit, the estimates, and ``obs`` and ``holdout`` with the estimated sigma."""
    confidence = float(options.get("confidence", 0.95))
    fit_rows = np.asarray(fit_rows, dtype=bool)
    if fit_rows.shape != (len(obs),):
        raise IdentificationError(f"fit_rows needs one flag per row ({len(obs)}), got shape {fit_rows.shape}")
    kinds = _kinds(obs)
    groups = [g for g in ("translation", "rotation") if (fit_rows & (kinds == g)).any()]
    quick = {k: v for k, v in options.items() if k not in ("profile", "bootstrap", "progress", "executor",
                                                             "callback", "holdout")}
    sigma = np.array(obs.sigma, float)
    k = np.asarray(k0, float)
    est: dict[str, tuple[float, float]] = {}
    single = len(groups) == 1 and fit_rows.all()   # one uniform scale: the optimum does not move
    passes = 0
    for passes in range(1, PASSES + 1):
        o = obs.with_sigma(sigma)
        r = identify(model, o, k, profile=False, bootstrap=0, chi2_test=False, **quick)
        k = r.k
        h = leverages(model, o, k)
        resid = o.values - r.predicted
        new = sigma.copy()
        for g in groups:
            m = fit_rows & (kinds == g)
            nu = float(m.sum() - h[m].sum())
            if nu <= 0.5:
                raise IdentificationError(
                    f"too few {g} rows without sigma ({int(m.sum())}) to estimate it from the fit of "
                    f"{r.n_params} parameter(s): give sigma, repeated readings or a declared accuracy")
            s = math.sqrt(float(resid[m] @ resid[m]) / nu)
            if not s > 0.0:
                raise IdentificationError(f"the fit reproduces the {g} rows exactly: no sigma can be estimated "
                                          f"from it; give sigma or a declared accuracy")
            new[m] = s
            est[g] = (s, nu)
        change = float(np.max(np.abs(new[fit_rows] / sigma[fit_rows] - 1.0)))
        sigma = new
        if single or change < PASS_RTOL:
            break
    dof = min([nu for _, nu in est.values()] + [other_dof])
    final_obs = obs.with_sigma(sigma)
    hold = holdout
    if holdout is not None and holdout_fit_rows is not None and np.any(holdout_fit_rows):
        hk = _kinds(holdout)
        hs = np.array(holdout.sigma, float)
        for g, (s, _) in est.items():
            hs[np.asarray(holdout_fit_rows, bool) & (hk == g)] = s
        for g in ("translation", "rotation"):
            if g not in est and (np.asarray(holdout_fit_rows, bool) & (hk == g)).any():
                raise IdentificationError(f"hold-out {g} rows have no sigma and no fitted {g} row estimates "
                                          f"one; give sigma or a declared accuracy")
        hold = holdout.with_sigma(hs)
    result = identify(model, final_obs, k, holdout=hold, sigma_dof=dof, chi2_test=False, **options)
    cis = [sigma_interval(s, nu, confidence) for s, nu in est.values()]
    fs = FitSigma(tuple(est), tuple(s for s, _ in est.values()), tuple(nu for _, nu in est.values()),
                  tuple(c[0] for c in cis), tuple(c[1] for c in cis),
                  tuple(int((fit_rows & (kinds == g)).sum()) for g in est), passes, confidence)
    return result, fs, final_obs, hold
