"""The least-squares core (``blackbox.fitting.lm``) and the statistics module
(``blackbox.fitting.statistics``).

Reference values: NIST Statistical Reference Datasets, nonlinear regression (StRD NLS,
https://www.itl.nist.gov/div898/strd/nls/nls_main.shtml), certified to 11 significant digits:
Misra1a (Misra 1978, dental research monomolecular adsorption; lower difficulty) and DanWood
(Daniel & Wood 1980, pp. 428-431; lower difficulty), both from NIST's two starting points. As
lmfit's NIST tests do, we count the matching significant digits ``-log10(|est - cert| / |cert|)``.
"""

import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear, nnls

from blackbox.fitting import (BoxBounds, FitStatistics, HoldoutStats, LogCoordinates, NaturalCoordinates,
                              chi2_band, covariance, levenberg_marquardt, plausibility_warning, solve_damped)
from blackbox.fitting.lm import PROJECTED_SCHEDULE, ProjectedBoxBounds


# --------------------------------------------------------------------------------------------
# NIST StRD nonlinear regression problems (certified values, unweighted: sigma = 1)
# --------------------------------------------------------------------------------------------
MISRA1A = dict(
    x=np.array([77.6, 114.9, 141.1, 190.8, 239.9, 289.0, 332.8, 378.4, 434.8, 477.3, 536.8, 593.1, 689.1, 760.0]),
    y=np.array([10.07, 14.73, 17.94, 23.93, 29.61, 35.18, 40.02, 44.82, 50.76, 55.05, 61.01, 66.40, 75.47,
                81.78]),
    f=lambda b, x: b[0] * (1.0 - np.exp(-b[1] * x)),
    J=lambda b, x: np.column_stack([1.0 - np.exp(-b[1] * x), b[0] * x * np.exp(-b[1] * x)]),
    starts=([500.0, 1e-4], [250.0, 5e-4]),
    cert=[2.3894212918e+02, 5.5015643181e-04], cert_std=[2.7070075241e+00, 7.2668688436e-06],
    rss=1.2455138894e-01)
DANWOOD = dict(
    x=np.array([1.309, 1.471, 1.490, 1.565, 1.611, 1.680]),
    y=np.array([2.138, 3.421, 3.597, 4.340, 4.882, 5.660]),
    f=lambda b, x: b[0] * x ** b[1],
    J=lambda b, x: np.column_stack([x ** b[1], b[0] * x ** b[1] * np.log(x)]),
    starts=([1.0, 5.0], [0.7, 4.0]),
    cert=[7.6886226176e-01, 3.8604055871e+00], cert_std=[1.8281973860e-02, 5.1726610913e-02],
    rss=4.3173084083e-03)
NIST = {"Misra1a": MISRA1A, "DanWood": DANWOOD}


class Curve:
    """``y = f(b, x)`` with sigma = 1 as a :class:`blackbox.fitting.lm.LeastSquaresProblem`."""

    def __init__(self, d, coordinates=None, bounds=None, admissible=None):
        self.d, self.x = d, d["x"]
        self.y = d["y"]
        self.weights = np.ones_like(self.y)
        self.n_params = 2
        self.coordinates = coordinates or NaturalCoordinates()
        self.bounds = bounds
        self._admissible = admissible
        self.n_predictions = 0

    def predict(self, b):
        self.n_predictions += 1
        with np.errstate(over="ignore", invalid="ignore"):
            f = self.d["f"](b, self.x)
        return f, None

    def jacobian(self, b, state):
        return self.d["J"](b, self.x)

    def admissible(self, b):
        return bool(np.all(np.isfinite(b))) and (self._admissible is None or self._admissible(b))


def digits(est, cert) -> float:
    """Matching significant digits, as lmfit's NIST tests count them (for messages)."""
    err = abs(est - cert)
    return 15.0 if err == 0 else -math.log10(err / abs(cert))


EPS = np.finfo(float).eps
XTOL = 1e-10


def certified_rounding(c: float) -> float:
    """One unit in the 11th significant digit of a certified value, relative to it: NIST
    certifies 11 digits, so the exact optimum may differ from the printed value by that much."""
    return 10.0 ** (math.floor(math.log10(abs(c))) - 10) / abs(c)


