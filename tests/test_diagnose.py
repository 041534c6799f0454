"""``blackbox diagnose`` (issue 6, parts 2 and 3): find what the declared model lacks.

Data: ``fixtures/undeclared/`` (``python fixtures/undeclared/generate.py``): studies that declare
the plain model (the joint as the simple model) with measurements simulated by the reference
solver from a truth deck that holds one undeclared effect (two in ``two_effects``, none in
``none``); 3 % noise floored at 5 % of the case's largest value of the same kind; hold-out cases
L5, L10, L15, L20. ``planted.json`` says what was planted; the tool never reads it.

Done when (issue 6): on every folder the first effect added is the planted one at the planted
place, the final reduced chi-square is inside the 99 % band of ``chi2(n - p) / (n - p)`` and the
hold-out RMS prediction error goes down; on ``none`` nothing is added. Two studies generated
here on other structures (a 4-branch star frame, a car-body tube) show it is not tuned to the
fixtures. Property tests: the black-box element stiffness is the Euler-Bernoulli frame element,
the split deck's rigid state is the declared model, the compliance form with the planted values
reproduces the truth decks, and the Jacobians agree with central differences.

Units N, m, rad.
"""

from __future__ import annotations

import copy
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

from blackbox import diagnosis as dg
from blackbox.cli import main as cli_main
from blackbox.commands import diagnose as diagnose_command
from blackbox.commands import identify as identify_command
from blackbox.commands.output import MARKER
from blackbox.diagnosis.effects import (Connection, JointCoupling, LoadScale, MemberStiffness, SensorGain,
                                        SupportFlexibility, UndeclaredJoint)
from blackbox.errors import DiagnosisError
from blackbox.joints import frame_element_stiffness, make_joint, spring_network
from blackbox.structures import random_loads, star_joint_frame, tube_body, write_study
from blackbox.commands import simulate as simulate_command
from blackbox.commands.output import write_output
from solver_adapters.bdf_write import write_deck
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from conftest import MYSTRAN_MARKS, fixture_diagnosis

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "undeclared"
FOLDERS = sorted(p.name for p in FIXTURES.iterdir() if (p / "planted.json").exists())
CUBE_FOLDERS = {"support_flexibility", "load_scale", "support_axes"}   # about 1 s each; the car ones 3-10 s

# one xdist worker for the modules that share conftest.fixture_diagnosis's cache
pytestmark = pytest.mark.xdist_group("fixture_diagnosis")


def _planted(folder: str) -> list[dict]:
    return json.loads((FIXTURES / folder / "planted.json").read_text())["effects"]


def _matches(added: dict, planted: dict, cases: list[str]) -> bool:
    """The added effect is the planted one at the planted place, at the planted variant when the
    planted effect names one (the new parameterisations' folders)."""
    where = planted["where"]
    if where == "all cases":
        where = cases
    return (added["effect"] == planted["effect"] and list(added["where"]) == list(where)
            and ("variant" not in planted or added.get("variant") == planted["variant"]))


@pytest.fixture(scope="module")
def diagnosed():
    """A fixture folder's diagnosis (default settings), shared with the other modules that
    check it (``conftest.fixture_diagnosis``)."""
    return lambda folder: fixture_diagnosis(FIXTURES / folder)


# --------------------------------------------------------------------------------------------
# the fixtures: the acceptance test
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("folder", [pytest.param(f, marks=() if f in CUBE_FOLDERS else pytest.mark.slow)
                                    for f in FOLDERS])
def test_fixture_folder(folder, diagnosed):
    d = diagnosed(folder)
    planted = _planted(folder)
    added = d["added"]
    if not planted:
        assert added == [], f"nothing was planted, but {added} was added"
        assert d["before"]["in_band"]
        assert d["verdict"] == "adequate"
        return
    assert d["verdict"] == "explained", d["verdict_detail"]
    assert added, f"{folder}: nothing added (candidates: {d['candidates'][:3]})"
    assert any(_matches(added[0], p, d["cases"]) for p in planted), \
        f"{folder}: first added {added[0]['effect']} @ {added[0]['where']}, planted {planted}"
    for p in planted:
        assert any(_matches(a, p, d["cases"]) for a in added), f"{folder}: planted {p} not found in {added}"
    assert len(added) == len(planted), f"{folder}: spurious additions {added[len(planted):]}"
    lo, hi = d["after"]["band_99"]
    assert lo <= d["after"]["reduced_chi2"] <= hi
    if any(p["effect"] == "outlier" for p in planted):
        # one reading: the omnibus band does not see it, and the hold-out cases (other cases)
        # cannot: the targeted score test finds it, its refit leaves the hold-out as it was
        assert abs(d["after"]["holdout_rms"] / d["before"]["holdout_rms"] - 1) < 1e-3
        return
    assert not d["before"]["in_band"]
    if all(p["effect"] in ("load_tilt", "case_tilt", "misplaced_load") for p in planted):
        # loads of a fitted case that went in otherwise: the hold-out cases went in as declared,
        # so their prediction moves only with the joint's estimate, by round-off and noise
        # (case_tilt: 1.3e-5 relative); it must not get worse beyond that
        assert d["after"]["holdout_rms"] < d["before"]["holdout_rms"] * (1 + 1e-3)
        return
    if d["validation"]["method"] == "kfold":        # no hold-out declared (load_scale_day)
        assert d["validation"]["cv_chi2_after"] < d["validation"]["cv_chi2_before"]
    else:
        assert d["after"]["holdout_rms"] < d["before"]["holdout_rms"]


@pytest.mark.slow
@pytest.mark.parametrize("folder, name", [("load_scale_group", "s_group_day2"), ("load_scale_day", "s_found_L6_8")])
def test_fixture_test_day_scale(folder, name, diagnosed):
    """One test day (L6-L13) with loads 5 % above nominal: named by the group column
    (``load_scale_group``, with hold-out cases) or found from the data (``load_scale_day``, no
    hold-out: checked by 5-fold cross-validation). The factor is 1.05 within 4 std."""
    d = diagnosed(folder)
    (a,) = d["added"]
    (p,) = a["parameters"]
    assert p["name"] == name and abs(p["value"] - 1.05) < 4 * p["std"], p
    assert d["validation"]["method"] == ("holdout" if folder == "load_scale_group" else "kfold")


def test_fixture_parameters_are_the_planted_ones(diagnosed):
    """The added effect's parameters agree with the planted values (within 4 std: the estimate is
    unbiased to first order; 4 std keeps the false-alarm rate of this check below 1e-4)."""
    d = diagnosed("support_flexibility")
    factor = _planted("support_flexibility")[0]["factor_of_local_stiffness"]
    # planted: every component's spring 3 x the members' own stiffness there, which is the
    # connection's k0 (per component, or the geometric mean of a group's for the "equal" variant)
    for p in d["added"][0]["parameters"]:
        assert abs(p["value"] - factor * p["k0"]) < 4 * p["std"], (p, factor)
    d = diagnosed("load_scale")
    p = d["added"][0]["parameters"][0]
    assert abs(p["value"] - 1.08) < 4 * p["std"]


