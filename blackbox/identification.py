"""Statistical identification of joint parameters (Chapter 4, Sec. 4.2-4.4, eq. 19-32).

The estimation model (eq. 21) is ``U_m = U_A(k) + E_m`` with ``E_m ~ N(0, V_m)``,
``V_m = diag(sigma^2)`` (the user's declared, absolute measurement errors). The estimate
minimises ``chi2(k) = sum ((U_m - U_A(k)) / sigma)^2``, the weighted least squares of Sec. 4.3
(weights ``V_m^-1``) and the maximum-likelihood estimate for Gaussian errors. Everything happens
in the condensed space of :class:`blackbox.condensation.CondensedModel`: no solver run after the
one batched condensation, so the iterations, the profiles and the bootstrap cost milliseconds.

Two iterative procedures, as in Figure 4.1:

1. **Fixed point** (Sec. 4.3.1, eq. 22-29), used when every DOF on which the joints act is
   measured in every fitted case. We use the *flexibility form* of eq. 24 (multiplied by
   ``G_BB = K_R^-1``, so the condensed flexibility is never inverted; ``dK = K_J(k) - K_deck``)::

       G X_m(U_mB) k  =  U_0 - U_m + G K_deck U_mB  +  M E_m ,   M = I + G dK S     (eq. 24-27)
       Y = U_0 - U_m + G K_deck U_mB,   X = G X_m,   V_e = M V_m M^T                  (eq. 27, 29)

   with ``G`` the rows of ``[G_BB; G_OB]`` of the measured DOFs (measurements away from the joints
   enter too, Sec. 4.2), ``U_0 = [U_B0; U_O0]``, ``X_m`` from the joints' ``x_matrix`` (Table 5.1)
   scattered into the boundary rows and ``S`` picking the measured joint DOFs; ``M`` is
   ``K_overall`` (eq. 25a) in flexibility form. The weighted regression (eq. 28) is repeated with
   ``V_e`` at the current ``k`` while it cuts ``chi2`` at least tenfold; once it does not -- it
   "approaches the neighborhood but does not converge", since ``X_m`` holds noisy measurements
   (an errors-in-variables bias) -- Newton takes over from the last accepted point. The
   regression is unconstrained: a result outside the admissible set (``K_C`` not positive
   definite, a spring < 0) is replaced by the better (lower ``chi2``) of the admissible point on
   the segment towards it and its nearest positive definite ``K_C`` with the eigenvalues floored
   at 0.01-0.3 times the largest (:func:`_admissible_fixed_point`; springs: the segment).
2. **Gauss-Newton** (Sec. 4.3.2, eq. 30-32) with the analytic condensed Jacobian (eq. 18, at the
   measured rows only), plus geodesic acceleration (Transtrum & Sethna 2012, one extra prediction,
   for the curved valleys of weakly determined springs; the accelerated and the plain step are
   both tried, the lower ``chi2`` wins), a backtracking line search and Levenberg-Marquardt
   damping (Marquardt's ``diag(J^T J)`` scaling): a trial step that raises ``chi2`` or leaves
   the admissible set is never taken, so the objective never increases.

Parameter coordinates
    * simple-model springs (:class:`SimpleJoint`) are iterated in ``log k``, so they stay ``> 0``
      (steps capped at a factor 100). The bound ``k = 0`` is handled as an active set: when the
      natural-coordinate Gauss-Newton step would take springs below a floor (``1e-6`` times the
      joint's stiffest spring) that bounded step is tried first (in log k the bound is infinitely
      far and the iteration would crawl), and a spring at the floor that still wants to decrease
      is held there. Such a spring is reported with a warning ("tends to 0"); its profile
      interval starts at 0.
    * the complex model is iterated in *matrix-logarithm* coordinates (:class:`_MatrixLog`):
      ``K_C = expm(S)``, ``S`` symmetric, ``phi`` = the upper triangle of ``S``. Every ``phi``
      gives a positive definite ``K_C``, and a step changes ``K_C`` relatively, as ``log k`` does
      a spring: the response is ~``K^-1``, and in the natural entries (iterated with step
      rejection at the positive definite boundary until this change) ``blackbox identify``
      needed 14 iterations on ``fixtures/cube_complex`` from ``K_C = 1e3 I`` (Table 5.12,
      ``chi2`` falling ~4x per iteration, steps cut at the boundary, the fixed point's step
      shortened to nothing), 6 now; ``fixtures/car_complex`` (Table 5.18) 8, now 6.
      ``dk/dphi`` is then a block (the Frechet derivative of ``expm``), not a diagonal; a step
      is capped by the spectral norm of ``dS`` (every eigenvalue of ``K_C`` changes by at most
      a factor 100). Statistics, intervals and profiles stay in the entries of ``K_C``: a
      profile needs its entry as a coordinate, so profiles iterate the complex model in the
      natural entries (``_Problem.natural``), starting at the optimum, with step rejection.
    * any other joint model is iterated in its natural parameters with step rejection.

    A ``K_C`` eigenvalue the data do not bound from above (a joint far stiffer than the
    structure in one mode, e.g. the cube's Table 5.12 joint with 5 % noise: ``std(log mu) = 4``
    at the truth; the maximum-likelihood estimate is then rigid in that mode in ~3 of 4 noise
    replicates) runs off to ``1e11-1e16`` and the iteration takes 9-30 steps to stop (30
    replicates of the issue's study: median 14, 1 not converged in 30 iterations; before: median
    18, 9 not converged); the covariance then flags every entry as not identifiable (rank 20 of
    21). A bound "rigid relative to the structure" (like the springs' floor) would end that
    sooner; not done.

Convergence: relative parameter step ``< xtol`` (``|d phi|`` in log coordinates: ``|d log k|``
for springs, ``|dS_ij|`` for a complex joint; ``|dk| / max|diag K_J|`` for the others), or both
the actual and the Gauss-Newton-predicted relative decrease of ``chi2`` ``< ftol`` (MINPACK's
test: a short step in a curved valley does not stop the iteration).

Uncertainty (Sec. 4.4)
    The covariance is ``(J^T V_m^-1 J)^-1`` in the natural parameters at the optimum, from a
    pivoted QR (``scipy.linalg.qr(pivoting=True)``) of the whitened Jacobian with every column
    scaled by its parameter's size. Its numerical rank (``|R_ii| > rank_rtol |R_00|``) and the
    null space of the leading rows decide identifiability: a parameter with a component in the
    null space is *not identifiable* (std ``inf``, interval ``nan``, a warning) instead of getting
    a huge number; the others get the pseudo-inverse variance, exact for estimable quantities.
    ``sigma`` is absolute, so the covariance is *not* scaled by the reduced chi-square by default
    (normal quantile; a warning when chi2 is implausible for the declared sigma);
    ``scale_covariance=True`` multiplies it by ``max(1, reduced_chi2)`` (only ever widening) and
    uses Student's t with ``n_obs - n_params`` degrees of freedom, for a sigma known only up to
    a factor.

    Intervals at ``confidence``. By default (``profile=True``) the reported ``ci_low, ci_high``
    are **profile-likelihood** intervals: ``{k_i : min_others chi2 <= chi2_min + z^2}``, found on
    the profile-t scale (Bates & Watts 1988) from the linearised end points, a few re-optimisations
    each. The linearised intervals (``linear_ci``: ``k exp(+-z std/k)`` for springs, ``k +- z std``
    otherwise) are always reported too, but they under-cover when a spring is weakly determined:
    on the cube of Chapter 5 with 5 % noise and 10 load cases the y-plane springs have 20-40 %
    relative uncertainty and the estimator is far from normal (curved valleys, the bound at 0);
    over 400 replicates the log-space linearised interval covered ``ky12`` 88 % of the time
    (outside the binomial band), the profile interval 94-95 % for every spring
    (``tests/test_identification.py``; 92-94 % with another seed set: the profile likelihood
    ratio of one spring has a mean of ~1.1 instead of 1 there, a small-sample effect).
    ``bootstrap=N`` adds a seeded parametric bootstrap (refits of data simulated from the
    estimate with the declared sigma) with percentile intervals.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import scipy.linalg as sla
from scipy import stats

from blackbox.condensation import CondensedModel, Response
from blackbox.errors import IdentificationError
from blackbox.joints import ComplexJoint, SimpleJoint
from solver_adapters.protocol import DofLabel

__all__ = ["Observations", "IterationRecord", "HoldoutStats", "IdentificationResult", "identify"]

STATUS_MESSAGES = {
    0: "maximum number of iterations reached",
    1: "relative parameter step below xtol",
    2: "relative decrease of chi2 below ftol",
    3: "relative parameter step below xtol and decrease of chi2 below ftol",
    4: "no damped step decreases chi2 any further",
    5: "stopped by the callback",
}
_MAX_LOG_STEP = math.log(100.0)     # a spring changes by at most a factor 100 per iteration
_BACKTRACK = (1.0, 0.5, 0.25, 0.125)  # step fractions tried before the damping is raised
_PROFILE_WIDTHS = 50.0              # other parameters: up to 50 linearised half-widths
_PROFILE_SPAN = 1e6                 # a spring's profile is searched up to 1e6 x its joint's stiffest
_PROFILE_TAU_RTOL = 1e-2            # end points to 1% of the profile-t level (coverage +-0.001)
_GEODESIC_H = 0.1                   # finite-difference step (in units of the step) for the acceleration
_GEODESIC_RATIO = 3.0               # the accelerated step is tried while |2 acc| <= 3 |step|
                                    # (Transtrum's 0.75 is for a step taken blind; the plain one
                                    # is tried beside it: car complex model, median 7 -> 6 iterations)
_SPRING_FLOOR = 1e-6                # a spring below this times its joint's stiffest is held at "0"
_FP_STALL = 0.1                     # a fixed-point step is taken only if it cuts chi2 tenfold
_FP_FLOORS = (0.01, 0.0316, 0.1, 0.316)   # K_C eigenvalue floors tried (x the largest) for the fixed point
_NULL_TOL = 1e-6                    # a null-space component above this makes a parameter unidentifiable


# --------------------------------------------------------------------------------------------
# observations
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Observations:
    """Measured rows mapped to the condensed model: row ``i`` is DOF ``dofs[i]`` in case
    ``case_labels[case_index[i]]`` (a column of ``Condensed.cases``), measured ``values[i]`` with
    standard deviation ``sigma[i]`` (absolute, the measurement's units)."""
    dofs: tuple[DofLabel, ...]
    case_index: np.ndarray
    values: np.ndarray
    sigma: np.ndarray
    case_labels: tuple[str, ...] = ()
    ref_dofs: tuple[DofLabel | None, ...] = ()
    """Per row, ``None`` or the DOF the row is measured relative to (Section 5.2 reference point):
    the row's value is then ``u(dof) - u(ref_dof)``. Empty: every row is absolute."""

    def __post_init__(self) -> None:
        try:
            dofs = tuple((int(g), int(c)) for g, c in self.dofs)
        except (TypeError, ValueError):
            raise IdentificationError("Observations.dofs must be (grid, component) pairs") from None
        ci = np.asarray(self.case_index)
        vals = np.asarray(self.values, dtype=float)
        sig = np.asarray(self.sigma, dtype=float)
        n = len(dofs)
        if ci.shape != (n,) or vals.shape != (n,) or sig.shape != (n,):
            raise IdentificationError(
                f"Observations need one case_index, value and sigma per DOF row ({n} rows), got "
                f"shapes {ci.shape}, {vals.shape}, {sig.shape}")
        if n and (not np.issubdtype(ci.dtype, np.integer) or ci.min() < 0):
            raise IdentificationError(f"case_index must be non-negative integers, got {ci[:5].tolist()}...")
        labels = tuple(str(c) for c in self.case_labels)
        if labels and n and ci.max() >= len(labels):
            raise IdentificationError(f"case_index {int(ci.max())} is out of range for {len(labels)} cases")
        bad = np.flatnonzero(~np.isfinite(vals))
        if bad.size:
            i = int(bad[0])
            raise IdentificationError(
                f"{bad.size} measured value(s) are not finite, first DOF {dofs[i]} in case "
                f"{self._label(labels, int(ci[i]))!r}: {vals[i]!r}")
        bad = np.flatnonzero(~(np.isfinite(sig) & (sig > 0)))
        if bad.size:
            i = int(bad[0])
            raise IdentificationError(
                f"{bad.size} sigma(s) are not finite and positive, first DOF {dofs[i]} in case "
                f"{self._label(labels, int(ci[i]))!r}: {sig[i]!r}")
        refs = tuple(None if r is None else (int(r[0]), int(r[1])) for r in self.ref_dofs)
        if refs and len(refs) != n:
            raise IdentificationError(f"ref_dofs needs one entry (None or a DOF) per row ({n}), got {len(refs)}")
        if not any(r is not None for r in refs):
            refs = ()
        seen: set = set()
        for i, (d, c) in enumerate(zip(dofs, ci.tolist())):
            key = (d, c, refs[i] if refs else None)
            if key in seen:
                raise IdentificationError(f"DOF {d} is measured twice in case {self._label(labels, c)!r}")
            if refs and refs[i] == d:
                raise IdentificationError(f"DOF {d} is measured relative to itself in case "
                                          f"{self._label(labels, c)!r}")
            seen.add(key)
        object.__setattr__(self, "ref_dofs", refs)
        ci = ci.astype(int)
        for name, arr in (("case_index", ci), ("values", vals), ("sigma", sig)):
            arr = arr.copy()
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "dofs", dofs)
        object.__setattr__(self, "case_labels", labels)

    @staticmethod
    def _label(labels: tuple[str, ...], c: int) -> str:
        return labels[c] if c < len(labels) else f"#{c}"

    def __len__(self) -> int:
        return len(self.dofs)

    @property
    def cases(self) -> tuple[int, ...]:
        """The case indices that have at least one row, ascending."""
        return tuple(int(c) for c in np.unique(self.case_index))

    @classmethod
    def from_measurements(cls, measurements, condensed_cases: Sequence[str]) -> "Observations":
        """From :class:`blackbox.study.Measurements` (rows ``cases, dofs, values, sigma``); every
        case label must be one of ``condensed_cases`` (``Condensed.cases``)."""
        labels = tuple(str(c) for c in condensed_cases)
        index = {c: j for j, c in enumerate(labels)}
        unknown = sorted({str(c) for c in measurements.cases} - set(index))
        if unknown:
            raise IdentificationError(
                f"measured case(s) {unknown} are not among the condensed load cases {list(labels)}")
        return cls(tuple(measurements.dofs), np.array([index[str(c)] for c in measurements.cases], dtype=int),
                   np.asarray(measurements.values, float), np.asarray(measurements.sigma, float), labels,
                   tuple(getattr(measurements, "refs", ()) or ()))

    def subset(self, mask: np.ndarray) -> "Observations":
        idx = np.flatnonzero(mask)
        return Observations(tuple(self.dofs[i] for i in idx), self.case_index[idx], self.values[idx],
                            self.sigma[idx], self.case_labels,
                            tuple(self.ref_dofs[i] for i in idx) if self.ref_dofs else ())

    def with_values(self, values: np.ndarray) -> "Observations":
        """The same rows with other measured values (bootstrap, simulation)."""
        return Observations(self.dofs, self.case_index, values, self.sigma, self.case_labels, self.ref_dofs)

    def split(self, holdout_cases: Sequence[str | int]) -> tuple["Observations", "Observations"]:
        """``(fit, holdout)``: the rows of ``holdout_cases`` (labels or case indices) go to ``holdout``."""
        idx = set()
        for c in holdout_cases:
            if isinstance(c, str):
                if c not in self.case_labels:
                    raise IdentificationError(
                        f"holdout case {c!r} is not a load case {list(self.case_labels)}")
                idx.add(self.case_labels.index(c))
            else:
                idx.add(int(c))
        empty = sorted(self._label(self.case_labels, c) for c in idx if c not in set(self.case_index.tolist()))
        if empty:
            raise IdentificationError(f"holdout case(s) {empty} have no observations")
        mask = np.isin(self.case_index, sorted(idx))
        return self.subset(~mask), self.subset(mask)


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class IterationRecord:
    """One accepted iterate: ``phase`` is ``"start"``, ``"fixed-point"`` or ``"newton"``."""
    iteration: int
    phase: str
    k: np.ndarray
    objective: float            # chi2 at k
    damping: float = 0.0        # Levenberg-Marquardt lambda of the accepted step


