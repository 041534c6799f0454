"""The refit of a model specification: weighted least squares with box bounds, and its statistics.

The iteration (:func:`fit_model`) is the package's one Levenberg-Marquardt core
(:func:`blackbox.fitting.lm.levenberg_marquardt`) in natural coordinates, with the box bounds by
projection (:class:`~blackbox.fitting.lm.ProjectedBoxBounds`: simple-model springs ``>= 0``,
compliances ``>= 0``, factors in their ranges) and the projected schedule
(:data:`~blackbox.fitting.lm.PROJECTED_SCHEDULE`). Natural rather than log coordinates because
every joint model is linear in its parameters and a spring that the data want at 0 (or a
compliance that stays at its nested 0) gets there, which ``log k`` makes crawl. A singular trial
point (a mechanism) is rejected. It runs to a relative decrease of chi2 below 1e-13, or until no
damped step decreases chi2 (lambda beyond 1e12, taken as the minimum to rounding): candidates
are compared by chi2 differences of a few units in 1e4-1e5, and a misfit declared model often
has a spring running to infinity (a flat valley) whose column shrinks like ``1/k^2``; the
schedule keeps that column (no dead-column test) so that the other parameters keep moving.

A complex joint (a declared one, or a simple one turned complex by ``joint_coupling``) is the
exception: its ``K_C`` is iterated in matrix-logarithm coordinates
(:class:`blackbox.identification.problem.MatrixLog`, as ``identify`` does) whenever the start is
positive definite. In its natural entries the refit follows a mode the data hardly bound across
the positive definite boundary (a ``K_C`` with an eigenvalue of ``-3e10`` next to entries of
``2e7``, which no joint has) and stops there, or crawls along the boundary; in ``logm K_C``
every step keeps ``K_C`` positive definite and changes it relatively, as ``log k`` does a spring.
The positive semi-definite ``K_C`` of a joint free in one mode is then approached, not reached:
such a joint is a mechanism of the frame model and does not fit either way.

A joint spring stops at its rigid limit (:meth:`~blackbox.diagnosis.model.AugmentedModel.rigid_limits`,
``1e8`` times the structure's stiffness along it): far beyond, the force through the joint is a
difference of nearly equal rotations times ``k`` and chi2 becomes rounding noise of several units
(at ``1e19`` a relative change of ``1e-14`` in the other parameters moves chi2 by thousands), which
the iteration would follow. When a refit ends with a spring at that limit (the flat valley of a
misfit model), it is repeated once from those springs as stiff as the structure and the lower
chi2 kept: the valley and a basin at a finite stiffness are both local minima. A diagonal entry of
``K_C`` at or beyond the same limit counts as rigid too (not bounded there: that would cut the
positive definiteness); it is brought to the structure's stiffness by a congruence that keeps
``K_C`` positive definite. This is what a ``joint_coupling`` refit needs when the declared fit
left one of the joint's springs rigid: from that nested point the refit stays in the rigid
valley (likelihood ratio 0.02 on a hall frame of the blind benchmark, where the score says
408), from the structure's stiffness it reaches the coupled joint (507).

Statistics (:mod:`blackbox.fitting.statistics`, the ones ``identify`` reports): Gaussian
likelihood with the declared sigma, ``chi2``, reduced chi-square, BIC, hold-out chi2 and RMS
prediction error; standard deviations from the whitened Jacobian at the optimum (pivoted QR of
the column-scaled Jacobian, ``inf`` for a parameter that is not identifiable).
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.model import RIGID_RATIO, AugmentedModel, ModelSpec, ObsMap
from blackbox.diagnosis.validation import inside_bounds
from blackbox.errors import IdentificationError
from blackbox.fitting.lm import PROJECTED_SCHEDULE, NaturalCoordinates, ProjectedBoxBounds, levenberg_marquardt
from blackbox.fitting.statistics import FitStatistics, HoldoutStats, chi2_band, covariance
from blackbox.identification.problem import MatrixLog
from blackbox.joints import ComplexJoint

__all__ = ["Fit", "fit_model", "prediction_basis", "std_of", "effective_rank", "chi2_band", "GRAM_RTOL", "RANK_RTOL"]

GRAM_RTOL = 1e-12           # Gram eigenvalues below this x the largest (column-scaled): rank loss
RANK_RTOL = 1e-6            # the same in singular values (|R_ii| of the pivoted QR): sqrt(GRAM_RTOL)


@dataclass(frozen=True, eq=False)
class Fit:
    """One weighted least-squares fit of a specification (Gaussian likelihood, declared sigma)."""
    spec: ModelSpec
    x: np.ndarray
    std: np.ndarray
    n_obs: int
    n_params: int
    chi2: float
    reduced_chi2: float
    rms_residual: float
    bic: float
    residuals: np.ndarray               # whitened, fit rows
    predicted: np.ndarray
    holdout_rms: float | None
    holdout_chi2: float | None
    holdout_n: int
    converged: bool
    message: str
    J: np.ndarray                       # whitened Jacobian at x (natural coordinates)
    holdout_predicted: np.ndarray | None = None     # predictions at the hold-out rows
    holdout_J: np.ndarray | None = None             # whitened Jacobian at the hold-out rows
    free: np.ndarray | None = None                  # the parameters strictly inside their bounds

    @functools.cached_property
    def holdout_basis(self) -> np.ndarray | None:
        """``A``: ``A A^T`` the whitened covariance of the hold-out predictions that the fitted
        parameters' error carries (:func:`prediction_basis`); ``None`` without hold-out rows.
        Derived when first asked: most refits are never compared on it."""
        if self.holdout_J is None or self.free is None:
            return None
        return prediction_basis(self.J, self.holdout_J, self.free)

    def basis_without(self, sl: slice | None) -> np.ndarray | None:
        """The prediction basis of the parameters outside ``sl`` with those in ``sl`` held at
        their values (their columns left out): the error of the parameters an addition shares
        with the fit it extends, given the addition's own (``holdout_basis`` when ``sl`` is
        ``None`` or the hold-out Jacobian was not kept)."""
        if sl is None or self.holdout_J is None or self.free is None:
            return self.holdout_basis
        cols = np.ones(self.J.shape[1], bool)
        cols[sl] = False
        return prediction_basis(self.J[:, cols], self.holdout_J[:, cols], self.free[cols])


class _Refit:
    """The refit as a :class:`blackbox.fitting.lm.LeastSquaresProblem`: natural coordinates,
    projected box bounds; a point where the augmented system is singular predicts ``nan`` (the
    core rejects it)."""

    def __init__(self, model: AugmentedModel, om: ObsMap, lo: np.ndarray, hi: np.ndarray):
        self.model, self.om = model, om
        self.n_params = model.p
        self.y = om.y
        self.weights = 1.0 / om.sigma
        self.coordinates = NaturalCoordinates()
        self.bounds = ProjectedBoxBounds(lo, hi)

    def positive_definite(self, k: np.ndarray) -> tuple["_Refit", np.ndarray]:
        """``(refit, coordinates of k)``: the same refit with every complex joint in
        matrix-logarithm coordinates (:class:`_DefiniteJoints`) when its ``K_C`` at ``k`` is
        positive definite; else ``self`` in natural coordinates."""
        blocks = [MatrixLog(sl, j.m) for j, sl in zip(self.model.spec.joints, self.model.spec.joint_slices())
                  if isinstance(j, ComplexJoint)]
        if blocks:
            coordinates = _DefiniteJoints(blocks)
            x = coordinates.to_coords(k)
            if all(np.all(np.isfinite(x[b.sl])) for b in blocks):
                out = copy.copy(self)
                out.coordinates = coordinates
                return out, x
        return self, self.coordinates.to_coords(k)

    def predict(self, k: np.ndarray):
        try:
            st = self.model.state(k)
            return self.model.predict(k, self.om, st), st
        except (np.linalg.LinAlgError, ValueError):
            return np.full(len(self.om.y), np.nan), None

    def jacobian(self, k: np.ndarray, st) -> np.ndarray:
        return self.model.jacobian(k, self.om, st)

    def admissible(self, k: np.ndarray) -> bool:
        return True


class _DefiniteJoints(NaturalCoordinates):
    """Natural coordinates but for the complex joints, iterated in ``logm K_C``
    (:class:`blackbox.identification.problem.MatrixLog`): every step keeps ``K_C`` positive
    definite and changes it relatively."""

    def __init__(self, blocks):
        super().__init__()
        self.blocks = blocks

    def to_natural(self, x):
        k = np.array(x, dtype=float)
        for b in self.blocks:
            k[b.sl] = b.to_k(k[b.sl])
        return k

    def to_coords(self, k):
        x = np.array(k, dtype=float)
        for b in self.blocks:
            x[b.sl] = b.to_phi(x[b.sl])
        return x

    def chain(self, J_k, k):
        J = J_k.copy()
        for b in self.blocks:
            J[:, b.sl] = J_k[:, b.sl] @ b.dk_dphi(k[b.sl])
        return J

    def unit_size(self, k):
        s = super().unit_size(k)
        for b in self.blocks:
            s[b.sl] = 1.0
        return s

    def log_step(self, dx):
        return max((float(np.max(np.abs(np.linalg.eigvalsh(b.sym(dx[b.sl]))), initial=0.0)) for b in self.blocks),
                   default=0.0)


FTOL = 1e-13                # relative decrease of chi2 that ends a refit (module docstring)
CONVERGED_STATUS = (1, 2, 3, 4)     # 4: no damped step decreases chi2 -- the minimum to rounding


def fit_model(model: AugmentedModel, om: ObsMap, hold: ObsMap | None, x0: np.ndarray,
              max_iterations: int = 200) -> Fit:
    """Weighted least squares of ``model`` at the rows ``om`` from ``x0`` (clipped into the
    bounds, a joint spring at most :meth:`AugmentedModel.rigid_limits`, where it is rigid to
    rounding); ``hold``: rows predicted, never fitted (module docstring)."""
    spec = model.spec
    _, lo, hi = spec.transforms()
    limit = model.rigid_limits()
    hi_rigid = np.minimum(hi, limit)
    complex_ = np.zeros(model.p, bool)
    for j, sl in zip(spec.joints, spec.joint_slices()):
        complex_[sl] = isinstance(j, ComplexJoint)
    hi = np.minimum(hi, np.where(complex_, np.inf, limit))
    x = np.clip(np.asarray(x0, float), lo, hi)
    prob = _Refit(model, om, lo, hi)
    f0, st = prob.predict(x)
    if st is None or not np.all(np.isfinite(f0)):
        raise IdentificationError("the model is singular at the start of a refit")
    if model.p:
        def run(k_start):
            k_start = _into_definite(spec, k_start)
            p, x_start = prob.positive_definite(k_start)
            return levenberg_marquardt(p, x_start, max_iterations=max_iterations,
                                       xtol=0.0, ftol=FTOL, geodesic=False, schedule=PROJECTED_SCHEDULE)
        res = run(x)
        # a spring (or a mode of K_C) that ended rigid may sit in the flat valley of a misfit
        # model while a basin at a finite stiffness fits better: once more from those springs as
        # stiff as the structure and the lower chi2 kept
        rigid = np.isfinite(limit) & (res.k >= limit * (1.0 - 1e-9))
        if np.any(rigid):
            again = run(_as_stiff_as_the_structure(spec, res.k, rigid, limit))
            if again.chi2 < res.chi2:
                res = again
        x, st = res.k, res.state
        converged, msg = res.status in CONVERGED_STATUS, res.message
    else:
        converged, msg = True, "no parameters"
    f = model.predict(x, om, st)
    w = prob.weights
    with_hold = hold is not None and len(hold.y) > 0
    free = inside_bounds(x, lo, hi_rigid)
    if model.p:
        Js = model.jacobians(x, (om, hold) if with_hold else (om,), st)
        Jn = Js[0] / om.sigma[:, None]
        Jh = Js[1] / hold.sigma[:, None] if with_hold else None
    else:
        Jn = np.zeros((len(om.y), 0))
        Jh = np.zeros((len(hold.y), 0)) if with_hold else None
    fs = FitStatistics.of(om.y, f, om.sigma, model.p, weights=w)
    h_rms = h_chi2 = fh = None
    hn = 0
    if with_hold:
        fh = model.predict(x, hold, st)
        hs = HoldoutStats.of((), hold.y, fh, 1.0 / hold.sigma)
        h_rms, h_chi2, hn = hs.rms_error, hs.chi2, hs.n_obs
    return Fit(spec, x, std_of(Jn), fs.n_obs, fs.n_params, fs.chi2, fs.reduced_chi2, fs.rms_residual, fs.bic,
               (om.y - f) * w, f, h_rms, h_chi2, hn, bool(converged), msg, Jn, fh, Jh, free)


def prediction_basis(J: np.ndarray, Jh: np.ndarray, free: np.ndarray) -> np.ndarray:
    """``A`` with ``A A^T`` the whitened covariance of the hold-out predictions that the fitted
    parameters carry (:mod:`blackbox.diagnosis.holdout`); ``J``, ``Jh``: the whitened fit and
    hold-out Jacobians; ``free``: the parameters that move. The fit's singular basis is cut at
    :data:`RANK_RTOL` of its largest singular value (the columns scaled to unit norm)."""
    if not free.any():
        return np.zeros((Jh.shape[0], 0))
    Jf = J[:, free]
    scale = np.linalg.norm(Jf, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    _, s, Wt = np.linalg.svd(Jf / scale, full_matrices=False)
    keep = s > RANK_RTOL * s[0] if s[0] > 0 else np.zeros(len(s), bool)
    return (Jh[:, free] / scale) @ Wt[keep].T / s[keep]


DEFINITE_LIFT = 1e-9
"""A start whose ``K_C`` is singular but positive semi-definite to rounding (a ``joint_coupling``
nested at a simple joint with a spring at 0) has its eigenvalues raised to at least this times
the largest, so that it has matrix-logarithm coordinates; the chi2 it changes is far below what
candidates are compared by, and the refit moves such a mode by up to a factor 100 an iteration."""


def _into_definite(spec: ModelSpec, k: np.ndarray) -> np.ndarray:
    """``k`` with every complex joint's singular, positive semi-definite ``K_C`` lifted to
    :data:`DEFINITE_LIFT` of its largest eigenvalue; an indefinite ``K_C`` (a start the refit
    then iterates in the natural entries) and a definite one are left as they are."""
    out = np.array(k, dtype=float)
    for j, sl in zip(spec.joints, spec.joint_slices()):
        if not isinstance(j, ComplexJoint):
            continue
        K = j.kc_matrix(out[sl])
        mu = np.linalg.eigvalsh(K)
        if not (mu[-1] > 0.0 and -1e-12 * mu[-1] <= mu[0] <= 0.0):
            continue
        out[sl] = j.params_from_kc(K + (DEFINITE_LIFT * mu[-1] - mu[0]) * np.eye(j.m))
    return out


def _as_stiff_as_the_structure(spec: ModelSpec, k: np.ndarray, rigid: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """``k`` with its ``rigid`` springs at ``limit / RIGID_RATIO``, the structure's own stiffness
    along them; a complex joint's rigid diagonal entry ``K_ii`` is brought there by the congruence
    ``D K_C D`` (``D = 1`` but ``D_ii = sqrt(target / K_ii)``), which scales row and column ``i``
    together and so keeps ``K_C`` positive definite."""
    out = np.where(rigid, limit / RIGID_RATIO, k)
    for j, sl in zip(spec.joints, spec.joint_slices()):
        if not isinstance(j, ComplexJoint) or not np.any(rigid[sl]):
            continue
        K = j.kc_matrix(k[sl])
        d = np.ones(j.m)
        iu = np.triu_indices(j.m)
        for q in np.flatnonzero(rigid[sl]):
            i = iu[0][q]
            d[i] = np.sqrt(out[sl][q] / K[i, i])
        out[sl] = (d[:, None] * K * d[None, :])[iu]
    return out


def std_of(J: np.ndarray) -> np.ndarray:
    """Standard deviations from the whitened Jacobian ``J``: ``sqrt diag (J^T J)^+`` with the
    columns scaled to unit norm, ``inf`` for a parameter with a component in the numerical null
    space (:func:`blackbox.fitting.statistics.covariance`, rank cut ``RANK_RTOL``)."""
    if J.shape[1] == 0:
        return np.zeros(0)
    s = np.linalg.norm(J, axis=0)
    return covariance(J, scale=1.0 / np.where(s > 0, s, 1.0), rank_rtol=RANK_RTOL).std


def effective_rank(J: np.ndarray) -> int:
    """How many parameters the whitened Jacobian ``J`` determines: its numerical rank with the
    columns scaled to unit norm, cut at :data:`RANK_RTOL` of the largest singular value (the cut
    of :func:`std_of`). A parameter (or combination) the data do not see moves no prediction
    and fits no noise: what an addition's likelihood-ratio test and BIC count as its degrees of
    freedom (:meth:`blackbox.diagnosis.search.Checks.judge`), as the score test counts the rank
    of its projected columns."""
    J = np.asarray(J, float)
    if J.ndim != 2 or J.shape[1] == 0 or J.shape[0] == 0:
        return 0
    s = np.linalg.norm(J, axis=0)
    sv = np.linalg.svd(J / np.where(s > 0, s, 1.0), compute_uv=False)
    return int(np.sum(sv > RANK_RTOL * sv[0])) if sv.size and sv[0] > 0 else 0
