"""Measurement simulation (Section 5.2) and ``blackbox simulate``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from blackbox import simulation as sim
from blackbox.cli import main
from blackbox.study import load_study
from blackbox.structures import FrameBuilder
from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from conftest import FIXTURES


def test_noise_sigma_is_proportional_with_a_floor():
    cfg = sim.NoiseConfig(relative=0.05, floor=0.1)
    true = np.array([1.0, -2.0, 0.0, 1e-6, 3.0])
    kinds = np.array([0, 0, 0, 1, 1])
    case = np.zeros(5, int)
    s = sim.noise_sigma(true, kinds, case, cfg)
    assert s[0] == pytest.approx(0.05) and s[1] == pytest.approx(0.1)
    assert s[2] == pytest.approx(0.05 * 0.1 * 2.0)        # floor: 10 % of the largest translation
    assert s[3] == pytest.approx(0.05 * 0.1 * 3.0)        # rotations have their own scale
    with pytest.raises(ValueError, match="sigma = 0"):
        sim.noise_sigma(np.zeros(2), np.zeros(2, int), np.zeros(2, int), sim.NoiseConfig(floor=0.0))


def test_contaminated_values_are_standard_normal_in_sigma_units():
    """Over 20000 draws the standardized errors have mean 0 and variance 1 within 4 standard
    errors (mean: 4/sqrt(n) = 0.028; variance: 4*sqrt(2/n) = 0.04)."""
    rng = np.random.default_rng(0)
    true = rng.uniform(-1, 1, 20000)
    sigma = sim.noise_sigma(true, np.zeros(20000, int), np.repeat(np.arange(100), 200), sim.NoiseConfig())
    z = (sim.contaminate(true, sigma, rng) - true) / sigma
    assert abs(z.mean()) < 0.028 and abs(z.var() - 1) < 0.04


def test_reference_point_error_follows_the_relative_motion():
    """Section 5.2: relative values with an error proportional to the relative motion only."""
    rng = np.random.default_rng(1)
    true = np.array([1.0, 1.1, 1.2, 5.0, 5.1])
    ref = np.array([1.0, 1.0, 1.0, 5.0, 5.0])
    out = sim.relative_to_reference(true, ref, np.zeros(5, int), np.array([0, 0, 0, 1, 1]),
                                    sim.NoiseConfig(relative=0.05, floor=0.1), rng)
    assert np.allclose(out.true, true - ref)
    assert np.allclose(out.sigma, 0.05 * np.maximum(np.abs(true - ref), 0.1 * np.array([.2, .2, .2, .1, .1])))
    assert np.all(np.abs(out.values - out.true) < 6 * out.sigma)


def test_member_rotation_samples_follow_the_beam():
    """Cantilever of length L, tip force P: theta(s) = P (L s - s^2/2) / (E I) (Gere &
    Timoshenko, App. G case 1); the Hermite interpolation of the end values is exact for it."""
    E, I, L, P = 2e11, 2e-6, 2.0, 1e3
    f = FrameBuilder(E=E, I1=I, I2=I)
    f.grid(1, (0, 0, 0)); f.grid(2, (L, 0, 0))
    f.bar(1, 2, v=(0, 1, 0))
    f.fix(1)
    a = ReferenceAdapter(read_deck_text(f.bdf()))
    dofs = [(g, c) for g in (1, 2) for c in range(1, 7)]
    U = a.solve(LoadMatrix.from_dense([(2, 2)], np.array([[P]]), ["c"]), dofs).values
    s = np.array([0.0, 0.5, 1.3, L])
    rot = sim.member_end_rotation_samples(U[:6], U[6:], np.zeros(3), np.array([L, 0, 0]),
                                          np.array([0, 1.0, 0]), s)
    assert np.allclose(rot[:, 2, 0], P * (L * s - s**2 / 2) / (E * I), rtol=1e-9, atol=1e-15)
    assert np.allclose(rot[:, :2, 0], 0, atol=1e-15)


def test_averaged_rotation_sigma_is_that_of_a_mean():
    rng = np.random.default_rng(2)
    samples = np.ones((4, 3, 2))
    mean, s = sim.averaged_rotation(samples, sim.NoiseConfig(relative=0.1, floor=0.0), rng, np.ones(2))
    assert np.allclose(s, 0.1 / 2)                         # sigma / sqrt(4)


def write_truth(tmp: Path, text: str) -> Path:
    p = tmp / "truth.toml"
    p.write_text(text)
    return p


def test_cli_simulate_noise_free_matches_exact_and_bias_scales(tmp_path):
    truth = write_truth(tmp_path, """
seed = 1
[[joints]]
name = "J7"
model = "simple"
value = 1.0e4
[noise]
relative = 0.0
absolute = 1e-16
[measure]
away_grids = [5]
""")
    assert main(["simulate", str(FIXTURES / "cube"), "--truth", str(truth), "--out", str(tmp_path / "a")]) == 0
    a = load_study(tmp_path / "a").measurements
    assert len(a) == 20 * (12 + 6)
    rec = json.loads((tmp_path / "a" / "truth.json").read_text())
    assert [p["value"] for p in rec["parameters"]] == [1.0e4] * 9 and rec["solver_runs"] == 1
    biased = truth.read_text().replace("seed = 1", "seed = 1\nforce_scale = 1.1")
    truth.write_text(biased)
    assert main(["simulate", str(FIXTURES / "cube"), "--truth", str(truth), "--out", str(tmp_path / "b")]) == 0
    b = load_study(tmp_path / "b").measurements
    # linear structure; atol: the noise of sigma 1e-16 (about the smallest sigma a study accepts at
    # values of 7e-6 to 3e-5: blackbox.study.SIGMA_RESOLUTION), 10 std of it, against values ~1e-5
    assert np.allclose(b.values, 1.1 * a.values, rtol=1e-12, atol=1e-9 * np.abs(a.values).max())


def test_cli_simulate_rejects_bad_truth(tmp_path, capsys):
    truth = write_truth(tmp_path, '[[joints]]\nname = "NOPE"\nvalue = 1.0\n')
    assert main(["simulate", str(FIXTURES / "cube"), "--truth", str(truth), "--out", str(tmp_path / "o")]) == 2
    assert "NOPE" in capsys.readouterr().err
    truth = write_truth(tmp_path, '[[joints]]\nname = "J7"\nvalue = 1.0\n[measure]\naway = [[999, 1]]\n')
    assert main(["simulate", str(FIXTURES / "cube"), "--truth", str(truth), "--out", str(tmp_path / "o")]) == 2
    assert "999" in capsys.readouterr().err
    truth = write_truth(tmp_path, '[[joints]]\nname = "J7"\nvalue = 1.0\nstub_length = 0.1\n')
    assert main(["simulate", str(FIXTURES / "cube"), "--truth", str(truth), "--out", str(tmp_path / "o")]) == 2
    assert "exactly one" in capsys.readouterr().err