def test_fixture_support_per_axis(diagnosed):
    """``support_axes``: the cube's clamp at grid 1 with a spring per component of 0.5, 5, 5, 0.3,
    5, 5 x the members' own stiffness there: the "per-axis" variant is chosen, and every spring is
    the planted one within 4 std (the 5x translations are stiff against the members, so their
    std is large; the soft ones are found to ~4 % and ~0.3 %)."""
    d = diagnosed("support_axes")
    (a,) = d["added"]
    assert a["effect"] == "support_flexibility" and a["where"] == [1] and a["variant"] == "per-axis"
    planted = _planted("support_axes")[0]["springs"]
    for p in a["parameters"]:
        assert abs(p["value"] - planted[p["name"]]) < 4 * p["std"], (p, planted[p["name"]])


def test_multiplicity_is_alpha_spending(diagnosed):
    """Round r spends alpha / 2^r, shared equally among the K_r kinds of effect in its pool and,
    within a kind, over its M_kind hypotheses (candidates plus their variant upgrades): each is
    tested at alpha / (2^r K_r M_kind), so the whole search's false-addition chance is below
    alpha; the effect added in round 1 passed its kind's level, and the levels halve from round
    to round (at equal counts). Exact arithmetic: 1e-12 relative."""
    from blackbox.diagnosis.search import multipliers
    d = diagnosed("support_flexibility")
    alpha = d["settings"]["alpha"]
    for r, st in enumerate(d["steps"], 1):
        assert st["hypotheses"] >= st["n_candidates"]
        levels, counts = st["lr_levels"], st["hypotheses_by_kind"]
        assert set(levels) == set(counts) and sum(counts.values()) == st["hypotheses"]
        assert sum(counts[k] * levels[k] for k in levels) == pytest.approx(alpha / 2 ** r, rel=1e-12)
    first = d["steps"][0]
    assert d["added"][0]["lr_p_value"] < first["lr_levels"][d["added"][0]["effect"]]
    pool = [SensorGain((g,), (f"g_{g}",)) for g in (1, 2, 3)] + [LoadScale(("L1",), ("s",))]
    m1, m2 = multipliers(pool, 1), multipliers(pool, 2)
    assert m1 == {"sensor_gain": 2 * 2 * 3, "load_scale": 2 * 2 * 1}
    assert all(m2[k] == pytest.approx(2 * m1[k], rel=1e-12) for k in m1)


@pytest.mark.slow
def test_fixture_sensor_offset_channel_and_value(diagnosed):
    """The offset is found first on the planted channel (grid 24, component 3), with the planted
    value (3 median sigmas of that channel) within 4 std (the same false-alarm argument as above)."""
    d = diagnosed("sensor_offset")
    planted = _planted("sensor_offset")[0]
    first = d["added"][0]
    assert (first["effect"], first["where"], first["component"]) == ("sensor_offset", [24], 3)
    (p,) = first["parameters"]
    assert p["name"] == "o_24_3" and abs(p["value"] - planted["offset"]) < 4 * p["std"], (p, planted)


@pytest.mark.slow
def test_unexplained_when_no_candidate_describes_the_effect(tmp_path, capsys):
    """The sensor offset at grid 24 / z with only load scales to choose from: no candidate
    describes it, the reduced chi2 stays above its band, the verdict is "unexplained" and the
    hotspots name the planted place: grid 24 first, component 3 first. The CLI exits 4 and says
    so on the terminal."""
    run = diagnose_command.run(FIXTURES / "sensor_offset", effects=["load_scale"], plots=False)
    d = run.document
    assert d["verdict"] == "unexplained", d["verdict_detail"]
    assert not d["after"]["in_band"] and d["after"]["reduced_chi2"] > d["after"]["band_99"][1]
    assert d["hotspots"][0]["grid"] == 24 and d["hotspot_components"][0]["component"] == 3
    # the planted channel is 16 of 3552 fitted rows yet carries most of the excess (the offset's
    # likelihood ratio, ~490, is about the declared fit's whole excess over n - p)
    assert d["hotspots"][0]["share"] > 0.5
    assert abs(sum(h["share"] for h in run.diagnosis.hotspots["components"]) - 1.0) < 1e-12
    assert "above the 99 % band" in d["verdict_detail"] and "grids 24" in d["verdict_detail"]
    out = tmp_path / "out"
    out.mkdir()
    run.write(out)
    report = (out / "report.md").read_text()
    assert "**unexplained**" in report and "| 24 |" in report
    capsys.readouterr()
    assert cli_main(["diagnose", str(FIXTURES / "sensor_offset"), "--effects", "load_scale",
                     "--out", str(tmp_path / "o"), "--no-cache"]) == 4
    err = capsys.readouterr().err
    assert "unexplained" in err and "grids 24" in err


def test_hotspots_and_verdict_definitions():
    """``hotspots``: a grid's share is its clipped excess sum(z^2 - 1) over the total clipped
    excess, per kind, largest first; groups at or below the noise get no share. ``verdict``:
    above the band -> unexplained, else explained / adequate by whether something was added."""
    from blackbox.diagnosis.residuals import hotspots
    from blackbox.diagnosis.search import verdict
    from blackbox.identification import Observations

    dofs = [(1, 1), (1, 2), (2, 1), (2, 2), (3, 1), (3, 2)] * 2
    obs = Observations(dofs=tuple(dofs), values=np.zeros(12), sigma=np.ones(12),
                       case_index=np.repeat([0, 1], 6), case_labels=("A", "B"))
    z = np.array([3.0, 1.0, 2.0, 0.0, 0.5, 0.5, 3.0, 1.0, 1.0, 1.0, 0.0, 0.0])
    h = hotspots(obs, z)
    # grid 1: 8 + 0 + 8 + 0 = 16; grid 2: 3 - 1 + 0 + 0 = 2; grid 3: 4 x (-0.75 or -1) < 0 -> 0
    assert [(g["grid"], g["share"]) for g in h["grids"]] == [(1, 16 / 18), (2, 2 / 18)]
    # case A: 8 + 0 + 3 - 1 - 0.75 - 0.75 = 8.5; case B: 8 + 0 + 0 + 0 - 1 - 1 = 6
    assert [(c["case"], c["share"]) for c in h["cases"]] == [("A", 8.5 / 14.5), ("B", 6 / 14.5)]
    # component 1: 8 + 3 - 0.75 + 8 + 0 - 1 = 17.25; component 2: 0 - 1 - 0.75 + 0 + 0 - 1 < 0
    assert [(c["component"], c["share"]) for c in h["components"]] == [(1, 1.0)]
    assert hotspots(obs, np.zeros(12)) == {"grids": [], "cases": [], "components": []}
    band = (0.9, 1.1)
    assert verdict(1.0, band, False) == "adequate" and verdict(1.0, band, True) == "explained"
    assert verdict(1.2, band, True) == verdict(1.2, band, False) == "unexplained"
    assert verdict(0.5, band, False) == "adequate"     # below the band: sigma overstated, no misfit