def _std(d, k) -> np.ndarray:
    """NIST's standard errors ``sqrt(diag((J^T J)^-1) RSS / (n - 2))`` at ``k``."""
    Js = d["J"](k, d["x"]) * np.abs(k)               # scaled: (J^T J)^-1_ii = k_i^2 ||row_i(Js^+)||^2
    r = d["y"] - d["f"](k, d["x"])
    _, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    return np.sqrt(np.sum((Vt.T / sv) ** 2, axis=1) * (r @ r) / (len(r) - 2)) * np.abs(k)


def attainable(d, k) -> dict:
    """What the stopping rule and the conditioning let an end point ``k`` claim, all relative.

    * ``delta``: the undamped Gauss-Newton correction at ``k`` (SVD of the scaled Jacobian
      ``J diag|k|``, computed here, independently of the fitting code): to first order the
      distance from ``k`` to the least-squares optimum, within a factor ``1 / (1 - rho)``, where
      ``rho`` is the residual-curvature ratio ``||(J^T J)^-1 sum r_i H_i||`` (small-residual
      problems: 0.004 for Misra1a, 0.016 for DanWood; asserted below 1/2, so the factor is <= 2).
    * ``floor``: how far the optimum itself moves with the rounding of the residuals (``y``
      rounded to double, ``f`` evaluated to a few ulps): ``(4 eps |f| + eps |y|)`` times the row
      norms of the scaled pseudo-inverse -- the conditioning.
    * ``resolved``: the distance at which chi2 can no longer tell two points apart, ``sqrt(4
      eps |r| |f|) / sigma_min`` of the scaled Jacobian. The iteration stops when a trial step is
      below ``xtol`` relative; a damped trial step is below it only after the undamped and less
      damped ones failed to lower chi2, i.e. within this distance. So the stopping rule promises
      ``|delta| <= max(xtol, resolved)``, whatever the BLAS kernels or the ``exp`` of the machine.
    """
    x, y = d["x"], d["y"]
    f = d["f"](k, x)
    r = y - f
    J = d["J"](k, x)
    Js = J * np.abs(k)
    U, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    delta = Vt.T @ ((U.T @ r) / sv)
    S = np.zeros((2, 2))
    for j in range(2):                  # sum r_i H_i in scaled parameters, by central differences of J
        h = 1e-6 * abs(k[j])
        kp, km = k.copy(), k.copy()
        kp[j] += h
        km[j] -= h
        S[:, j] = -((d["J"](kp, x) - d["J"](km, x)) / (2 * h) * np.abs(k) * abs(k[j])).T @ r
    rho = float(np.linalg.norm(np.linalg.solve(Js.T @ Js, S), 2))
    rows = np.sqrt(np.sum((Vt.T / sv) ** 2, axis=1))
    return {"delta": delta, "rho": rho, "sv": sv,
            "floor": (4 * EPS * np.linalg.norm(f) + EPS * np.linalg.norm(y)) * rows,
            "resolved": math.sqrt(4 * EPS * np.linalg.norm(r) * np.linalg.norm(f)) / sv[-1]}