@dataclass(frozen=True, eq=False)
class HoldoutStats:
    """Prediction of held-out cases with the fitted parameters."""
    cases: tuple[str, ...]
    n_obs: int
    rms_error: float            # unweighted, measurement units
    chi2: float
    residuals: np.ndarray       # standardized, (measured - predicted) / sigma


@dataclass(frozen=True, eq=False)
class IdentificationResult:
    """The estimate, its uncertainty and the fit statistics (scipy ``OptimizeResult`` /
    lmfit ``MinimizerResult`` in spirit; a report is written elsewhere)."""
    k: np.ndarray
    param_names: tuple[str, ...]
    param_joint: tuple[str, ...]
    std: np.ndarray                     # inf for a parameter that is not identifiable
    ci_low: np.ndarray                  # at `confidence` by `ci_method`; nan if not identifiable
    ci_high: np.ndarray
    confidence: float
    ci_method: str
    linear_ci: np.ndarray               # (n_params, 2) linearised (log-space for springs)
    identifiable: np.ndarray            # bool per parameter
    rank: int
    covariance: np.ndarray              # natural parameters; nan rows/cols if not identifiable
    correlation: np.ndarray
    covariance_scale: float             # 1, or max(1, reduced_chi2) with scale_covariance
    converged: bool
    status: int
    message: str
    iterations: int
    n_fixed_point: int
    n_newton: int
    history: tuple[IterationRecord, ...]
    n_obs: int
    n_params: int
    chi2: float
    reduced_chi2: float
    rms_residual: float
    aic: float
    bic: float
    residuals: np.ndarray               # standardized, per observation row
    predicted: np.ndarray
    holdout: HoldoutStats | None
    profile_ci: np.ndarray | None       # (n_params, 2)
    bootstrap_ci: np.ndarray | None     # (n_params, 2)
    bootstrap_samples: np.ndarray | None
    warnings: tuple[str, ...]

    @property
    def success(self) -> bool:
        return self.converged

    def to_json_dict(self, solver_info: dict) -> dict:
        """``result.json`` of CONTRACT.md section 3 (non-finite numbers become ``null``)."""
        params = []
        for i in range(self.n_params):
            p = {"joint": self.param_joint[i], "name": self.param_names[i], "value": _num(self.k[i]),
                 "std": _num(self.std[i]), "ci_low": _num(self.ci_low[i]),
                 "ci_high": _num(self.ci_high[i]), "identifiable": bool(self.identifiable[i])}
            p["linear_ci"] = [_num(v) for v in self.linear_ci[i]]
            if self.profile_ci is not None:
                p["profile_ci"] = [_num(v) for v in self.profile_ci[i]]
            if self.bootstrap_ci is not None:
                p["bootstrap_ci"] = [_num(v) for v in self.bootstrap_ci[i]]
            params.append(p)
        h = self.holdout
        return {
            "converged": bool(self.converged),
            "iterations": int(self.iterations),
            "parameters": params,
            "fit": {"n_obs": self.n_obs, "n_params": self.n_params, "chi2": _num(self.chi2),
                    "reduced_chi2": _num(self.reduced_chi2), "rms_residual": _num(self.rms_residual),
                    "aic": _num(self.aic), "bic": _num(self.bic)},
            "holdout": {"cases": list(h.cases) if h else [], "rms_error": _num(h.rms_error) if h else None,
                        "chi2": _num(h.chi2) if h else None, "n_obs": h.n_obs if h else 0},
            "solver": dict(solver_info),
            "status": int(self.status),
            "message": self.message,
            "confidence": self.confidence,
            "ci_method": self.ci_method,
            "identifiable": [bool(v) for v in self.identifiable],
            "rank": int(self.rank),
            "covariance_scale": _num(self.covariance_scale),
            "correlation": [[_num(v) for v in row] for row in self.correlation],
            "iterations_by_phase": {"fixed-point": self.n_fixed_point, "newton": self.n_newton},
            "history": [{"iteration": r.iteration, "phase": r.phase, "objective": _num(r.objective),
                         "damping": _num(r.damping), "k": [_num(v) for v in r.k]} for r in self.history],
            "warnings": list(self.warnings),
        }


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