@pytest.mark.parametrize("n", [3, 8, 25])
def test_found_groups_bound_holds_whatever_groups_are_chosen(n):
    """With no load scaled, the best load-scale group found from the data (the groups
    ``LoadScale.found_groups`` offers, ordered by the case scales) drops the chi2 by less than
    ``t`` at least as often as the bound of ``found_group_log_sf`` says, at the levels a search
    spends (simulated: independent standardized case scales with unequal standard deviations,
    as cases of different load magnitudes give). The tolerance is the simulation's own: 40,000
    noise-only data sets put a binomial standard error of 16 % on a 1e-3 tail; the bound must
    fall below the simulated tail by more than 3 such errors nowhere. Its looseness is bounded
    too (a looser bound would cost a real test day its detection): measured, the bound is 2.5-3.1x
    the simulated tail for 3 cases, 3.2-4.3x for 8 and 8-16x for 25 at 1e-2 and 1e-3 (the
    critical chi2 drop at 1e-3 19 %, 19 % and 30 % above the simulated one); beyond 25x fails the
    test."""
    from blackbox.diagnosis.effects.load_scale import found_group_log_sf
    rng = np.random.default_rng(11)
    std = rng.uniform(0.3, 3.0, n)                    # each case's scale standard deviation
    z = rng.standard_normal((40_000, n))
    labels = [f"L{i + 1}" for i in range(n)]
    # the groups found_groups offers, checked on one draw against the vectorised order below
    a0 = z[0] * std
    groups = {g.cases for g in LoadScale.found_groups(labels, {c: (a0[i], std[i]) for i, c in enumerate(labels)})}
    o0 = np.argsort(a0, kind="stable")
    assert groups == {tuple(sorted(o0[:k])) for k in range(2, n)} | {tuple(sorted(o0[n - k:])) for k in range(2, n)}
    o = np.argsort(z * std, axis=1)
    w = 1.0 / std
    zw = np.take_along_axis(z * w, o, 1)
    ww = np.take_along_axis(np.broadcast_to(w ** 2, z.shape), o, 1)
    best = np.zeros(len(z))
    for k in range(2, n):
        for sl in (slice(0, k), slice(n - k, n)):
            best = np.maximum(best, zw[:, sl].sum(1) ** 2 / ww[:, sl].sum(1))
    for q in (1e-2, 1e-3):
        t = float(np.quantile(best, 1 - q))
        bound = np.exp(found_group_log_sf(t, n))
        se = np.sqrt(q * (1 - q) / len(z))
        assert bound >= q - 3 * se, (n, q, t, bound)
        assert bound <= 25 * q, (n, q, t, bound)


@pytest.mark.parametrize("group_column", [True, False], ids=["group-column", "found-from-data"])
def test_generated_load_scale_of_one_group(tmp_path, group_column):
    """A 4-branch star frame with 17 load cases in two groups: the 8 cases of group B were run
    with loads 6 % above nominal (simulated with ``force_scale = 1.06``), the 9 of group A at
    nominal (the issue's "x1.06 on 8 of 17 cases, one test day"). With ``loads.csv``'s ``group``
    column the group's factor is found first, on exactly group B's cases; without it the group
    is found from the data (the 8 cases whose own scale is largest). Either way at 1.06 within
    4 std (the estimate's own interval), and the verdict is explained."""
    b = star_joint_frame(4, seed=0)
    loads = random_loads(b, 17, seed=3)
    study = _truth_study(tmp_path, b, b, loads, "star", 1.0e5, [100, 101, 102, 103], seed=5)
    cases = list(dict.fromkeys(c for c, *_ in loads))
    group_b = set(cases[1::2])                                   # L2, L4, ..., L16: 8 of 17
    assert len(cases) == 17 and len(group_b) == 8
    _scale_cases(tmp_path, study, group_b, 1.06)
    if group_column:
        with (study / "loads.csv").open("w") as fh:
            fh.write("case,grid,component,value,group\n")
            for case, g, c, v in loads:
                fh.write(f"{case},{g},{c},{v!r},{'B' if case in group_b else 'A'}\n")
    d = diagnose_command.run(study, plots=False).document
    first = d["added"][0]
    assert first["effect"] == "load_scale", d["added"]
    assert set(first["where"]) == group_b
    (p,) = first["parameters"]
    if group_column:
        assert first.get("group") == "B" and p["name"] == "s_group_B", first
    else:
        assert first.get("group") == "found from the data (8 cases)" and p["name"].startswith("s_found_"), first
    assert abs(p["value"] - 1.06) < 4 * p["std"], p
    assert d["verdict"] == "explained"


@pytest.mark.slow
def test_fixture_parameters_car(diagnosed):
    d = diagnosed("member_stiffness")
    p = d["added"][0]["parameters"][0]
    assert p["name"] == "alpha_88" and abs(p["value"] - 0.6) < 4 * p["std"]
    d = diagnosed("undeclared_joint")
    for p in d["added"][0]["parameters"]:
        assert abs(p["value"] - 1.0e5) < 4 * p["std"], p


@pytest.mark.slow
def test_fixture_new_parameterisations(diagnosed):
    """The two folders of the richer variants: each planted effect is found at its variant
    (checked by ``test_fixture_folder``) with the planted values within 4 std (the false-alarm
    argument above), and the simpler variants were tried first and beaten.

    ``joint_translation_axes``: springs 1.0 / 0.8 / 1.2e6 N/m along x / y / z from branch grids
    111 and 112 to grid 11 (planted.json): the per-branch variant's springs of those branches;
    grid 11's own spring to the centre is rigid in the truth, so it must come out at least 10x
    stiffer than the others (or be dropped at its bound). ``member_bending``: member 70's I1 and
    I2 x 0.65, A and J as declared: EI1, EI2 factors 0.65, EA and GJ factors 1."""
    d = diagnosed("joint_translation_axes")
    (a,) = d["added"]
    ks = _planted("joint_translation_axes")[0]["springs"]
    params = {p["name"]: p for p in a["parameters"]}
    for axis in "xyz":
        for g in (111, 112):
            p = params[f"kt{axis}_JB_{g}"]
            assert abs(p["value"] - ks[f"kt{axis}"]) < 4 * p["std"], p
        centre = params.get(f"kt{axis}_JB_11")
        assert centre is None or centre["value"] is None or centre["value"] > 10 * ks[f"kt{axis}"], centre
    # The path to per-branch starts from whichever simpler variant scored first: equal springs
    # here, a single axis on another machine's BLAS (the two score within a few percent).
    tried = [(t["from_variant"], t["variant"], t["accepted"]) for t in a["variants_tried"]]
    assert tried and tried[0][0] in ("equal", "axis-x", "axis-y", "axis-z"), tried
    assert [t for t in tried if t[2]][-1][1] == "per-branch", tried
    d = diagnosed("member_bending")
    (a,) = d["added"]
    truth = _planted("member_bending")[0]["factors"]
    for p in a["parameters"]:
        name = p["name"].split("_")[0]
        assert abs(p["value"] - truth[name]) < 4 * p["std"], (p, truth[name])
    assert [(t["from_variant"], t["variant"], t["accepted"]) for t in a["variants_tried"]] == \
        [("whole", "sections", True)]