def assert_certified(d, k, chi2, xtol=XTOL):
    """The parameters, the residual sum of squares and the standard errors of the end point
    ``k`` agree with NIST's certified values within what :func:`attainable` derives: tolerances
    from the stopping rule and the conditioning, not from one machine's digits. On the machine
    these tests were written on they amount to 9.0-10.9 matching digits (the certified values'
    own rounding in their 11th digit is the last term of each)."""
    a = attainable(d, k)
    assert a["rho"] < 0.5, a["rho"]
    assert np.all(np.abs(a["delta"]) <= max(xtol, a["resolved"])), (a["delta"], a["resolved"])
    cert = np.array(d["cert"])
    tol = 2 * np.abs(a["delta"]) + a["floor"] + [certified_rounding(c) for c in cert]
    err = np.abs(k - cert) / np.abs(cert)
    assert np.all(err <= tol), (k, cert, [digits(b, c) for b, c in zip(k, cert)], err, tol)
    # chi2: second order in the distance (|Js delta|^2), plus its own rounding
    Js = d["J"](k, d["x"]) * np.abs(k)
    r_norm = math.sqrt(chi2)
    tol_rss = (float(np.sum((Js @ a["delta"]) ** 2)) / chi2 + 4 * EPS * np.linalg.norm(d["f"](k, d["x"])) / r_norm
               + certified_rounding(d["rss"]))
    assert abs(chi2 - d["rss"]) / d["rss"] <= tol_rss, (chi2, d["rss"], digits(chi2, d["rss"]))
    # standard errors: the change the correction delta would make (x 2, as above), the
    # rounding of (J^T J)^-1 (cond(Js)^2 eps), the certified values' rounding
    std, moved = _std(d, k), _std(d, k * (1 + a["delta"]))
    cert_std = np.array(d["cert_std"])
    tol_std = (2 * np.abs(moved - std) / std + 4 * EPS * (a["sv"][0] / a["sv"][-1]) ** 2
               + [certified_rounding(c) for c in cert_std])
    assert np.all(np.abs(std - cert_std) / cert_std <= tol_std), (std, cert_std, [digits(s, c) for s, c in zip(std, cert_std)])


@pytest.mark.parametrize("name", sorted(NIST))
@pytest.mark.parametrize("start", [0, 1])
@pytest.mark.parametrize("coords", ["natural", "log"])
def test_nist_certified_values(name, start, coords):
    """Both NIST starts, natural and log coordinates: the certified parameters, the residual sum
    of squares and the standard errors ``sqrt(diag((J^T J)^-1) RSS / dof)``, within the
    tolerances :func:`assert_certified` derives from the stopping rule (xtol = 1e-10 on the
    relative step) and the problem's conditioning. (A fixed count of 9 digits held on one CPU
    and failed on another: the end point moves with the BLAS kernels and numpy's SIMD ``exp``
    by up to 6e-10 relative, within what the stopping rule promises.)"""
    d = NIST[name]
    cc = NaturalCoordinates() if coords == "natural" else LogCoordinates(np.ones(2, bool))
    prob = Curve(d, cc)
    res = levenberg_marquardt(prob, cc.to_coords(np.array(d["starts"][start])), max_iterations=200,
                              xtol=XTOL, ftol=1e-15)
    assert res.converged, res.message
    cov = covariance(prob.jacobian(res.k, None))
    assert cov.rank == 2 and cov.identifiable.all()
    n = len(d["y"])
    std = cov.std * math.sqrt(res.chi2 / (n - 2))            # NIST: sigma estimated from the residuals
    sv = np.linalg.svd(prob.jacobian(res.k, None) * np.abs(res.k), compute_uv=False)
    # the module's covariance against the formula's: both round at cond(Js)^2 eps at most
    np.testing.assert_allclose(std, _std(d, res.k), rtol=100 * EPS * (sv[0] / sv[-1]) ** 2)
    assert_certified(d, res.k, res.chi2)


def test_the_derived_tolerances_are_not_vacuous():
    """What the derived tolerances accept and refuse, around the converged Misra1a fit: the fit
    passes; a point 1e-7 away (beyond what chi2 resolves, 4e-8) fails; a point 3e-9 away
    passes only because its own Gauss-Newton correction accounts for the distance; a residual sum
    of squares off by 1e-8 fails."""
    d = MISRA1A
    res = levenberg_marquardt(Curve(d), np.array(d["starts"][1]), max_iterations=200, xtol=XTOL, ftol=1e-15)
    assert_certified(d, res.k, res.chi2)

    def rss(k):
        r = d["y"] - d["f"](k, d["x"])
        return float(r @ r)

    far = res.k * (1 + np.array([1e-7, -1e-7]))
    with pytest.raises(AssertionError):
        assert_certified(d, far, rss(far))
    near = res.k * (1 + np.array([3e-9, -3e-9]))
    assert_certified(d, near, rss(near))
    with pytest.raises(AssertionError):
        assert_certified(d, res.k, res.chi2 * (1 + 1e-8))


