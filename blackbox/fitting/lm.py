"""One safeguarded Levenberg-Marquardt core for weighted least squares (Sec. 4.3.2, eq. 30-32).

The problem is ``min chi2(k) = sum_i ((y_i - f_i(k)) w_i)^2`` with the weights ``w = 1 / sigma``
(the declared measurement errors, ``V_m = diag(sigma^2)``): the maximum-likelihood estimate for
Gaussian errors. The iteration runs in coordinates ``x`` of the parameters, ``k = k(x)`` (a
:class:`Coordinates`): ``log k`` for a parameter that must stay positive, the matrix logarithm
for a positive definite matrix, the natural parameters for the rest. With the whitened residual
``r = (y - f) w`` and Jacobian ``J = diag(w) (df/dk) (dk/dx)`` one iteration solves

    (J^T J + lambda D^T D) dx = J^T r,    D = diag(J^T J)^(1/2)                (eq. 32; Marquardt 1963)

by :func:`solve_damped` (column-scaled normal equations, minimum-norm in the numerical null
space: a combination the data do not determine is not moved). ``lambda = 0`` is the Gauss-Newton
step: the model linearised at the current parameters (eq. 32) solved by the weighted regression
of eq. 28 with ``X = df/dx`` and ``V = V_m``. Marquardt's scaling makes the damping invariant to
the units of each parameter.

Safeguards, in the order they act in an iteration:

* **bounds by an active set** (:class:`Bounds`, optional): before the damped steps, the problem may
  offer a point with the parameters that the Gauss-Newton step would take past a bound placed on
  it (an active set in the natural parameters, :func:`bounded_gauss_newton_step`); it is taken if
  it does not raise ``chi2``. A parameter at a bound that the step pushes further out is held
  there for the iteration.
* **geodesic acceleration** (Transtrum & Sethna 2012, *arXiv:1201.5885*, eq. 14-16; optional):
  the second directional derivative ``f_vv`` along the step from one extra prediction at
  ``x + h dx`` (``h = 0.1``), ``f_vv = (2/h) ((f(x + h dx) - f) / h - J dx)``, and the correction
  ``a`` solving the same damped system with ``-f_vv``; ``dx + a/2`` follows a curved valley
  (weakly determined parameters) to second order. It is offered while ``|a| <= 1.5 |dx|``, next
  to the plain step: at every trial length the lower ``chi2`` wins.
* **step cap**: a step moves at most ``log(100)`` in log coordinates (:meth:`Coordinates.log_step`):
  a spring changes by at most a factor 100 per iteration.
* **backtracking**: fractions 1, 1/2, 1/4, 1/8 of the (damped) step; a trial point that is not
  admissible or raises ``chi2`` is never taken, so ``chi2`` never increases. When no fraction is
  accepted ``lambda`` rises (``1e-3``, then x10 up to ``1e12``); after an accepted step it falls
  tenfold (to 0 below ``1e-6``).

The damping schedule, the backtracking fractions, the acceptance of an equal ``chi2``, the
predicted-decrease test and the dead-column threshold of :func:`solve_damped` are an
:class:`LMSchedule` (the defaults above). Bounds may instead be handled by **projection**
(:class:`ProjectedBoxBounds`): the parameters at a bound that the steepest-descent direction
``J^T r`` pushes further out are held for the iteration, every trial point is projected into the
box, no bounded point is offered. With natural coordinates, no dead columns and no backtracking
this is the classical projected Levenberg-Marquardt that lets a spring run far toward infinity
(a flat valley of a misfit model) while the other parameters keep moving (see
:data:`PROJECTED_SCHEDULE`).

Convergence (MINPACK's tests, Moré 1978): status 1 when the relative step is below ``xtol``
(``|dx|`` in log coordinates, ``|dk| / size`` in natural ones, :meth:`Coordinates.unit_size`);
status 2 when both the actual decrease of ``chi2`` and the decrease the undamped Gauss-Newton
step predicts (``|J dx_GN|^2``) are below ``ftol * chi2`` -- a short step in a curved valley alone
does not stop the iteration; 3 for both. Status 0: the iteration limit; 4: no damped step
decreases ``chi2`` (stuck, or at the minimum to rounding); 5: the callback asked to stop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Protocol, Sequence

import numpy as np

__all__ = ["STATUS_MESSAGES", "Coordinates", "NaturalCoordinates", "LogCoordinates", "Bounds", "BoxBounds",
           "ProjectedBoxBounds", "LMSchedule", "DEFAULT_SCHEDULE", "PROJECTED_SCHEDULE",
           "LeastSquaresProblem", "LMIteration", "LMResult", "levenberg_marquardt", "solve_damped",
           "bounded_gauss_newton_step"]

STATUS_MESSAGES = {
    0: "maximum number of iterations reached",
    1: "relative parameter step below xtol",
    2: "relative decrease of chi2 below ftol",
    3: "relative parameter step below xtol and decrease of chi2 below ftol",
    4: "no damped step decreases chi2 any further",
    5: "stopped by the callback",
}
CONVERGED = (1, 2, 3)
MAX_LOG_STEP = math.log(100.0)      # a log coordinate changes by at most log(100) per iteration
BACKTRACK = (1.0, 0.5, 0.25, 0.125)  # step fractions tried before the damping is raised
GEODESIC_H = 0.1                    # finite-difference step (in units of the step) for f_vv
GEODESIC_RATIO = 3.0                # the accelerated step is offered while |2 a| <= 3 |dx|
                                    # (Transtrum's 0.75 is for a step taken blind; here the plain
                                    # step is always tried beside it)
LAMBDA_START = 1e-3                 # first nonzero Marquardt lambda
LAMBDA_MAX = 1e12                   # beyond: no damped step decreases chi2 (status 4)
LAMBDA_RESET = 1e-6                 # after a success lambda / 10, or 0 below this
DEAD_RTOL = 1e-12                   # a column whose effect is below this x the largest is dead


@dataclass(frozen=True)
class LMSchedule:
    """How the iteration damps, searches and stops (module docstring); the defaults are the
    safeguarded iteration of the identification.

    ``lambda_start``: the first nonzero Marquardt lambda; ``lambda_reset``: after an accepted
    step lambda falls tenfold, to 0 below this; ``lambda_max``: beyond it no damped step
    decreases chi2 (status 4); ``backtrack``: the step fractions tried before lambda rises;
    ``accept_equal``: whether a trial point with the same chi2 is accepted;
    ``predicted_decrease``: whether the ftol test also needs the Gauss-Newton step's predicted
    decrease below ``ftol * chi2`` (else the actual decrease alone); ``dead_rtol``: the
    dead-column threshold of :func:`solve_damped` (0: only an exactly zero column is dead)."""
    lambda_start: float = LAMBDA_START
    lambda_reset: float = LAMBDA_RESET
    lambda_max: float = LAMBDA_MAX
    backtrack: tuple[float, ...] = BACKTRACK
    accept_equal: bool = True
    predicted_decrease: bool = True
    dead_rtol: float = DEAD_RTOL


DEFAULT_SCHEDULE = LMSchedule()
# projected Levenberg-Marquardt in natural coordinates: a parameter whose column shrinks toward 0
# (a spring running to infinity, dU/dk ~ 1/k^2) keeps its column, lambda climbs to 1e12 before
# the iteration gives up, only a strict decrease is a step and the full damped step is the only
# trial point (its projection into the box already shortens it)
PROJECTED_SCHEDULE = LMSchedule(lambda_start=1e-4, lambda_reset=1e-3, backtrack=(1.0,), accept_equal=False,
                                predicted_decrease=False, dead_rtol=0.0)


# --------------------------------------------------------------------------------------------
# the linear algebra of one step
# --------------------------------------------------------------------------------------------
def solve_damped(J: np.ndarray, r: np.ndarray, lam: float = 0.0, size: np.ndarray | None = None,
                 dead_rtol: float = DEAD_RTOL) -> np.ndarray:
    """``argmin |J x - r|^2 + lam |D x|^2`` with Marquardt's ``D = diag(J^T J)^(1/2)``.

    Through the column-scaled normal equations and a symmetric eigendecomposition (the
    problems are a few parameters wide: microseconds, where a threaded LAPACK least-squares call
    on a tall matrix costs milliseconds); directions with eigenvalue below ``1e-13`` of the
    largest are left out (the minimum-norm solution: an unidentifiable combination is not
    moved). A column whose effect ``|J_i| * size_i`` (``size``: the parameter's magnitude in the
    units of ``x``) is below ``dead_rtol`` (``1e-12``) of the largest has no effect at all and
    gets ``x_i = 0``; with ``dead_rtol = 0`` only a zero column does.
    """
    N = J.T @ J
    d = np.sqrt(np.diag(N))
    effect = d * (1.0 if size is None else size)
    live = effect > dead_rtol * max(float(effect.max(initial=0.0)), np.finfo(float).tiny)
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


def bounded_gauss_newton_step(J: np.ndarray, r: np.ndarray, k: np.ndarray, use: np.ndarray,
                              lower: np.ndarray, upper: np.ndarray,
                              size: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Newton step in the natural parameters ``k`` (``J`` whitened, ``df/dk``) with the
    box ``lower <= k <= upper`` by an active set: the ``use`` parameters that the step takes past
    a bound are fixed at it and the rest re-solved, until no free parameter crosses. Returns the
    new point (clipped into the box) and the mask of the active parameters (none: no bound was
    crossed, and the point is the unbounded step)."""
    p = k.size
    active = np.zeros(p, dtype=bool)
    at_hi = np.zeros(p, dtype=bool)
    k_new = k.copy()
    for _ in range(p):
        rest = use & ~active
        if not np.any(rest):
            break
        shift = np.where(active, np.where(at_hi, upper, lower) - k, 0.0)
        d = solve_damped(J[:, rest], r - J @ shift, size=None if size is None else size[rest])
        k_new = k + shift
        k_new[rest] += d
        cross_lo = rest & (k_new < lower)
        cross_hi = rest & (k_new > upper)
        if not np.any(cross_lo | cross_hi):
            break
        active |= cross_lo | cross_hi
        at_hi |= cross_hi
    return np.minimum(np.maximum(k_new, lower), upper), active