def test_section_parts_split_the_frame_element():
    """``section_parts`` of the Euler-Bernoulli frame element (``frame_element_stiffness``, an
    oblique member with an orientation vector off the axes) sum to it, and scaling one of A,
    I1, I2, J (and G for J) changes the element by exactly that part times (factor - 1): the
    four parts are the axial, plane-1 (I1), plane-2 (I2) and torsion stiffness. Tolerance 1e-9
    of the largest entry: the split is exact algebra, the rounding of a 12 x 12 product."""
    from blackbox.diagnosis.effects.member_stiffness import section_parts
    xa, xb, v = (0.1, 0.2, 0.3), (1.3, 0.9, 0.5), (0.2, -0.1, 1.0)
    E, G, A, I1, I2, J = 2.1e11, 8.1e10, 4e-4, 3e-8, 7e-8, 5e-8

    def K(a=A, i1=I1, i2=I2, j=J):
        return frame_element_stiffness(xa, xb, E, G, a, i2, i1, j, v)
    K0 = K()
    parts = section_parts(K0, np.array(v))
    assert parts is not None
    tol = 1e-9 * np.abs(K0).max()
    np.testing.assert_allclose(parts.sum(axis=0), K0, rtol=0, atol=tol)
    for q, kw in enumerate(({"a": 0.5 * A}, {"i1": 0.5 * I1}, {"i2": 0.5 * I2}, {"j": 0.5 * J})):
        np.testing.assert_allclose(K(**kw) - K0, -0.5 * parts[q], rtol=0, atol=tol)
    # an orientation vector 45 degrees off (I1 != I2 couples the planes there): no split, the
    # member then keeps the "whole" variant only
    ex = np.subtract(xb, xa) / np.linalg.norm(np.subtract(xb, xa))
    ey = np.array(v) - (np.array(v) @ ex) * ex
    ey /= np.linalg.norm(ey)
    assert section_parts(K0, ey + np.cross(ex, ey)) is None


def test_per_branch_nests_per_axis():
    """The per-branch basis at equal compliances ``theta / n`` is the per-axis (complete graph)
    basis at ``theta``, for 2..5 branches (the star-mesh identity); the equal variant is the
    per-axis one at equal thetas. Exact algebra: 1e-12 relative."""
    from blackbox.diagnosis.effects.connection import branch_ladder
    k = np.array([2.0e6, 5.0e5, 1.0e6])
    for n in range(2, 6):
        ladder = branch_ladder(n, k, ("x", "y", "z"), "e", tuple(str(i) for i in range(n)))
        assert [r.variant for r in ladder] == (["equal", "per-axis"] + (["per-branch"] if n >= 3 else []))
        theta = np.array([0.3])
        D = np.tensordot(theta, ladder[0].basis, 1)
        for r in ladder[1:]:
            theta = r.embed @ theta
            np.testing.assert_allclose(np.tensordot(theta, r.basis, 1), D, rtol=1e-12, atol=1e-12 * np.abs(D).max())


# --------------------------------------------------------------------------------------------
# the command and its outputs
# --------------------------------------------------------------------------------------------
def test_cli_writes_the_contract(tmp_path):
    out = tmp_path / "diag"
    assert cli_main(["diagnose", str(FIXTURES / "load_scale"), "--out", str(out), "--no-cache"]) == 0
    d = json.loads((out / "diagnosis.json").read_text())
    for key in ("before", "after"):
        assert {"reduced_chi2", "rms_residual", "holdout_rms", "bic"} <= set(d[key])
    assert d["candidates"] and {"effect", "where", "delta_bic", "p_value"} <= set(d["candidates"][0])
    assert all(c["effect"] in dg.kinds() for c in d["candidates"])
    (a,) = d["added"]
    assert {"effect", "where", "parameters"} <= set(a)
    assert {"name", "value", "std"} <= set(a["parameters"][0])
    assert d["steps"][0]["joint_parameters_before"]["J7"]["model"] == "simple"
    sv = d["solver"]                # without the cache every batch is a run: study, element, split deck
    assert sv["runs"] == len(sv["by_run"]) >= 3 and sv["cached_batches"] == 0
    assert sv["right_hand_sides"] == sum(r["right_hand_sides"] for r in sv["by_run"])
    assert (out / "decks" / "split.bdf").exists() and (out / MARKER).exists()
    report = (out / "report.md").read_text()
    assert "## Before and after" in report and "load_scale" in report
    pytest.importorskip("matplotlib")
    for name in ("residual_map_before.png", "residual_map_after.png", "candidates.png", "steps.png"):
        assert (out / name).stat().st_size > 1000


def test_cli_bad_input(tmp_path, capsys):
    assert cli_main(["diagnose", str(FIXTURES / "load_scale"), "--out", str(tmp_path), "--effects",
                     "support_flexibility,gremlins"]) == 2
    assert "unknown effect kind(s) ['gremlins']" in capsys.readouterr().err
    assert cli_main(["diagnose", str(FIXTURES / "load_scale"), "--out", str(tmp_path), "--alpha", "2"]) == 2


def test_options_and_families_are_checked_before_any_work(tmp_path):
    """Bad options raise DiagnosisError naming what was given, before the study is even read (a
    folder that does not exist is not reported)."""
    missing = tmp_path / "no_such_study"
    with pytest.raises(DiagnosisError, match=r"unknown effect kind\(s\) \['gremlins'\]"):
        diagnose_command.run(missing, effects=["load_scale", "gremlins"])
    with pytest.raises(DiagnosisError, match="alpha must be in"):
        diagnose_command.run(missing, alpha=0.0)
    with pytest.raises(DiagnosisError, match="refit_top"):
        diagnose_command.run(missing, refit_top=0)


def test_registry_one_family_per_module():
    """Every family is registered under its kind, in its own module named after it; the kinds
    are the ones diagnosis.json uses."""
    assert set(dg.kinds()) == {"joint_coupling", "joint_translation", "undeclared_joint", "support_flexibility",
                               "load_scale", "sensor_gain", "sensor_offset", "member_stiffness", "joint_gap",
                               "outlier", "sign_flip", "channel_swap", "misplaced_sensor", "joint_softening",
                               "joint_unloading", "p_delta", "rigid_end_zone", "bad_channel", "bad_case",
                               "rigid_motion", "support_fixity", "case_swap", "load_tilt", "case_tilt", "misplaced_load",
                               "load_cell"}
    for kind in dg.kinds():
        cls = dg.get(kind)
        assert cls.kind == kind and cls.__module__ == f"blackbox.diagnosis.effects.{kind}"
        assert cls.summary
    with pytest.raises(DiagnosisError, match="unknown effect kind 'gremlins'"):
        dg.get("gremlins")