# --------------------------------------------------------------------------------------------
# matrix-logarithm coordinates of a complex joint
# --------------------------------------------------------------------------------------------
class _MatrixLog:
    """``K_C = expm(S)`` with ``S`` symmetric: the coordinates ``phi`` of a complex joint are the
    upper triangle of ``S`` (row then column, the order of the parameters ``k``, the upper
    triangle of ``K_C``). Every ``S`` gives a positive definite ``K_C``, and a step in ``S``
    changes ``K_C`` *relatively* -- the analogue of ``log k`` for a spring: ``S = log(k) I`` is
    the complex model with every eigenvalue ``k``. With ``S = V diag(l) V^T``,
    ``K_C = V diag(exp l) V^T`` and the Frechet derivative of ``expm`` at ``S`` in a direction
    ``E`` is (Daleckii-Krein; Higham, *Functions of Matrices*, 2008, Thm. 3.11)::

        dK_C = V (Gamma o (V^T E V)) V^T,   Gamma_ij = (e^l_i - e^l_j) / (l_i - l_j)  (e^l_i if equal)

    the first divided differences of ``exp``; ``dk/dphi`` is that map on the basis ``E_q`` of
    symmetric matrices (``E_ij + E_ji`` off the diagonal), restricted to the upper triangle.
    Checked against ``scipy.linalg.expm_frechet`` in the tests."""

    def __init__(self, sl: slice, m: int):
        self.sl, self.m = sl, m
        self.iu = np.triu_indices(m)
        E = np.zeros((self.iu[0].size, m, m))
        q = np.arange(self.iu[0].size)
        E[q, self.iu[0], self.iu[1]] = 1.0
        E[q, self.iu[1], self.iu[0]] = 1.0
        self.E = E

    def sym(self, v: np.ndarray) -> np.ndarray:
        A = np.zeros((self.m, self.m))
        A[self.iu] = v
        return A + np.triu(A, 1).T

    def to_k(self, phi: np.ndarray) -> np.ndarray:
        if not np.all(np.isfinite(phi)):
            return np.full(phi.shape, np.nan)
        lam, V = np.linalg.eigh(self.sym(phi))
        return ((V * np.exp(np.minimum(lam, 700.0))) @ V.T)[self.iu]     # > 1e150: inadmissible

    def to_phi(self, k: np.ndarray) -> np.ndarray:
        if not np.all(np.isfinite(k)):
            return np.full(k.shape, np.nan)
        mu, V = np.linalg.eigh(self.sym(k))
        if mu[0] <= 0.0:
            return np.full(k.shape, np.nan)
        return ((V * np.log(mu)) @ V.T)[self.iu]

    def dk_dphi(self, k: np.ndarray) -> np.ndarray:
        """``(n_params, n_params)``: column ``q`` is ``dk / dphi_q`` at ``K_C(k)``."""
        mu, V = np.linalg.eigh(self.sym(k))
        lam = np.log(np.maximum(mu, np.finfo(float).tiny))
        a = np.abs(lam[:, None] - lam[None, :])
        with np.errstate(invalid="ignore", divide="ignore"):   # (1 - e^-a) / a without overflow
            q = np.where(a > 0.0, -np.expm1(-a) / a, 1.0)
        gamma = np.exp(np.maximum(lam[:, None], lam[None, :])) * q
        Et = np.einsum("ai,qab,bj->qij", V, self.E, V)
        dK = np.einsum("ia,qab,jb->qij", V, Et * gamma, V)
        return dK[:, self.iu[0], self.iu[1]].T


