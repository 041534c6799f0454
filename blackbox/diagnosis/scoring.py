"""Score (Lagrange multiplier) tests of candidate effects at the current optimum.

Whitened residuals ``r``, Jacobians ``J`` at the current optimum (declared sigma). The score test
of a candidate with Jacobian ``J_c``: ``S = h^T M^+ h`` with ``M = (Pi J_c)^T Pi J_c``,
``h = (Pi J_c)^T Pi r`` and ``Pi`` the projector out of the span of the current model's *free*
parameters' columns (a spring held at its bound 0 leaves its direction to a candidate that can go
beyond it, as the complex model can); for one-sided parameters (compliances ``>= 0``) ``S`` is the
largest decrease of the linearised chi2 over the cone ``theta >= 0`` and ``chi2(df)`` a
conservative reference; ``df = rank M``. Everything through Gram matrices of a few columns (a
LAPACK SVD of the tall Jacobian costs 100x more with a threaded BLAS).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import optimize, stats

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.fit import GRAM_RTOL, Fit
from blackbox.diagnosis.model import AugmentedModel, ObsMap
from blackbox.errors import IdentificationError

__all__ = ["CandidateScore", "Projector", "fit_projector", "score_test", "sparse_score", "score_candidates",
           "family_scores", "log10_sf", "log10_sf_array", "SCORE_RTOL"]

SCORE_RTOL = 1e-8           # a candidate direction whose part outside the model's span is below
                            # 1e-4 of its own size (eigenvalue 1e-8) adds nothing (rounding)


def evidence(delta_bic: float, holdout_delta_chi2: float | None, dispersion: float = 1.0) -> float:
    """``delta BIC`` plus the hold-out chi2 change when there are hold-out cases
    (:mod:`blackbox.diagnosis.validation`), that change divided by the hold-out's ``dispersion``
    (:func:`blackbox.diagnosis.search.holdout_dispersion`) where it ranks additions against each
    other; admitting one weighs it undivided (``dispersion`` 1)."""
    return delta_bic + (holdout_delta_chi2 or 0.0) / dispersion


@dataclass(frozen=True, eq=False)
class CandidateScore:
    """The score test of one candidate at the current optimum, and its refit if it was made."""
    effect: Effect
    score: float
    df: int
    p_value: float
    log10_p: float
    p_adjusted: float
    step_estimate: np.ndarray           # one Gauss-Newton step from the nested point
    delta_bic: float                    # refit, else the score approximation -S + df log n
    delta_bic_method: str
    refit: Fit | None = None
    lr: float | None = None
    lr_p_value: float | None = None
    lr_p_adjusted: float | None = None
    holdout_delta_chi2: float | None = None
    holdout_dispersion: float = 1.0     # search.holdout_dispersion after the refit
    accepted: bool = False
    reason: str = ""
    variants: tuple = ()                # search.VariantTrial: richer variants tried after acceptance
    kfold_delta_chi2: float | None = None
    kfold_checked: bool = False         # some fold both learnt and predicted with it (validation.cv_chi2)
    screen_drop: float | None = None    # the chi2 drop at the effect's screen point, others held
                                        # (search.screen: a member removed), when evaluated
    prior: float = 0.0                  # 2 ln M_k: -2 ln of its prior probability, up to the
                                        # round's shared constant (search.multipliers)

    @property
    def evidence(self) -> float:
        """``delta_bic`` plus the hold-out chi2 change (when there are hold-out cases) over the
        hold-out's dispersion (:func:`evidence`): the data's evidence
        for the addition, in which the gap to an alternative is measured."""
        return evidence(self.delta_bic, self.holdout_delta_chi2, self.holdout_dispersion)

    @property
    def posterior(self) -> float:
        """:attr:`evidence` plus :attr:`prior`: -2 ln of the candidate's posterior odds against the
        current model, up to the round's shared constant. What chooses the addition among the
        accepted candidates."""
        return self.evidence + self.prior


class Projector:
    """Projection out of the span of the current model's whitened Jacobian ``J0``, through its
    (column-scaled) Gram matrix: ``Pi r = r - J0 N0^+ J0^T r``."""

    def __init__(self, J0: np.ndarray, r: np.ndarray):
        self.J0, self.r = J0, r
        p = J0.shape[1]
        if p:
            s = np.linalg.norm(J0, axis=0)
            self.s = np.where(s > 0, s, 1.0)
            w, V = np.linalg.eigh((J0.T @ J0) / np.outer(self.s, self.s))
            keep = w > GRAM_RTOL * max(float(w[-1]), 1e-300)
            self.Ninv = (V[:, keep] / w[keep]) @ V[:, keep].T
            self.b0 = (J0.T @ r) / self.s
        self.p = p

    def reduced(self, Jc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(M, h)`` = ``((Pi Jc)^T Pi Jc, (Pi Jc)^T Pi r)``."""
        M = Jc.T @ Jc
        h = Jc.T @ self.r
        if self.p:
            C = (self.J0.T @ Jc) / self.s[:, None]
            M = M - C.T @ self.Ninv @ C
            h = h - C.T @ self.Ninv @ self.b0
        return 0.5 * (M + M.T), h


