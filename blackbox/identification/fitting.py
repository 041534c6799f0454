"""Statistical identification of joint parameters (Chapter 4, Sec. 4.2-4.4, eq. 19-32): :func:`identify`.

The estimation model (eq. 21) is ``U_m = U_A(k) + E_m`` with ``E_m ~ N(0, V_m)``,
``V_m = diag(sigma^2)`` (the user's declared, absolute measurement errors). The estimate
minimises ``chi2(k) = sum ((U_m - U_A(k)) / sigma)^2``, the weighted least squares of Sec. 4.3
(weights ``V_m^-1``) and the maximum-likelihood estimate for Gaussian errors. Everything happens
in the condensed space of :class:`blackbox.condensation.CondensedModel`: no solver run after the
one batched condensation, so the iterations, the profiles and the bootstrap cost milliseconds.

Two iterative procedures, as in Figure 4.1:

1. **Fixed point** (Sec. 4.3.1, eq. 22-29; :mod:`blackbox.identification.fixed_point`) while it
   cuts ``chi2`` at least tenfold per step, when every joint DOF is measured in every case;
2. **Gauss-Newton** (Sec. 4.3.2, eq. 30-32; :mod:`blackbox.identification.newton`) from the last
   accepted point: the safeguarded Levenberg-Marquardt core of :mod:`blackbox.fitting.lm` with
   the analytic condensed Jacobian (eq. 18, at the measured rows only), log / matrix-log
   coordinates (:mod:`blackbox.identification.problem`), geodesic acceleration, backtracking and
   Marquardt damping; ``chi2`` never increases.

Convergence: relative parameter step ``< xtol`` (``|d phi|`` in log coordinates: ``|d log k|``
for springs, ``|dS_ij|`` for a complex joint; ``|dk| / max|diag K_J|`` for the others), or both
the actual and the Gauss-Newton-predicted relative decrease of ``chi2`` ``< ftol`` (MINPACK's
test: a short step in a curved valley does not stop the iteration).

The fit statistics are those of :class:`blackbox.fitting.statistics.FitStatistics`; the
covariance, the profile-likelihood intervals and the bootstrap are described in
:mod:`blackbox.identification.uncertainty`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from blackbox.condensation import CondensedModel
from blackbox.distributions import norm_ppf, t_ppf
from blackbox.errors import IdentificationError
from blackbox.fitting.lm import STATUS_MESSAGES
from blackbox.fitting.statistics import FitStatistics, HoldoutStats, plausibility_warning
from blackbox.identification.fixed_point import FP_STALL, _admissible_fixed_point, _FixedPoint, _relative_step
from blackbox.identification.newton import _Fit, _newton
from blackbox.identification.observations import Observations
from blackbox.identification.problem import SPRING_FLOOR, _Problem
from blackbox.identification.result import IdentificationResult, IterationRecord
from blackbox.identification.uncertainty import _covariance, _profile_ci, linear_intervals, parametric_bootstrap

__all__ = ["identify"]


def _check_inputs(model: CondensedModel, obs, k0, confidence, max_iterations, xtol, ftol, bootstrap,
                  holdout) -> tuple[np.ndarray, _Problem, _Problem | None]:
    """Every input check, before any work (each message says what was given)."""
    if not isinstance(obs, Observations):
        raise IdentificationError(f"obs must be Observations, got {type(obs).__name__}")
    if holdout is not None and not isinstance(holdout, Observations):
        raise IdentificationError(f"holdout must be Observations or None, got {type(holdout).__name__}")
    if not 0.0 < confidence < 1.0:
        raise IdentificationError(f"confidence must be in (0, 1), got {confidence!r}")
    if int(max_iterations) < 1:
        raise IdentificationError(f"max_iterations must be >= 1, got {max_iterations!r}")
    if not (xtol > 0 and ftol > 0):
        raise IdentificationError(f"xtol and ftol must be > 0, got xtol={xtol!r}, ftol={ftol!r}")
    if int(bootstrap) < 0:
        raise IdentificationError(f"bootstrap must be a number of replicates >= 0, got {bootstrap!r}")
    names, p = model.assembly.param_names, model.n_params
    try:
        k0 = np.array(k0, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise IdentificationError(f"k0 must be a vector of {p} numbers, got {k0!r}") from None
    if k0.shape != (p,):
        raise IdentificationError(
            f"k0 has {k0.size} values, the joints have {p} parameters {list(names)}")
    if not np.all(np.isfinite(k0)):
        raise IdentificationError(f"k0 must be finite, got {k0.tolist()}")
    prob = _Problem(model, obs)
    if not prob.admissible(k0):
        bad = [j.name for j, sl in zip(model.assembly.joints, model.assembly.slices)
               if not j.is_admissible(k0[sl], strict=True)]
        raise IdentificationError(
            f"k0 is not admissible for joint(s) {bad} (simple-model springs must be > 0, the complex "
            f"model's K_C positive definite), got {k0.tolist()}")
    if len(obs) < p:
        raise IdentificationError(
            f"too few observations: {len(obs)} measured values for {p} parameters {list(names)}")
    f0, _ = prob.predict(k0)
    if not np.all(np.isfinite(f0)):
        raise IdentificationError(f"residuals are not finite at the start k0 = {k0.tolist()}")
    holdout_prob = _Problem(model, holdout) if holdout is not None and len(holdout) else None
    return k0, prob, holdout_prob


def _estimate(prob: _Problem, k0: np.ndarray, fixed_point: bool, max_iterations: int, xtol: float,
              ftol: float, callback, warnings: list[str]) -> tuple[_Fit, list[IterationRecord], int, int]:
    """Fixed point while it converges fast, then Newton (Figure 4.1). Returns the fit, the
    history and the iteration counts of both phases."""
    k = k0.copy()
    F = prob.chi2(prob.predict(k)[0])
    history = [IterationRecord(0, "start", k.copy(), F)]
    n_fp = 0
    if fixed_point:
        fp = _FixedPoint(prob)
        if not fp.applicable:
            warnings.append(fp.reason + "; Gauss-Newton only")
        if fp.applicable:
            f0, resp0 = prob.predict(k)
            effect = np.linalg.norm(prob.jacobian_k(k, resp0) * prob.w[:, None], axis=0) * prob.scale(k)
            live = effect > 1e-12 * max(float(effect.max()), np.finfo(float).tiny)
        while fp.applicable and n_fp < max_iterations:
            k_t, F_t = _admissible_fixed_point(prob, k, fp.step(k, live))
            if k_t is None:
                break
            if not F_t < FP_STALL * F:           # stalls or oscillates: hand over to Newton
                break
            small = _relative_step(prob, k, k_t, np.ones(prob.p, dtype=bool)) < xtol
            k, F = k_t, F_t
            n_fp += 1
            rec = IterationRecord(n_fp, "fixed-point", k.copy(), F)
            history.append(rec)
            if callback is not None and callback(rec):
                f, _ = prob.predict(k)
                return _Fit(prob.to_phi(k), k, f, F, 5, 0), history, n_fp, 0
            if small:
                break
    if n_fp >= max_iterations:
        return _Fit(prob.to_phi(k), k, prob.predict(k)[0], F, 0, 0), history, n_fp, 0
    fit = _newton(prob, prob.to_phi(k), max_iterations=max_iterations - n_fp, xtol=xtol, ftol=ftol,
                  first_iteration=n_fp + 1, history=history, callback=callback)
    if fit.status != 5:
        fit = _restart_trapped(prob, fit, k0, max_iterations, xtol, ftol, history, callback)
    return fit, history, n_fp, fit.iterations


RESTARTS = 8
TRAPPED_RATIO = 1e3


def trapped(prob: _Problem, k: np.ndarray, k0: np.ndarray) -> np.ndarray:
    """Simple-model springs that ended at the floor or ``TRAPPED_RATIO`` times stiffer than their
    start: in log coordinates such a spring's column shrinks like ``k`` (or ``1/k``), so once a
    step has thrown it there the iteration cannot bring it back, even where a finite value fits
    better."""
    lg = prob.log_mask
    return lg & (prob.at_floor(k, 2.0 * SPRING_FLOOR) | (k > TRAPPED_RATIO * k0))


def _restart_trapped(prob: _Problem, fit: _Fit, k0: np.ndarray, max_iterations: int, xtol: float,
                     ftol: float, history: list, callback=None) -> _Fit:
    """Restarts of a fit with trapped springs (:func:`trapped`): those springs back at their
    start, the others where they are, the Newton phase again; kept only when chi2 ends lower
    (a spring the data really want at 0 or rigid goes back there and the first fit stands),
    at most :data:`RESTARTS` times. An accepted restart is one ``"restart"`` record in the
    history, passed to ``callback`` like every iterate (its own iterates start above the fit it
    improves, so they are not listed); a true return stops the restarts."""
    for _ in range(RESTARTS):
        bad = trapped(prob, fit.k, k0)
        if not bad.any():
            break
        again = _newton(prob, prob.to_phi(np.where(bad, k0, fit.k)), max_iterations=max_iterations,
                        xtol=xtol, ftol=ftol)
        if not again.chi2 < fit.chi2 * (1.0 - 1e-9):
            break
        fit = _Fit(again.phi, again.k, again.f, again.chi2, again.status, fit.iterations + again.iterations)
        rec = IterationRecord(history[-1].iteration + 1, "restart", fit.k.copy(), fit.chi2)
        history.append(rec)
        if callback is not None and callback(rec):
            break
    return fit


def identify(model: CondensedModel, obs: Observations, k0, *, fixed_point: bool = True,
             max_iterations: int = 30, confidence: float = 0.95, holdout: Observations | None = None,
             xtol: float = 1e-8, ftol: float = 1e-10, callback: Callable[[IterationRecord], bool] | None = None,
             profile: bool = True, bootstrap: int = 0, seed: int = 0, scale_covariance: bool = False,
             rank_rtol: float = 1e-8, progress: Callable[[str], None] | None = None,
             executor=None, sigma_dof: float | None = None, chi2_test: bool = True) -> IdentificationResult:
    """Weighted least-squares estimate of the joint parameters (Sec. 4.3) with its uncertainty.

    ``k0``: the start, the concatenated parameters of ``model.assembly`` (admissible: springs > 0,
    ``K_C`` positive definite). ``fixed_point``: start with the fixed-point scheme when it
    applies. ``callback(record)`` is called after every accepted iteration; a true return value
    stops (status 5). ``holdout`` rows are predicted with the estimate, never fitted.
    ``profile``: report profile-likelihood intervals (default; ``False`` reports the linearised
    ones, faster, e.g. inside a loop). ``bootstrap = N``: a parametric bootstrap of ``N``
    replicates seeded by ``seed``. ``scale_covariance``: multiply the covariance by
    ``max(1, reduced_chi2)`` and use Student's t (a sigma known only up to a factor);
    ``rank_rtol``: the numerical rank of the Jacobian (:func:`blackbox.fitting.statistics.covariance`).
    ``progress(message)`` hears of the long stages after the estimate (profiles, bootstrap).
    ``executor`` (e.g. :class:`blackbox.parallel.DaskExecutor`, ``--workers``): where the
    bootstrap refits run (:func:`~blackbox.identification.uncertainty.parametric_bootstrap`; the
    same samples as here); everything else runs here. ``sigma_dof``: ``sigma`` is an estimate
    with that many degrees of freedom (repeated readings, the fit: :mod:`blackbox.noise`), so
    the intervals take Student's t with ``sigma_dof`` instead of the normal quantile (``None`` or
    ``inf``: sigma known). ``chi2_test=False``: sigma was estimated from this very fit, so the
    chi-square says nothing about the model and is not judged.
    """
    k0, prob, holdout_prob = _check_inputs(model, obs, k0, confidence, max_iterations, xtol, ftol,
                                           bootstrap, holdout)
    names, joints_of = model.assembly.param_names, model.assembly.param_joint
    p, n = prob.p, len(obs)
    warnings: list[str] = []
    fit, history, n_fp, n_newton = _estimate(prob, k0, fixed_point, int(max_iterations), xtol, ftol,
                                             callback, warnings)
    converged = fit.status in (1, 2, 3)
    message = STATUS_MESSAGES[fit.status]
    k = fit.k

    # ---- fit statistics (Gaussian likelihood with known sigma) ---------------------------------
    f, resp = prob.predict(k)
    res = (prob.y - f) * prob.w
    fs = FitStatistics.of(prob.y, f, prob.sigma, p, prob.w)
    dof, red = fs.dof, fs.reduced_chi2
    implausible = plausibility_warning(fs.chi2, dof) if chi2_test else None
    if implausible:
        warnings.append(implausible)

    # ---- covariance, identifiability, linearised intervals -------------------------------------
    cov, ident, rank = _covariance(prob, k, resp, rank_rtol)
    scaled = scale_covariance and dof > 0
    cscale = max(1.0, red) if scaled else 1.0
    cov = cov * cscale
    std = np.where(ident, np.sqrt(np.abs(np.diag(cov))), np.inf)
    t_dof = dof if scaled else (float(sigma_dof) if sigma_dof is not None and np.isfinite(sigma_dof) else None)
    if t_dof is not None and not t_dof > 0:
        raise IdentificationError(f"sigma_dof must be > 0, got {sigma_dof!r}")
    z = float(t_ppf(0.5 + confidence / 2.0, t_dof) if t_dof is not None
              else norm_ppf(0.5 + confidence / 2.0))
    lg = prob.log_mask
    lin, half = linear_intervals(k, std, z, lg, ident)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        corr = cov / np.outer(std, std)
    if not np.all(ident):
        bad = [names[i] for i in np.flatnonzero(~ident)]
        warnings.append(f"parameter(s) {bad} are not identifiable from these observations "
                        f"(rank {rank} of {p}): only combinations with others are determined")
    at_zero = prob.at_floor(k, 2.0 * SPRING_FLOOR)
    if np.any(at_zero):
        warnings.append(f"spring(s) {[names[i] for i in np.flatnonzero(at_zero)]} tend to 0 (held at "
                        f"{SPRING_FLOOR:g} x the joint's stiffest): the data want no spring there")
    if not converged:
        warnings.append(f"not converged: {message}")

    # ---- profile likelihood, bootstrap ---------------------------------------------------------
    prof = None
    say = progress or (lambda message: None)
    if profile:
        prof = np.full((p, 2), np.nan)
        todo = np.flatnonzero(ident)
        for n_done, i in enumerate(todo, 1):
            try:
                prof[i] = _profile_ci(prob, fit, int(i), z * z * cscale, half[i], xtol, ftol)
            except (np.linalg.LinAlgError, FloatingPointError) as exc:
                warnings.append(f"no profile interval for {names[i]}: the profile refit failed ({exc}); "
                                "its linearised interval is reported instead")
                prof[i] = lin[i]
            say(f"profile intervals: {n_done}/{len(todo)} ({names[i]})")
        ci, ci_method = prof, "profile likelihood"
    else:
        ci, ci_method = lin, "linearised"
    quantile = ("Student t" if scaled else f"Student t, sigma estimated with {t_dof:.4g} dof" if t_dof is not None
                else "normal")
    ci_method += (f" ({quantile} quantile {z:.4g}"
                  f"{'; log-space for simple-model springs' if np.any(lg) and not profile else ''})")
    boot_ci = boot = None
    if bootstrap:
        workers = getattr(executor, "workers", 1) if executor is not None else 1
        say(f"parametric bootstrap: {int(bootstrap)} refits" + (f" on {workers} workers" if workers > 1 else ""))
        boot = parametric_bootstrap(prob, fit, f, int(bootstrap), seed, int(max_iterations), xtol, ftol,
                                    executor=executor)
        if len(boot) < bootstrap:
            warnings.append(f"{bootstrap - len(boot)} of {bootstrap} bootstrap refits did not converge")
        a = 100.0 * (1.0 - confidence) / 2.0
        boot_ci = np.percentile(boot, [a, 100.0 - a], axis=0).T if len(boot) else np.full((p, 2), np.nan)
        boot_ci[~ident] = np.nan

    # ---- holdout --------------------------------------------------------------------------------
    hstats = None
    if holdout_prob is not None:
        fh, _ = holdout_prob.predict(k)
        labels = model.c.cases
        overlap = set(holdout.cases) & set(obs.cases)
        if overlap:
            warnings.append(f"holdout case(s) {[labels[c] for c in sorted(overlap)]} are also fitted")
        hstats = HoldoutStats.of((labels[c] for c in holdout.cases), holdout_prob.y, fh, holdout_prob.w)

    return IdentificationResult(
        k=k, param_names=tuple(names), param_joint=tuple(joints_of), std=std,
        ci_low=ci[:, 0].copy(), ci_high=ci[:, 1].copy(), confidence=float(confidence),
        ci_method=ci_method, linear_ci=lin, identifiable=ident, rank=rank, covariance=cov,
        correlation=corr, covariance_scale=cscale, converged=converged, status=fit.status,
        message=message, iterations=n_fp + n_newton, n_fixed_point=n_fp, n_newton=n_newton,
        history=tuple(history), n_obs=n, n_params=p, chi2=fs.chi2, reduced_chi2=red,
        rms_residual=fs.rms_residual, aic=fs.aic, bic=fs.bic, residuals=res, predicted=f, holdout=hstats,
        profile_ci=prof, bootstrap_ci=boot_ci, bootstrap_samples=boot, warnings=tuple(warnings))
