"""Many specimens of one joint design (``blackbox.population``, ``blackbox population``).

References of the exact checks:

* a Gaussian specimen likelihood convolved with the population, ``N(m; mu, c^2 + tau^2)``
  (closed form), and a tabulated one against numerical quadrature of its own interpolant
  (``scipy.integrate.quad``);
* specimens equally well measured with Gaussian likelihoods: the centre's interval is Student's t
  interval of the specimens' estimates (``t_{S-1}``) and the spread's interval the chi-square
  interval of their variance minus the measurement variance (Student 1908; any statistics
  textbook), exactly;
* unequal precisions: the Q-profile interval and the Paule-Mandel estimate, by an independent
  implementation of Viechtbauer (2007, *Stat. Med.* 26:37, eq. 6-7) and Paule & Mandel (1982);
* a tabulated (exact) profile likelihood against the profile-likelihood interval of
  ``blackbox identify`` on the same data.

Statistical checks: coverage of the centre's and the spread's intervals over seeded simulated
populations, with few (4, 8) and many (30) specimens, one and two joints, on generated structures
(``blackbox.structures.star_joint_frame``, ``braced_portal``): one condensation per structure, every
specimen of every replicate in the condensed space. Tolerances are binomial: the pooled coverage
(``R x p`` intervals) must lie in the 99.9 % band of ``n = R p`` independent intervals of nominal
95 %, each parameter's in the band at level ``1 - 0.01 / p`` of ``n = R`` (Bonferroni over the
parameters, so one test fails by chance about once in a hundred runs at most). The full table
with more replicates is ``benchmarks/population.py`` (docs/population.md).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import integrate, stats

from blackbox.cli import main
from blackbox.commands.population import simulate_specimens
from blackbox.condensation import CondensedModel, condense
from blackbox.joints import make_joint
from blackbox.population.coverage import population_coverage, simulate_specimen
from blackbox.population.fit import fit_population
from blackbox.population.hierarchy import fit_parameter
from blackbox.population.likelihood import GaussianLikelihood, TabulatedLikelihood
from blackbox.population.specimen import fit_specimen
from blackbox.identification import identify
from blackbox.simulation import NoiseConfig
from blackbox.structures import braced_portal, random_loads, star_joint_frame, write_study

from conftest import adapter_of, load_matrix

CONTRACT_PARAMETER_KEYS = {"joint", "name", "center", "center_ci_low", "center_ci_high", "spread", "spread_ci_low",
                           "spread_ci_high"}
CONTRACT_SPECIMEN_KEYS = {"joint", "name", "value", "ci_low", "ci_high"}
PORTAL_CENTRE = np.array([1e5, 8e4, 1.2e5, 1e5, 8e4, 1.2e5])     # N m/rad, JL then JR: kx12, ky12, kz12
PORTAL_SPREAD = np.array([0.2, 0.1, 0.3, 0.2, 0.1, 0.3])         # coefficients of variation


def band(n: int, level: float) -> tuple[float, float]:
    """Where the coverage of ``n`` independent 95 % intervals falls with probability ``level``."""
    a = (1.0 - level) / 2.0
    return stats.binom.ppf(a, n, 0.95) / n, stats.binom.ppf(1.0 - a, n, 0.95) / n


def assert_coverage(hits: np.ndarray, what: str) -> None:
    """``hits``: (replicates, parameters) booleans; pooled and per-parameter binomial bands."""
    R, p = hits.shape
    lo, hi = band(R * p, 0.999)
    pooled = hits.mean()
    assert lo <= pooled <= hi, f"{what}: pooled coverage {pooled:.3f} outside [{lo:.3f}, {hi:.3f}] (n = {R * p})"
    lo, hi = band(R, 1.0 - 0.01 / p)
    each = hits.mean(axis=0)
    assert np.all((each >= lo) & (each <= hi)), f"{what}: per-parameter coverage {each} outside [{lo:.3f}, {hi:.3f}]"


@pytest.fixture(scope="module")
def portal():
    """The braced portal with two semi-rigid knees, 12 random load cases, condensed once."""
    f = braced_portal()
    joints = [make_joint(n, g, "simple") for n, g in f.joints]
    boundary = [d for j in joints for d in j.dofs]
    c = condense(adapter_of(f), load_matrix(random_loads(f, 12, seed=3)), boundary)
    return CondensedModel(c, joints), boundary


@pytest.fixture(scope="module")
def star():
    """One 3-branch joint (9 springs), 12 random load cases, condensed once."""
    f = star_joint_frame(3, seed=2)
    joints = [make_joint(n, g, "simple") for n, g in f.joints]
    boundary = [d for j in joints for d in j.dofs]
    c = condense(adapter_of(f), load_matrix(random_loads(f, 12, seed=1)), boundary)
    return CondensedModel(c, joints), boundary


# --------------------------------------------------------------------------------------------
# exact pieces
# --------------------------------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
def test_specimen_integral_against_quadrature():
    """``log I(mu, tau)`` of both likelihood forms against ``quad`` (rtol 1e-6: quad's own
    accuracy on these smooth integrands), including a side left open (flat) and tau = 0."""
    g = GaussianLikelihood(11.5, 0.1)
    t = np.linspace(11.2, 11.9, 81)
    r = (t - 11.5) / 0.1 * (1.0 + 0.3 * (t - 11.5))             # a skewed profile
    tab = TabulatedLikelihood(t, -0.5 * r ** 2, abs(r[1] - r[0]) / (t[1] - t[0]),
                              abs(r[-1] - r[-2]) / (t[-1] - t[-2]), 11.5, 0.1)
    flat = TabulatedLikelihood(t, -0.5 * np.minimum(r, 0.0) ** 2, 10.0, 0.0, 11.5, 0.2)
    for mu, tau in [(11.5, 0.05), (11.7, 0.2), (10.9, 0.3), (12.5, 0.5), (11.6, 2.0)]:
        for L in (g, tab, flat):
            def f(th):
                return math.exp(float(L.log_value(th))) * stats.norm.pdf(th, mu, tau)
            a, b = mu - 12 * tau, mu + 12 * tau
            kinks = [x for x in t if a < x < b]             # the table is linear between its nodes
            num = integrate.quad(f, a, b, points=kinks or None, limit=800, epsabs=0, epsrel=1e-9)[0]
            assert float(L.log_integral(mu, tau)) == pytest.approx(math.log(num), abs=1e-6)
    # closed form of the Gaussian: log(c / sqrt(c^2 + tau^2)) - (m - mu)^2 / (2 (c^2 + tau^2))
    assert float(g.log_integral(11.8, 0.4)) == pytest.approx(math.log(0.1 / math.hypot(0.1, 0.4))
                                                             - 0.3 ** 2 / (2 * 0.17), rel=1e-12)
    # tau = 0: the likelihood itself at mu
    assert float(tab.log_integral(11.63, 0.0)) == pytest.approx(float(tab.log_value(11.63)), abs=1e-9)


def test_equally_measured_specimens_give_student_and_chi_square_intervals():
    rng = np.random.default_rng(4)
    S, c = 6, 0.05
    for _ in range(5):
        m = 11.0 + 0.2 * rng.standard_normal(S) + c * rng.standard_normal(S)
        P = fit_parameter([GaussianLikelihood(x, c) for x in m])
        s2 = m.var(ddof=1)
        half = stats.t.ppf(0.975, S - 1) * math.sqrt(s2 / S)
        assert P.mu == pytest.approx(m.mean(), abs=1e-12)
        assert P.mu_ci == pytest.approx((m.mean() - half, m.mean() + half), abs=1e-9)
        v = ((S - 1) * s2 / stats.chi2.ppf(0.975, S - 1), (S - 1) * s2 / stats.chi2.ppf(0.025, S - 1))
        expect = tuple(math.sqrt(max(x - c * c, 0.0)) for x in v)
        assert P.tau_ci == pytest.approx(expect, abs=1e-6)
        assert P.tau == pytest.approx(math.sqrt(max(s2 - c * c, 0.0)), abs=1e-6)   # Paule-Mandel


def test_unequal_precisions_q_profile_and_paule_mandel():
    """Viechtbauer's Q-profile interval and the Paule-Mandel estimate, computed here from their
    definitions (generalised Q = chi2 quantiles, monotone in tau^2)."""
    from scipy import optimize

    m = np.array([11.2, 11.45, 10.9, 11.6, 11.3, 11.05, 11.7])
    c = np.array([0.05, 0.2, 0.1, 0.3, 0.08, 0.15, 0.4])

    def Q(t2):
        w = 1.0 / (c ** 2 + t2)
        mu = np.sum(w * m) / np.sum(w)
        return float(np.sum(w * (m - mu) ** 2))

    def root(level):
        return 0.0 if Q(0.0) <= level else math.sqrt(optimize.brentq(lambda t2: Q(t2) - level, 0.0, 100.0,
                                                                     xtol=1e-14))
    P = fit_parameter([GaussianLikelihood(a, b) for a, b in zip(m, c)])
    S = m.size
    assert P.tau == pytest.approx(root(S - 1), rel=1e-5)
    assert P.tau_ci == pytest.approx((root(stats.chi2.ppf(0.975, S - 1)), root(stats.chi2.ppf(0.025, S - 1))),
                                     rel=1e-5, abs=1e-9)
    assert P.common_statistic == pytest.approx(Q(0.0), rel=1e-9)          # Cochran's Q


def test_exact_profile_agrees_with_identify(portal):
    """A weakly determined spring (5 % noise): its tabulated likelihood's 95 % crossings are the
    profile-likelihood interval of ``identify`` (to 1 %: the table is linear in L between nodes,
    identify's ends are found to 1 % of the profile-t level)."""
    model, dofs = portal
    rng = np.random.default_rng(5)
    obs = simulate_specimen(model, PORTAL_CENTRE, dofs, range(12), NoiseConfig(relative=0.05), rng)
    fit = fit_specimen(model, obs, PORTAL_CENTRE / 10)
    ref = identify(model, obs, PORTAL_CENTRE / 10)
    exact = [j for j, L in enumerate(fit.likelihoods) if isinstance(L, TabulatedLikelihood)]
    assert exact, "at 5 % noise some springs of the portal are weak enough to need the exact profile"
    for j in exact:
        lo, hi = fit.interval(j)
        assert lo == pytest.approx(ref.ci_low[j], rel=0.01)
        assert hi == pytest.approx(ref.ci_high[j], rel=0.01)
    for j, L in enumerate(fit.likelihoods):
        if not isinstance(L, TabulatedLikelihood):      # quadratic: the linearised interval in log k
            assert fit.interval(j) == pytest.approx(tuple(ref.linear_ci[j]), rel=1e-6)


# --------------------------------------------------------------------------------------------
# calibration
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_coverage_gaussian_specimens_of_unequal_precision():
    """Specimen likelihoods Gaussian with standard deviations from 0.05 to 0.2 in log k
    (fourfold), tau = 0.1: 4 and 8 specimens, 600 replicates each."""
    rng = np.random.default_rng(11)
    for S in (4, 8):
        hits = np.zeros((600, 2), dtype=bool)
        for r in range(600):
            c = rng.uniform(0.05, 0.2, S)
            m = 0.1 * rng.standard_normal(S) + c * rng.standard_normal(S)
            P = fit_parameter([GaussianLikelihood(a, b) for a, b in zip(m, c)])
            hits[r] = (P.mu_ci[0] <= 0.0 <= P.mu_ci[1], P.tau_ci[0] <= 0.1 <= P.tau_ci[1])
        assert_coverage(hits[:, :1], f"centre, {S} specimens")
        assert_coverage(hits[:, 1:], f"spread, {S} specimens")


@pytest.mark.slow
def test_coverage_one_joint_four_specimens(star):
    """One 3-branch joint (9 springs at 5e4 N m/rad, spread 20 %), 4 specimens, 1 % noise."""
    model, dofs = star
    t = population_coverage(model, dofs, range(12), np.full(9, 5e4), np.full(9, 0.2), 4, replicates=300,
                            noise=0.01, seed=3)
    assert_coverage(t.centre_hit, "centre")
    assert_coverage(t.spread_hit, "spread")


@pytest.mark.slow
def test_coverage_two_joints_eight_specimens(portal):
    model, dofs = portal
    t = population_coverage(model, dofs, range(12), PORTAL_CENTRE, PORTAL_SPREAD, 8, replicates=150,
                            noise=0.003, seed=5)
    assert_coverage(t.centre_hit, "centre")
    assert_coverage(t.spread_hit, "spread")


@pytest.mark.slow
def test_coverage_two_joints_thirty_specimens(portal):
    model, dofs = portal
    t = population_coverage(model, dofs, range(12), PORTAL_CENTRE, PORTAL_SPREAD, 30, replicates=60,
                            noise=0.003, seed=6)
    assert_coverage(t.centre_hit, "centre")
    assert_coverage(t.spread_hit, "spread")


@pytest.mark.slow
def test_coverage_with_exact_specimen_likelihoods(portal):
    """2 % noise: most specimens' likelihoods of the weak springs fail the quadratic check and are
    tabulated exactly; 8 specimens, with the shrunk specimen intervals."""
    model, dofs = portal
    t = population_coverage(model, dofs, range(12), PORTAL_CENTRE, PORTAL_SPREAD, 8, replicates=40,
                            noise=0.02, seed=8, shrinkage=True)
    assert t.exact_share > 0.25
    assert_coverage(t.centre_hit, "centre")
    assert_coverage(t.spread_hit, "spread")
    # the specimens' shrunk intervals: every specimen of every replicate (n = 40 x 8 per parameter)
    lo, hi = band(40 * 8 * 6, 0.999)
    assert lo - 0.02 <= np.mean(t.specimen_cover) <= hi + 0.02    # 0.02: the specimens of a replicate share mu, tau


@pytest.mark.slow
def test_specimens_differ_test_is_calibrated_and_detects(portal):
    """Identical specimens (spread 0): the pooled likelihood-ratio p-value falls below 0.05 in
    about 5 % of the replicates (99.9 % binomial band of 80); a 20 % spread: always below 1e-3."""
    model, dofs = portal
    same = population_coverage(model, dofs, range(12), PORTAL_CENTRE, np.zeros(6), 5, replicates=80, noise=0.003,
                               seed=9, differ=True)
    k = int(np.sum(same.differ_p < 0.05))
    assert stats.binom.ppf(0.0005, 80, 0.05) <= k <= stats.binom.ppf(0.9995, 80, 0.05)
    diff = population_coverage(model, dofs, range(12), PORTAL_CENTRE, PORTAL_SPREAD, 5, replicates=5, noise=0.003,
                               seed=10, differ=True)
    assert np.all(diff.differ_p < 1e-3)


def test_outlier_is_named_and_a_clean_population_is_not_accused(portal):
    model, dofs = portal
    rng = np.random.default_rng(12)
    tau = np.sqrt(np.log1p(PORTAL_SPREAD ** 2))
    noise = NoiseConfig(relative=0.003)

    def population(factor):
        k = PORTAL_CENTRE * np.exp(tau * rng.standard_normal((8, 6)))
        k[3, 1] *= factor                         # specimen 4, JL.ky12: a bad weld, 3x as stiff
        fits = [fit_specimen(model, simulate_specimen(model, ks, dofs, range(12), noise, rng), PORTAL_CENTRE / 10)
                for ks in k]
        return fit_population(fits, model.assembly.param_joint, model.assembly.param_names, shrinkage=False,
                              differ=False)
    pf = population(4.0)
    assert [(o.specimen, o.parameter) for o in pf.outliers] == [(3, 1)]
    assert pf.outliers[0].p_adjusted < 0.01 and pf.n_outlier_tests == 8 * 6
    false = sum(len(population(1.0).outliers) for _ in range(6))
    assert false == 0                             # family-wise 1 %: 6 clean populations, none accused


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
def _portal_study(folder, loads):
    f = braced_portal()
    return write_study(folder, f, loads, "portal", initial=1e4)


@pytest.fixture(scope="module")
def specimens(tmp_path_factory):
    """5 specimen studies of the portal (simulated, 0.3 % noise on both joints' DOFs), and one
    whose loads all lie in the portal's plane (its out-of-plane springs are not identifiable)."""
    root = tmp_path_factory.mktemp("population")
    f = braced_portal()
    base = _portal_study(root / "design", random_loads(f, 12, seed=3))
    folders = simulate_specimens(base, root / "specimens", 5, PORTAL_CENTRE, PORTAL_SPREAD, seed=2,
                                 noise={"relative": 0.003})
    planar = _portal_study(root / "planar_design", [("P1", 3, 1, 500.0), ("P2", 3, 3, -800.0), ("P3", 6, 1, 300.0),
                                                     ("P4", 7, 5, 50.0), ("P5", 6, 5, -40.0), ("P6", 7, 1, -200.0)])
    planar_specimens = simulate_specimens(planar, root / "planar", 3, PORTAL_CENTRE, PORTAL_SPREAD, seed=4,
                                          noise={"relative": 0.003}, prefix="planar")
    return folders, planar_specimens, root


def test_command_writes_the_contract_with_one_solver_run_per_specimen(specimens, tmp_path, capsys):
    folders, _, _ = specimens
    out = tmp_path / "pop"
    code = main(["population", *map(str, folders), "--out", str(out), "--no-cache"])
    assert code == 0, capsys.readouterr().err

    def no_constant(name):
        raise AssertionError(f"population.json holds {name}: not strict JSON")
    doc = json.loads((out / "population.json").read_text(), parse_constant=no_constant)
    assert {"parameters", "specimens", "specimens_differ"} <= set(doc)
    assert len(doc["parameters"]) == 6
    for p in doc["parameters"]:
        assert CONTRACT_PARAMETER_KEYS <= set(p)
        assert p["center_ci_low"] < p["center"] < p["center_ci_high"]
        assert p["spread_ci_low"] <= p["spread"] <= p["spread_ci_high"]
    assert [s["study"] for s in doc["specimens"]] == [f.name for f in folders]
    for s in doc["specimens"]:
        assert len(s["parameters"]) == 6
        for p in s["parameters"]:
            assert CONTRACT_SPECIMEN_KEYS <= set(p)
            assert p["ci_low"] < p["value"] < p["ci_high"]
    assert {"p_value", "statistic"} <= set(doc["specimens_differ"])
    assert doc["specimens_differ"]["p_value"] < 1e-6          # a 10-30 % spread at 0.3 % noise
    assert doc["solver"]["runs"] == 5 and all(s["solver"]["runs"] == 1 for s in doc["specimens"])
    for name in ("report.md", "specimens.png", "spread.png"):
        assert (out / name).is_file()
    text = (out / "report.md").read_text()
    assert "## Population" in text and "## Do the specimens differ?" in text
    # the specimens share the deck, the loads and the measured DOFs: with one cache folder for all
    # of them the first specimen's run serves the others, and a second command runs nothing
    cache = ["--cache-dir", str(tmp_path / "cache")]
    for runs, cached in ((1, 4), (0, 5)):
        capsys.readouterr()
        assert main(["population", *map(str, folders), "--out", str(out), *cache]) == 0
        again = json.loads((out / "population.json").read_text())
        assert (again["solver"]["runs"], again["solver"]["cached_batches"]) == (runs, cached)
        assert [p["center"] for p in again["parameters"]] == [p["center"] for p in doc["parameters"]]


def test_unidentifiable_parameters_are_said_not_dressed_up(specimens, tmp_path, capsys):
    """Loads in the portal's plane only: the knees' out-of-plane springs (kx12, kz12 of each
    joint) move nothing measured. In a population of such specimens only: not determined, no
    numbers, exit 4. Mixed with fully loaded specimens: left out of those parameters' fits, their
    values the population's prediction, marked so."""
    folders, planar, _ = specimens
    out = tmp_path / "planar"
    assert main(["population", *map(str, planar), "--out", str(out), "--no-cache"]) == 4
    err = capsys.readouterr().err
    assert "do not determine" in err and "JL.kx12" in err
    doc = json.loads((out / "population.json").read_text())
    by = {(p["joint"], p["name"]): p for p in doc["parameters"]}
    for key in (("JL", "kx12"), ("JL", "kz12"), ("JR", "kx12"), ("JR", "kz12")):
        p = by[key]
        assert p["n_specimens"] == 0 and p["determined"] is False
        assert p["center"] is None and p["spread"] is None and p["center_ci_low"] is None
    assert by[("JL", "ky12")]["determined"] and by[("JL", "ky12")]["n_specimens"] == 3

    mixed = tmp_path / "mixed"
    assert main(["population", *map(str, folders), str(planar[0]), "--out", str(mixed), "--no-cache"]) == 0
    doc = json.loads((mixed / "population.json").read_text())
    by = {(p["joint"], p["name"]): p for p in doc["parameters"]}
    assert by[("JL", "kx12")]["n_specimens"] == 5 and by[("JL", "ky12")]["n_specimens"] == 6
    last = {(p["joint"], p["name"]): p for p in doc["specimens"][-1]["parameters"]}
    assert last[("JL", "kx12")]["identifiable"] is False
    assert last[("JL", "kx12")]["source"].startswith("population only")
    assert last[("JL", "kx12")]["alone"]["value"] is None
    assert "population only" in (mixed / "report.md").read_text()


def test_bad_input_is_named(specimens, tmp_path, capsys):
    folders, _, root = specimens
    from conftest import FIXTURES
    assert main(["population", str(folders[0]), "--out", str(tmp_path / "one")]) == 2
    assert "at least 2 studies" in capsys.readouterr().err
    assert main(["population", str(folders[0]), str(FIXTURES / "cube"), "--out", str(tmp_path / "mix"),
                 "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "cube" in err and "same joints" in err
    assert main(["population", str(folders[0]), str(root / "nowhere"), "--out", str(tmp_path / "x")]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert not (tmp_path / "mix").exists()


@pytest.mark.slow
def test_workers_give_the_serial_result(specimens, tmp_path, capsys):
    """``--workers 2``: the specimens on a real local Dask cluster (loopback); the same numbers."""
    pytest.importorskip("distributed")
    folders, _, _ = specimens
    docs = []
    for name, extra in (("serial", []), ("dask", ["--workers", "2"])):
        assert main(["population", *map(str, folders[:4]), "--out", str(tmp_path / name), "--no-cache",
                     *extra]) == 0
        docs.append(json.loads((tmp_path / name / "population.json").read_text()))
    assert "Dask" in docs[1]["executor"] and docs[1]["solver"]["runs"] == 4
    for a, b in zip(docs[0]["parameters"], docs[1]["parameters"]):
        for key in CONTRACT_PARAMETER_KEYS - {"joint", "name"}:
            assert a[key] == pytest.approx(b[key], rel=1e-9)      # the same arithmetic per specimen