def test_run_writes_nothing_until_write(tmp_path, monkeypatch):
    """``run`` leaves the study, the working folder and the temporary folder as they were (the
    edited decks live in a temporary folder that is removed); ``write`` puts every file it
    names, decks included, into the given folder."""
    study = tmp_path / "study"
    shutil.copytree(FIXTURES / "load_scale", study)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.chdir(scratch)
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    result = diagnose_command.run(study, plots=False)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before
    assert result.command == "diagnose"
    out = tmp_path / "out"
    out.mkdir()
    files = result.write(out)
    assert sorted(files) == sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert {"diagnosis.json", "report.md", "decks/elements.bdf", "decks/split.bdf"} <= set(files)
    assert (out / "decks" / "split.bdf").read_text() == dict(result.decks)["split.bdf"]
    assert json.loads((out / "diagnosis.json").read_text())["added"] == result.document["added"]


def test_candidate_caps_are_reported_and_follow_the_residual(tmp_path):
    """Beyond ``max_joint_candidates`` / ``max_member_candidates`` a diagnosis considers the grids
    and members nearest the declared fit's residual and says so: on the car's undeclared-joint
    fixture (planted at grid 41, 115 members) capped at 5 grids and 20 members, the candidates are
    exactly that many, grid 41 is among the 5, the split run reports the considered members' end
    DOFs and no other member's, the document lists both caps and warns of each, and the planted
    joint is still the effect added (``rigid_end_zone`` considers the same grids and reports its cap
    too)."""
    d = tmp_path / "decks"
    d.mkdir()
    pr = diagnose_command.prepare(FIXTURES / "undeclared_joint", d, max_joint_candidates=5, max_member_candidates=20)
    lim = {x.kind: x for x in pr.limits}
    declared = {g for j in pr.joints for g in j.grids}
    n_grids = len(dg.effects.undeclared_joint.joint_candidate_grids(pr.deck, declared))
    assert (lim["undeclared_joint"].considered, lim["undeclared_joint"].available) == (5, n_grids) and n_grids > 5
    assert (lim["member_stiffness"].considered, lim["member_stiffness"].available) == (20, len(pr.deck.cbars))
    joints = [c for c in pr.candidates if c.kind == "undeclared_joint"]
    members = [c for c in pr.candidates if c.kind == "member_stiffness"]
    # one joint candidate per grid, beside it a hinge track per member ending there (all but
    # the first where the grid turns under a moment or a reading: tests/test_hinge.py)
    grids = {c.where[0] for c in joints if c.hinged_member is None}
    at = dg.decks.members_at(pr.deck)
    assert len(grids) == 5 and len(members) == 20 and 41 in grids
    hinges = {(c.where[0], c.hinged_member) for c in joints if c.hinged_member is not None}
    assert {(g, e) for g in grids for e in at[g][1:]} <= hinges <= {(g, e) for g in grids for e in at[g]}
    rows = set(pr.base.rows)
    assert all(dof in rows for c in members for dof in c.dofs)
    others = [eid for eid in pr.split.member_dofs if eid not in {c.eid for c in members}]
    assert any(not set(pr.split.member_dofs[eid]) <= rows for eid in others)
    doc = diagnose_command.run(FIXTURES / "undeclared_joint", plots=False, max_joint_candidates=5,
                               max_member_candidates=20).document
    assert {x["effect"]: (x["considered"], x["available"]) for x in doc["settings"]["candidates_limited"]} == {
        "undeclared_joint": (5, n_grids), "member_stiffness": (20, len(pr.deck.cbars)),
        "rigid_end_zone": (5, n_grids)}
    assert any(w.startswith(f"undeclared_joint: 5 of {n_grids} candidates considered") for w in doc["warnings"])
    assert any(w.startswith("member_stiffness: 20 of 115 candidates considered") for w in doc["warnings"])
    assert doc["added"][0]["effect"] == "undeclared_joint" and doc["added"][0]["where"] == [41]
    # no cap reached: nothing said
    assert diagnose_command.run(FIXTURES / "support_flexibility", plots=False).document["settings"][
        "candidates_limited"] == []


def test_default_member_cap_counts_end_grids_not_members(monkeypatch):
    """Without ``max_member_candidates`` every member is considered up to ``MEMBER_GRIDS`` end
    grids, beyond them ``MAX_MEMBER_CANDIDATES``; a value given is the cap whatever the size.
    The car (115 members on 65 end grids) is far inside the default."""
    from blackbox.diagnosis.decks import member_ends
    from blackbox.study import load_study
    deck = load_study(FIXTURES / "undeclared_joint").deck
    members = [*deck.cbars, *deck.rods]
    grids = {g for e in members for g in member_ends(deck, e)}
    assert diagnose_command.member_cap(deck, None) == len(members) > 100
    assert diagnose_command.member_cap(deck, 20) == 20
    monkeypatch.setattr(diagnose_command, "MEMBER_GRIDS", len(grids) - 1)
    assert diagnose_command.member_cap(deck, None) == diagnose_command.MAX_MEMBER_CANDIDATES
    assert diagnose_command.member_cap(deck, 500) == 500


def test_without_a_declared_fit_the_cap_keeps_the_grids_nearest_the_sensors():
    """No declared joints, so no residual to follow: the cap keeps the points nearest the
    measured grids (every measured grid weighs 1; a measured grid itself scores the most)."""
    from blackbox.diagnosis.effects import CandidateContext
    from blackbox.identification import Observations
    from blackbox.study import load_study

    study = load_study(FIXTURES.parent / "car", need_measurements=True)
    obs = Observations.from_measurements(study.measurements, study.loads.cases)
    ctx = CandidateContext(study.deck, (), {}, obs, tuple(study.loads.cases), None, 5)
    measured = {g for g, _ in obs.dofs}
    points = {g.id: g.xyz for g in study.deck.grids.values()}
    chosen = ctx.nearest_residual(points, 5)
    assert len(chosen) == 5 and set(chosen) <= measured
    assert chosen == [g for g in points if g in measured][:5]          # ties keep the points' order
    far = max(points, key=lambda g: min(np.linalg.norm(np.subtract(points[g], points[m])) for m in measured))
    assert far not in ctx.nearest_residual(points, len(points) - 1)


def test_refits_go_to_the_workers_only_when_that_pays():
    """``search.refits_pay``: six refits estimated from a 1 s declared fit (18 s serially) are
    sent to 2 workers even with a 50 MB base (9 s + 0.5 s + 0.2 s); from a 10 ms fit (0.18 s)
    they stay here whatever the base (the round's 0.2 s overhead alone is more than the saving);
    one worker, or one refit, never."""
    from blackbox.diagnosis.search import refits_pay

    assert refits_pay(6, 1.0, 50.0, 2) and refits_pay(6, 1.0, 50.0, 8)
    assert not refits_pay(6, 0.01, 0.0, 2) and not refits_pay(6, 0.01, 50.0, 8)
    assert not refits_pay(6, 1.0, 50.0, 1) and not refits_pay(1, 1.0, 0.0, 2)
    # the base's trip counts: 0.1 s fits (1.8 s serially, 0.9 s + 0.2 s mapped) pay with a small
    # base, not with a 100 MB one (+1 s)
    assert refits_pay(6, 0.1, 1.0, 2) and not refits_pay(6, 0.1, 100.0, 2)