def test_chi2_never_increases_and_records_are_consistent():
    """From NIST's far start of Misra1a: every accepted step lowers chi2 (or keeps it); the
    records are numbered from ``first_iteration`` and hold chi2 at their k; the geodesic
    acceleration changes the path, not the answer."""
    prob = Curve(MISRA1A)
    x0 = np.array(MISRA1A["starts"][0])
    F0 = float(np.sum((prob.y - prob.predict(x0)[0]) ** 2))
    for geodesic in (True, False):
        res = levenberg_marquardt(prob, x0, max_iterations=500, xtol=1e-10, ftol=1e-15, geodesic=geodesic,
                                  first_iteration=3)
        assert res.converged and res.success
        chi2 = [F0] + [h.chi2 for h in res.history]
        assert all(b <= a for a, b in zip(chi2, chi2[1:]))
        assert [h.iteration for h in res.history] == list(range(3, 3 + len(res.history)))
        for h in res.history:
            r = prob.y - prob.predict(h.k)[0]
            assert h.chi2 == float(r @ r)                       # chi2 at the recorded k, exactly
        assert res.history[-1].chi2 == res.chi2
        assert_certified(MISRA1A, res.k, res.chi2)


def test_callback_stops_and_iteration_limit():
    prob = Curve(MISRA1A)
    x0 = np.array(MISRA1A["starts"][0])
    res = levenberg_marquardt(prob, x0, callback=lambda rec: rec.iteration == 2)
    assert res.status == 5 and res.iterations == 2 and not res.converged
    assert res.message == "stopped by the callback"
    res = levenberg_marquardt(prob, x0, max_iterations=1)
    assert res.status == 0 and res.iterations == 1 and len(res.history) == 1
    res = levenberg_marquardt(prob, x0, free=np.zeros(2, bool))          # nothing to fit
    assert res.status == 1 and res.iterations == 0 and np.array_equal(res.k, x0)


def test_inadmissible_points_are_never_taken():
    """Admissibility ``b2 <= 4.5e-4`` (below the certified 5.5e-4): the iteration stops at the
    boundary side of the valley, every accepted point admissible, chi2 never rising."""
    prob = Curve(MISRA1A, admissible=lambda b: b[1] <= 4.5e-4)
    res = levenberg_marquardt(prob, np.array(MISRA1A["starts"][0]), max_iterations=200)
    assert all(h.k[1] <= 4.5e-4 for h in res.history)
    chi2 = [h.chi2 for h in res.history]
    assert all(b <= a for a, b in zip(chi2, chi2[1:]))
    assert res.chi2 > MISRA1A["rss"]


# --------------------------------------------------------------------------------------------
# bounds by an active set: linear problems with known bounded solutions
# --------------------------------------------------------------------------------------------
class Linear:
    """``y = A k`` with weights ``w``."""

    def __init__(self, A, y, w, bounds=None, coordinates=None):
        self.A, self.y, self.weights = A, y, w
        self.n_params = A.shape[1]
        self.coordinates = coordinates or NaturalCoordinates()
        self.bounds = bounds

    def predict(self, k):
        return self.A @ k, None

    def jacobian(self, k, state):
        return self.A

    def admissible(self, k):
        return bool(np.all(np.isfinite(k)))