# --------------------------------------------------------------------------------------------
# the problem in the condensed space
# --------------------------------------------------------------------------------------------
class _Problem:
    """Observations located in the condensed model; predictions, Jacobians, coordinates."""

    def __init__(self, model: CondensedModel, obs: Observations):
        c = model.c
        L, nB = len(c.cases), len(c.boundary)
        if obs.case_labels and obs.case_labels != tuple(c.cases):
            raise IdentificationError(
                f"observations refer to cases {list(obs.case_labels)}, the condensed model has "
                f"{list(c.cases)}")
        if len(obs) and int(obs.case_index.max()) >= L:
            raise IdentificationError(f"case_index {int(obs.case_index.max())} is out of range "
                                      f"for the {L} condensed cases")
        try:
            loc = model.locate(obs.dofs)
        except KeyError as exc:
            raise IdentificationError(str(exc.args[0])) from None
        self.model, self.obs = model, obs
        self.L, self.nB = L, nB
        self.rows = np.array([i if s == "B" else nB + i for s, i in loc], dtype=int)
        self.flat = self.rows * L + obs.case_index
        # rows measured relative to a reference DOF (Section 5.2): predicted u(dof) - u(ref)
        self.has_ref = np.array([r is not None for r in obs.ref_dofs], dtype=bool) if obs.ref_dofs \
            else np.zeros(len(obs), dtype=bool)
        ref_rows = np.zeros(len(obs), dtype=int)
        if self.has_ref.any():
            try:
                rloc = model.locate([r for r in obs.ref_dofs if r is not None])
            except KeyError as exc:
                raise IdentificationError(str(exc.args[0])) from None
            ref_rows[self.has_ref] = [i if s == "B" else nB + i for s, i in rloc]
        self.ref_rows = ref_rows
        self.flat_ref = ref_rows * L + obs.case_index
        all_rows = np.concatenate([self.rows, ref_rows[self.has_ref]])
        self._rows_u, inv = np.unique(all_rows, return_inverse=True)
        self._rows_inv = inv[:len(obs)]
        self._ref_inv = inv[len(obs):]
        self.y, self.sigma = obs.values, obs.sigma
        self.w = 1.0 / obs.sigma
        asm = model.assembly
        self.p = asm.n_params
        self.log_mask = np.zeros(self.p, dtype=bool)
        for j, sl in zip(asm.joints, asm.slices):
            if isinstance(j, SimpleJoint):
                self.log_mask[sl] = True
        self._spring_slices = [sl for j, sl in zip(asm.joints, asm.slices) if isinstance(j, SimpleJoint)]
        self._others = [(j, sl) for j, sl in zip(asm.joints, asm.slices) if not isinstance(j, SimpleJoint)]
        # complex joints: phi = the upper triangle of S = logm(K_C) (K_C = expm(S))
        self._mlog = [_MatrixLog(sl, j.m) for j, sl in self._others if isinstance(j, ComplexJoint)]
        self.mlog_mask = np.zeros(self.p, dtype=bool)
        for b in self._mlog:
            self.mlog_mask[b.sl] = True
        self.log_coords = self.log_mask | self.mlog_mask
        # Every model of blackbox.joints is linear in k (K_J = sum k_p dK_J/dk_p): then K_J is a
        # contraction with a constant basis, much cheaper than asking every joint each time.
        probe = np.arange(1.0, self.p + 1.0)
        D = asm.derivatives(probe)
        self._D = D if (np.allclose(D, asm.derivatives(2.0 * probe), rtol=1e-14, atol=0.0) and
                        np.allclose(np.tensordot(probe, D, 1), asm.matrix(probe), rtol=1e-14,
                                    atol=1e-14 * float(np.abs(D).max(initial=1.0)))) else None
        self._Dflat = D.reshape(self.p, -1)

    # ---- coordinates: log k for springs, logm K_C for complex joints, k for the rest ----------
    def natural(self) -> "_Problem":
        """The same problem with every complex joint in its natural parameters (the entries of
        ``K_C``; springs stay in log k): for profiling an entry of ``K_C``, which must then be a
        coordinate."""
        out = copy.copy(self)
        out._mlog = []
        out.mlog_mask = np.zeros(self.p, dtype=bool)
        out.log_coords = self.log_mask.copy()
        return out

    def to_k(self, phi: np.ndarray) -> np.ndarray:
        k = np.array(phi, dtype=float)
        k[self.log_mask] = np.exp(np.minimum(k[self.log_mask], 700.0))   # > 1e150: inadmissible
        for b in self._mlog:
            k[b.sl] = b.to_k(k[b.sl])
        return k

    def to_phi(self, k: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_k`; ``nan`` for a spring <= 0 or a ``K_C`` that is not positive
        definite (no coordinates there)."""
        phi = np.array(k, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi[self.log_mask] = np.where(phi[self.log_mask] > 0.0, np.log(phi[self.log_mask]), np.nan)
        for b in self._mlog:
            phi[b.sl] = b.to_phi(phi[b.sl])
        return phi

    def chain(self, J_k: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``J_k dk/dphi``: a Jacobian in ``k`` (columns) to one in ``phi``. ``dk/dphi`` is
        ``diag(k)`` for springs, the identity for natural parameters and, per complex joint, the
        Frechet derivative of ``expm`` at ``S`` (:class:`_MatrixLog`)."""
        J = J_k * np.where(self.log_mask, k, 1.0)
        for b in self._mlog:
            J[:, b.sl] = J_k[:, b.sl] @ b.dk_dphi(k[b.sl])
        return J

    def log_step_size(self, step: np.ndarray) -> float:
        """How far a step in ``phi`` moves in log coordinates: the largest ``|d log k|`` of a
        spring and spectral norm of ``dS`` of a complex joint (which bounds the change of every
        eigenvalue's logarithm, Weyl). 0 when nothing is in log coordinates."""
        big = float(np.max(np.abs(step[self.log_mask]), initial=0.0))
        for b in self._mlog:
            big = max(big, float(np.max(np.abs(np.linalg.eigvalsh(b.sym(step[b.sl]))), initial=0.0)))
        return big

    def scale(self, k: np.ndarray) -> np.ndarray:
        """The size of each parameter: ``k`` for springs (at least 1e-3 of the joint's stiffest),
        ``max|diag K_J|`` of the joint otherwise."""
        s = np.abs(np.asarray(k, float)).copy()
        for sl in self._spring_slices:                   # a spring near 0 keeps its joint's scale
            s[sl] = np.maximum(s[sl], 1e-3 * np.max(s[sl]))
        for j, sl in self._others:
            s[sl] = float(np.max(np.abs(np.diag(j.matrix(k[sl])))))
        tiny = np.finfo(float).tiny
        return np.where(s > tiny, s, 1.0)

    def floor_value(self, k: np.ndarray) -> np.ndarray:
        """``_SPRING_FLOOR`` times the stiffest spring of the joint (springs only, else 0)."""
        out = np.zeros(self.p)
        for sl in self._spring_slices:
            out[sl] = _SPRING_FLOOR * np.max(k[sl])
        return out

    def at_floor(self, k: np.ndarray, relative: float = _SPRING_FLOOR) -> np.ndarray:
        """Springs at or below ``relative`` times the stiffest spring of their joint."""
        out = np.zeros(self.p, dtype=bool)
        for sl in self._spring_slices:
            out[sl] = k[sl] <= relative * np.max(k[sl]) * (1.0 + 1e-9)
        return out

    def admissible(self, k: np.ndarray) -> bool:
        """Finite, springs > 0 (always so in log space), other joints ``is_admissible(strict)``."""
        if not np.all(np.isfinite(k)) or np.any(k[self.log_mask] <= 0.0) or np.max(np.abs(k)) > 1e150:
            return False
        return all(j.is_admissible(k[sl], strict=True) for j, sl in self._others)

    def clipped(self, k: np.ndarray, relative: float) -> np.ndarray | None:
        """The nearest point (Frobenius norm, per joint) whose ``K_C`` eigenvalues are at least
        ``relative`` times the joint's largest (Higham 1988: clip the eigenvalues); ``None`` when
        a ``K_C`` has no positive eigenvalue, or the result is not admissible (e.g. a spring
        < 0: springs and other joint models are left as they are)."""
        out = np.array(k, dtype=float)
        if not np.all(np.isfinite(out)):
            return None
        for j, sl in self._others:
            if isinstance(j, ComplexJoint):
                mu, V = np.linalg.eigh(j.kc_matrix(out[sl]))
                if not mu[-1] > 0.0:
                    return None
                out[sl] = j.params_from_kc((V * np.maximum(mu, relative * mu[-1])) @ V.T)
        return out if self.admissible(out) else None

    # ---- model -----------------------------------------------------------------------------
    def dK(self, k: np.ndarray) -> np.ndarray:
        """``K_J(k) - K_deck`` over the boundary DOFs."""
        K_J = self.model.assembly.matrix(k) if self._D is None else (k @ self._Dflat).reshape(self.nB, self.nB)
        return K_J - self.model.K_deck

    def derivatives(self, k: np.ndarray) -> np.ndarray:
        return self.model.assembly.derivatives(k) if self._D is None else self._D

    def predict(self, k: np.ndarray) -> tuple[np.ndarray, Response]:
        """Eq. 22/30 in flexibility form, as ``CondensedModel.response`` (same result, tested)."""
        c = self.model.c
        try:
            if self._D is None:
                r = self.model.response(k)
            else:
                dK = self.dK(k)
                U_B = np.linalg.solve(np.eye(self.nB) + c.G_BB @ dK, c.U_B0)
                r = Response(U_B, c.U_O0 - c.G_OB @ (dK @ U_B))
        except np.linalg.LinAlgError:                     # singular: reported as non-finite
            r = Response(np.full_like(c.U_B0, np.nan), np.full_like(c.U_O0, np.nan))
        full = np.vstack([r.U_B, r.U_O]).ravel()
        f = full[self.flat]
        if self.has_ref.any():
            f = f - np.where(self.has_ref, full[self.flat_ref], 0.0)
        return f, r

    def jacobian_k(self, k: np.ndarray, r: Response) -> np.ndarray:
        """``dU/dk`` at the observed rows, ``(n_obs, n_params)``: eq. 18 in flexibility form,
        evaluated only where measured (``CondensedModel.sensitivities`` gives every row; the two
        agree to rounding, see the tests). With ``H = d U / d F_B`` of the structure with joints,
        ``H = [A^-1 G_BB; G_OB (I - dK A^-1 G_BB)]``, ``A = I + G_BB dK`` and ``D_p = dK_J/dk_p``::

            dU/dk_p = -H D_p U_B                                      (no solver run)
        """
        c = self.model.c
        dK = self.dK(k)
        W = np.linalg.solve(np.eye(self.nB) + c.G_BB @ dK, c.G_BB)
        H = np.vstack([W, c.G_OB - (c.G_OB @ dK) @ W])[self._rows_u]
        D = self.derivatives(k)
        p, nB, L = self.p, self.nB, self.L
        V = (D.reshape(-1, nB) @ r.U_B).reshape(p, nB, L)
        T = (H @ V.transpose(1, 0, 2).reshape(nB, -1)).reshape(len(self._rows_u), p, L)
        J = -T[self._rows_inv, :, self.obs.case_index]
        if self.has_ref.any():
            J[self.has_ref] += T[self._ref_inv, :, self.obs.case_index[self.has_ref]]
        return J

    def chi2(self, f: np.ndarray, y: np.ndarray | None = None) -> float:
        rr = ((self.y if y is None else y) - f) * self.w
        return float(rr @ rr)


# --------------------------------------------------------------------------------------------
# fixed-point scheme (eq. 22-29)
# --------------------------------------------------------------------------------------------
class _FixedPoint:
    """The regression of eq. 26-28 in flexibility form (see the module docstring)."""

    def __init__(self, prob: _Problem):
        model = prob.model
        c = model.c
        asm = model.assembly
        self.prob = prob
        self.G = np.vstack([c.G_BB, c.G_OB])
        self.U0 = np.vstack([c.U_B0, c.U_O0])
        self.K_deck = model.K_deck
        bindex = {d: i for i, d in enumerate(c.boundary)}
        self.joint_idx = [np.array([bindex[d] for d in j.dofs]) for j in asm.joints]
        D = np.abs(asm.derivatives(np.ones(asm.n_params))).sum(axis=0) + np.abs(self.K_deck)
        self.needed = np.flatnonzero(D.sum(axis=0) > 0)         # DOFs on which K_J or K_deck act
        self.reason = ""
        self.case_rows: list[tuple[int, np.ndarray, np.ndarray]] = []
        # Section 5.2: a row measured relative to a reference point becomes absolute by adding the
        # reference point's own (absolute) measurement of the same case; the fixed point is only
        # the start of the iteration, so the correlation this creates is not carried into V_e
        # (the Newton phase uses the rows as measured).
        self.y, self.w = prob.y, prob.w
        if prob.has_ref.any():
            obs = prob.obs
            absolute = {(d, c): i for i, (d, c, r) in
                        enumerate(zip(obs.dofs, obs.case_index.tolist(), prob.has_ref)) if not r}
            y, var = prob.y.copy(), prob.sigma.copy() ** 2
            for i in np.flatnonzero(prob.has_ref):
                j = absolute.get((obs.ref_dofs[i], int(obs.case_index[i])))
                if j is None:
                    self.reason = (f"the fixed-point scheme needs the reference DOF {obs.ref_dofs[i]} "
                                   f"measured absolutely in every case with relative rows")
                    return
                y[i] += prob.y[j]
                var[i] += prob.sigma[j] ** 2
            self.y, self.w = y, 1.0 / np.sqrt(var)
        for case in prob.obs.cases:
            rows = np.flatnonzero(prob.obs.case_index == case)
            if prob.has_ref.any():          # the reference point's rows sit among the absolute ones
                rows = rows[np.unique(prob.rows[rows], return_index=True)[1]]
            pos_of = {int(prob.rows[i]): a for a, i in enumerate(rows)}
            missing = [c.boundary[b] for b in self.needed if int(b) not in pos_of]
            if missing:
                lab = prob.obs.case_labels[case] if prob.obs.case_labels else f"#{case}"
                self.reason = (f"the fixed-point scheme needs every joint DOF measured in every case; "
                               f"case {lab!r} lacks {missing[:4]}{' ...' if len(missing) > 4 else ''}")
                break
            self.case_rows.append((case, rows, np.array([pos_of[int(b)] for b in self.needed])))

    @property
    def applicable(self) -> bool:
        return not self.reason

    def step(self, k: np.ndarray, live: np.ndarray) -> np.ndarray:
        """One weighted regression (eq. 28) with ``V_e`` (eq. 29) at ``k``: the new ``k``. Only the
        ``live`` parameters move: one the model response does not depend on at all would
        otherwise be fitted to the noise in ``X_m``."""
        prob, model = self.prob, self.prob.model
        asm = model.assembly
        dK = prob.dK(k)
        dK_nn = dK[np.ix_(self.needed, self.needed)]
        Xs, Ys = [], []
        for case, rows, pos in self.case_rows:
            srow = prob.rows[rows]
            um = self.y[rows]
            uB = np.zeros(prob.nB)
            uB[self.needed] = um[pos]
            X_m = np.zeros((prob.nB, prob.p))                    # Table 5.1, scattered into B
            for j, idx, sl in zip(asm.joints, self.joint_idx, asm.slices):
                X_m[idx, sl] = j.x_matrix(uB[idx])
            Gr = self.G[srow]
            X = Gr @ X_m                                         # eq. 27b, flexibility form
            Y = self.U0[srow, case] - um + Gr @ (self.K_deck @ uB)   # eq. 27a, flexibility form
            M = np.eye(rows.size)                                # K_overall of eq. 25a, flexibility form
            M[:, pos] += Gr[:, self.needed] @ dK_nn
            Xs.append(np.linalg.solve(M, X) * self.w[rows, None])     # V_e^-1/2 = V_m^-1/2 M^-1
            Ys.append(np.linalg.solve(M, Y) * self.w[rows])
        X, Y = np.vstack(Xs), np.concatenate(Ys)
        # eq. 28 as a least-squares problem for the change (min-norm: unidentifiable directions stay)
        out = k.copy()
        out[live] += _lsq(X[:, live], Y - X @ k, size=prob.scale(k)[live])
        return out


# --------------------------------------------------------------------------------------------
# Gauss-Newton / Levenberg-Marquardt (eq. 30-32)
# --------------------------------------------------------------------------------------------
@dataclass
class _Fit:
    phi: np.ndarray
    k: np.ndarray
    f: np.ndarray
    chi2: float
    status: int
    iterations: int


def _lsq(J: np.ndarray, r: np.ndarray, lam: float = 0.0, size: np.ndarray | None = None) -> np.ndarray:
    """``argmin |J x - r|^2 + lam |D x|^2`` with Marquardt's ``D = diag(J^T J)^(1/2)``.

    Through the column-scaled normal equations and a symmetric eigendecomposition (the
    problems are ``n_params`` wide: microseconds, where a threaded LAPACK least-squares call on a
    tall matrix costs milliseconds); directions with eigenvalue below ``1e-13`` of the largest
    are left out (the minimum-norm solution: an unidentifiable combination is not moved). A
    column whose effect ``|J_i| * size_i`` (``size``: the parameter's magnitude in the units of
    ``x``) is below ``1e-12`` of the largest has no effect at all and gets ``x_i = 0``.
    """
    N = J.T @ J
    d = np.sqrt(np.diag(N))
    effect = d * (1.0 if size is None else size)
    live = effect > 1e-12 * max(float(effect.max(initial=0.0)), np.finfo(float).tiny)
    x = np.zeros(J.shape[1])
    if not np.any(live):
        return x
    d = d[live]
    Ns = N[np.ix_(live, live)] / np.outer(d, d) + lam * np.eye(d.size)
    w, V = np.linalg.eigh(Ns)
    keep = w > 1e-13 * max(float(w[-1]), np.finfo(float).tiny)
    g = V[:, keep].T @ ((J[:, live].T @ r) / d)
    x[live] = (V[:, keep] @ (g / w[keep])) / d
    return x


def _relative_step(prob: _Problem, k_old: np.ndarray, k_new: np.ndarray, free: np.ndarray) -> float:
    """``|d phi|`` in log coordinates (``|d log k|`` for springs, ``|dS_ij|`` for a complex joint
    in ``logm K_C``), ``|dk| / scale`` for the others; the largest over ``free``."""
    d = np.abs(k_new - k_old) / prob.scale(k_old)
    lc = prob.log_coords
    with np.errstate(invalid="ignore"):
        d[lc] = np.abs(prob.to_phi(k_new)[lc] - prob.to_phi(k_old)[lc])
    d[~np.isfinite(d)] = np.inf
    return float(np.max(d[free])) if np.any(free) else 0.0


def _admissible_on_segment(prob: _Problem, k: np.ndarray, k_t: np.ndarray,
                           shrink: float = 0.9) -> np.ndarray | None:
    """The regression of eq. 28 is unconstrained and can leave the admissible set (a spring
    below 0, ``K_C`` not positive definite). The admissible set is convex and ``k`` is in it, so
    the segment towards ``k_t`` stays admissible up to some fraction: bisect for it and stop a
    little short (``shrink``), so that the next iterate is strictly inside."""
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if prob.admissible(k + mid * (k_t - k)):
            lo = mid
        else:
            hi = mid
    if lo <= 0.0:
        return None
    return k + shrink * lo * (k_t - k)


def _admissible_fixed_point(prob: _Problem, k: np.ndarray, k_t: np.ndarray
                            ) -> tuple[np.ndarray | None, float]:
    """The regression's result ``k_t`` made admissible, with its ``chi2``: ``k_t`` itself if it
    is, else the best (lowest ``chi2``) of the admissible point on the segment from ``k``
    (:func:`_admissible_on_segment`) and the nearest points with the ``K_C`` eigenvalues floored
    at :data:`_FP_FLOORS` times the largest (:meth:`_Problem.clipped`). The regression leaves
    the positive definite set through the noise in ``X_m`` along a weakly determined direction;
    the segment then shortens the *whole* step, the clipped matrix keeps it (the issue's cube
    study, 5 % noise, from ``K_C = 1e3 I``: ``chi2`` 5e7 -> 3e7 on the segment, -> 2e3
    clipped; over 40 cube and 20 car replicates the floor chosen was 0.03-0.3). Floors far
    below the rest are not offered: the estimate would start Newton where the response no
    longer feels that direction (``u ~ 1 / k``) and log coordinates crawl back -- a spring
    clipped to 1e-4 of the others on the car with joint-only measurements took 8 extra
    iterations, which is why springs keep the segment."""
    def chi2(kc: np.ndarray | None) -> float:
        if kc is None:
            return np.inf
        f = prob.predict(kc)[0]
        return prob.chi2(f) if np.all(np.isfinite(f)) else np.inf

    if prob.admissible(k_t):
        return k_t, chi2(k_t)
    cands = [_admissible_on_segment(prob, k, k_t)] + [prob.clipped(k_t, r) for r in _FP_FLOORS]
    F = [chi2(c) for c in cands]
    i = int(np.argmin(F))
    return (cands[i], F[i]) if np.isfinite(F[i]) else (None, np.inf)


def _shift(phi: np.ndarray, free: np.ndarray, step: np.ndarray) -> np.ndarray:
    out = phi.copy()
    out[free] += step
    return out


def _bounded_natural_step(prob: _Problem, J_k: np.ndarray, r: np.ndarray, k: np.ndarray,
                          use: np.ndarray) -> np.ndarray | None:
    """The Gauss-Newton step in natural coordinates with the springs bounded below by the floor,
    by an active set: ``None`` unless some spring's natural step would cross the floor. (In
    log k the bound is infinitely far: a spring heading for 0 would crawl.)"""
    floor = prob.floor_value(k)
    active = np.zeros(prob.p, dtype=bool)
    for _ in range(prob.p):
        rest = use & ~active
        if not np.any(rest):
            break
        shift = np.where(active, floor - k, 0.0)
        d = _lsq(J_k[:, rest], r - J_k @ shift, size=prob.scale(k)[rest])
        k_new = k + shift
        k_new[rest] += d
        cross = rest & prob.log_mask & (k_new < floor)
        if not np.any(cross):
            break
        active |= cross
    if not np.any(active):
        return None
    k_new = np.maximum(k_new, np.where(prob.log_mask, floor, -np.inf))
    return k_new if prob.admissible(k_new) else None


def _newton(prob: _Problem, phi0: np.ndarray, *, y: np.ndarray | None = None, free: np.ndarray | None = None,
            max_iterations: int, xtol: float, ftol: float, first_iteration: int = 1,
            history: list | None = None, callback: Callable | None = None) -> _Fit:
    """Damped Gauss-Newton (eq. 30-32) in ``phi`` (log k for springs, logm K_C for complex joints)
    over the ``free`` parameters.

    Each iteration solves the linearised problem (eq. 32) by least squares, tries the step with
    and without the geodesic acceleration at full length and shortened (:data:`_BACKTRACK`;
    at each length the lower ``chi2`` wins), and if no fraction decreases ``chi2`` (or all leave
    the admissible set) raises the Levenberg-Marquardt damping ``lambda`` (Marquardt's
    ``diag(J^T J)`` scaling). ``ftol`` needs both the actual
    decrease and the decrease the undamped Gauss-Newton step predicts below ``ftol * chi2`` (as
    MINPACK): a short step in a curved valley does not stop the iteration.

    Springs and the bound ``k = 0``: when the Gauss-Newton step in natural coordinates would take
    a spring below the floor (:data:`_SPRING_FLOOR` times its joint's stiffest), that bounded
    natural step (:func:`_bounded_natural_step`) is taken first if it does not raise ``chi2`` --
    in log k the bound is infinitely far -- and a spring at the floor that still wants to
    decrease is held there (an active bound).
    """
    y = prob.y if y is None else y
    free = np.ones(prob.p, dtype=bool) if free is None else free
    phi = np.array(phi0, dtype=float)
    k = prob.to_k(phi)
    f, resp = prob.predict(k)
    F = prob.chi2(f, y)
    if not np.any(free):
        return _Fit(phi, k, f, F, 1, 0)
    lam, status, it = 0.0, 0, 0
    while it < max_iterations and status == 0:
        it += 1
        r = (y - f) * prob.w
        J_k = prob.jacobian_k(k, resp) * prob.w[:, None]         # whitened, natural parameters
        J_all = prob.chain(J_k, k)
        use = free.copy()
        size = np.where(prob.log_coords, 1.0, prob.scale(k))     # of a unit of phi
        step_gn = _lsq(J_all[:, use], r, size=size[use])
        # the bound k = 0 of the springs (active set)
        down = np.zeros(prob.p, dtype=bool)
        down[use] = step_gn < 0.0
        held = use & down & prob.at_floor(k, 2.0 * _SPRING_FLOOR)
        # the natural GN step is k * d(log k): a spring crosses the floor iff d log k < floor/k - 1
        crossing = np.zeros(prob.p, dtype=bool)
        lg = use & prob.log_mask
        crossing[lg] = step_gn[prob.log_mask[use]] < prob.floor_value(k)[lg] / k[lg] - 1.0
        k_b = None
        if np.any(crossing & ~held):
            k_b = _bounded_natural_step(prob, J_k, r, k, use & ~held)
        if k_b is not None:
            f_b, resp_b = prob.predict(k_b)
            F_b = prob.chi2(f_b, y) if np.all(np.isfinite(f_b)) else np.inf
            if F_b <= F:
                phi, k, f, resp, F = prob.to_phi(k_b), k_b, f_b, resp_b, F_b
                r = (y - f) * prob.w
                J_k = prob.jacobian_k(k, resp) * prob.w[:, None]
                J_all = prob.chain(J_k, k)
                size = np.where(prob.log_coords, 1.0, prob.scale(k))
                held |= use & prob.at_floor(k, 2.0 * _SPRING_FLOOR)
        if np.any(held):
            use &= ~held
            if not np.any(use):
                status = 1
                break
            step_gn = _lsq(J_all[:, use], r, size=size[use])
        J = J_all[:, use]
        predicted = float(np.sum((J @ step_gn) ** 2))          # decrease the GN step promises
        ok = small = False
        while True:
            step = step_gn.copy() if lam == 0.0 else _lsq(J, r, lam, size[use])
            # geodesic acceleration (Transtrum & Sethna 2012): a second-order correction along
            # the curved valleys of weakly determined springs, from one extra prediction
            steps = [step]
            k_h = prob.to_k(_shift(phi, use, _GEODESIC_H * step))
            if prob.admissible(k_h):
                f_vv = (2.0 / _GEODESIC_H) * ((prob.predict(k_h)[0] - f) / _GEODESIC_H
                                              - (J @ step) / prob.w)
                acc = _lsq(J, -f_vv * prob.w, lam, size[use])
                if np.all(np.isfinite(acc)) and (2.0 * np.linalg.norm(acc)
                                                 <= _GEODESIC_RATIO * np.linalg.norm(step)):
                    steps = [step + 0.5 * acc, step]
            for j, st in enumerate(steps):
                big = prob.log_step_size(_shift(np.zeros(prob.p), use, st))
                if big > _MAX_LOG_STEP:
                    steps[j] = st * (_MAX_LOG_STEP / big)
            # relative step (as _relative_step): phi itself in log coordinates, else dk / scale
            small = float(np.max(np.abs(steps[-1]) / size[use])) < xtol
            for alpha in _BACKTRACK:                  # line search along the (damped) GN step
                best = None
                for st in steps:
                    phi_c = _shift(phi, use, alpha * st)
                    k_c = prob.to_k(phi_c)
                    if not prob.admissible(k_c):
                        continue
                    f_c, resp_c = prob.predict(k_c)
                    F_c = prob.chi2(f_c, y) if np.all(np.isfinite(f_c)) else np.inf
                    if F_c <= F and (best is None or F_c < best[-1]):
                        best = (phi_c, k_c, f_c, resp_c, F_c)
                if best is not None:
                    phi_t, k_t, f_t, resp_t, F_t = best
                    ok = True
                    break
            if ok or small:
                break
            lam = 1e-3 if lam == 0.0 else 10.0 * lam
            if lam > 1e12:
                break
        if not ok:
            status = 1 if small else 4                # at the minimum to rounding, or stuck
            break
        dF = F - F_t
        phi, k, f, resp, F = phi_t, k_t, f_t, resp_t, F_t
        if history is not None:
            rec = IterationRecord(first_iteration + it - 1, "newton", k.copy(), F, lam)
            history.append(rec)
            if callback is not None and callback(rec):
                status = 5
                break
        status = (1 if small else 0) + (2 if max(dF, predicted) <= ftol * max(F, np.finfo(float).tiny) else 0)
        lam = 0.0 if lam < 1e-6 else lam / 10.0
    return _Fit(phi, k, f, F, status, it)


# --------------------------------------------------------------------------------------------
# uncertainty
# --------------------------------------------------------------------------------------------
def _covariance(prob: _Problem, k: np.ndarray, resp: Response, rank_rtol: float):
    """``(J^T V_m^-1 J)^+`` via pivoted QR; returns ``(cov, identifiable, rank)``."""
    p = prob.p
    s = prob.scale(k)
    Js = prob.jacobian_k(k, resp) * prob.w[:, None] * s          # whitened, scaled columns
    _, R, P = sla.qr(Js, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > rank_rtol * d[0])) if d.size and d[0] > 0 else 0
    cov = np.full((p, p), np.nan)
    ident = np.zeros(p, dtype=bool)
    if rank:
        Q2, T = sla.qr(R[:rank, :].T, mode="full")             # R1 = T^T Q2^T: complete orthogonal
        Tr = T[:rank, :rank]
        Ti = np.linalg.inv(Tr)
        C = Q2[:, :rank] @ (Ti.T @ Ti) @ Q2[:, :rank].T          # pinv(R1^T R1) in pivoted order
        null = np.zeros((p, p - rank))
        null[P] = Q2[:, rank:]
        ident = np.linalg.norm(null, axis=1) < _NULL_TOL if p > rank else np.ones(p, dtype=bool)
        cov_s = np.empty((p, p))
        cov_s[np.ix_(P, P)] = C
        cov = cov_s * np.outer(s, s)                           # k = s * (k / s)
        cov[~ident, :] = np.nan
        cov[:, ~ident] = np.nan
    return cov, ident, rank


def _root_through_origin(p1: tuple[float, float], p2: tuple[float, float], level: float) -> float:
    """Where ``tau(h) = level`` for ``tau = a h + b h^2`` through ``(0, 0)``, ``p1``, ``p2``
    (the secant of ``p1, p2`` when ``p1`` is the origin or the parabola has no root beyond 0)."""
    (h1, t1), (h2, t2) = p1, p2
    if not (np.isfinite(t1) and np.isfinite(t2)) or h1 == h2:
        return np.nan
    if h1 > 0.0:
        det = h1 * h2 * (h2 - h1)
        a = (t1 * h2 * h2 - t2 * h1 * h1) / det
        b = (t2 * h1 - t1 * h2) / det
        if b != 0.0:
            disc = a * a + 4.0 * b * level
            if disc >= 0.0:
                roots = [(-a + sgn * math.sqrt(disc)) / (2.0 * b) for sgn in (1.0, -1.0)]
                roots = [x for x in roots if x > 0.0]
                if roots:
                    return min(roots, key=lambda x: abs(x - h2))
    return h2 + (level - t2) * (h2 - h1) / (t2 - t1) if t2 != t1 else np.nan


def _profile_ci(prob: _Problem, fit: _Fit, i: int, delta: float, half_width: float,
                xtol: float, ftol: float) -> tuple[float, float]:
    """Profile-likelihood interval of parameter ``i``: where the profile ``min chi2`` with
    ``phi_i`` fixed (the others re-optimised, warm-started from the nearest solved point)
    reaches ``chi2_min + delta``. Searched in ``phi`` (log k for springs, the entries of ``K_C``
    for the complex model: :meth:`_Problem.natural`) on the profile-t
    scale ``tau = sqrt(chi2_profile - chi2_min)`` (Bates & Watts 1988, ch. 6), which is linear
    in ``phi`` when the model is: the first trial is the linearised end point ``half_width``
    (at most a factor 10 for a spring) and a secant on ``tau`` usually ends the search in 2-3
    profiles. A side where the profile stays below the level is unbounded: ``inf``, or ``0`` for
    the lower end of a spring (springs are searched down to the floor and up to
    :data:`_PROFILE_SPAN` times the joint's stiffest spring, other parameters over
    :data:`_PROFILE_WIDTHS` linearised half-widths)."""
    prob = prob.natural()                             # k_i must be a coordinate
    phi_fit = prob.to_phi(fit.k)
    free = np.ones(prob.p, dtype=bool)
    free[i] = False
    tau_star = math.sqrt(delta)
    phi_hat = float(phi_fit[i])
    ends = []
    for side in (-1.0, 1.0):
        solved = {0.0: phi_fit}

        def tau(h: float) -> float:
            near = min(solved, key=lambda u: abs(u - h))
            phi = solved[near].copy()
            phi[i] = phi_hat + side * h
            if not prob.admissible(prob.to_k(phi)):
                return np.inf
            sub = _newton(prob, phi, free=free, max_iterations=50, xtol=max(xtol, 1e-6), ftol=max(ftol, 1e-8))
            solved[h] = sub.phi
            return math.sqrt(max(sub.chi2 - fit.chi2, 0.0))

        lo, hi = 0.0, np.inf                          # tau(lo) < tau_star <= tau(hi)
        h = half_width if np.isfinite(half_width) and half_width > 0 else 1.0
        if prob.log_mask[i]:                          # springs: from the floor to 1e6 x the stiffest
            floor = prob.floor_value(fit.k)[i]
            top = floor / _SPRING_FLOOR                # the stiffest spring of the joint
            limit = math.log(fit.k[i] / floor) if side < 0 else math.log(_PROFILE_SPAN * top / fit.k[i])
            h = min(h, math.log(10.0))                # the first crossing, not a far one:
            max_stride = math.log(10.0)               # a decade at a time
            if limit <= 1e-9:
                ends.append(-np.inf)                  # at the floor: the lower end is 0
                continue
        else:
            limit, max_stride = _PROFILE_WIDTHS * h, np.inf
        h = min(h, limit)
        result = np.inf
        prev = (0.0, 0.0)                             # the last evaluated point, for the secant
        for _ in range(30):
            t = tau(h)
            if abs(t - tau_star) <= _PROFILE_TAU_RTOL * tau_star:
                result = h
                break
            if t < tau_star:
                lo = h
            else:
                hi = h
            if np.isfinite(hi) and hi - lo <= _PROFILE_TAU_RTOL * min(half_width, h):
                result = 0.5 * (lo + hi)
                break
            # tau(0) = 0: the parabola through 0 and the last two points, else their secant ...
            h_new = _root_through_origin(prev, (h, t), tau_star)
            prev = (h, t)
            if np.isfinite(hi):                       # ... kept inside the bracket
                h = h_new if lo < h_new < hi else 0.5 * (lo + hi)
            else:                                     # ... or a bounded extrapolation
                if lo >= limit:
                    break                             # flat: unbounded on this side
                h_new = 1.05 * h_new if np.isfinite(h_new) else 4.0 * lo
                h = min(max(h_new, 1.1 * lo), 4.0 * lo, limit, lo + max_stride)
        ends.append(phi_hat + side * result)
    out = np.array(ends)
    if prob.log_mask[i]:
        with np.errstate(over="ignore"):
            return float(np.exp(out[0])), float(np.exp(out[1]))
    return float(out[0]), float(out[1])


# --------------------------------------------------------------------------------------------
# the estimator
# --------------------------------------------------------------------------------------------
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
            if not F_t < _FP_STALL * F:           # stalls or oscillates: hand over to Newton
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
    return fit, history, n_fp, fit.iterations


def identify(model: CondensedModel, obs: Observations, k0, *, fixed_point: bool = True,
             max_iterations: int = 30, confidence: float = 0.95, holdout: Observations | None = None,
             xtol: float = 1e-8, ftol: float = 1e-10, callback: Callable[[IterationRecord], bool] | None = None,
             profile: bool = True, bootstrap: int = 0, seed: int = 0, scale_covariance: bool = False,
             rank_rtol: float = 1e-8) -> IdentificationResult:
    """Weighted least-squares estimate of the joint parameters (Sec. 4.3) with its uncertainty.

    ``k0``: the start, the concatenated parameters of ``model.assembly`` (admissible: springs > 0,
    ``K_C`` positive definite). ``fixed_point``: start with the fixed-point scheme when it
    applies. ``callback(record)`` is called after every accepted iteration; a true return value
    stops (status 5). ``holdout`` rows are predicted with the estimate, never fitted.
    ``profile``: report profile-likelihood intervals (default; ``False`` reports the linearised
    ones, faster, e.g. inside a loop). ``bootstrap = N``: a parametric bootstrap of ``N``
    replicates seeded by ``seed``. ``scale_covariance``, ``rank_rtol``: see the module docstring.
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
    chi2 = float(res @ res)
    dof = n - p
    red = chi2 / dof if dof > 0 else float("nan")
    m2logL = chi2 + float(np.sum(np.log(2.0 * np.pi * prob.sigma ** 2)))
    aic, bic = m2logL + 2 * p, m2logL + p * math.log(n)
    rms = float(np.sqrt(np.mean((prob.y - f) ** 2)))
    if dof > 0:
        pval = float(stats.chi2.sf(chi2, dof))
        if pval < 1e-3:
            warnings.append(
                f"chi2 = {chi2:.4g} for {dof} degrees of freedom (p = {pval:.2g}): the residuals are "
                f"larger than the declared sigma explains (model error or underestimated sigma); "
                f"the intervals assume sigma is right unless scale_covariance=True")

    # ---- covariance, identifiability, linearised intervals -------------------------------------
    cov, ident, rank = _covariance(prob, k, resp, rank_rtol)
    scaled = scale_covariance and dof > 0
    cscale = max(1.0, red) if scaled else 1.0
    cov = cov * cscale
    std = np.where(ident, np.sqrt(np.abs(np.diag(cov))), np.inf)
    z = float(stats.t.ppf(0.5 + confidence / 2.0, dof) if scaled else stats.norm.ppf(0.5 + confidence / 2.0))
    lin = np.full((p, 2), np.nan)
    lg = prob.log_mask
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        half = z * std / np.where(lg, k, 1.0)                # in log k for springs, else in k
        lin[lg & ident] = k[lg & ident, None] * np.exp(np.outer(half[lg & ident], [-1.0, 1.0]))
        lin[~lg & ident] = k[~lg & ident, None] + np.outer(half[~lg & ident], [-1.0, 1.0])
        corr = cov / np.outer(std, std)
    if not np.all(ident):
        bad = [names[i] for i in np.flatnonzero(~ident)]
        warnings.append(f"parameter(s) {bad} are not identifiable from these observations "
                        f"(rank {rank} of {p}): only combinations with others are determined")
    at_zero = prob.at_floor(k, 2.0 * _SPRING_FLOOR)
    if np.any(at_zero):
        warnings.append(f"spring(s) {[names[i] for i in np.flatnonzero(at_zero)]} tend to 0 (held at "
                        f"{_SPRING_FLOOR:g} x the joint's stiffest): the data want no spring there")
    if not converged:
        warnings.append(f"not converged: {message}")

    # ---- profile likelihood, bootstrap ---------------------------------------------------------
    prof = None
    if profile:
        prof = np.full((p, 2), np.nan)
        for i in np.flatnonzero(ident):
            prof[i] = _profile_ci(prob, fit, int(i), z * z * cscale, half[i], xtol, ftol)
        ci, ci_method = prof, "profile likelihood"
    else:
        ci, ci_method = lin, "linearised"
    ci_method += (f" ({'Student t' if scaled else 'normal'} quantile {z:.4g}"
                  f"{'; log-space for simple-model springs' if np.any(lg) and not profile else ''})")
    boot_ci = boot = None
    if bootstrap:
        rng = np.random.default_rng(seed)
        samples = []
        for _ in range(int(bootstrap)):
            y_b = f + prob.sigma * rng.standard_normal(n)
            b = _newton(prob, fit.phi, y=y_b, max_iterations=int(max_iterations), xtol=xtol, ftol=ftol)
            if b.status in (1, 2, 3):
                samples.append(b.k)
        boot = np.array(samples).reshape(-1, p)
        if len(samples) < bootstrap:
            warnings.append(f"{bootstrap - len(samples)} of {bootstrap} bootstrap refits did not converge")
        a = 100.0 * (1.0 - confidence) / 2.0
        boot_ci = np.percentile(boot, [a, 100.0 - a], axis=0).T if len(samples) else np.full((p, 2), np.nan)
        boot_ci[~ident] = np.nan

    # ---- holdout --------------------------------------------------------------------------------
    hstats = None
    if holdout_prob is not None:
        fh, _ = holdout_prob.predict(k)
        rh = (holdout_prob.y - fh) * holdout_prob.w
        labels = model.c.cases
        overlap = set(holdout.cases) & set(obs.cases)
        if overlap:
            warnings.append(f"holdout case(s) {[labels[c] for c in sorted(overlap)]} are also fitted")
        hstats = HoldoutStats(tuple(labels[c] for c in holdout.cases), len(holdout),
                              float(np.sqrt(np.mean((holdout_prob.y - fh) ** 2))), float(rh @ rh), rh)

    return IdentificationResult(
        k=k, param_names=tuple(names), param_joint=tuple(joints_of), std=std,
        ci_low=ci[:, 0].copy(), ci_high=ci[:, 1].copy(), confidence=float(confidence),
        ci_method=ci_method, linear_ci=lin, identifiable=ident, rank=rank, covariance=cov,
        correlation=corr, covariance_scale=cscale, converged=converged, status=fit.status,
        message=message, iterations=n_fp + n_newton, n_fixed_point=n_fp, n_newton=n_newton,
        history=tuple(history), n_obs=n, n_params=p, chi2=chi2, reduced_chi2=red, rms_residual=rms,
        aic=aic, bic=bic, residuals=res, predicted=f, holdout=hstats, profile_ci=prof,
        bootstrap_ci=boot_ci, bootstrap_samples=boot, warnings=tuple(warnings))