def test_declared_fit_keeps_rigid_pairs(tmp_path):
    """With ``rigid_pairs`` the declared fit inside diagnose is identify's: the cube with branches
    7 and 71 of joint J7 declared rigid (its data were simulated with every pair flexible, so the
    tie costs chi2), the same hold-out cases in both. The split deck conditioned on rigid cuts
    with the rigid-pair penalty predicts identify's fit to 1e-6 sigma at identify's estimate
    (penalty 1e6 x the joint's stiffness: ~1e-10 of cond(A) ~ 1e10 rounding, with margin), and
    the refit lands at identify's chi2 to 1e-6 (identify stops at ftol 1e-10 of chi2, the refit
    at 1e-13). Without the penalty the same parameters give a chi2 that differs by far more."""
    study = tmp_path / "cube"
    shutil.copytree(Path(__file__).resolve().parents[1] / "fixtures" / "cube", study)
    toml = (study / "study.toml").read_text()
    toml = toml.replace('model = "simple"\n', 'model = "simple"\nrigid_pairs = [[7, 71]]\n', 1)
    toml = toml.replace("holdout_cases = []", 'holdout_cases = ["L5", "L10"]')
    (study / "study.toml").write_text(toml)
    ident = identify_command.run(study, profile=False).result
    res = diagnose_command.run(study, max_steps=0, plots=False)
    pr, declared = res.prepared, res.diagnosis.declared
    assert pr.joints[0].rigid_pairs == ((1, 2),) and pr.joints[0].n_params == 6
    assert res.diagnosis.nesting_error < 1e-6
    assert declared.chi2 == pytest.approx(ident.chi2, rel=1e-6)
    assert declared.chi2 <= ident.chi2 * (1 + 1e-9)            # the refit never ends higher
    assert res.document["before"]["reduced_chi2"] == pytest.approx(ident.reduced_chi2, rel=1e-6)
    np.testing.assert_allclose(pr.ident.k, ident.k, rtol=1e-9)
    loose, om = _model(pr, dg.ModelSpec(tuple(pr.joints)), K_deck=pr.declared.deck_matrix())
    chi2_loose = float(np.sum(((om.y - loose.predict(ident.k, om)) / om.sigma) ** 2))
    assert abs(chi2_loose - ident.chi2) > 0.1 * ident.chi2


# --------------------------------------------------------------------------------------------
# properties of the method
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cube_prepared(tmp_path_factory):
    return diagnose_command.prepare(FIXTURES / "support_flexibility", tmp_path_factory.mktemp("prep"))


def test_element_stiffness_is_the_frame_element(cube_prepared):
    """``K_e`` from the element deck's one run equals the Euler-Bernoulli frame element
    (``blackbox.joints.frame_element_stiffness``, the textbook 12 x 12 matrix the reference solver
    also assembles) to rounding: the flexibility inversion loses ~cond(F_bb) ~ 1e6 x eps."""
    pr = cube_prepared
    deck = pr.deck
    for eid, b in deck.cbars.items():
        p = deck.pbars[b.pid]
        m = deck.mat1s[p.mid]
        K = frame_element_stiffness(deck.grids[b.ga].xyz, deck.grids[b.gb].xyz, m.e, m.g, p.a, p.i2, p.i1,
                                    p.j, b.x)
        np.testing.assert_allclose(pr.K_e[eid], K, rtol=0, atol=1e-9 * np.abs(K).max())
    assert pr.element_asymmetry < 1e-12            # Maxwell-Betti in the element run


def _element_flexibility_per_dof(adapter, members):
    """The element run the way it was first written: one unit load per member-end DOF (``6 m``
    cases), every member's ``F_bb`` the diagonal block of the dense ``6 m x 6 m`` answer."""
    dofs = [(gb, c) for _, gb in members.values() for c in range(1, 7)]
    V = adapter.solve(LoadMatrix.unit(dofs), dofs).values
    blocks = {eid: V[6 * i:6 * i + 6, 6 * i:6 * i + 6] for i, eid in enumerate(members)}
    off = V.copy()
    for i in range(len(members)):
        off[6 * i:6 * i + 6, 6 * i:6 * i + 6] = 0.0
    return blocks, off


@pytest.mark.parametrize("adapter_name", ["reference", pytest.param("mystran", marks=MYSTRAN_MARKS)])
def test_element_run_six_cases_equals_one_unit_load_per_dof(adapter_name, tmp_path):
    """The element deck gives every member its own two grids and clamps end a, and nothing else
    couples the members, so loading component c at end b of EVERY member at once (6 cases,
    ``element_flexibility``) gives each member the flexibility of its own unit loads (6 m cases).
    Checked on the car fixture's deck (115 members): the per-DOF answer has exactly zero
    off-diagonal blocks (the premise), and the blocks agree (bit for bit when written; allowed:)
    the reference solver to 1e-12 of the block's largest entry (one sparse factorization either
    way, only the summation order of the substitutions could differ), MYSTRAN to 1e-6 (its 7
    printed digits: half a unit in the 7th digit is 5e-7 relative); ``K_e`` after the inversion
    to cond(F_bb) ~ 1e6 times that."""
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study

    study = load_study(FIXTURES.parent / "car")
    edeck, members, tips = dg.element_deck(study.deck)
    assert not tips                                   # no pin flags in the car
    assert len({g for ends in members.values() for g in ends}) == 2 * len(members)     # own grids
    assert not edeck.springs and not edeck.rbe2s and not edeck.rbe3s
    path = tmp_path / "elements.bdf"
    path.write_text(write_deck(edeck, "large"))
    adapter = make_adapter_for(study, adapter_name, deck=path, cache=False)
    per_dof, off = _element_flexibility_per_dof(adapter, members)
    assert np.all(off == 0.0)
    log = []
    flex = dg.element_flexibility(adapter, members, log)
    assert [r.right_hand_sides for r in log] == [6]
    rtol = 1e-12 if adapter_name == "reference" else 1e-6
    for eid, F in per_dof.items():
        np.testing.assert_allclose(flex[eid], F, rtol=0, atol=rtol * np.abs(F).max(), err_msg=f"member {eid}")
    K, asym = dg.element_stiffness(adapter, members, [])
    assert asym < (1e-12 if adapter_name == "reference" else 1e-5)
    xyz = adapter.grid_xyz()
    for eid, (ga, gb) in members.items():
        F = 0.5 * (per_dof[eid] + per_dof[eid].T)
        gamma = np.eye(6)
        r = np.subtract(xyz[gb], xyz[ga])
        gamma[:3, 3:] = -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
        T = np.hstack([-gamma, np.eye(6)])
        K_old = T.T @ np.linalg.inv(F) @ T
        np.testing.assert_allclose(K[eid], 0.5 * (K_old + K_old.T), rtol=0,
                                   atol=1e6 * rtol * np.abs(K_old).max(), err_msg=f"member {eid}")


