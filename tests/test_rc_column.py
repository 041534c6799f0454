"""The measured fixture: Soesianawati, Park & Priestley (1986) unit 1 (fixtures/measured/rc_column).

References: the published record itself (source/, the quoFEM example's files), and the closed form
of the fit: for the cantilever on a base spring the top deflection is ``u = F (a + L^2 c)`` with
``a = L^3 / (3 E I)`` and ``c = 1 / k``, linear in ``c``, so the weighted least-squares estimate
with one sigma for all rows is ``c = sum F (u - a F) / (L^2 sum F^2)`` and its interval
``c +- z sigma / (L^2 sqrt(sum F^2))`` (exact: the profile likelihood of a linear model; the
interval of ``k`` is its image under ``k = 1 / c``).
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from blackbox.cli import main
from blackbox.commands import identify

ROOT = Path(__file__).resolve().parents[1]
RC = ROOT / "fixtures" / "measured" / "rc_column"
L, E, I = 1.6, 30.0e9, 0.4 ** 4 / 12.0
SIGMA = 1.6e-4 / math.sqrt(3.0)          # study.toml: translation_accuracy = 1.6e-4, rectangular
README_EFFECTS = ("joint_softening,joint_unloading,p_delta,joint_coupling,support_flexibility,member_stiffness,joint_gap,"
                  "undeclared_joint")

ESTIMATE_RTOL = 1e-7
"""The fit stops at a relative step of 1e-8 in log k (xtol): the estimate is the closed form's to ~1e-8."""
INTERVAL_RTOL = 2e-2
"""Profile end points are found to 1 % of the profile-t level (PROFILE_TAU_RTOL)."""