def _bounded_problem(seed):
    """A weighted linear problem with ``0 <= k <= 2`` and some bounds active at its solution:
    ``A, y, w, lo, hi`` and the bounded-variable least-squares solution (scipy's ``lsq_linear``)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((40, 5))
    k_true = np.array([-0.5, 0.3, 2.8, 1.0, -1.2])
    w = 1.0 / rng.uniform(0.5, 2.0, 40)
    y = A @ k_true + 0.1 * rng.standard_normal(40) / w
    lo, hi = np.zeros(5), np.full(5, 2.0)
    ref = lsq_linear(A * w[:, None], y * w, bounds=(lo, hi), method="bvls", tol=1e-14).x
    return A, y, w, lo, hi, ref


@pytest.mark.parametrize("seed", range(5))
def test_box_bounds_reach_the_bounded_least_squares_solution(seed):
    """With ``0 <= k <= 2`` the core's active set ends at the bounded-variable least-squares
    solution (scipy's ``lsq_linear``, BVLS; and ``nnls`` for the lower bound alone), with the
    active parameters exactly at their bounds. Data drawn so that some bounds are active."""
    A, y, w, lo, hi, ref = _bounded_problem(seed)
    res = levenberg_marquardt(Linear(A, y, w, BoxBounds(lo, hi)), np.full(5, 1.0), max_iterations=50)
    assert res.converged, res.message
    np.testing.assert_allclose(res.k, ref, atol=1e-9)          # BVLS to its tolerance
    assert np.all((res.k >= lo) & (res.k <= hi))
    active = (ref <= 1e-9) | (ref >= 2.0 - 1e-9)
    assert active.any()
    assert np.all((res.k[active] == 0.0) | (res.k[active] == 2.0))
    ref_nn, _ = nnls(A * w[:, None], y * w)
    res = levenberg_marquardt(Linear(A, y, w, BoxBounds(lo, np.full(5, np.inf))), np.full(5, 1.0))
    np.testing.assert_allclose(res.k, ref_nn, atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_projected_bounds_reach_the_bounded_least_squares_solution(seed):
    """The projected variant (the diagnosis's refits: free set by the descent direction, trial
    points clipped into the box, :data:`PROJECTED_SCHEDULE`) ends at the same BVLS solution on
    the problems above. Tolerance 1e-7: projected LM approaches the active face linearly and
    stops on a relative chi2 decrease of 1e-13, i.e. ~sqrt(1e-13 chi2) in whitened units."""
    A, y, w, lo, hi, ref = _bounded_problem(seed)
    res = levenberg_marquardt(Linear(A, y, w, ProjectedBoxBounds(lo, hi)), np.full(5, 1.0), max_iterations=200,
                              xtol=0.0, ftol=1e-13, geodesic=False, schedule=PROJECTED_SCHEDULE)
    assert res.status in (2, 4), res.message
    np.testing.assert_allclose(res.k, ref, atol=1e-7)
    assert np.all((res.k >= lo) & (res.k <= hi))
    chi2 = [h.chi2 for h in res.history]
    assert all(b < a for a, b in zip(chi2, chi2[1:]))          # only strict decreases are steps


def test_projected_schedule_keeps_a_vanishing_column():
    """A column 1e-14 of the others' size (a spring far out in a flat valley: dU/dk ~ 1/k^2) is
    dead for the default schedule (``dead_rtol`` 1e-12 with unit size 1), so its parameter never
    moves; :data:`PROJECTED_SCHEDULE` keeps it and reaches the least-squares solution."""
    rng = np.random.default_rng(7)
    A = rng.standard_normal((30, 3))
    A[:, 2] *= 1e-14
    k_true = np.array([1.0, -2.0, 3e13])
    y = A @ k_true
    scale = lambda k: np.ones_like(k)                           # noqa: E731 (unit sizes 1)
    prob = Linear(A, y, np.ones(30), None, NaturalCoordinates(scale))
    frozen = levenberg_marquardt(prob, np.zeros(3), max_iterations=50, geodesic=False)
    assert frozen.k[2] == 0.0
    res = levenberg_marquardt(prob, np.zeros(3), max_iterations=50, xtol=0.0, ftol=1e-13, geodesic=False,
                              schedule=PROJECTED_SCHEDULE)
    np.testing.assert_allclose(res.k, k_true, rtol=1e-8)       # exact data: to rounding of cond(A)~1e14


def test_log_coordinates_with_a_floor_reach_zero_without_crawling():
    """A positive parameter the data want at 0, in log coordinates with a floor bound: the
    bounded natural step puts it at the floor in one iteration instead of halving log k."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((30, 3))
    y = A @ np.array([1.0, 2.0, -0.5])
    floor = np.array([1e-6, 1e-6, 1e-6])
    prob = Linear(A, y, np.ones(30), BoxBounds(floor, np.full(3, np.inf)), LogCoordinates(np.ones(3, bool)))
    res = levenberg_marquardt(prob, np.log([1.0, 1.0, 1.0]), max_iterations=30)
    assert res.converged and res.iterations <= 6
    assert res.k[2] == pytest.approx(1e-6, rel=1e-12)
    ref = lsq_linear(A, y, bounds=(floor, np.inf), method="bvls", tol=1e-14).x
    np.testing.assert_allclose(res.k, ref, rtol=1e-8)


# --------------------------------------------------------------------------------------------
# statistics
# --------------------------------------------------------------------------------------------
def test_covariance_flags_rank_deficiency():
    """Two columns that enter only as their sum: rank 2 of 3; those two are not identifiable
    (std inf, nan covariance), the third gets its exact variance ``1 / |J_3|^2`` (orthogonal to
    the others), and the damped solve does not move the null direction (minimum norm)."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal(20)
    b = rng.standard_normal(20)
    b -= a * (a @ b) / (a @ a)                                # b orthogonal to a
    J = np.column_stack([a, a, b])
    c = covariance(J, scale=np.array([1.0, 10.0, 100.0]))
    assert c.rank == 2
    assert c.identifiable.tolist() == [False, False, True]
    assert np.isinf(c.std[:2]).all() and np.isnan(c.cov[0]).all()
    assert c.std[2] == pytest.approx(1.0 / np.linalg.norm(b), rel=1e-12)
    x = solve_damped(J, 3.0 * a + 2.0 * b)
    np.testing.assert_allclose(x, [1.5, 1.5, 2.0], rtol=1e-12)   # the minimum-norm split of 3
    full = covariance(np.column_stack([a, b]))
    assert full.rank == 2 and full.identifiable.all()
    np.testing.assert_allclose(full.cov, np.linalg.inv(np.column_stack([a, b]).T @ np.column_stack([a, b])),
                               rtol=1e-12, atol=1e-15)


def test_fit_statistics_definitions():
    """chi2, reduced chi2, RMS, -2 log L = chi2 + sum log(2 pi sigma^2), AIC = -2 log L + 2 p,
    BIC = -2 log L + p log n, written out."""
    rng = np.random.default_rng(1)
    y = rng.standard_normal(50)
    f = y + 0.1 * rng.standard_normal(50)
    sigma = rng.uniform(0.05, 0.2, 50)
    s = FitStatistics.of(y, f, sigma, 3)
    chi2 = float(np.sum(((y - f) / sigma) ** 2))
    m2logL = chi2 + float(np.sum(np.log(2 * np.pi * sigma ** 2)))
    assert s.chi2 == pytest.approx(chi2, rel=1e-14) and s.dof == 47
    assert s.reduced_chi2 == pytest.approx(chi2 / 47, rel=1e-14)
    assert s.rms_residual == pytest.approx(float(np.sqrt(np.mean((y - f) ** 2))), rel=1e-14)
    assert s.aic == pytest.approx(m2logL + 6, rel=1e-14)
    assert s.bic == pytest.approx(m2logL + 3 * math.log(50), rel=1e-14)
    assert math.isnan(FitStatistics.of(y[:3], f[:3], sigma[:3], 3).reduced_chi2)
    h = HoldoutStats.of(["a"], y, f, 1.0 / sigma)
    assert h.chi2 == pytest.approx(chi2, rel=1e-14) and h.n_obs == 50 and h.cases == ("a",)


def test_chi2_band_and_plausibility():
    """The 99 % band of chi2(dof)/dof (scipy's chi2 quantiles) holds ~99 % of simulated reduced
    chi-squares; the warning fires only for a chi2 beyond its 1e-3 upper tail."""
    lo, hi = chi2_band(100, 0.99)
    assert lo < 1.0 < hi
    red = np.random.default_rng(2).chisquare(100, 20000) / 100
    inside = np.mean((red >= lo) & (red <= hi))
    assert abs(inside - 0.99) < 4 * math.sqrt(0.99 * 0.01 / 20000)     # 4 binomial sigmas
    assert all(math.isnan(v) for v in chi2_band(0))
    assert plausibility_warning(100.0, 100) is None
    w = plausibility_warning(200.0, 100)
    assert w is not None and "100 degrees of freedom" in w
    assert plausibility_warning(5.0, 0) is None


def test_chi2_band_is_the_one_of_the_diagnosis():
    from blackbox import diagnosis

    assert diagnosis.chi2_band is chi2_band