def _model(pr, spec, om_obs=None, K_deck="declared"):
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    obs = om_obs or pr.fit_obs
    model = dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck if K_deck == "declared" else K_deck, o)
    return model, dg.ObsMap.of(obs, {d: i for i, d in enumerate(o)})


def test_rigid_state_is_the_declared_model(cube_prepared):
    """The split deck (48 cut pairs on K0 springs) conditioned on rigid cuts predicts what the
    study's own deck predicts, at the declared estimate: to 1e-9 sigma (rounding, cond(S) ~ 1e5)."""
    pr = cube_prepared
    model, om = _model(pr, dg.ModelSpec(tuple(pr.joints)))
    f = model.predict(pr.ident.k, om)
    assert np.max(np.abs(f - pr.ident.predicted) / om.sigma) < 1e-9


def test_compliance_form_reproduces_the_truth_deck(cube_prepared):
    """Support springs ``k`` as compliances ``theta = k_ref / k`` on the split deck (K0 springs
    subtracted in the compliance form) give the truth deck's displacements (the reference solver
    on ``truth/truth.bdf``, no noise) to 1e-9 of the largest."""
    pr = cube_prepared
    planted = _planted("support_flexibility")[0]["springs"]
    eff = next(e for e in pr.candidates if isinstance(e, SupportFlexibility) and e.where == (1,))
    eff = eff.richer(np.zeros(eff.n_params))[-1][0]             # "per-axis": one spring per component
    assert eff.variant == "per-axis"
    joint = pr.joints[0]
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(eff, joint.initial_params(1.0e4))
    x[joint.n_params:] = [eff.k_ref[q] / planted[n] for q, n in enumerate(eff.names)]
    model, om = _model(pr, spec)
    truth = ReferenceAdapter(FIXTURES / "support_flexibility" / "truth" / "truth.bdf")
    U = truth.solve(pr.study.loads, model.o_dofs).values
    f_true = om.pick(U)
    f = model.predict(x, om)
    assert np.max(np.abs(f - f_true)) < 1e-9 * np.max(np.abs(f_true))


def test_jacobians_match_central_differences(cube_prepared):
    """Every parameter kind at once, away from the nested point: joint (complex model after
    coupling), undeclared joint (per-branch), support, member (EA, EI1, EI2, GJ), load scale,
    sensor gain. Central differences
    with h = 1e-6 of the parameter's scale have truncation error ~1e-10 relative and rounding
    ~1e-16 / 1e-6 = 1e-10 of the column: 1e-5 leaves margin."""
    pr = cube_prepared
    pick = {k: next(e for e in pr.candidates if isinstance(e, k))
            for k in (UndeclaredJoint, SupportFlexibility, MemberStiffness, LoadScale, SensorGain)}
    mem = [e for e in pr.candidates if isinstance(e, MemberStiffness)][3]
    pr.base.ensure_columns(mem.dofs, "test")
    # the richest variants: per-branch springs of the undeclared joint, the member's EA, EI1,
    # EI2, GJ factors (the simplest ones are linear combinations of these columns)
    pick[UndeclaredJoint] = pick[UndeclaredJoint].richer(np.zeros(1))[-1][0]
    mem = mem.richer(np.ones(1))[0][0]
    assert (pick[UndeclaredJoint].variant, mem.variant) == ("per-branch", "sections")
    spec, x = dg.ModelSpec(tuple(pr.joints)), pr.joints[0].initial_params(2.0e4)
    for e in list(pick.values())[:2] + [mem] + list(pick.values())[3:]:
        spec, x = spec.add(e, x)
    spec, x = spec.add(JointCoupling.of("J7"), x)
    rng = np.random.default_rng(0)
    pj = spec.joint_params
    x[pj:] = [0.3 + rng.random() if isinstance(e, Connection) else 0.8 + 0.4 * rng.random()
              for e in spec.effects for _ in e.names]
    model, om = _model(pr, spec)
    J = model.jacobian(x, om)
    scale = np.where(np.arange(len(x)) < pj, np.max(np.abs(x[:pj])), np.maximum(np.abs(x), 1e-3))
    for i in range(len(x)):
        h = 1e-6 * scale[i]
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fp, fm = model.predict(xp, om), model.predict(xm, om)
        fd = (fp - fm) / (2 * h)
        # plus the difference quotient's own rounding, 1e3 eps |f| / h (the prediction is exact to
        # ~cond eps, cond of the augmented solve ~1e3; its error grows as 1 / h below h = 1e-5 x
        # scale, so it is rounding): a per-branch spring that hardly moves the structure has a
        # column of 1e-8, near that level
        rounding = 1e3 * np.finfo(float).eps * np.max(np.abs(fp)) / h
        assert np.max(np.abs(J[:, i] - fd)) <= 1e-5 * np.max(np.abs(fd)) + rounding, spec.names[i]


def test_score_approximates_the_likelihood_ratio(diagnosed):
    """For the refitted candidates of the no-effect folder the score statistic and the likelihood
    ratio agree (both ~chi2(df) under the null; locally equal): within 25 % + 0.5."""
    d = diagnosed("load_scale")
    for c in d["steps"][-1]["candidates"]:
        if c.get("refit") and c["df"] == 1:
            assert abs(c["score"] - c["lr"]) < 0.25 * c["lr"] + 0.5, c


# --------------------------------------------------------------------------------------------
# studies it has never seen: other structures, built here
# --------------------------------------------------------------------------------------------
NOISE_TOML = "[noise]\nrelative = 0.03\nfloor = 0.05\n"


def _truth_study(tmp: Path, study_b, truth_b, loads, name, joint_k: float, measured: list[int], seed: int) -> Path:
    """``study_b`` written as the study (its joints declared simple), ``truth_b`` plus the joints'
    springs at ``joint_k`` as the truth deck, simulated with the fixtures' noise."""
    src = write_study(tmp / f"{name}_src", study_b, loads, name, initial=joint_k / 10)
    tb = copy.deepcopy(truth_b)
    for jname, grids in study_b.joints:
        j = make_joint(jname, grids, "simple")
        for s in spring_network(j, j.initial_params(joint_k)):
            tb.springs.append((s.a[0], s.a[1], *(s.b or (0, 0)), s.k))
    (tmp / "truth.bdf").write_text(tb.bdf("truth"))
    (tmp / "truth.toml").write_text(f'seed = {seed}\ndeck = "truth.bdf"\n{NOISE_TOML}\n[measure]\n'
                                    f"joint = true\naway_grids = {measured}\n")
    out = tmp / name
    write_output(out, "simulate", simulate_command.run(src, tmp / "truth.toml").write)
    return out


