"""The diagnosis loop: fit the declared model, score every candidate, refit the best, add one.

Fit the declared model (on the split structure's rigid state, which is the declared model
exactly); test the standardized residuals against the declared noise (chi-square band, structure
per case / grid / component); score every candidate effect against the residual
(:mod:`blackbox.diagnosis.scoring`; each candidate at its family's simplest variant); refit the
``refit_top`` best by ``p`` (bounded Levenberg-Marquardt from the starts each effect offers;
parameters that end at their nested bound are dropped), then every other candidate that could
still win (:func:`refit_schedule`), judged on its score or, for an effect large only when
complete (a member removed), on its exact chi2 there (:func:`screen`). A candidate is *accepted* when its
likelihood-ratio p-value passes the round's multiplicity-controlled level, BIC improves, and it
passes the check against data it was not fitted to (:mod:`blackbox.diagnosis.validation`): with
hold-out cases, ``delta BIC + hold-out chi2 change < 0`` (the hold-out's evidence weighed with the
fit's, so a hold-out that barely sees the effect cannot veto it by chance and one the effect
predicts clearly worse does); without them, the K-fold chi2 over the load cases must decrease
(an effect confined to one case, which no fold can predict, rests on the LR test and BIC, and its
decision says so). The ``refine_top`` candidates whose refit lowers BIC (accepted or not: a joint
loose about one axis may fail as one equal spring and pass as one spring per axis) with the lowest
``delta BIC + hold-out chi2`` are then *refined* (:func:`refine`): its richer variants
(:meth:`blackbox.diagnosis.effects.Effect.richer`, nested: per-axis springs, per-branch springs,
a member's separate EA / EI1 / EI2 / GJ factors) are refitted from their nested point and one
is kept only when it passes the same tests against the variant it extends; this repeats from the
kept variant. Every other candidate whose refit lowers BIC is refined too when its richer
variant could still win (:func:`refine_schedule`: the score of that variant at the candidate's
own refit bounds what it can gain). The accepted candidate with the lowest ``delta BIC + hold-out chi2 + 2 ln M_k``
*at its refined variant* is added (``M_k`` its kind's hypotheses in the round: -2 ln of its
posterior odds under the prior the multiplicity rule below assumes, kinds alike and places
within a kind alike; :attr:`CandidateScore.posterior`), so a mis-specified simple variant never
stays in the model for a further effect to patch. Repeat until no candidate is accepted: a
candidate that is significant after the correction is still added when the overall reduced chi2 is already inside its 99 % band (the band
is a weak omnibus test; a localised effect is found by the targeted score first).

An effect that sets readings aside (a bad channel, a bad case) takes the place of the effects of
the current model it subsumes (:meth:`Effect.subsumes`: an offset, a sign flip, outliers of its
channel), which the step records as removed; its hold-out check compares both fits on the
hold-out rows it does not set aside.

*Multiplicity* (alpha spending, :func:`round_level`): round ``r`` (1, 2, ...) spends
``alpha / 2^r``, split evenly (Bonferroni) over its hypotheses: every candidate scored in the
round plus the variant upgrades each could be refined through (:attr:`Effect.variant_tests`);
candidates the data chose as one family (load-scale groups found from the case scales) are one
hypothesis, tested for the choice (:meth:`Effect.selection_log_sf`).
Each LR test of the round (a candidate's, a variant's) is made at ``alpha / (2^r M_r)``; the
reported adjusted p-value is ``p 2^r M_r``, compared with ``alpha``. Over the whole search, with
no effect present, the chance of any false addition is at most ``sum_r alpha / 2^r < alpha``,
however many rounds run.

The verdict (:func:`verdict`) compares the final reduced chi2 with its 99 % band: *adequate*
(nothing added, within or below the band), *explained* (effects added, back within or below the
band), *unexplained* (above the band: the model still lacks something no candidate describes,
or the data cannot tell which). The hold-out cases, never fitted, are then read against the final
model (:mod:`blackbox.diagnosis.holdout`): a reading or a case found there to be a defect of the
data (an outlier, a case of another size or another case's readings) makes an *adequate* verdict
*explained*, and a hold-out case or rest the final model does not predict makes any verdict
*unexplained*. A reduced chi2 below the band is no missing effect (a misfit only raises chi2); it
says the declared sigma may be too large, and is a warning. The hotspots
(:func:`blackbox.diagnosis.residuals.hotspots`) say where the final fit's chi-square excess sits.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np
from scipy import special, stats

from blackbox.diagnosis.effects.base import Effect, proximity, takes_readings
from blackbox.diagnosis.effects.load_scale import case_scales
from blackbox.diagnosis.fit import Fit, chi2_band, effective_rank, fit_model
from blackbox.diagnosis.holdout import HoldoutCheck, check_holdout, free_parameters
from blackbox.diagnosis.noise_level import NoiseLevel, leverages, noise_level
from blackbox.diagnosis.model import RIGID_RATIO, AugmentedModel, ModelSpec, ObsMap
from blackbox.diagnosis.residuals import hotspots, residual_structure
from blackbox.diagnosis.runs import RunRecord
from blackbox.diagnosis.scoring import (CandidateScore, evidence, family_scores, log10_sf, log10_sf_array,
                                       score_candidates)
from blackbox.diagnosis.separation import separating_measurements
from blackbox.diagnosis.split import SplitBase
from blackbox.diagnosis.validation import Validation, cv_chi2, kfold
from blackbox.errors import EditedDeckError, IdentificationError
from blackbox.identification import Observations
from blackbox.joints import ComplexJoint, JointModel, SimpleJoint
from solver_adapters.protocol import DofLabel

__all__ = ["declared_fit", "multipliers", "hypotheses_by_kind", "refit_schedule", "screen", "SCREEN_DOF_COLUMNS", "eliminate", "without", "Step", "Diagnosis", "VariantTrial", "Judgement", "Checks", "evidence", "near_tie", "holdout_dispersion", "holdout_worse", "case_metric", "prediction_metric", "VERDICTS", "verdict",
           "refit_candidate", "subsumed_removed", "refine", "round_level", "diagnose", "map_refits", "refits_pay"]


AMBIGUOUS = 10.0            # evidence (delta BIC + hold-out chi2, ~ -2 ln Bayes factor) within which
                            # another accepted candidate is named beside the one added: below 10 the
                            # data do not decide "very strongly" between them (Kass & Raftery 1995)

REFINE_TOP = 3              # candidates refined per round (those whose refit lowers BIC, strongest
                            # evidence first): a richer variant can overtake the runner-ups (an EI-only
                            # member against an undeclared joint at its end); refining all six refits
                            # costs 2x the round


def near_tie(c: CandidateScore, added: CandidateScore) -> bool:
    """Whether the data hardly tell ``c`` from the candidate ``added``: their evidence (without
    the prior) within :data:`AMBIGUOUS`, either way."""
    return abs(c.evidence - added.evidence) < AMBIGUOUS


KFOLD_TIE = 2.0
"""Two accepted candidates whose evidence (delta BIC, ~ -2 ln Bayes factor) differs by less than
this are a tie the fitted data cannot break ("not worth more than a bare mention", Kass & Raftery
1995); with every case fitted (K-fold), the one that predicts the left-out cases better is taken."""


def kfold_tiebreak(best: CandidateScore, ok: Sequence[CandidateScore]) -> CandidateScore:
    """Among the accepted candidates ``ok`` whose evidence is within :data:`KFOLD_TIE` of that of
    the most probable ``best``, the one of least K-fold chi2, when the K-fold checked each of them
    (an effect no fold can learn and predict, an outlier, has a K-fold chi2 that says nothing);
    else ``best``. The prior (its kind's places) does not enter: it separated a ladder's member
    factor from the undeclared joint at its end by 2.1 where the data did by 0.34, and the joint
    predicted the left-out cases better by 10."""
    if not kfold_tied(best, best):
        return best
    ties = [c for c in ok if kfold_tied(c, best)]
    return min(ties, key=lambda c: (c.kfold_delta_chi2, c.posterior))


def kfold_tied(c: CandidateScore, best: CandidateScore) -> bool:
    """Whether ``c`` is in :func:`kfold_tiebreak`'s tie with ``best``: checked by the K-fold, and
    its evidence within :data:`KFOLD_TIE` of ``best``'s."""
    return c.kfold_checked and c.kfold_delta_chi2 is not None and abs(c.evidence - best.evidence) < KFOLD_TIE


def round_level(alpha: float, round_no: int, n_hypotheses: int) -> float:
    """The LR-test level of one hypothesis in round ``round_no`` (1-based) of ``n_hypotheses``:
    ``alpha / (2^round_no n_hypotheses)`` (module docstring, alpha spending)."""
    return alpha / (2.0 ** round_no * max(n_hypotheses, 1))


@dataclass(frozen=True, eq=False)
class VariantTrial:
    """One richer variant refitted against the variant it extends."""
    effect: Effect
    from_variant: str
    refit: Fit | None
    lr: float | None
    lr_p_value: float | None
    lr_p_adjusted: float | None
    delta_bic: float | None
    holdout_delta_chi2: float | None
    accepted: bool
    reason: str
    kfold_delta_chi2: float | None = None


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
    level: float = float("nan")         # the LR-test level of one hypothesis of the added kind
    hypotheses: int = 0                 # the round's hypotheses (candidates + variant upgrades)
    levels: dict = field(default_factory=dict)      # kind -> the level of one of its hypotheses
    by_kind: dict = field(default_factory=dict)     # kind -> its hypotheses in this round
    removed: tuple = ()                 # (effect, Judgement): earlier effects the addition made unnecessary
    separations: dict = field(default_factory=dict)  # alternative's key -> separating_measurements()


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
    validation: Validation = Validation("holdout")
    kfold: dict | None = None           # K-fold: the folds' case labels and the cv chi2 before / after
    holdout_check: HoldoutCheck | None = None   # the hold-out cases read against the final model
    noise_level: NoiseLevel | None = None       # above the band: whether the misfit looks like noise
    sigmas_exchanged: tuple[str, str] | None = None     # the two exchanged cases' sigmas were read as
                                                        # each other's (blackbox.diagnosis.exchange)
    other_search: dict | None = None    # the search on the other reading of those sigmas, in brief
                                        # (blackbox.diagnosis.exchange.brief): kept or not, never lost

    @property
    def added(self) -> list[CandidateScore]:
        """The candidate score of every effect in the final model, in the order added (an effect
        a later addition made unnecessary was removed and is not here)."""
        keys = {e.key for e in self.final.spec.effects}
        return [s.added for s in self.steps if s.added is not None and s.added.effect.key in keys]

    @property
    def verdict(self) -> str:
        return verdict(self.final.reduced_chi2, self.band, bool(self.added), self.holdout_check)


VERDICTS = ("adequate", "explained", "unexplained")


def verdict(reduced_chi2: float, band: tuple[float, float], added: bool,
            holdout: HoldoutCheck | None = None) -> str:
    """``"unexplained"`` above the band or when the hold-out cases are not predicted
    (:mod:`blackbox.diagnosis.holdout`), else ``"explained"`` when effects were added or defects
    of the data were found in the hold-out cases, and ``"adequate"`` when neither (module
    docstring)."""
    if not reduced_chi2 <= band[1] or (holdout is not None and not holdout.predicted):
        return "unexplained"
    return "explained" if added or (holdout is not None and holdout.findings) else "adequate"


def refit_candidate(base: SplitBase, fit: Fit, e: Effect, om: ObsMap, hold: ObsMap | None, boundary,
                    K_deck, o_dofs, step: np.ndarray) -> tuple[Fit, Effect]:
    """Refit the current model plus ``e`` from the starts the effect offers (the nested point,
    the score step...); parameters that end at their nested bound are dropped
    (``Effect.trimmed``: a connection stays rigid there) and the rest refitted. Effects of the
    current model that ``e`` subsumes (:meth:`Effect.subsumes`) leave it in the refit."""
    spec0, x0 = subsumed_removed(fit.spec, fit.x, e)
    spec2, x2 = spec0.add(e, x0)
    m2 = AugmentedModel(base, spec2, boundary, K_deck, o_dofs)
    first = spec2.n_params - e.n_params          # the effect's own parameters: x[first:]
    _, lo, hi = spec2.transforms()
    best = _best_of(m2, om, hold, e.refit_starts(x2, step, lo, hi, first), e)
    e2 = e.trimmed(best.x[first:])
    if e2 is not None:
        spec3 = ModelSpec(spec2.joints, spec2.effects[:-1] + (e2,))
        keep = np.array([n in e2.names for n in e.names])
        x3 = np.concatenate([best.x[:first], best.x[first:][keep]])
        m3 = AugmentedModel(base, spec3, boundary, K_deck, o_dofs)
        best = fit_model(m3, om, hold, x3)
        e = e2
    return _capped(base, best, e, om, hold, boundary, K_deck, o_dofs)


def _capped(base: SplitBase, best: Fit, e: Effect, om: ObsMap, hold, boundary, K_deck, o_dofs) -> tuple[Fit, Effect]:
    """``(best, e)``, or the refit with ``e``'s parameters that ran to an implausible bound
    brought back to the plausible point they started from (:meth:`Effect.capped`) when the data
    do not tell the two apart: the chi2 rises by less than the 95 % point of chi2 with 1 degree
    of freedom (the profile likelihood's interval of that parameter reaches the start). A
    parameter the data push to the bound stays there, and the refit is rejected for it."""
    first = best.spec.n_params - e.n_params
    e3 = e.capped(best.x[first:])
    if e3 is None:
        return best, e
    spec3 = ModelSpec(best.spec.joints, best.spec.effects[:-1] + (e3,))
    x3 = best.x.copy()
    x3[first:] = np.minimum(x3[first:], e3.bounds[1])
    try:
        f3 = fit_model(AugmentedModel(base, spec3, boundary, K_deck, o_dofs), om, hold, x3)
    except (np.linalg.LinAlgError, IdentificationError):
        return best, e
    if f3.chi2 - best.chi2 < stats.chi2.ppf(0.95, 1):
        return f3, e3
    return best, e


def subsumed_removed(spec: ModelSpec, x: np.ndarray, e: Effect) -> tuple[ModelSpec, np.ndarray]:
    """``spec`` and ``x`` without the effects ``e`` subsumes (effects of the data only, which
    leave the joints' parameters as they are)."""
    keep = [i for i, o in enumerate(spec.effects) if not e.subsumes(o)]
    if len(keep) == len(spec.effects):
        return spec, x
    sl = spec.effect_slices()
    x2 = np.concatenate([x[:spec.joint_params]] + [x[sl[i]] for i in keep])
    return ModelSpec(spec.joints, tuple(spec.effects[i] for i in keep)), x2


def _refit_task(item: tuple[Effect, np.ndarray], shared: tuple) -> tuple[Fit, Effect] | IdentificationError:
    """:func:`refit_candidate` of one ``(effect, score step)`` against ``shared = (base, fit, om,
    hold, boundary, K_deck, o_dofs)``, where the task runs; a failed refit is returned, not raised
    (the round records it)."""
    base, fit, om, hold, boundary, K_deck, o_dofs = shared
    try:
        return refit_candidate(base, fit, item[0], om, hold, boundary, K_deck, o_dofs, item[1])
    except IdentificationError as exc:
        return exc


REFIT_PER_FIT = 3.0         # a candidate's refit takes ~1-10x the declared model's fit (2-3 starts from
                            # a nested point, not one from the optimum): 3, the median measured on
                            # the fixtures and a 1e3-DOF tube (docs/parallel.md)
SHIP_S_PER_MB = 0.01        # sending the split base to the workers: 45 MB to 2 local workers in 0.08-0.46 s
ROUND_OVERHEAD_S = 0.2      # a round's tasks through the scheduler and their results back


def refits_pay(n: int, fit_s: float, base_mb: float, workers: int) -> bool:
    """Whether ``n`` refits, each estimated at ``REFIT_PER_FIT * fit_s`` (``fit_s``: the declared
    model's fit, timed here), finish at least 20 % sooner on ``workers`` workers, counting the
    split base's trip (``base_mb``) and the round's overhead."""
    serial = n * REFIT_PER_FIT * fit_s
    mapped = serial / max(1, min(n, workers)) + base_mb * SHIP_S_PER_MB + ROUND_OVERHEAD_S
    return mapped < 0.8 * serial


def map_refits(base: SplitBase, fit: Fit, short: Sequence[CandidateScore], om: ObsMap, hold, boundary, K_deck,
               o_dofs, executor=None, fit_s: float | None = None) -> list[tuple[Fit, Effect] | IdentificationError]:
    """The round's refits (:func:`refit_candidate` of each short-listed candidate), in order: here,
    or with ``executor`` (an object with ``workers``, ``share`` and ``map_shared``, e.g.
    :class:`blackbox.parallel.DaskExecutor`) one task per candidate, the split base (without its
    adapter: :meth:`SplitBase.detached`) and the fit sent to each worker once. With ``fit_s``
    (the declared fit's time) only when that pays (:func:`refits_pay`); without, always. Each
    task is the serial refit; only BLAS threading can make the numbers differ (single-threaded
    on a worker)."""
    items = [(c.effect, c.step_estimate) for c in short]
    workers = getattr(executor, "workers", 1) if executor is not None else 1
    if (workers <= 1 or len(items) < 2
            or (fit_s is not None and not refits_pay(len(items), fit_s, base.detached_nbytes() / 1e6, workers))):
        shared = (base, fit, om, hold, boundary, K_deck, o_dofs)
        return [_refit_task(x, shared) for x in items]
    with executor.share((base.detached(), fit, om, hold, boundary, K_deck, o_dofs)) as handle:
        return executor.map_shared(_refit_task, handle, items)


def _best_of(model: AugmentedModel, om: ObsMap, hold, starts, e: Effect) -> Fit:
    """The lowest-chi2 refit of ``model`` over ``starts``; starts whose refit is singular are
    skipped, and none left is an :class:`IdentificationError` naming the effect ``e``."""
    best = None
    for xs in starts:
        try:
            f = fit_model(model, om, hold, xs)
        except (np.linalg.LinAlgError, IdentificationError):
            continue
        if best is None or f.chi2 < best.chi2:
            best = f
    if best is None:
        raise IdentificationError(f"refit of {e.label()} failed")
    return best


@dataclass(frozen=True)
class Judgement:
    """An addition (or a richer variant) against the model it extends (module docstring)."""
    lr: float
    lr_p: float
    lr_p_adjusted: float
    delta_bic: float
    holdout_delta_chi2: float | None
    kfold_delta_chi2: float | None
    reasons: tuple[str, ...]
    note: str = ""
    holdout_dispersion: float = 1.0
    kfold_checked: bool = False         # the K-fold both learnt and predicted with the addition

    @property
    def accepted(self) -> bool:
        return not self.reasons

    @property
    def evidence(self) -> float:
        """The data's evidence for the addition (:func:`evidence`): what ranks the variants of
        one effect, and the effects that no longer pass elimination."""
        return evidence(self.delta_bic, self.holdout_delta_chi2, self.holdout_dispersion)

    @property
    def decision(self) -> str:
        return "; ".join(self.reasons) or ("accepted" + (f" ({self.note})" if self.note else ""))


HOLDOUT_Z = 3.0
"""How many standard deviations of its chance fluctuation the hold-out chi2 may rise by before an
addition counts as predicting the hold-out cases worse (:func:`holdout_worse`)."""


def holdout_worse(fit: Fit, f2: Fit, hold: ObsMap | None, keep: np.ndarray | None = None,
                  weights: np.ndarray | None = None, metric=None,
                  metric_basis: np.ndarray | None = None) -> str | None:
    """Why ``f2`` predicts the hold-out cases worse than ``fit`` beyond chance, or ``None``.

    With ``d`` the whitened change of the hold-out predictions, an addition that is right
    changes the hold-out chi2 by ``-|d|^2 - 2 r.d``, ``r`` the hold-out residual of ``f2``: mean
    ``-|d|^2``, standard deviation ``2|d|`` when the fits determine the parameters the hold-out
    cases see. When they leave them loose, ``r`` carries the prediction error of ``f2``'s fitted
    parameters (whitened covariance ``A2 A2^T``, ``A2`` its
    :func:`~blackbox.diagnosis.holdout.prediction_basis`; ``A1`` the same of ``fit``), and ``d``
    the part of it the added parameters bring, ``B B^T = A2 A2^T - A1 A1^T`` for nested linear
    fits: the change's mean is then ``-|d|^2 + 2 tr(B B^T)`` and its variance about
    ``4 d^T (I + A2 A2^T) d + 8 tr((B B^T)^2)``, counted when the noise alone would veto. A rise
    beyond the mean plus ``HOLDOUT_Z`` standard deviations has probability below 0.2 % under
    that hypothesis (0.1 % measured on nested least squares, ``tests/test_data_defects.py``):
    the hold-out cases contradict the addition, which is then never
    kept, however much it improves the fit (a load scale or sensor offset that absorbs the
    misfit of an effect no candidate describes). An addition the hold-out cases hardly see
    (``|d|`` ~ 0) cannot be vetoed by their noise. ``keep``: the hold-out rows compared (default
    all; an addition that sets readings aside is judged on the others). Each case's rows are
    weighed by :func:`holdout_case_weights` (``weights``: those weights, when the caller has
    them): a hold-out case neither fit predicts does not follow the noise this rule assumes.
    ``metric``: the ``M`` of :func:`prediction_metric` when the fits' hold-out residuals are
    already read in that metric, ``metric_basis`` (``As``) the basis it was made of (default
    ``f2``'s whole basis): there ``r`` has covariance ``I + M (A2 A2^T - As As^T) M``, and
    ``A2``, ``A1`` are read through ``M`` too."""
    if hold is None or fit.holdout_predicted is None or f2.holdout_predicted is None:
        return None
    keep = np.ones(len(hold.sigma), bool) if keep is None else keep
    w = (holdout_case_weights(fit, f2, hold, keep) if weights is None else weights)[keep]
    d = ((f2.holdout_predicted - fit.holdout_predicted) / hold.sigma)[keep] * np.sqrt(w)
    dh = float(np.sum(w * (_whitened_sq(f2, hold) - _whitened_sq(fit, hold))[keep]))
    dn = float(np.linalg.norm(d))
    floor = 1e-9 * max(1.0, fit.holdout_chi2)
    limit = max(-dn * dn + HOLDOUT_Z * 2.0 * dn, floor)
    if dh > limit and getattr(f2, "holdout_basis", None) is not None:
        # the prediction error's share, only when the noise alone would veto (it can only widen)
        sw = np.sqrt(w)[:, None]
        A2 = f2.holdout_basis
        A1 = getattr(fit, "holdout_basis", None)
        A1 = A2[:, :0] if A1 is None else A1
        As = None
        if metric is not None:
            As = metric((A2 if metric_basis is None else metric_basis))[keep] * sw
            A2, A1 = metric(A2), metric(A1)
        A2, A1 = A2[keep] * sw, A1[keep] * sw
        added = max(float(np.sum(A2 * A2) - np.sum(A1 * A1)), 0.0)
        added_sq = max(float(np.sum((A2.T @ A2) ** 2) - 2.0 * np.sum((A1.T @ A2) ** 2)
                             + np.sum((A1.T @ A1) ** 2)), 0.0)
        # the residual's covariance beyond the noise: A2 A2^T, less what the metric took out
        spread = float(np.sum((A2.T @ d) ** 2)) - (0.0 if As is None else float(np.sum((As.T @ d) ** 2)))
        spread = max(spread, 0.0)
        var = 4.0 * (dn * dn + spread) + 8.0 * added_sq
        limit = max(-dn * dn + 2.0 * added + HOLDOUT_Z * math.sqrt(var), floor)
    if dh > limit:
        return (f"it predicts the hold-out cases worse (hold-out chi2 {dh:+.4g}, beyond the {limit:+.3g} "
                f"that chance allows for an addition that changes their prediction by {dn:.3g} sigma"
                + (")" if np.all(w == 1.0) else ", cases neither fit predicts weighed down by their misfit)"))
    return None


def scale_profiled(fit: Fit, hold: ObsMap) -> Fit:
    """``fit`` with each hold-out case's predictions times that case's own least-squares scale
    (``sum(u y / s^2) / sum(u^2 / s^2)``, ``u`` its predictions): what the hold-out cases say of
    the responses' shape, whatever each case's load amplitude (:meth:`Effect.holdout_scale_free`)."""
    if fit.holdout_predicted is None:
        return fit
    u = np.asarray(fit.holdout_predicted, float)
    out = u.copy()
    for k, (s, _) in case_scales(hold.case, hold.y, hold.sigma, u, range(int(hold.case.max()) + 1)).items():
        rows = hold.case == k
        out[rows] = u[rows] * (1.0 + s)
    return replace(fit, holdout_predicted=out, holdout_chi2=float(np.sum(((hold.y - out) / hold.sigma) ** 2)))


def case_metric(A: np.ndarray, hold: ObsMap, keep: np.ndarray | None = None):
    """``M``: per hold-out case (rows ``keep``), ``(I + A_c A_c^T)^-1/2`` of that case's rows of
    the prediction basis ``A``, as a function of a row-indexed array (rows outside ``keep`` kept
    as they are). Applied to a fit's whitened hold-out residual it gives the residual in the
    metric of that prediction (:func:`prediction_metric`)."""
    keep = np.ones(len(hold.y), bool) if keep is None else np.asarray(keep, bool)
    case = getattr(hold, "case", None)
    case = np.zeros(len(hold.y), int) if case is None else case
    groups = []
    for k in np.unique(case[keep]):
        rows = np.flatnonzero(keep & (case == k))
        U, sv, _ = np.linalg.svd(A[rows], full_matrices=False)
        groups.append((rows, U, 1.0 - 1.0 / np.sqrt(1.0 + sv * sv)))

    def apply(X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, float)
        out = X.copy()
        for rows, U, shrink in groups:
            c = U.T @ X[rows]
            out[rows] = X[rows] - U @ (shrink[:, None] * c if c.ndim == 2 else shrink * c)
        return out
    return apply


def prediction_metric(fit: Fit, f2: Fit, hold: ObsMap, keep: np.ndarray | None = None,
                      basis: np.ndarray | None = None):
    """``(fit, f2, M)``: the fits with their hold-out residuals measured in the metric of
    ``f2``'s prediction: each hold-out case's whitened residual ``r`` (rows ``keep``) replaced
    by ``z = M r`` with ``z^T z = r^T (I + A A^T)^-1 r``, ``A`` the rows' part of ``basis``
    (default ``f2.holdout_basis``: its fitted parameters' error carried to them,
    :func:`~blackbox.diagnosis.fit.prediction_basis`), as the final hold-out check reads them
    (:func:`case_metric`: ``M``). A hold-out case that loads a parameter the fit rows leave
    loose (a joint spring they hardly see) is off the plain prediction by wherever that
    parameter happens to land, by many times its noise for either fit, and would otherwise
    decide between two additions by that landing (a blind truss whose one hold-out case loads
    such a spring vetoed the planted effect, which predicts every hold-out case to its noise in
    this metric). The search takes ``basis`` from the parameters the addition shares with the
    fit it extends, its own held (:meth:`~blackbox.diagnosis.fit.Fit.basis_without`): the
    addition's own error runs along the response it adds, and a metric that discounted it would
    discount the very misfit the addition explains, the more the less precisely the data size
    it (a support spring against the member ending there). ``(fit, f2, None)`` when there is
    no such basis."""
    A = f2.holdout_basis if basis is None else basis
    if (A is None or A.shape[1] == 0 or fit.holdout_predicted is None or f2.holdout_predicted is None):
        return fit, f2, None
    M = case_metric(A, hold, keep)
    out = []
    for f in (fit, f2):
        z = M((hold.y - f.holdout_predicted) / hold.sigma)
        out.append(replace(f, holdout_predicted=hold.y - z * hold.sigma, holdout_chi2=float(np.sum(z * z))))
    return out[0], out[1], M


def _whitened_sq(fit: Fit, hold: ObsMap) -> np.ndarray:
    return ((hold.y - fit.holdout_predicted) / hold.sigma) ** 2


def holdout_case_weights(fit: Fit, f2: Fit, hold: ObsMap, keep: np.ndarray) -> np.ndarray:
    """The weight of each hold-out row when two fits are compared on the hold-out cases: one
    over its case's dispersion, the case's chi2 under the fit that predicts it better over the
    upper end of its 99 % band (at least 1; :func:`holdout_dispersion`). A case either fit
    predicts within its band keeps its whole chi2 change, so a case an addition spoils still
    vetoes it. A case neither fit predicts, by many times its noise (its readings another
    case's, in other units, a load put in elsewhere), changes its chi2 with every move of the
    model by amounts that say how its defect projects on the move, not whether the addition is
    right; weighed down, it counts as a change of that size would in a case predicted to its
    noise. Rows outside ``keep`` get weight 0."""
    w = np.zeros(len(hold.sigma))
    r1, r2 = _whitened_sq(fit, hold), _whitened_sq(f2, hold)
    case = getattr(hold, "case", None)
    case = np.zeros(len(w), int) if case is None else case
    for k in np.unique(case[keep]):
        rows = keep & (case == k)
        w[rows] = 1.0 / holdout_dispersion(min(float(r1[rows].sum()), float(r2[rows].sum())), int(rows.sum()))
    return w


def holdout_chi2(fit: Fit, hold: ObsMap, keep: np.ndarray) -> float:
    """The hold-out chi2 of ``fit`` over the rows ``keep``."""
    return float(np.sum(_whitened_sq(fit, hold)[keep]))


def holdout_dispersion(chi2: float, n: int) -> float:
    """The hold-out's excess dispersion after an addition: its chi2 over the upper end of its
    99 % band for ``n`` readings, at least 1 -- the quasi-likelihood scale the LR test takes
    from the fitted readings' reduced chi2, counted only where noise cannot explain it. A
    hold-out that the fit still predicts at many times the noise (its cases excite joint
    parameters the fitted cases leave loose) changes its chi2 with every move of those
    parameters, by amounts that follow the loose parameters more than the effect; divided by the
    dispersion, such a change ranks an addition as a change of that size would in a hold-out
    predicted to its noise. A hold-out predicted within its band keeps the whole change, so two
    additions that both predict it to its noise are not ranked by their chance wobble within
    the band."""
    n = max(int(n), 1)
    return max(1.0, chi2 / float(stats.chi2.ppf(0.99, n)))


class Checks:
    """The tests an addition must pass (module docstring), with the K-fold chi2 of each fit
    computed once."""

    def __init__(self, om: ObsMap, hold: ObsMap | None, val: Validation):
        self.om, self.hold, self.val = om, hold, val
        self._cv: dict[int, tuple[Fit, float, list[bool]]] = {}
        self._rank: dict[int, tuple[Fit, int]] = {}

    def rank(self, fit: Fit) -> int:
        """:func:`~blackbox.diagnosis.fit.effective_rank` of ``fit``'s Jacobian, computed once."""
        hit = self._rank.get(id(fit))
        if hit is None or hit[0] is not fit:
            hit = (fit, effective_rank(fit.J))
            self._rank[id(fit)] = hit
        return hit[1]

    def added_dof(self, fit: Fit, f2: Fit) -> int:
        """The degrees of freedom ``f2`` adds to ``fit``: the parameters it adds that the data
        determine (the rise of the Jacobian's numerical rank), between 1 and the nominal count.
        A joint turned complex adds the 12 entries of ``K_C`` a simple joint lacks, of which the
        measured readings may see 6: counting all 12 charges BIC ``6 ln n`` for parameters that
        fit nothing, so that a one-parameter data defect absorbing part of the signature wins
        the choice (and the score test, which counts the rank, disagrees with the refit)."""
        dp = f2.n_params - fit.n_params
        if dp <= 0:
            return dp
        return min(dp, max(1, self.rank(f2) - self.rank(fit)))

    def cv(self, fit: Fit) -> tuple[float, list[bool]]:
        hit = self._cv.get(id(fit))
        if hit is None or hit[0] is not fit:
            _, lo, hi = fit.spec.transforms()
            owners = fit.spec.effect_slices()
            nominal = np.full(fit.spec.n_params, np.nan)
            for e, sl in zip(fit.spec.effects, owners):
                nominal[sl] = e.nominal
            hit = (fit, *cv_chi2(fit.J, fit.residuals, fit.x, lo, hi, nominal, self.om.case, self.val.folds, owners))
            self._cv[id(fit)] = hit
        return hit[1], hit[2]

    def judge(self, fit: Fit, f2: Fit, multiplier: float, alpha: float, effect: int) -> Judgement:
        """``f2`` against ``fit``; ``multiplier``: ``2^r M_r``; ``effect``: the index in
        ``f2.spec.effects`` of the effect added or enriched."""
        dp = self.added_dof(fit, f2)                # the parameters the data determine
        lr = max(fit.chi2 - f2.chi2, 0.0)
        phi = max(1.0, f2.reduced_chi2)             # misfit left after the addition (quasi-likelihood)
        lr_p = float(stats.chi2.sf(lr / phi, dp)) if dp > 0 else 1.0
        # BIC with the determined parameters counted (f2.bic counts every nominal one)
        dbic = f2.bic - fit.bic - (f2.n_params - fit.n_params - dp) * math.log(f2.n_obs)
        e = f2.spec.effects[effect] if 0 <= effect < len(f2.spec.effects) else None
        log_sel = e.selection_log_sf(lr / phi) if e is not None and f2.n_params - fit.n_params == 1 else None
        if log_sel is not None:
            # a candidate the data chose (module docstring of its family): its p-value accounts
            # for the choice, and its chi2 drop counts as what a fixed one-parameter candidate
            # would need for that p-value, so it competes with fixed candidates on equal terms
            lr_p = math.exp(log_sel)
            lr_fixed = phi * float(special.ndtri_exp(log_sel - math.log(2.0))) ** 2 if log_sel < 0 else 0.0
            dbic += max(lr - lr_fixed, 0.0)
        lr_eff = lr if log_sel is None else min(lr, lr_fixed)
        lr_adj = min(1.0, multiplier * lr_p)
        reasons, note = [], ""
        if phi > 1.0 and dbic < 0 and not -lr_eff / phi + dp * math.log(f2.n_obs) < 0:
            reasons.append(f"BIC does not improve once the misfit it leaves (reduced chi2 {phi:.3g}) is "
                           f"counted ({-lr_eff / phi + dp * math.log(f2.n_obs):+.4g})")
        why = e.rejection(f2.x[f2.spec.effect_slices()[effect]]) if e is not None else None
        if why:
            reasons.append(why)
        if not lr_adj < alpha:
            reasons.append(f"not significant (LR p x {multiplier:.4g} = {lr_adj:.3g} >= {alpha:g})")
        if not dbic < 0:
            reasons.append(f"BIC does not improve ({dbic:+.4g})")
        dh = dcv = None
        disp = 1.0
        checked = False
        if self.val.kind == "holdout" and fit.holdout_chi2 is not None and f2.holdout_chi2 is not None:
            if e is not None and e.holdout_scale_free(self.hold):
                fit, f2 = scale_profiled(fit, self.hold), scale_profiled(f2, self.hold)
            # readings the addition sets aside (a bad channel's hold-out readings) are compared
            # for neither fit: what it claims is that they follow no model
            aside = e.set_aside_rows(self.hold) if e is not None else None
            keep = None if aside is None or not aside.any() else ~aside
            shared = f2.basis_without(f2.spec.effect_slices()[effect]) if e is not None else None
            fit, f2, metric = prediction_metric(fit, f2, self.hold, keep, shared)
            h2 = f2.holdout_chi2 if keep is None else holdout_chi2(f2, self.hold, keep)
            dh = h2 - (fit.holdout_chi2 if keep is None else holdout_chi2(fit, self.hold, keep))
            disp = holdout_dispersion(h2, len(self.hold.y) if keep is None else int(keep.sum()))
            # the veto weighs each hold-out case by its misfit (holdout_case_weights)
            mask = np.ones(len(self.hold.sigma), bool) if keep is None else keep
            w = holdout_case_weights(fit, f2, self.hold, mask)
            dhw = float(np.sum(w * (_whitened_sq(f2, self.hold) - _whitened_sq(fit, self.hold))))
            if dbic < 0 and not evidence(dbic, dhw) < 0:
                reasons.append(f"the hold-out prediction gets worse by more than the fit improves "
                               f"(delta BIC {dbic:+.4g}, hold-out chi2 {dh:+.4g}"
                               + (")" if np.all(w[mask] == 1.0) else f", {dhw:+.4g} with cases neither fit "
                                                                     f"predicts weighed down)"))
            elif (worse := holdout_worse(fit, f2, self.hold, keep, w, metric, shared)) is not None:
                reasons.append(worse)
        elif self.val.kind == "kfold":
            cv0, _ = self.cv(fit)
            cv1, checkable = self.cv(f2)
            dcv = cv1 - cv0
            checked = bool(checkable[effect])
            if not checkable[effect]:
                note = ("confined to cases no other fold predicts, or too weak in the cases the folds "
                        "predict to be told from noise: LR test and BIC only")
            elif not dcv < 0:
                reasons.append(f"the {self.val.k}-fold prediction over load cases is not better (chi2 {dcv:+.4g})")
        return Judgement(lr, lr_p, lr_adj, dbic, dh, dcv, tuple(reasons), note, disp, checked)


def _judged(c: CandidateScore, j: Judgement, **kw) -> CandidateScore:
    return replace(c, lr=j.lr, lr_p_value=j.lr_p, lr_p_adjusted=j.lr_p_adjusted, delta_bic=j.delta_bic,
                   holdout_delta_chi2=j.holdout_delta_chi2, holdout_dispersion=j.holdout_dispersion,
                   kfold_delta_chi2=j.kfold_delta_chi2, kfold_checked=j.kfold_checked,
                   accepted=j.accepted, reason=j.decision, **kw)


def _refit_variant(base: SplitBase, fit: Fit, i: int, e: Effect, x_e: np.ndarray, om: ObsMap, hold,
                   boundary, K_deck, o_dofs) -> tuple[Fit, Effect]:
    """Refit ``fit`` with its effect ``i`` replaced by the variant ``e`` from its nested start
    ``x_e`` (and, when some compliance starts at its bound 0, from it lifted off the bound); a
    parameter that ends at its nested bound is dropped and the rest refitted."""
    sl = fit.spec.effect_slices()[i]

    def at(e_new, xe):
        spec2 = fit.spec.replace_effect(i, e_new)
        x2 = np.concatenate([fit.x[:sl.start], xe, fit.x[sl.stop:]])
        return AugmentedModel(base, spec2, boundary, K_deck, o_dofs), x2

    m2, x2 = at(e, np.asarray(x_e, float))
    starts = [x2]
    one = e.one_sided
    if np.any(one & (x2[sl.start:sl.start + e.n_params] <= 0)):
        xs = x2.copy()
        xs[sl.start:sl.start + e.n_params] = np.where(one, np.maximum(x_e, 1e-3), x_e)
        starts.append(xs)
    best = _best_of(m2, om, hold, starts, e)
    xe = best.x[sl.start:sl.start + e.n_params]
    e2 = e.trimmed(xe)
    if e2 is not None:
        keep = np.array([n in e2.names for n in e.names])
        m3, x3 = at(e2, xe[keep])
        x3[:sl.start] = best.x[:sl.start]
        x3[sl.start + e2.n_params:] = best.x[sl.start + e.n_params:]
        best = fit_model(m3, om, hold, x3)
        e = e2
    return best, e


def refine(base: SplitBase, fit: Fit, i: int, om: ObsMap, hold: ObsMap | None, boundary, K_deck, o_dofs,
           alpha: float, multiplier: float, checks: Checks | None = None) -> tuple[Fit, tuple[VariantTrial, ...]]:
    """Climb effect ``i`` of ``fit`` up its richer variants (module docstring): refit each richer
    variant from its nested point, keep the accepted one with the strongest evidence (lowest
    ``delta BIC + hold-out chi2``), repeat from it. ``checks``: the search's tests (default: the
    hold-out when there is one). Returns the final fit and every variant tried."""
    checks = checks or Checks(om, hold, Validation("holdout" if hold is not None else "none"))
    trials: list[VariantTrial] = []
    while True:
        e = fit.spec.effects[i]
        sl = fit.spec.effect_slices()[i]
        best = None
        for r, xr in e.richer(fit.x[sl]):
            try:
                f2, r2 = _refit_variant(base, fit, i, r, xr, om, hold, boundary, K_deck, o_dofs)
            except IdentificationError as exc:
                trials.append(VariantTrial(r, e.variant, None, None, None, None, None, None, False,
                                           f"refit failed: {exc}"))
                continue
            j = checks.judge(fit, f2, multiplier, alpha, i)
            if f2.n_params <= fit.n_params:
                j = replace(j, reasons=j.reasons + ("no parameter added after dropping those at their bound",))
            trials.append(VariantTrial(r2, e.variant, f2, j.lr, j.lr_p, j.lr_p_adjusted, j.delta_bic,
                                       j.holdout_delta_chi2, j.accepted, j.decision, j.kfold_delta_chi2))
            if j.accepted and (best is None or j.evidence < best[1]):
                best = (f2, j.evidence)
        if best is None:
            return fit, tuple(trials)
        fit = best[0]


RICHER_RATIO = 2.0
"""How many times the score of its richer variants (at the nested point, the candidate's own
refit) a candidate's refined likelihood ratio is allowed to gain when :func:`refine_schedule`
decides whether it could win. The nested point is the candidate's optimum, close to where its
richer variant ends, so the score is a near estimate: on the 18 refinements of the
unlisted-structure benchmark's seed 10 box s0003 the refits gained 0.52 to 1.07 times it."""


def richer_gain(base: SplitBase, fit: Fit, i: int, om: ObsMap, boundary, K_deck, o_dofs) -> list[tuple[float, int]]:
    """``[(S, ddf)]`` per richer variant of effect ``i`` of ``fit`` (:meth:`Effect.richer`): the
    score statistic of the variant's model at its nested point (``fit`` itself: ``|P r|^2``,
    ``r`` the whitened residual and ``P`` the projection on the span of the variant's whitened
    Jacobian there) and the parameters it adds. Bounds are not imposed: the score can only be
    larger than the bounded one, so a schedule using it leaves out nothing the bounded one
    keeps."""
    e = fit.spec.effects[i]
    sl = fit.spec.effect_slices()[i]
    out = []
    for r, xr in e.richer(fit.x[sl]):
        spec2 = fit.spec.replace_effect(i, r)
        x2 = np.concatenate([fit.x[:sl.start], np.asarray(xr, float), fit.x[sl.stop:]])
        try:
            m2 = AugmentedModel(base, spec2, boundary, K_deck, o_dofs)
            st = m2.state(x2)
            res = (om.y - m2.predict(x2, om, st)) / om.sigma
            J = m2.jacobian(x2, om, st) / om.sigma[:, None]
        except (np.linalg.LinAlgError, IdentificationError, ValueError):
            continue
        if not (np.all(np.isfinite(res)) and np.all(np.isfinite(J))):
            continue
        scale = np.linalg.norm(J, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        d = np.linalg.lstsq(J / scale, res, rcond=1e-10)[0]
        out.append((float(np.sum(((J / scale) @ d) ** 2)), r.n_params - e.n_params))
    return out


def refine_schedule(base: SplitBase, candidates: Sequence[tuple[int, CandidateScore]], best_posterior: float,
                    om: ObsMap, boundary, K_deck, o_dofs) -> list[tuple[float, int]]:
    """``[(best case, index)]``, best first: the refitted candidates beyond the ``refine_top``
    whose richer variant could still be added. A candidate's best case is its posterior less
    ``RICHER_RATIO`` times its richer variant's score, plus that variant's added parameters
    times ``ln n`` (:func:`richer_gain`, the best over its variants); it is kept when that beats
    ``best_posterior``, the best accepted posterior so far. The caller refines them in this
    order and stops at the first best case the posterior of what it refined has passed."""
    out = []
    for k, c in candidates:
        i = len(c.refit.spec.effects) - 1
        ln_n = math.log(c.refit.n_obs)
        gains = richer_gain(base, c.refit, i, om, boundary, K_deck, o_dofs)
        if not gains:
            continue
        bound = c.posterior + min(-RICHER_RATIO * S + ddf * ln_n for S, ddf in gains)
        if bound < best_posterior:
            out.append((bound, k))
    return sorted(out)


def multipliers(pool: Sequence[Effect], round_no: int) -> dict[str, float]:
    """Kind -> the Bonferroni multiplier of one hypothesis of that kind in round ``round_no``:
    ``2^r K M_k`` -- the round spends ``alpha / 2^r``, shared equally among the ``K`` kinds of
    effect in the pool (every kind of explanation equally likely a priori), and within a kind
    evenly over its ``M_k`` hypotheses (candidates plus their variant upgrades). A kind with
    thousands of places (one reading an outlier, two channels swapped) thus does not dilute the
    level of a kind with a few (a support, a joint); the family-wise false-addition chance stays
    below ``sum_r alpha / 2^r < alpha``."""
    per = hypotheses_by_kind(pool)
    K = len(per)
    return {k: 2.0 ** round_no * K * m for k, m in per.items()}


def hypotheses_by_kind(pool: Sequence[Effect]) -> dict[str, int]:
    """Kind -> how many hypotheses its candidates in ``pool`` make: one per candidate (per
    :attr:`Effect.hypothesis`: a family chosen from the data as a whole is one) plus the
    variant upgrades each could be refined through."""
    seen: set = set()
    per: dict[str, int] = {}
    for e in pool:
        h = e.hypothesis
        per[e.kind] = per.get(e.kind, 0) + (h not in seen) + e.variant_tests
        seen.add(h)
    return per


SCREEN = 1.0
"""A structural candidate beyond the ``refit_top`` best is refitted only when its score's
adjusted p-value is below this: 1 is ``1 / alpha`` (100) times the round's level."""

SCORE_RATIO = 10.0
"""How many times its score a structural candidate's likelihood ratio is allowed to reach on a
refit when the schedule decides whether it could win (:func:`refit_schedule`): the score is the
local slope at the nested point, and a compliance or a member factor far from it bends away
from its tangent. Output-side candidates (factors, offsets, mixes on measured rows: linear in
their parameters) use their score as it is, plus ``OUTPUT_MARGIN``."""

OUTPUT_MARGIN = 10.0


SCREEN_DOF_COLUMNS = 2.0e7
"""What the removal screen may add to the split run, in model DOFs x new unit-load columns
(:func:`screen`): every member of a study of a few thousand DOFs (a few thousand columns cost
about a second through the reference solver), about 200 columns at 1e5 DOFs (15 s through
MYSTRAN, whose every right-hand side costs about 0.15 s there), 20 at 1e6."""


def _nearest_residual_order(effects: Sequence[Effect], fit: Fit, om: ObsMap, xyz: dict | None) -> list[Effect]:
    """``effects`` nearest the fit's residual first: each scores the largest per-grid RMS of the
    whitened residual discounted by ``exp(-distance / median member length)``, its position the
    mean of its DOFs' grids (:func:`~blackbox.diagnosis.effects.base.proximity`, as
    :meth:`CandidateContext.nearest_residual`)."""
    if not xyz:
        return list(effects)
    per: dict[int, list[float]] = {}
    for g, r in zip(om.grid, fit.residuals):
        per.setdefault(int(g), []).append(float(r) ** 2)
    meas = [(np.asarray(xyz[g], float), float(np.sqrt(np.mean(v)))) for g, v in per.items() if g in xyz]
    if not meas:
        return list(effects)
    P = np.array([p for p, _ in meas])
    w = np.array([v for _, v in meas])
    pos, ends = [], []
    for e in effects:
        pts = [np.asarray(xyz[g], float) for g in dict.fromkeys(int(d[0]) for d in e.refit_columns()) if g in xyz]
        pos.append(np.mean(pts, axis=0) if pts else np.full(3, np.nan))
        ends.append(float(np.linalg.norm(pts[0] - pts[-1])) if len(pts) > 1 else 0.0)
    ell = float(np.median([x for x in ends if x > 0])) if any(x > 0 for x in ends) else 1.0
    score = np.nan_to_num(proximity(np.array(pos), P, w, ell), nan=-1.0)
    return [effects[i] for i in np.argsort(-score, kind="stable")]


def screen(model: AugmentedModel, fit: Fit, om: ObsMap, pool: Sequence[Effect], base: SplitBase, boundary,
           K_deck, o_dofs, label: str, budget: int,
           xyz: dict | None = None) -> tuple[dict, int, int, dict]:
    """``(drops, columns added, candidates left out, which)``: effect key -> the chi2 drop of
    ``fit`` with the candidate added at the best of its
    :meth:`~blackbox.diagnosis.effects.base.Effect.screen_points` (``which``: key -> its index),
    every other parameter held, for the candidates of ``pool`` that have one. Their columns are
    run in one batch and kept for later rounds; beyond ``budget`` new columns, only the
    candidates nearest the fit's residual (whose columns fit in it, and every one whose columns
    are there already). A point where the augmented system is singular (a member whose removal
    leaves a mechanism) gives no entry. Held parameters make each drop a lower bound of what the
    candidate's refit reaches when it starts there (it does when the drop exceeds its score)."""
    todo = [e for e in pool if e.screen_points()]
    if not todo:
        return {}, 0, 0, {}
    have = set(base.col_of)
    chosen, new, left = [], {}, 0
    for e in _nearest_residual_order(todo, fit, om, xyz):
        extra = [tuple(d) for d in e.refit_columns() if tuple(d) not in have and tuple(d) not in new]
        if len(new) + len(extra) > budget:
            left += 1
            continue
        new.update(dict.fromkeys(extra))
        chosen.append(e)
    if new:
        base.ensure_columns(list(new), label)
    chi2_0 = float(np.sum(((om.y - model.predict(fit.x, om)) / om.sigma) ** 2))
    out, which = {}, {}
    for e in chosen:
        for k, (alt, point) in enumerate(e.screen_points()):
            spec2, x2 = fit.spec.add(alt, fit.x)
            x2[spec2.n_params - alt.n_params:] = point
            try:
                f = AugmentedModel(base, spec2, boundary, K_deck, o_dofs).predict(x2, om)
            except (np.linalg.LinAlgError, IdentificationError):
                continue
            chi2 = float(np.sum(((om.y - f) / om.sigma) ** 2))
            if np.isfinite(chi2) and (e.key not in out or chi2_0 - chi2 > out[e.key]):
                out[e.key], which[e.key] = chi2_0 - chi2, k
    return out, len(new), left, which


def refit_schedule(scored: Sequence[CandidateScore], best_evidence: float, alpha: float,
                   log_n: float, screened: dict | None = None,
                   multiplier: dict | None = None, family: dict | None = None) -> list[CandidateScore]:
    """The candidates (not refitted yet) that could still win on a refit against the best
    accepted candidate so far, ``best_evidence`` (its :attr:`~CandidateScore.posterior`, ``delta
    BIC + hold-out chi2 + prior``; infinite when none was accepted: then every candidate that
    could be accepted). A candidate's best case is ``-c S + df ln n``, its score ``S`` times ``c =
    SCORE_RATIO`` for a structural candidate and ``c = 1`` (less ``OUTPUT_MARGIN``) for an
    output-side one: it must lower BIC and, with its own prior added, beat ``best_evidence``; it
    must also be significant on its score at ``SCREEN`` (structural) or at the round's level
    (output-side). So a candidate is left out only when even that best case cannot be accepted
    or win -- the stated guarantee of the search. The cost: the refits the schedule adds are counted in each
    round's ``candidates`` (``refit``) and measured in docs (benchmarks/diagnose_refits.py).

    ``screened``: effect key -> the chi2 drop at the candidate's screen point (:func:`screen`),
    a lower bound of its refit's; a candidate whose drop alone is significant at ``SCREEN``
    (``multiplier``: its kind's Bonferroni factor) and beats the best evidence is refitted
    whatever its score. So the guarantee also covers effects that are small to first order
    and large when complete.

    ``family``: effect key -> ``(S, df)``, the score of the candidate's richest variant
    (:func:`blackbox.diagnosis.scoring.family_scores`); a candidate whose family score is
    significant at ``SCREEN`` and whose best case on it beats the best evidence is refitted
    (and its richer variants then weighed by :func:`refine_schedule`). So the guarantee covers
    what its richer variants could reach, not only its simplest one."""
    out = []
    screened, multiplier, family = screened or {}, multiplier or {}, family or {}

    def wins(best_case: float, c: CandidateScore) -> bool:
        return best_case < 0.0 and best_case + c.prior < best_evidence

    for c in scored:
        if c.df == 0:
            continue
        if c.effect.acts_on_output:
            ok = c.p_adjusted < alpha and wins(-c.score + c.df * log_n - OUTPUT_MARGIN, c)
        else:
            ok = c.p_adjusted < SCREEN and wins(-SCORE_RATIO * c.score + c.df * log_n, c)
            d = screened.get(c.effect.key)
            if not ok and d is not None and d > 0:
                p = min(1.0, multiplier.get(c.effect.kind, 1.0) * float(stats.chi2.sf(d, c.df)))
                ok = p < SCREEN and wins(-d + c.df * log_n, c)
            fam = family.get(c.effect.key)
            if not ok and fam is not None:
                S_f, df_f = fam
                p = min(1.0, multiplier.get(c.effect.kind, 1.0) * float(stats.chi2.sf(S_f, df_f)))
                ok = p < SCREEN and wins(-SCORE_RATIO * S_f + c.df * log_n, c)
        if ok:
            out.append(c)
    return out


@dataclass(frozen=True)
class _Refits:
    """What a refit of the current model without one of its effects needs."""
    base: SplitBase
    om: ObsMap
    hold: ObsMap | None
    boundary: tuple
    K_deck: np.ndarray | None
    o_dofs: tuple
    joints: tuple
    declared: Fit


def without(ctx: _Refits, fit: Fit, j: int) -> Fit:
    """``fit`` refitted without its effect ``j``: the declared joints with the other effects
    added in their order, every parameter started at its value in ``fit`` (a joint model an
    effect changed -- a coupling -- and removed again starts at the declared estimate)."""
    spec, x = ModelSpec(ctx.joints), ctx.declared.x.copy()
    for i, e in enumerate(fit.spec.effects):
        if i != j:
            spec, x = spec.add(e, x)
    val = dict(zip(fit.spec.names, fit.x))
    x = np.array([val.get(nm, v) for nm, v in zip(spec.names, x)])
    model = AugmentedModel(ctx.base, spec, ctx.boundary, ctx.K_deck, ctx.o_dofs)
    return fit_model(model, ctx.om, ctx.hold, x)


def eliminate(ctx: _Refits, fit: Fit, mults: dict, alpha: float, checks: "Checks") -> tuple[Fit, list]:
    """Backward elimination after an addition: every earlier effect is judged again as if it
    were added last to the model without it (the same tests, at the level it was admitted
    with); of those that no longer pass, the weakest (highest ``delta BIC + hold-out chi2``) is
    removed and the rest judged again, until every effect passes. The effect just added is not
    judged again. Returns the final fit and ``[(effect, Judgement)]`` removed."""
    removed = []
    while len(fit.spec.effects) >= 2:
        worst = None
        for j, e in enumerate(fit.spec.effects[:-1]):
            try:
                f_minus = without(ctx, fit, j)
            except IdentificationError:
                continue
            jd = checks.judge(f_minus, fit, mults.get(e.key, 1.0), alpha, j)
            if not jd.accepted:
                ev = jd.evidence
                if worst is None or ev > worst[0]:
                    worst = (ev, e, jd, f_minus)
        if worst is None:
            break
        _, e, jd, f_minus = worst
        removed.append((e, jd))
        fit = f_minus
    return fit, removed


NESTING_TOL = 0.05
"""Whitened norm ``|(f_split - f_declared) / sigma|`` of the split deck's rigid-state difference
from the declared model below which it cannot matter: it moves the chi2 by ``2 r.d + |d|^2``,
at most ~0.1, far below any decision of the search (a BIC step of a few units)."""

NESTING_STIFF = 1e-6
"""The nesting is checked with every joint spring at most this fraction of its rigid limit
(``RIGID_RATIO * NESTING_STIFF`` = 100 times the structure's stiffness along it): a split deck
that is another structure shows there as anywhere, while at the rigid limit itself the
declared model's own evaluation keeps too few digits (measured on a blind ladder study whose
fit pushed 25 springs to 1e12-1e13: relative differences 2e-4 at the limit, 3e-5 at 1e-3 of
it, 6e-10 at 1e-6 of it)."""

NESTING_ROUNDING = 10.0
"""Beyond :data:`NESTING_TOL`, a difference is still the solver's rounding when its relative
size (largest difference over the largest prediction of the same kind, translations or
rotations) stays below this many times ``eps_solver * cond(S)``: the split run's relative noise
(its flexibility's asymmetry, at least double precision) amplified by the conditioning on the
cut pairs or, when larger, of the augmented system at the declared fit (a declared spring many
decades stiffer than the members around it). Measured: the actual difference is ~1e-2 of ``eps_solver * cond(S)`` (MYSTRAN's 7
printed digits on the rich test deck and on the shell-panel car body of
``tests/test_unmodelled.py``), so the factor leaves a margin of ~1e3; an edited deck that lost a
coordinate system or a support set differs by 1e-2..1 relative."""


def declared_fit(model: AugmentedModel, om: ObsMap, hold: ObsMap | None, x0: np.ndarray) -> Fit:
    """The declared model's fit, which every addition is judged against: from ``x0`` (the
    identification's estimate) and once more with each simple joint's springs all at the median
    of its estimate; the lower chi2 is kept. The identification can end with single springs
    thrown to 0 or rigid at a local minimum, and a misfit left there would be explained by added
    effects on data that have nothing wrong (a clean study of the blind benchmark started at
    reduced chi2 1.53 where the equal start reaches 1.10)."""
    fit = fit_model(model, om, hold, x0)
    xs = np.asarray(x0, float).copy()
    simple = False
    for j, sl in zip(model.spec.joints, model.spec.joint_slices()):
        if isinstance(j, SimpleJoint) and sl.stop > sl.start:
            xs[sl] = float(np.median(x0[sl]))
            simple = True
    if simple and not np.array_equal(xs, x0) and np.all(np.isfinite(xs)) and np.all(xs > 0.0):
        try:
            alt = fit_model(model, om, hold, xs)
        except IdentificationError:         # the equal start is singular: the first fit stands
            return fit
        if alt.chi2 < fit.chi2:
            return alt
    return fit


def check_nesting(f_split: np.ndarray, f_declared: np.ndarray, om: ObsMap, labels: Sequence[str],
                  solver_rounding: float = 0.0, condition: float = 1.0) -> tuple[float, str | None]:
    """The largest rigid-state difference in sigma, and a warning when it exceeds
    :data:`NESTING_TOL` within the solver's rounding (:data:`NESTING_ROUNDING`); beyond the
    rounding, :class:`EditedDeckError` with the rows that differ most."""
    f_split, f_declared = np.asarray(f_split, float), np.asarray(f_declared, float)
    d = (f_split - f_declared) / om.sigma
    if not d.size:
        return 0.0, None
    nest = float(np.max(np.abs(d)))
    norm = float(np.linalg.norm(d))
    if norm <= NESTING_TOL:
        return nest, None
    rot = (om.comp >= 4) if om.comp is not None else np.zeros(len(d), bool)
    rel = 0.0
    for grp in (rot, ~rot):
        if grp.any():
            scale = float(np.max(np.abs(f_declared[grp]))) or 1.0
            rel = max(rel, float(np.max(np.abs(f_split[grp] - f_declared[grp]))) / scale)
    allowed = NESTING_ROUNDING * max(solver_rounding, np.finfo(float).eps) * max(condition, 1.0)
    if np.isfinite(rel) and rel <= allowed:
        return nest, (f"the split deck reproduces the declared model to {norm:.3g} sigma (whitened norm; "
                      f"largest {nest:.3g}): the solver's rounding (relative {rel:.2g}, within "
                      f"{allowed:.2g} = {NESTING_ROUNDING:g} x its noise x the conditioning) "
                      "is not small against the declared sigma here, so scores and refits carry it")
    order = np.argsort(-np.abs(d))[:10]
    rows = [(int(om.grid[i]), int(om.comp[i]) if om.comp is not None else 0, str(labels[om.case[i]]),
             float(d[i])) for i in order]
    raise EditedDeckError(
        f"the split deck at its rigid state does not reproduce the declared model: the predictions "
        f"differ by {norm:.3g} sigma (whitened norm over {len(d)} rows), {rel:.2g} relative where the "
        f"solver's rounding allows {allowed:.2g}, most at " + ", ".join(
            f"grid {g} component {c} case {k} ({v:+.3g} sigma)" for g, c, k, v in rows[:5]), rows)


def diagnose(base: SplitBase, boundary: Sequence[DofLabel], K_deck: np.ndarray | None,
             joints: Sequence[JointModel], k_start: np.ndarray, obs_fit: Observations,
             obs_hold: Observations | None, candidates: Sequence[Effect], *, alpha: float = 0.01,
             refit_top: int = 6, refine_top: int = REFINE_TOP, max_steps: int = 5, band_level: float = 0.99,
             declared_prediction: np.ndarray | None = None, xyz: dict | None = None,
             progress=None, executor=None, always_map_refits: bool = False,
             load_magnitudes: tuple[float, float] | None = None, complete_refits: bool = True,
             declared_predict: Callable[[np.ndarray], np.ndarray] | None = None,
             holdout_loads: Sequence[Effect] = ()) -> Diagnosis:
    """The loop of the module docstring. ``k_start``: the declared joints' estimate (e.g. from
    :func:`blackbox.identification.identify`); ``declared_prediction``: that estimate's fit-row
    predictions on the original deck, to measure how exactly the split deck nests the declared
    model (``nesting_error``, in sigma); ``executor``: where each round's refits run when that
    pays (:func:`map_refits`, :func:`refits_pay`; ``always_map_refits``: whenever there is one);
    default here. ``load_magnitudes``: the study's typical force and moment, the size of the
    load cases the report proposes to separate near-equal alternatives
    (:mod:`blackbox.diagnosis.separation`). ``complete_refits=False`` refits only the
    ``refit_top`` best by score and refines only the ``refine_top`` strongest (what the
    guarantees of :func:`refit_schedule` and :func:`refine_schedule` cost is measured against
    it: ``benchmarks/refit_schedule.py``). ``declared_predict(k)``: the declared
    model's fit-row predictions at any ``k``; when the estimate has springs beyond their rigid
    limit (:meth:`AugmentedModel.rigid_limits`, where both models are rounding), the nesting is
    checked at those limits instead, as the fit starts there. ``holdout_loads``: effects in a
    hold-out case (a load turned or put in at a neighbouring grid there) that the hold-out check
    tries a case it does not predict as (:func:`~blackbox.diagnosis.holdout.check_holdout`)."""
    t0 = time.perf_counter()
    boundary = tuple(boundary)
    o_dofs = tuple(dict.fromkeys(list(obs_fit.dofs) + [r for r in obs_fit.ref_dofs if r is not None]
                                 + (list(obs_hold.dofs) + [r for r in obs_hold.ref_dofs if r is not None]
                                    if obs_hold is not None else [])
                                 + [d for e in candidates for d in e.source_dofs]))
    o_index = {d: i for i, d in enumerate(o_dofs)}
    om = ObsMap.of(obs_fit, o_index)
    hold = ObsMap.of(obs_hold, o_index) if obs_hold is not None and len(obs_hold) else None
    warnings: list[str] = []

    spec = ModelSpec(tuple(joints))
    model = AugmentedModel(base, spec, boundary, K_deck, o_dofs)
    x0 = np.asarray(k_start, float)
    nest = None
    if declared_prediction is not None:
        x_nest, f_declared = x0, declared_prediction
        limit = model.rigid_limits()
        if declared_predict is not None and np.any(x0 > NESTING_STIFF * limit):
            # a spring at 1e14-1e21 (a joint stiffer than rigid would be) leaves both predictions
            # to rounding there, beyond any check; whether the split deck is the declared
            # structure shows as well where the springs are merely stiff, and there both agree
            # to a few digits more than the check needs
            x_nest = np.minimum(x0, NESTING_STIFF * limit)
            f_declared = np.asarray(declared_predict(x_nest), float)
            names = [n for n, a, b in zip(spec.names, x0, limit) if a > b]
            if names:
                warnings.append(f"the declared estimate has {len(names)} spring(s) beyond their rigid limit "
                                f"({', '.join(names[:4])}{' ...' if len(names) > 4 else ''}; {RIGID_RATIO:g} x "
                                "the structure's stiffness along each), where its predictions are rounding: the "
                                "diagnosis starts at that limit, and the split deck's nesting is checked with "
                                f"those springs at {RIGID_RATIO * NESTING_STIFF:g} x the structure's stiffness")
        # the rounding of both evaluations grows with the cut pairs' conditioning and with the
        # augmented system's at the point compared (the identification solves the same system)
        nest, note = check_nesting(model.predict(x_nest, om), f_declared, om, obs_fit.case_labels,
                                   base.symmetry_error, max(base.condition, model.condition(x_nest)))
        if note:
            warnings.append(note)
    t_fit = time.perf_counter()
    fit = declared_fit(model, om, hold, x0)
    fit_s = None if always_map_refits else time.perf_counter() - t_fit
    declared = fit
    val = Validation("holdout") if hold is not None else kfold(np.unique(om.case))
    checks = Checks(om, hold, val)
    steps: list[Step] = []
    counts: dict = {}
    for e in candidates:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    stop = "max_steps reached"
    candidates = list(candidates)
    labels = obs_fit.case_labels
    kept_mult: dict = {}                 # effect key -> the multiplier it was admitted with
    ctx = _Refits(base, om, hold, boundary, K_deck, o_dofs, tuple(joints), declared)
    n_dof = len(base.adapter.dofs()) if base.adapter is not None else 1
    screen_budget, screen_left = int(SCREEN_DOF_COLUMNS / max(n_dof, 1)), 0
    for it in range(max_steps):
        runs0 = len(base.log)
        if it:                          # candidates that depend on the current fit, re-listed from it
            for fam in dict.fromkeys(type(e) for e in candidates):
                candidates = fam.refresh(candidates, fit, om, labels)
        pool = [e for e in candidates if not fit.spec.has(e) and e.applicable(fit.spec)]
        if not pool:
            stop = "no candidate left"
            break
        mults = multipliers(pool, it + 1)
        by_kind = hypotheses_by_kind(pool)
        M = sum(by_kind.values())                       # the round's hypotheses
        raw = score_candidates(model, fit, om, pool, boundary, K_deck, o_dofs)
        n = fit.n_obs
        scored = []
        Ss = np.array([r[1] for r in raw], float)
        dfs = np.array([r[2] for r in raw], int)
        ps, lps = np.ones(len(raw)), np.zeros(len(raw))
        for df in np.unique(dfs[dfs > 0]):          # one vectorised call per df (thousands of candidates)
            k = dfs == df
            ps[k] = stats.chi2.sf(Ss[k], df)
            lps[k] = log10_sf_array(Ss[k], int(df))
        for (e, S, df, step), p, lp in zip(raw, ps, lps):
            scored.append(CandidateScore(e, S, df, float(p), float(lp), min(1.0, mults[e.kind] * float(p)), step,
                                         (-S + df * math.log(n)) if df else 0.0, "score approximation",
                                         prior=2.0 * math.log(by_kind[e.kind])))
        scored.sort(key=lambda c: (c.log10_p + math.log10(mults[c.effect.kind]), -c.score))
        refits: list[CandidateScore] = []
        done_keys: set = set()

        def run_refits(chunk):
            need = [d for c in chunk for d in c.effect.refit_columns()]
            if need:
                base.ensure_columns(need, f"member columns for refits (round {it + 1})")
            done_all = map_refits(base, fit, chunk, om, hold, boundary, K_deck, o_dofs, executor, fit_s)
            for c, done in zip(chunk, done_all):
                done_keys.add(c.effect.key)
                if isinstance(done, IdentificationError):
                    refits.append(replace(c, reason=f"refit failed: {done}"))
                    continue
                f2, e2 = done
                refits.append(_judged(c, checks.judge(fit, f2, mults[c.effect.kind], alpha,
                                                      len(f2.spec.effects) - 1),
                                      effect=e2, refit=f2, delta_bic_method="refit"))

        # the refit_top best by score, then every candidate that could still beat the best
        # refit's evidence (refit_schedule); a second pass cannot admit more, since the best
        # evidence only falls
        run_refits([c for c in scored[:refit_top] if c.df > 0])
        best_ev = min((c.posterior for c in refits if c.refit is not None and c.accepted), default=math.inf)
        if complete_refits:
            screened, used, left, which = screen(model, fit, om, [c.effect for c in scored], base, boundary,
                                                 K_deck, o_dofs,
                                                 f"member columns for the removal screen (round {it + 1})",
                                                 screen_budget, xyz)
            screen_budget -= used
            screen_left = max(screen_left, left)
            # a candidate the screen shows larger than its score is large only when complete:
            # its refit also starts there
            scored = [c if c.effect.key not in screened else
                      replace(c, screen_drop=screened[c.effect.key],
                              effect=(c.effect.started_at_screen(which[c.effect.key])
                                      if screened[c.effect.key] > c.score else c.effect))
                      for c in scored]
            rest = [c for c in scored if c.effect.key not in done_keys]
            family = family_scores(model, fit, om, [c.effect for c in rest if c.df > 0 and not c.effect.acts_on_output],
                                   boundary, K_deck, o_dofs)
            run_refits(refit_schedule(rest, best_ev, alpha, math.log(fit.n_obs), screened, mults, family))
            # refitted already, but as a variant that cannot reach what another of its screen
            # points shows (a member refitted as one factor whose section is turned): refitted
            # again from there, and the better of the two refits kept
            first_refit = {c.effect.key: c for c in refits if c.refit is not None}
            again = [replace(c, effect=c.effect.started_at_screen(which[c.effect.key])) for c in scored
                     if which.get(c.effect.key, 0) != 0 and c.effect.key in first_refit
                     and screened[c.effect.key] > (first_refit[c.effect.key].lr or 0.0)]
            if again:
                n0 = len(refits)
                run_refits(again)
                for c2 in refits[n0:]:
                    c1 = first_refit[c2.effect.key]
                    worse = c2 if (c2.refit is None or (c1.accepted, -c1.evidence) >= (c2.accepted, -c2.evidence)) \
                        else c1
                    refits[:] = [c for c in refits if c is not worse]
        # the strongest candidates at the variant their data support, before they compete: every
        # refit that lowers BIC, not only the accepted ones (a joint loose about one axis is not
        # significant as one equal spring, but is as one spring per axis)
        order = sorted((k for k, c in enumerate(refits) if c.refit is not None and c.delta_bic < 0),
                       key=lambda k: refits[k].posterior)

        def run_refine(k):
            c = refits[k]
            i = len(c.refit.spec.effects) - 1
            mk = mults[c.effect.kind]
            f3, trials = refine(base, c.refit, i, om, hold, boundary, K_deck, o_dofs, alpha, mk, checks)
            if f3 is not c.refit:
                c = _judged(c, checks.judge(fit, f3, mk, alpha, i), effect=f3.spec.effects[-1], refit=f3)
            refits[k] = replace(c, variants=trials)

        for k in order[:refine_top]:
            run_refine(k)
        # then every other one whose richer variant could still win (refine_schedule): a
        # connection released on one branch shows little as one equal spring on all of them
        best_post = min((c.posterior for c in refits if c.accepted), default=math.inf)
        later = [(k, refits[k]) for k in order[refine_top:]] if complete_refits else []
        for bound, k in refine_schedule(base, later, best_post, om, boundary, K_deck, o_dofs):
            if bound >= best_post:
                break
            run_refine(k)
            if refits[k].accepted:
                best_post = min(best_post, refits[k].posterior)
        ok = [c for c in refits if c.accepted]
        best = min(ok, key=lambda c: c.posterior) if ok else None
        by_prediction = kfold_tiebreak(best, ok) if best is not None and val.kind == "kfold" else best
        if best is not None:
            probable = best

            def why(c: CandidateScore) -> str:
                if by_prediction is not probable and kfold_tied(c, probable):
                    return (f"accepted, but another candidate that the fitted data support as well (evidence "
                            f"within {KFOLD_TIE:g}) predicts the left-out cases better (K-fold chi2 "
                            f"{by_prediction.kfold_delta_chi2:+.4g} against {c.kfold_delta_chi2:+.4g})")
                return ("accepted, but another candidate is more probable (lower delta BIC + hold-out chi2 + "
                        "2 ln of its kind's hypotheses)")

            best = by_prediction
            refits = [replace(c, reason=why(c)) if (c.accepted and c is not best) else c for c in refits]
            best = next(c for c in refits if c.effect is best.effect)
        by_key = {c.effect.key: c for c in refits}
        ranked = [by_key.get(c.effect.key, c) for c in scored]
        sb = residual_structure(obs_fit, fit.residuals, xyz)
        levels = {k: alpha / m for k, m in mults.items()}
        if best is None:
            steps.append(Step(fit, tuple(ranked), None, fit, sb, sb, len(base.log) - runs0,
                              min(levels.values()), M, levels=levels, by_kind=by_kind))
            stop = ("no candidate is significant at the round's level (alpha spending, Bonferroni "
                    "within each kind of effect, the kinds weighed equally), improves BIC and passes the check "
                    "against data it was not fitted to: " + val.describe() + ")")
            break
        seps = {}
        for c in refits:                    # what would separate the near-equal alternatives
            if (c.accepted or c.reason.startswith("accepted")) and c is not best and c.refit is not None \
                    and near_tie(c, best) and len(seps) < 2:
                seps[c.effect.key] = separating_measurements(base, best.refit, c.refit, boundary, K_deck, om,
                                                             load_magnitudes)
        subsumed = [(o, Judgement(0.0, 1.0, 1.0, 0.0, None, None,
                                  (f"subsumed by {best.effect.label()}: its readings are set aside",)))
                    for o in fit.spec.effects if not best.refit.spec.has(o)]
        for o, _ in subsumed:
            kept_mult.pop(o.key, None)
        kept_mult[best.effect.key] = mults[best.effect.kind]
        if best.effect.source_dofs:         # later member scores read the mixed rows by reciprocity
            base.ensure_columns(best.effect.source_dofs, f"columns at the DOFs {best.effect.label()} reads")
        new, removed = eliminate(ctx, best.refit, kept_mult, alpha, checks)
        removed = subsumed + removed
        for e, _ in removed:
            kept_mult.pop(e.key, None)
        steps.append(Step(fit, tuple(ranked), best, new, sb, residual_structure(obs_fit, new.residuals, xyz),
                          len(base.log) - runs0, levels[best.effect.kind], M, levels=levels,
                          by_kind=by_kind, removed=tuple(removed), separations=seps))
        if progress is not None:
            progress(steps[-1])
        fit = new
        model = AugmentedModel(base, fit.spec, boundary, K_deck, o_dofs)
    lo, hi = chi2_band(fit.n_obs - fit.n_params, band_level)
    if val.kind == "none":
        warnings.append("one fitted case and no hold-out cases: effects were added on the LR test and BIC "
                        "alone, without a check of their prediction")
    if screen_left:
        warnings.append(f"the member removal screen left out up to {screen_left} member(s) whose own columns would "
                        f"exceed its share of the solver's work ({SCREEN_DOF_COLUMNS:g} model DOFs x columns); "
                        "it took those nearest the residual: a member missing elsewhere is found only if its "
                        "score shows it")
    if fit.reduced_chi2 > hi:
        warnings.append(f"the final reduced chi2 {fit.reduced_chi2:.4g} is above the {band_level:.0%} "
                        f"band [{lo:.4g}, {hi:.4g}] of the declared noise: the misfit is unexplained")
    elif fit.reduced_chi2 < lo:
        warnings.append(f"the final reduced chi2 {fit.reduced_chi2:.4g} is below the {band_level:.0%} "
                        f"band [{lo:.4g}, {hi:.4g}] of the declared noise: the declared sigma may be too large")
    for j, sl in zip(fit.spec.joints, fit.spec.joint_slices()):
        if isinstance(j, ComplexJoint) and not j.is_admissible(fit.x[sl]):
            warnings.append(f"joint {j.name}: the fitted K_C is not positive semi-definite")
    hc = None
    final_model = AugmentedModel(base, fit.spec, boundary, K_deck, o_dofs)
    rig = next((e for e in candidates if e.kind == "rigid_motion"), None)     # its measured-grid geometry
    geometry = None if rig is None else (rig.geometry, rig.centre)
    loads = None
    if hold is not None and holdout_loads:
        def augment(effects):
            spec2, x2 = fit.spec, fit.x
            for e in effects:
                spec2, x2 = spec2.add(e, x2)
            try:
                return AugmentedModel(base, spec2, boundary, K_deck, o_dofs), x2
            except (np.linalg.LinAlgError, IdentificationError):
                return None
        loads = (lambda label: [e for e in holdout_loads if e.case == label], augment)
    if hold is not None:
        hc = check_holdout(final_model, fit, hold, alpha, geometry, om, loads=loads)
        warnings += [f"hold-out check: {w}" for w in hc.sentences()]
    nl = None
    if fit.reduced_chi2 > hi:
        # readings an offset of their own takes (set aside, outliers) say nothing of the noise
        taken = np.zeros(len(om.y), bool)
        for e in fit.spec.effects:
            if takes_readings(e):
                for _, rows in e.offset_rows(om):
                    taken |= np.asarray(rows, bool)
        kept = ~taken
        h = leverages(fit.J[:, free_parameters(final_model, fit)])
        predicted = om.y - fit.residuals * om.sigma
        nl = noise_level(fit.residuals[kept], h[kept], om.grid[kept], om.case[kept], om.comp[kept],
                         om.sigma[kept], predicted[kept], alpha,
                         None if hold is None else (lambda c: check_holdout(final_model, fit, hold, alpha, geometry,
                                                                            om, noise_factor=c, loads=loads).predicted))
        warnings.append(nl.sentence())
    kf = None
    if val.kind == "kfold":
        kf = {"k": val.k, "folds": [[obs_fit.case_labels[c] for c in f] for f in val.folds],
              "cv_chi2_before": checks.cv(declared)[0], "cv_chi2_after": checks.cv(fit)[0]}
    return Diagnosis(declared, fit, tuple(steps), counts, alpha, (lo, hi),
                     tuple(obs_hold.case_labels[c] for c in obs_hold.cases) if obs_hold is not None else (),
                     nest, tuple(base.log), time.perf_counter() - t0, stop, tuple(warnings),
                     hotspots(obs_fit, fit.residuals), val, kf, hc, nl)
