"""The diagnosis loop: fit the declared model, score every candidate, refit the best, add one.

Fit the declared model (on the split structure's rigid state, which is the declared model
exactly); test the standardized residuals against the declared noise (chi-square band, structure
per case / grid / component); score every candidate effect against the residual
(:mod:`blackbox.diagnosis.scoring`); refit the ``refit_top`` best by ``p`` (bounded
Levenberg-Marquardt from the starts each effect offers; parameters that end at their nested
bound are dropped). A candidate is *accepted* when its likelihood-ratio p-value times the number
of candidates scored (Bonferroni) is below ``alpha``, BIC improves, and the hold-out chi2 does
not grow by more than its number of parameters (the effect must improve prediction, not only the
fit); the accepted one with the lowest BIC is added. Repeat until no candidate is accepted: a
candidate that is significant after the correction is still added when the overall reduced chi2
is already inside its 99 % band (the band is a weak omnibus test; a localised effect is found by
the targeted score first), and with no effect present the Bonferroni level bounds the chance of a
false addition per round by ``alpha``.

The verdict (:func:`verdict`) compares the final reduced chi2 with its 99 % band: *adequate*
(nothing added, within or below the band), *explained* (effects added, back within or below the
band), *unexplained* (above the band: the model still lacks something no candidate describes,
or the data cannot tell which). A reduced chi2 below the band is no missing effect (a misfit only
raises chi2); it says the declared sigma may be too large, and is a warning. The hotspots
(:func:`blackbox.diagnosis.residuals.hotspots`) say where the final fit's chi-square excess sits.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from scipy import stats

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.fit import Fit, chi2_band, fit_model
from blackbox.diagnosis.model import AugmentedModel, ModelSpec, ObsMap
from blackbox.diagnosis.residuals import hotspots, residual_structure
from blackbox.diagnosis.runs import RunRecord
from blackbox.diagnosis.scoring import CandidateScore, log10_sf, score_candidates
from blackbox.diagnosis.split import SplitBase
from blackbox.errors import IdentificationError
from blackbox.identification import Observations
from blackbox.joints import ComplexJoint, JointModel
from solver_adapters.protocol import DofLabel

__all__ = ["Step", "Diagnosis", "VERDICTS", "verdict", "refit_candidate", "diagnose"]


@dataclass(frozen=True, eq=False)
class Step:
    """One round: the fit it started from, every candidate's score (best first), the refits,
    the effect added (or None) and the fit after."""
    before: Fit
    scores: tuple[CandidateScore, ...]
    added: CandidateScore | None
    after: Fit
    structure_before: dict
    structure_after: dict
    runs: int


@dataclass(frozen=True, eq=False)
class Diagnosis:
    declared: Fit
    final: Fit
    steps: tuple[Step, ...]
    n_candidates: dict
    alpha: float
    band: tuple[float, float]
    holdout_cases: tuple[str, ...]
    nesting_error: float | None
    runs: tuple[RunRecord, ...]
    wall_s: float
    stop_reason: str
    warnings: tuple[str, ...] = ()
    hotspots: dict = field(default_factory=dict)

    @property
    def added(self) -> list[CandidateScore]:
        return [s.added for s in self.steps if s.added is not None]

    @property
    def verdict(self) -> str:
        return verdict(self.final.reduced_chi2, self.band, bool(self.added))


VERDICTS = ("adequate", "explained", "unexplained")


def verdict(reduced_chi2: float, band: tuple[float, float], added: bool) -> str:
    """``"unexplained"`` above the band, else ``"explained"`` when effects were added and
    ``"adequate"`` when none was (module docstring)."""
    if not reduced_chi2 <= band[1]:
        return "unexplained"
    return "explained" if added else "adequate"


def refit_candidate(base: SplitBase, fit: Fit, e: Effect, om: ObsMap, hold: ObsMap | None, boundary,
                    K_deck, o_dofs, step: np.ndarray) -> tuple[Fit, Effect]:
    """Refit the current model plus ``e`` from the starts the effect offers (the nested point,
    the score step...); parameters that end at their nested bound are dropped
    (``Effect.trimmed``: a connection stays rigid there) and the rest refitted."""
    spec2, x2 = fit.spec.add(e, fit.x)
    m2 = AugmentedModel(base, spec2, boundary, K_deck, o_dofs)
    first = spec2.n_params - e.n_params          # the effect's own parameters: x[first:]
    _, lo, hi = spec2.transforms()
    best = None
    for xs in e.refit_starts(x2, step, lo, hi, first):
        try:
            f = fit_model(m2, om, hold, xs)
        except (np.linalg.LinAlgError, IdentificationError):
            continue
        if best is None or f.chi2 < best.chi2:
            best = f
    if best is None:
        raise IdentificationError(f"refit of {e.label()} failed")
    e2 = e.trimmed(best.x[first:])
    if e2 is not None:
        spec3 = ModelSpec(spec2.joints, spec2.effects[:-1] + (e2,))
        keep = np.array([n in e2.names for n in e.names])
        x3 = np.concatenate([best.x[:first], best.x[first:][keep]])
        m3 = AugmentedModel(base, spec3, boundary, K_deck, o_dofs)
        best = fit_model(m3, om, hold, x3)
        e = e2
    return best, e


def diagnose(base: SplitBase, boundary: Sequence[DofLabel], K_deck: np.ndarray | None,
             joints: Sequence[JointModel], k_start: np.ndarray, obs_fit: Observations,
             obs_hold: Observations | None, candidates: Sequence[Effect], *, alpha: float = 0.01,
             refit_top: int = 6, max_steps: int = 5, band_level: float = 0.99,
             declared_prediction: np.ndarray | None = None, xyz: dict | None = None,
             progress=None) -> Diagnosis:
    """The loop of the module docstring. ``k_start``: the declared joints' estimate (e.g. from
    :func:`blackbox.identification.identify`); ``declared_prediction``: that estimate's fit-row
    predictions on the original deck, to measure how exactly the split deck nests the declared
    model (``nesting_error``, in sigma)."""
    t0 = time.perf_counter()
    boundary = tuple(boundary)
    o_dofs = tuple(dict.fromkeys(list(obs_fit.dofs) + [r for r in obs_fit.ref_dofs if r is not None]
                                 + (list(obs_hold.dofs) + [r for r in obs_hold.ref_dofs if r is not None]
                                    if obs_hold is not None else [])))
    o_index = {d: i for i, d in enumerate(o_dofs)}
    om = ObsMap.of(obs_fit, o_index)
    hold = ObsMap.of(obs_hold, o_index) if obs_hold is not None and len(obs_hold) else None
    warnings: list[str] = []

    spec = ModelSpec(tuple(joints))
    model = AugmentedModel(base, spec, boundary, K_deck, o_dofs)
    x0 = np.asarray(k_start, float)
    nest = None
    if declared_prediction is not None:
        nest = float(np.max(np.abs(model.predict(x0, om) - declared_prediction) / om.sigma))
        if nest > 1e-3:
            warnings.append(f"the split deck reproduces the declared model only to {nest:.2g} sigma "
                            "(rigid-state nesting); scores may be inaccurate")
    fit = fit_model(model, om, hold, x0)
    declared = fit
    steps: list[Step] = []
    counts: dict = {}
    for e in candidates:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    stop = "max_steps reached"
    for it in range(max_steps):
        runs0 = len(base.log)
        pool = [e for e in candidates if not fit.spec.has(e) and e.applicable(fit.spec)]
        if not pool:
            stop = "no candidate left"
            break
        M = len(pool)
        raw = score_candidates(model, fit, om, pool, boundary, K_deck, o_dofs)
        n = fit.n_obs
        scored = []
        for e, S, df, step in raw:
            p = float(stats.chi2.sf(S, df)) if df else 1.0
            lp = log10_sf(S, df)
            scored.append(CandidateScore(e, S, df, p, lp, min(1.0, M * p), step,
                                         (-S + df * math.log(n)) if df else 0.0, "score approximation"))
        scored.sort(key=lambda c: (c.log10_p, -c.score))
        short = [c for c in scored[:refit_top] if c.df > 0]
        need = [d for c in short for d in c.effect.refit_columns()]
        if need:
            base.ensure_columns(need, f"member columns for refits (round {it + 1})")
        refits = []
        for c in short:
            try:
                f2, e2 = refit_candidate(base, fit, c.effect, om, hold, boundary, K_deck, o_dofs, c.step_estimate)
            except IdentificationError as exc:
                refits.append(replace(c, reason=f"refit failed: {exc}"))
                continue
            dp = f2.n_params - fit.n_params
            lr = max(fit.chi2 - f2.chi2, 0.0)
            lr_p = float(stats.chi2.sf(lr, dp)) if dp > 0 else 1.0
            lr_adj = min(1.0, M * lr_p)
            dbic = f2.bic - fit.bic
            dh = (f2.holdout_chi2 - fit.holdout_chi2) if (hold is not None and fit.holdout_chi2 is not None) else None
            reasons = []
            if not lr_adj < alpha:
                reasons.append(f"not significant (LR p x {M} = {lr_adj:.3g} >= {alpha:g})")
            if not dbic < 0:
                reasons.append(f"BIC does not improve ({dbic:+.4g})")
            if dh is not None and dh > max(dp, 1):
                reasons.append(f"hold-out prediction worse (chi2 {dh:+.4g})")
            refits.append(replace(c, effect=e2, refit=f2, lr=lr, lr_p_value=lr_p, lr_p_adjusted=lr_adj,
                                  delta_bic=dbic, delta_bic_method="refit", holdout_delta_chi2=dh,
                                  accepted=not reasons, reason="; ".join(reasons) or "accepted"))
        ok = [c for c in refits if c.accepted]
        best = min(ok, key=lambda c: c.delta_bic) if ok else None
        if best is not None:
            refits = [replace(c, reason="significant, but another candidate improves BIC more")
                      if (c.accepted and c is not best) else c for c in refits]
            best = next(c for c in refits if c.effect is best.effect)
        by_key = {c.effect.key: c for c in refits}
        ranked = [by_key.get(c.effect.key, c) for c in scored]
        sb = residual_structure(obs_fit, fit.residuals, xyz)
        if best is None:
            steps.append(Step(fit, tuple(ranked), None, fit, sb, sb, len(base.log) - runs0))
            stop = "no candidate is significant after the Bonferroni correction and improves BIC"
            break
        new = best.refit
        steps.append(Step(fit, tuple(ranked), best, new, sb, residual_structure(obs_fit, new.residuals, xyz),
                          len(base.log) - runs0))
        if progress is not None:
            progress(steps[-1])
        fit = new
        model = AugmentedModel(base, fit.spec, boundary, K_deck, o_dofs)
    lo, hi = chi2_band(fit.n_obs - fit.n_params, band_level)
    if fit.reduced_chi2 > hi:
        warnings.append(f"the final reduced chi2 {fit.reduced_chi2:.4g} is above the {band_level:.0%} "
                        f"band [{lo:.4g}, {hi:.4g}] of the declared noise: the misfit is unexplained")
    elif fit.reduced_chi2 < lo:
        warnings.append(f"the final reduced chi2 {fit.reduced_chi2:.4g} is below the {band_level:.0%} "
                        f"band [{lo:.4g}, {hi:.4g}] of the declared noise: the declared sigma may be too large")
    for j, sl in zip(fit.spec.joints, fit.spec.joint_slices()):
        if isinstance(j, ComplexJoint) and not j.is_admissible(fit.x[sl]):
            warnings.append(f"joint {j.name}: the fitted K_C is not positive semi-definite")
    return Diagnosis(declared, fit, tuple(steps), counts, alpha, (lo, hi),
                     tuple(obs_hold.case_labels[c] for c in obs_hold.cases) if obs_hold is not None else (),
                     nest, tuple(base.log), time.perf_counter() - t0, stop, tuple(warnings),
                     hotspots(obs_fit, fit.residuals))