def _generate():
    spec = importlib.util.spec_from_file_location("rc_generate", RC / "generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_study_files_are_what_the_generator_writes(tmp_path):
    _generate().write(tmp_path)
    for name in ("model.bdf", "loads.csv", "measurements.csv"):
        assert (tmp_path / name).read_bytes() == (RC / name).read_bytes(), name


def test_the_record_is_the_published_one():
    """548 steps, the first the origin; the first peak at +19.51 mm and 188.13 kN (step 15), the
    last step -75.689 mm, -163.3 kN (source/ as quoFEM ships it)."""
    gen = _generate()
    d, f = gen.read_record()
    assert d.size == f.size == 548 and d[0] == f[0] == 0.0
    assert (d[15], f[15]) == (pytest.approx(0.01951, rel=1e-12), 188130.0)     # the file's text, parsed
    assert (d[-1], f[-1]) == (pytest.approx(-0.075689, rel=1e-12), -163300.0)
    labels = gen.case_labels(d)
    assert len(labels) == 547 and labels[14] == "s015-a20-c1-pos-load" and labels[15] == "s016-a20-c1-pos-unload"
    assert sum(lab.endswith("-load") for lab in labels) + sum(lab.endswith("-unload") for lab in labels) == 547


@pytest.fixture(scope="module")
def identified():
    return identify.run(RC, adapter="reference")


def test_identify_on_the_early_steps_is_the_closed_form(identified):
    """Steps 1-4, one declared sigma: the estimate and its 95 % interval are the closed form's
    (module docstring); the chi-square test fails and the scaled interval uses t(3)."""
    gen = _generate()
    d, f = gen.read_record()
    F, u = f[1:5], d[1:5]
    a = L ** 3 / (3.0 * E * I)
    c = float(F @ (u - a * F)) / (L * L * float(F @ F))
    r = identified.result
    assert r.param_names == ("ky12",) and r.n_obs == 4
    assert r.k[0] == pytest.approx(1.0 / c, rel=ESTIMATE_RTOL)
    half = 1.959964 * SIGMA / (L * L * math.sqrt(float(F @ F)))
    assert (r.ci_low[0], r.ci_high[0]) == pytest.approx((1.0 / (c + half), 1.0 / (c - half)), rel=INTERVAL_RTOL)
    chi2 = float(np.sum((u - F * (a + L * L * c)) ** 2)) / SIGMA ** 2
    assert r.chi2 == pytest.approx(chi2, rel=1e-6) and r.reduced_chi2 > 30
    sc = identified.scaled
    half_s = stats.t.ppf(0.975, 3) * SIGMA * math.sqrt(chi2 / 3) / (L * L * math.sqrt(float(F @ F)))
    assert half_s > c                                  # the data bound k from below only
    assert sc.ci_low[0] == pytest.approx(1.0 / (c + half_s), rel=INTERVAL_RTOL) and math.isinf(sc.ci_high[0])


def test_identify_cli_on_the_fixture(tmp_path, capsys):
    """The README's command: exit 0, the selection, the sigma source, the reference spring."""
    assert main(["identify", str(RC), "--out", str(tmp_path / "id"), "--no-cache"]) == 0
    out = capsys.readouterr().out
    assert "fitted the 4 case(s) matching ['s00[1-4]-*']; 543 other case(s) predicted" in out
    assert "chi-square test fails; with sigma scaled to the residuals" in out
    doc = json.loads((tmp_path / "id" / "result.json").read_text())
    assert doc["sigma"]["rows_by_source"] == {"accuracy": 547} and doc["sigma"]["chi2_test"] is True
    assert doc["selection"]["excluded_cases"] == 543
    assert doc["reference_springs"]["springs"] == [{"a": [1, 5], "b": [2, 5], "k": 1.0e8}]
    assert doc["constrained_springs"] == {"base": ["kx12", "kz12"]}
    report = (tmp_path / "id" / "report.md").read_text()
    for section in ("[[Measurement errors]]", "[[Case selection]]", "[[Residual by amplitude]]",
                    "[[Joints held for the condensation]]", "load_displacement.png", "residual_amplitude.png"):
        assert section in report, section
    assert not (RC / "out").exists()


def test_diagnose_on_the_whole_record_says_unexplained(tmp_path, capsys):
    """The README's diagnose: the whole record; the base joint softening with the amplitude (at its
    yield limit: the secant stiffness at 78 mm, which with the column is the record's 2,000-2,300
    kN/m there, README) and softer while unloading; p_delta offered (the declared 744 kN) but not
    added; the verdict unexplained (exit 4), the hotspots the 78 mm unloading branches, the misfit
    after the additions reduced most at the smallest amplitudes; the two response plots."""
    assert main(["diagnose", str(RC), "--out", str(tmp_path / "dg"), "--effects", README_EFFECTS, "--no-cache"]) == 4
    assert "unexplained (exit 4)" in capsys.readouterr().err
    doc = json.loads((tmp_path / "dg" / "diagnosis.json").read_text())
    assert doc["verdict"] == "unexplained" and doc["before"]["reduced_chi2"] > 1e4
    assert [(a["effect"], a["where"]) for a in doc["added"]] == [("joint_softening", ["base"]),
                                                                  ("joint_unloading", ["base"])]
    soft, unload = (a["parameters"][0]["value"] for a in doc["added"])
    assert soft > 0.9999 and 0.6 < unload < 0.9
    k = doc["joint_parameters"]["final"]["base"]["parameters"]["ky12"]["value"]
    lateral = 1.0 / (L ** 2 / k + L ** 3 / (3.0 * E * I))                # N/m at the top, a = 1
    assert 1.8e6 < lateral < 2.6e6                                        # the 78 mm secant, +-15 %
    assert doc["settings"]["candidates_by_effect"]["p_delta"] == 1
    assert doc["after"]["reduced_chi2"] < 0.5 * doc["before"]["reduced_chi2"]
    assert doc["hotspot_cases"] and all("-a78-" in h["case"] for h in doc["hotspot_cases"][:3])
    # hysteresis, not noise larger than declared: the misfit sits with the size of the response
    nl = doc["noise_level"]
    assert not nl["noise_like"] and {u["grouping"] for u in nl["uneven"]} == {"response quarter"}
    report = (tmp_path / "dg" / "report.md").read_text()
    rows = report.split("## Residual by amplitude", 1)[1].split("|---|")[-1].strip().splitlines()
    before = [float(r.split("|")[5]) for r in rows]                # chi2/n of the declared model
    after = [float(r.split("|")[7]) for r in rows]
    assert len(before) == 6 and before == sorted(before) and before[-1] > 5 * before[0]
    assert all(a < b for a, b in zip(after, before)) and after[0] < 0.1 * before[0]
    if importlib.util.find_spec("matplotlib") is not None:
        for name in ("load_displacement.png", "residual_amplitude.png"):
            assert (tmp_path / "dg" / name).exists() and f"({name})" in report