def score_test(proj: Projector, Jc: np.ndarray, one_sided: np.ndarray):
    """``(S, df, step)``: the score statistic of the extra whitened columns ``Jc`` given the
    current fit (``proj``): ``S = h^T M^+ h`` with ``M, h`` the projected Gram matrix and
    right-hand side, or, when some parameters are one-sided (compliances ``>= 0``), the largest
    decrease of chi2 of the linearised problem over the feasible cone. ``df``: the rank of ``M``
    (eigenvalues above ``SCORE_RTOL`` of the columns' own scale); ``step``: the maximiser (one
    Gauss-Newton step from the nested point)."""
    M, h = proj.reduced(Jc)
    return _score_of(M, h, np.sqrt(np.maximum(np.sum(Jc ** 2, axis=0), 1e-300)), one_sided)


def _score_of(M: np.ndarray, h: np.ndarray, scale: np.ndarray, one_sided: np.ndarray):
    """:func:`score_test` from the projected Gram matrix ``M`` and right-hand side ``h`` of
    columns of norms ``scale``."""
    pc = len(h)
    step = np.zeros(pc)
    Ms, hs = M / np.outer(scale, scale), h / scale
    w, V = np.linalg.eigh(Ms)
    keep = w > SCORE_RTOL
    df = int(np.sum(keep))
    if not df:
        return 0.0, 0, step
    Vk, wk = V[:, keep], w[keep]
    full = float(np.sum((Vk.T @ hs) ** 2 / wk))
    th = Vk @ ((Vk.T @ hs) / wk)
    if np.any(one_sided) and np.any(th[one_sided] < 0):
        R = np.sqrt(wk)[:, None] * Vk.T                      # M = R^T R on its range
        b = (Vk.T @ hs) / np.sqrt(wk)
        lb = np.where(one_sided, 0.0, -np.inf)
        th = optimize.lsq_linear(R, b, bounds=(lb, np.full(pc, np.inf)), method="bvls").x
        full = float(b @ b - np.sum((R @ th - b) ** 2))
    step = th / scale
    return max(full, 0.0), df, step


def sparse_score(proj: Projector, rows: np.ndarray, col: np.ndarray, one_sided: np.ndarray):
    """:func:`score_test` of one whitened column that is zero outside ``rows`` (values ``col``
    there), without forming it: ``M = c.c - C^T N^+ C`` and ``h = c.r - C^T N^+ b0`` with
    ``C = J0[rows]^T c`` (column-scaled). ``col`` of shape ``(len(rows), q)``: ``q`` columns
    that are all zero outside ``rows`` (one channel's per-case offsets)."""
    rows = np.asarray(rows, int)
    c = np.asarray(col, float)
    if c.ndim == 2:
        M = c.T @ c
        h = c.T @ proj.r[rows]
        if proj.p:
            C = (proj.J0[rows].T @ c) / proj.s[:, None]
            M = M - C.T @ proj.Ninv @ C
            h = h - C.T @ proj.Ninv @ proj.b0
        return _score_of(0.5 * (M + M.T), h, np.sqrt(np.maximum(np.sum(c ** 2, axis=0), 1e-300)),
                         np.asarray(one_sided, bool))
    scale = float(np.sqrt(max(float(c @ c), 1e-300)))
    M = float(c @ c)
    h = float(c @ proj.r[rows])
    if proj.p:
        C = (proj.J0[rows].T @ c) / proj.s
        M = M - float(C @ proj.Ninv @ C)
        h = h - float(C @ proj.Ninv @ proj.b0)
    Ms = M / (scale * scale)
    if not Ms > SCORE_RTOL:
        return 0.0, 0, np.zeros(1)
    th = (h / scale) / Ms
    if np.any(one_sided) and th < 0:
        return 0.0, 1, np.zeros(1)
    return max((h / scale) ** 2 / Ms, 0.0), 1, np.array([th / scale])


def fit_projector(fit: Fit) -> Projector:
    """The projection out of ``fit``'s free directions, for score tests at its optimum. At a
    bounded optimum the residual is orthogonal only to the free parameters' columns: a parameter
    held at its bound (a spring at 0) does not remove its direction from a candidate that can go
    beyond it (the complex model's ``K_C`` is not sign-restricted)."""
    _, lo, hi = fit.spec.transforms()
    g = fit.J.T @ fit.residuals
    held = ((fit.x <= lo) & (g < 0)) | ((fit.x >= hi) & (g > 0))
    return Projector(fit.J[:, ~held], fit.residuals)