# --------------------------------------------------------------------------------------------
# what a problem supplies
# --------------------------------------------------------------------------------------------
class Coordinates(Protocol):
    """The parameter transform ``k = k(x)`` the iteration runs in."""

    def to_natural(self, x: np.ndarray) -> np.ndarray:
        """``k(x)``."""

    def to_coords(self, k: np.ndarray) -> np.ndarray:
        """``x(k)``; ``nan`` where ``k`` has no coordinates (outside the admissible set)."""

    def chain(self, J_k: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``J_k dk/dx``: a Jacobian in ``k`` (columns) to one in ``x``."""

    def unit_size(self, k: np.ndarray) -> np.ndarray:
        """The size of one unit of each coordinate relative to its parameter: 1 for a log
        coordinate, the parameter's magnitude for a natural one (relative steps, dead columns)."""

    def log_step(self, dx: np.ndarray) -> float:
        """How far ``dx`` moves in log coordinates (for the step cap); 0 when none is."""


class NaturalCoordinates:
    """``x = k``; ``scale(k)`` gives each parameter's magnitude (default ``|k|``, at least the
    smallest normal number)."""

    def __init__(self, scale: Callable[[np.ndarray], np.ndarray] | None = None):
        self._scale = scale

    def to_natural(self, x: np.ndarray) -> np.ndarray:
        return np.array(x, dtype=float)

    def to_coords(self, k: np.ndarray) -> np.ndarray:
        return np.array(k, dtype=float)

    def chain(self, J_k: np.ndarray, k: np.ndarray) -> np.ndarray:
        return J_k.copy()

    def unit_size(self, k: np.ndarray) -> np.ndarray:
        s = np.abs(k) if self._scale is None else self._scale(k)
        return np.where(s > np.finfo(float).tiny, s, 1.0)

    def log_step(self, dx: np.ndarray) -> float:
        return 0.0


class LogCoordinates(NaturalCoordinates):
    """``x_i = log k_i`` where ``mask`` (parameters that must stay positive), natural elsewhere."""

    def __init__(self, mask: np.ndarray, scale: Callable[[np.ndarray], np.ndarray] | None = None):
        super().__init__(scale)
        self.mask = np.asarray(mask, dtype=bool)

    def to_natural(self, x: np.ndarray) -> np.ndarray:
        k = np.array(x, dtype=float)
        k[self.mask] = np.exp(np.minimum(k[self.mask], 700.0))
        return k

    def to_coords(self, k: np.ndarray) -> np.ndarray:
        x = np.array(k, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            x[self.mask] = np.where(x[self.mask] > 0.0, np.log(x[self.mask]), np.nan)
        return x

    def chain(self, J_k: np.ndarray, k: np.ndarray) -> np.ndarray:
        return J_k * np.where(self.mask, k, 1.0)

    def unit_size(self, k: np.ndarray) -> np.ndarray:
        return np.where(self.mask, 1.0, super().unit_size(k))

    def log_step(self, dx: np.ndarray) -> float:
        return float(np.max(np.abs(dx[self.mask]), initial=0.0))


class Bounds(Protocol):
    """Bounds on the natural parameters, handled as an active set (see the module docstring)."""

    def held(self, k: np.ndarray, step: np.ndarray, use: np.ndarray) -> np.ndarray:
        """The ``use`` parameters at a bound that the step (in coordinates, 0 off ``use``)
        pushes further out: held for this iteration."""

    def bounded_point(self, k: np.ndarray, J_k: np.ndarray, r: np.ndarray, step: np.ndarray,
                      use: np.ndarray, held: np.ndarray) -> np.ndarray | None:
        """A point with the parameters that the step takes past a bound placed on it (``J_k``
        whitened, in the natural parameters), or ``None`` when the step crosses no bound."""

    def at_bound(self, k: np.ndarray) -> np.ndarray:
        """The parameters at a bound (held after a bounded point is taken)."""


class BoxBounds:
    """``lower <= k <= upper`` in the natural parameters (with :class:`NaturalCoordinates`, or
    :class:`LogCoordinates` with a positive lower bound); ``scale(k)``: the parameters'
    magnitudes (default ``|k|``); a parameter within ``rtol`` of them from a bound is at it. A
    bounded point puts its active parameters exactly on their bounds."""

    def __init__(self, lower: Sequence[float], upper: Sequence[float],
                 scale: Callable[[np.ndarray], np.ndarray] | None = None, rtol: float = 1e-12):
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        if self.lower.shape != self.upper.shape or np.any(self.lower > self.upper):
            raise ValueError(f"bounds need lower <= upper of one shape, got {self.lower} and {self.upper}")
        self._scale, self.rtol = scale, rtol

    def _size(self, k: np.ndarray) -> np.ndarray:
        s = np.abs(k) if self._scale is None else self._scale(k)
        return np.where(s > np.finfo(float).tiny, s, 1.0)

    def _tol(self, k: np.ndarray) -> np.ndarray:
        return self.rtol * (np.abs(k) if self._scale is None else self._scale(k))

    def at_bound(self, k: np.ndarray) -> np.ndarray:
        tol = self._tol(k)
        return (k <= self.lower + tol) | (k >= self.upper - tol)

    def held(self, k: np.ndarray, step: np.ndarray, use: np.ndarray) -> np.ndarray:
        tol = self._tol(k)
        return use & (((k <= self.lower + tol) & (step < 0.0)) | ((k >= self.upper - tol) & (step > 0.0)))

    def bounded_point(self, k, J_k, r, step, use, held):
        k_new, active = bounded_gauss_newton_step(J_k, r, k, use & ~held, self.lower, self.upper,
                                                  size=self._size(k))
        if not np.any(active):
            return None
        # k + (bound - k) is the bound only to rounding: put the active parameters on it
        with np.errstate(invalid="ignore"):
            nearer_lo = np.abs(k_new - self.lower) <= np.abs(k_new - self.upper)
        return np.where(active, np.where(nearer_lo, self.lower, self.upper), k_new)


class ProjectedBoxBounds:
    """``lower <= k <= upper`` in the natural parameters handled by projection (with
    :class:`NaturalCoordinates`): the free set of an iteration leaves out the parameters at a bound
    that the steepest-descent direction pushes further out, and every trial point is projected
    (clipped) into the box; no bounded point is offered."""

    def __init__(self, lower: Sequence[float], upper: Sequence[float]):
        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        if self.lower.shape != self.upper.shape or np.any(self.lower > self.upper):
            raise ValueError(f"bounds need lower <= upper of one shape, got {self.lower} and {self.upper}")

    def project(self, k: np.ndarray) -> np.ndarray:
        """The nearest point of the box."""
        return np.clip(k, self.lower, self.upper)

    def at_bound(self, k: np.ndarray) -> np.ndarray:
        return (k <= self.lower) | (k >= self.upper)

    def held(self, k: np.ndarray, step: np.ndarray, use: np.ndarray) -> np.ndarray:
        """``step``: the steepest-descent direction ``J^T r`` (0 off ``use``)."""
        return use & (((k <= self.lower) & (step < 0.0)) | ((k >= self.upper) & (step > 0.0)))

    def bounded_point(self, k, J_k, r, step, use, held):
        return None


class LeastSquaresProblem(Protocol):
    """What :func:`levenberg_marquardt` needs: data ``y`` with weights ``1 / sigma``, the model's
    prediction and Jacobian in the natural parameters ``k``, admissibility, the coordinates and
    (optionally) bounds."""
    n_params: int
    y: np.ndarray
    weights: np.ndarray
    coordinates: Coordinates
    bounds: Bounds | None

    def predict(self, k: np.ndarray) -> tuple[np.ndarray, Any]:
        """``(f(k), state)``; ``state`` is passed back to :meth:`jacobian` (non-finite ``f``:
        the point is rejected)."""

    def jacobian(self, k: np.ndarray, state: Any) -> np.ndarray:
        """``df/dk``, ``(n_obs, n_params)``, not whitened."""

    def admissible(self, k: np.ndarray) -> bool:
        """Whether ``k`` may be evaluated and accepted."""


# --------------------------------------------------------------------------------------------
# result
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LMIteration:
    """One accepted step."""
    iteration: int
    x: np.ndarray
    k: np.ndarray
    chi2: float
    damping: float              # Marquardt lambda of the accepted step


@dataclass(frozen=True, eq=False)
class LMResult:
    """The end point (scipy ``OptimizeResult`` in spirit): coordinates ``x``, parameters ``k``,
    prediction ``f`` and ``state`` (as :meth:`LeastSquaresProblem.predict` returned them)."""
    x: np.ndarray
    k: np.ndarray
    f: np.ndarray
    state: Any
    chi2: float
    status: int
    iterations: int
    history: tuple[LMIteration, ...]

    @property
    def converged(self) -> bool:
        return self.status in CONVERGED

    @property
    def success(self) -> bool:
        return self.converged

    @property
    def message(self) -> str:
        return STATUS_MESSAGES[self.status]


# --------------------------------------------------------------------------------------------
# the iteration
# --------------------------------------------------------------------------------------------
def _chi2(y: np.ndarray, f: np.ndarray, w: np.ndarray) -> float:
    rr = (y - f) * w
    return float(rr @ rr)


def _shift(x: np.ndarray, use: np.ndarray, step: np.ndarray) -> np.ndarray:
    out = x.copy()
    out[use] += step
    return out


def levenberg_marquardt(problem: LeastSquaresProblem, x0: np.ndarray, *, y: np.ndarray | None = None,
                        free: np.ndarray | None = None, max_iterations: int = 100, xtol: float = 1e-8,
                        ftol: float = 1e-10, geodesic: bool = True,
                        callback: Callable[[LMIteration], bool] | None = None,
                        first_iteration: int = 1, schedule: LMSchedule = DEFAULT_SCHEDULE) -> LMResult:
    """Minimise ``chi2`` from the coordinates ``x0`` over the ``free`` parameters (default all).

    ``y``: other data than ``problem.y`` (a bootstrap replicate). ``callback(record)`` is called
    after every accepted step; a true return stops (status 5). ``first_iteration`` numbers the
    records (when another phase came before). ``schedule``: damping, backtracking and stopping
    (:class:`LMSchedule`). With :class:`ProjectedBoxBounds` the bounds are handled by projection.
    See the module docstring for the method.
    """
    y = problem.y if y is None else np.asarray(y, dtype=float)
    w = problem.weights
    coords, bounds = problem.coordinates, problem.bounds
    p = problem.n_params
    free = np.ones(p, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    x = np.array(x0, dtype=float)
    k = coords.to_natural(x)
    f, state = problem.predict(k)
    F = _chi2(y, f, w)
    history: list[LMIteration] = []
    if not np.any(free):
        return LMResult(x, k, f, state, F, 1, 0, ())

    def trial(k_c: np.ndarray):
        f_c, state_c = problem.predict(k_c)
        return f_c, state_c, (_chi2(y, f_c, w) if np.all(np.isfinite(f_c)) else np.inf)

    sch = schedule
    project = getattr(bounds, "project", None)                # bounds by projection
    lam, status, it = 0.0, 0, 0
    while it < max_iterations and status == 0:
        it += 1
        r = (y - f) * w
        J_k = problem.jacobian(k, state) * w[:, None]         # whitened, natural parameters
        J_all = coords.chain(J_k, k)
        use = free.copy()
        size = coords.unit_size(k)                            # of a unit of x
        held = np.zeros(p, dtype=bool)
        if project is not None:                               # free set by the descent direction
            held = bounds.held(k, np.where(use, J_all.T @ r, 0.0), use)
            use &= ~held
            if not np.any(use):
                status = 1
                break
        step_gn = solve_damped(J_all[:, use], r, size=size[use], dead_rtol=sch.dead_rtol)
        if bounds is not None and project is None:            # the bounds (active set)
            step_full = _shift(np.zeros(p), use, step_gn)
            held = bounds.held(k, step_full, use)
            k_b = bounds.bounded_point(k, J_k, r, step_full, use, held)
            if k_b is not None:
                f_b, state_b, F_b = trial(k_b)
                if F_b <= F:
                    x, k, f, state, F = coords.to_coords(k_b), k_b, f_b, state_b, F_b
                    r = (y - f) * w
                    J_k = problem.jacobian(k, state) * w[:, None]
                    J_all = coords.chain(J_k, k)
                    size = coords.unit_size(k)
                    held |= use & bounds.at_bound(k)
        if project is None and np.any(held):
            use &= ~held
            if not np.any(use):
                status = 1
                break
            step_gn = solve_damped(J_all[:, use], r, size=size[use], dead_rtol=sch.dead_rtol)
        J = J_all[:, use]
        predicted = float(np.sum((J @ step_gn) ** 2))        # decrease the GN step promises
        ok = small = False
        while True:
            step = step_gn.copy() if lam == 0.0 else solve_damped(J, r, lam, size[use], sch.dead_rtol)
            steps = [step]
            if geodesic:                                      # Transtrum & Sethna 2012
                k_h = coords.to_natural(_shift(x, use, GEODESIC_H * step))
                if problem.admissible(k_h):
                    f_vv = (2.0 / GEODESIC_H) * ((problem.predict(k_h)[0] - f) / GEODESIC_H - (J @ step) / w)
                    acc = solve_damped(J, -f_vv * w, lam, size[use], sch.dead_rtol)
                    if np.all(np.isfinite(acc)) and (2.0 * np.linalg.norm(acc)
                                                     <= GEODESIC_RATIO * np.linalg.norm(step)):
                        steps = [step + 0.5 * acc, step]
            for j, st in enumerate(steps):                    # the cap in log coordinates
                big = coords.log_step(_shift(np.zeros(p), use, st))
                if big > MAX_LOG_STEP:
                    steps[j] = st * (MAX_LOG_STEP / big)
            small = float(np.max(np.abs(steps[-1]) / size[use])) < xtol
            for alpha in sch.backtrack:                       # line search along the damped step
                best = None
                for st in steps:
                    x_c = _shift(x, use, alpha * st)
                    k_c = coords.to_natural(x_c)
                    if project is not None:
                        k_c = project(k_c)
                        x_c = coords.to_coords(k_c)
                    if not problem.admissible(k_c):
                        continue
                    f_c, state_c, F_c = trial(k_c)
                    if (F_c <= F if sch.accept_equal else F_c < F) and (best is None or F_c < best[-1]):
                        best = (x_c, k_c, f_c, state_c, F_c)
                if best is not None:
                    x_t, k_t, f_t, state_t, F_t = best
                    ok = True
                    break
            if ok or small:
                break
            lam = sch.lambda_start if lam == 0.0 else 10.0 * lam
            if lam > sch.lambda_max:
                break
        if not ok:
            status = 1 if small else 4                        # at the minimum to rounding, or stuck
            break
        dF = F - F_t
        x, k, f, state, F = x_t, k_t, f_t, state_t, F_t
        rec = LMIteration(first_iteration + it - 1, x.copy(), k.copy(), F, lam)
        history.append(rec)
        if callback is not None and callback(rec):
            status = 5
            break
        decrease = max(dF, predicted) if sch.predicted_decrease else dF
        status = (1 if small else 0) + (2 if decrease <= ftol * max(F, np.finfo(float).tiny) else 0)
        lam = 0.0 if lam < sch.lambda_reset else lam / 10.0
    return LMResult(x, k, f, state, F, status, it, tuple(history))