def _local(b, bar_ids, grid):
    """Diagonal (6) of the members' stiffness at ``grid`` (sum over ``bar_ids``)."""
    out = np.zeros(6)
    for eid in bar_ids:
        _, ga, gb, v = b.bars[eid - 1]
        K = frame_element_stiffness(b.grids[ga], b.grids[gb], b.E, b.G, b.A, b.I2, b.I1, b.J, v)
        out += np.diag(K)[:6] if ga == grid else np.diag(K)[6:]
    return out


def _elastic_base(b):
    """``b`` with its base grid 201 no longer clamped but on grounded springs of 2 x the legs' own
    stiffness there, every component."""
    truth = copy.deepcopy(b)
    del truth.spcs[201]
    legs = [e for e, ga, gb, _ in b.bars if 201 in (ga, gb)]
    local = _local(b, legs, 201)
    for c in range(6):
        truth.springs.append((201, c + 1, 0, 0, 2.0 * local[c]))
    return truth


def _scale_cases(tmp: Path, study: Path, cases: set[str], scale: float) -> None:
    """The measurements of ``cases`` in ``study`` replaced by a second simulation of
    ``_truth_study``'s source and truth with ``force_scale = scale`` (same seed, so the same noise
    draws): those cases were run with loads ``scale`` x nominal."""
    toml = (tmp / "truth.toml").read_text()
    (tmp / "truth.toml").write_text(toml.replace('deck = "truth.bdf"', f'deck = "truth.bdf"\nforce_scale = {scale!r}'))
    scaled = tmp / "scaled"
    write_output(scaled, "simulate", simulate_command.run(tmp / f"{study.name}_src", tmp / "truth.toml").write)
    rows = (study / "measurements.csv").read_text().splitlines()
    rows_scaled = (scaled / "measurements.csv").read_text().splitlines()
    merged = [rows[0]] + [s if r.split(",")[0] in cases else r for r, s in zip(rows[1:], rows_scaled[1:])]
    (study / "measurements.csv").write_text("\n".join(merged) + "\n")


def test_generated_star_frame_support_flexibility(tmp_path):
    """A 4-branch star frame (``star_joint_frame(4)``): base grid 201, clamped in the study, is
    elastic in the truth (2 x the leg's own stiffness in every component)."""
    b = star_joint_frame(4, seed=0)
    truth = _elastic_base(b)
    loads = random_loads(b, 15, seed=3)
    study = _truth_study(tmp_path, b, truth, loads, "star", 1.0e5, [100, 101, 102, 103], seed=5)
    d = diagnose_command.run(study, plots=False).document
    assert d["added"] and d["added"][0]["effect"] == "support_flexibility" and d["added"][0]["where"] == [201]
    assert d["after"]["in_band"] and not d["before"]["in_band"]
    # no hold-out declared: every case is fitted and the additions were checked by 5-fold
    # cross-validation over the load cases, whose prediction error the effect lowers
    assert d["validation"]["method"] == "kfold" and d["validation"]["k"] == 5
    assert d["validation"]["cv_chi2_after"] < d["validation"]["cv_chi2_before"]


@pytest.mark.slow
def test_generated_tube_body_undeclared_joint(tmp_path):
    """A car-body tube (``tube_body(7, 8)``, 56 nodes, a 5-branch roof joint
    declared at node 27) with an undeclared flexible joint at node 42 (6 members; springs at
    2e5 N m/rad, about half the members' 4EI/L), every other node measured."""
    b = tube_body(7, 8)
    node = 42
    truth = copy.deepcopy(b)
    bars = [e for e, ga, gb, _ in truth.bars if node in (ga, gb)]
    grids = truth.flexible_joint("U", node, bars, 9000)
    truth.joints.pop()
    j = make_joint("U", grids, "simple")
    for s in spring_network(j, j.initial_params(2.0e5)):
        truth.springs.append((s.a[0], s.a[1], *(s.b or (0, 0)), s.k))
    loads = random_loads(b, 20, seed=4)
    measured = [g for g in sorted(b.grids) if g % 2 == 1 and g <= 7 * 8 and g not in b.spcs]
    study = _truth_study(tmp_path, b, truth, loads, "tube", 1.0e6, measured, seed=6)
    d = diagnose_command.run(study, plots=False).document
    assert d["added"] and d["added"][0]["effect"] == "undeclared_joint" and d["added"][0]["where"] == [node]
    assert d["after"]["in_band"]
    # no hold-out declared: every case is fitted and the additions were checked by 5-fold
    # cross-validation over the load cases, whose prediction error the effect lowers
    assert d["validation"]["method"] == "kfold" and d["validation"]["k"] == 5
    assert d["validation"]["cv_chi2_after"] < d["validation"]["cv_chi2_before"]


def test_generated_support_and_a_scaled_test_day(tmp_path):
    """The issue's second blind failure: a flexible support plus loads 6 % high on 7 of 12 cases
    (one test day, no ``group`` column, no hold-out: K-fold). The 4-branch star frame's base grid
    201 rests on springs of 2 x the legs' stiffness (as in the test above); cases L1-L7 were
    simulated with ``force_scale = 1.06``. Both effects are added (the support at 201, the scale
    on exactly L1-L7 found from the data, 1.06 within 4 std) and the fit is back in its band."""
    b = star_joint_frame(4, seed=0)
    truth = _elastic_base(b)
    loads = random_loads(b, 12, seed=3)
    study = _truth_study(tmp_path, b, truth, loads, "star", 1.0e5, [100, 101, 102, 103], seed=5)
    day = {f"L{i}" for i in range(1, 8)}
    _scale_cases(tmp_path, study, day, 1.06)
    d = diagnose_command.run(study, plots=False).document
    assert d["validation"]["method"] == "kfold"
    found = {(a["effect"], tuple(sorted(map(str, a["where"])))): a for a in d["added"]}
    assert ("support_flexibility", ("201",)) in found, d["added"]
    scale = found.get(("load_scale", tuple(sorted(day))))
    assert scale is not None, d["added"]
    (p,) = scale["parameters"]
    assert abs(p["value"] - 1.06) < 4 * p["std"], p
    assert len(d["added"]) == 2 and d["verdict"] == "explained"


def test_declared_fit_is_not_left_in_a_trap_of_the_identification(tmp_path):
    """Study 401 of the blind benchmark's seed 1 is clean (a storey frame, three joints of 2-3
    branches, nothing planted: the truth is the declared model). The identification ends with
    springs thrown to ~1 N m/rad and 3.6e17 at reduced chi2 1.53 (rank 2 of 21); left there, the
    search explained that misfit with a joint softening, a false alarm. The declared fit's second
    start (each joint's springs equal at their median) reaches the noise band, and nothing is
    added (reference: the generator's record of what it planted, nothing)."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from benchmarks.blind.generate import generate_study

    st = generate_study(401, 1, tmp_path)
    assert st.planted["effects"] == []
    res = diagnose_command.run(st.folder, plots=False)
    doc = json.loads(json.dumps(res.document, default=float))
    assert doc["verdict"] == "adequate" and doc["added"] == []
    lo, hi = doc["before"]["band_99"]
    assert lo <= doc["before"]["reduced_chi2"] <= hi