def score_candidates(model: AugmentedModel, fit: Fit, om: ObsMap, candidates: Sequence[Effect],
                     boundary, K_deck, o_dofs) -> list[tuple[Effect, float, int, np.ndarray]]:
    """Score every candidate at the current optimum: ``[(effect, S, df, step)]``. A family that
    scores its candidates without augmenting the model (``Effect.batch_columns``: members by
    reciprocity, no run) comes first; the others are scored through their augmented model."""
    proj = fit_projector(fit)
    st = model.state(fit.x)
    out = []
    batched: set[int] = set()
    for family in dict.fromkeys(type(c) for c in candidates):
        group = [c for c in candidates if type(c) is family]
        sparse = family.sparse_columns(model, st, fit.x, om, group)
        if sparse is not None:
            for e, (rows, vals) in zip(group, sparse):
                w = om.sigma[rows] if np.ndim(vals) == 1 else om.sigma[rows][:, None]
                S, df, step = sparse_score(proj, rows, vals / w, e.one_sided)
                out.append((e, S, df, step))
                batched.add(id(e))
            continue
        cols = family.batch_columns(model, st, fit.x, om, group)
        if cols is None:
            continue
        Jb = cols / om.sigma[:, None]
        for q, e in enumerate(group):
            S, df, step = score_test(proj, Jb[:, q:q + 1], e.one_sided)
            out.append((e, S, df, step))
            batched.add(id(e))
    for e in candidates:
        if id(e) in batched:
            continue
        spec2, x2 = fit.spec.add(e, fit.x)
        try:
            m2 = AugmentedModel(model.base, spec2, boundary, K_deck, o_dofs)
            J2 = m2.jacobian(x2, om) / om.sigma[:, None]
        except (np.linalg.LinAlgError, IdentificationError):
            out.append((e, 0.0, 0, np.zeros(e.n_params)))
            continue
        cols, one = e.scored_columns(fit.spec, spec2)
        S, df, step = score_test(proj, J2[:, cols], one)
        out.append((e, S, df, step))
    return out


def family_scores(model: AugmentedModel, fit: Fit, om: ObsMap, candidates: Sequence[Effect], boundary, K_deck,
                  o_dofs) -> dict:
    """Effect key -> ``(S, df)``: the score test, at the current optimum, of each candidate's
    richest variant (the last of :meth:`Effect.richer` at its nested point: per-branch springs,
    per-axis springs), for candidates scored through their augmented model. Each variant nests
    the simpler ones at the same point, so this bounds the first-order gain of the whole family:
    a joint released on one branch scores little as one equal spring on all branches and much
    as springs per branch. Families scored without augmenting the model (members, by
    reciprocity) and candidates without a richer variant have no entry."""
    proj = fit_projector(fit)
    out = {}
    for e in candidates:
        if (type(e).sparse_columns.__func__ is not Effect.sparse_columns.__func__
                or type(e).batch_columns.__func__ is not Effect.batch_columns.__func__):
            continue
        rich = e.richer(e.nominal)
        if not rich:
            continue
        r, xr = rich[-1]
        spec2, x2 = fit.spec.add(r, fit.x)
        x2[spec2.n_params - r.n_params:] = xr
        try:
            m2 = AugmentedModel(model.base, spec2, boundary, K_deck, o_dofs)
            J2 = m2.jacobian(x2, om) / om.sigma[:, None]
        except (np.linalg.LinAlgError, IdentificationError):
            continue
        cols, one = r.scored_columns(fit.spec, spec2)
        S, df, _ = score_test(proj, J2[:, cols], one)
        if df:
            out[e.key] = (S, df)
    return out


def log10_sf(S: float, df: int) -> float:
    """``log10 chi2.sf(S, df)``, finite however large ``S`` (the leading term of the asymptotic
    tail, ``sf ~ pdf(S) * 2`` for ``S >> df``, where scipy's ``logsf`` underflows to -inf)."""
    if not df:
        return 0.0
    v = float(stats.chi2.logsf(S, df))
    if not math.isfinite(v):
        v = float(stats.chi2.logpdf(S, df)) + math.log(2.0)
    return v / math.log(10.0)


def log10_sf_array(S: np.ndarray, df: int) -> np.ndarray:
    """:func:`log10_sf` of many statistics with one ``df``, vectorised."""
    S = np.asarray(S, float)
    v = stats.chi2.logsf(S, df)
    bad = ~np.isfinite(v)
    if bad.any():
        v[bad] = stats.chi2.logpdf(S[bad], df) + math.log(2.0)
    return v / math.log(10.0)
