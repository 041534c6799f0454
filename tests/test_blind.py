"""The blind benchmark (``benchmarks/blind``): a small seeded subset.

The generator must write valid studies whose planted effect is in the truth and not in what the
diagnosis sees, sized within 0.5-5 times its threshold; the scoring must read the diagnosis's
document correctly. The full benchmark (200 studies, ``docs/blind.md``) is run by hand.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.blind import generate as gen                      # noqa: E402
from benchmarks.blind.run import is_match, markdown, run_one, score, size_bin, summarize  # noqa: E402
from blackbox.study import load_study                            # noqa: E402
from solver_adapters.bdf import read_deck                         # noqa: E402

SEED = 11
# (index, kind, shape): six studies, each kind's evidence checked in the truth deck or the values
SUBSET = [(0, "support_flexibility", None), (1, "member_stiffness", None), (2, "undeclared_joint", None),
          (3, "joint_translation", None), (4, "sensor_gain", None), (5, "none", None),
          (6, "joint_coupling", None), (7, "sensor_offset", None)]


@pytest.fixture(scope="module")
def studies(tmp_path_factory):
    out = tmp_path_factory.mktemp("blind")
    return [gen.generate_study(i, SEED, out, kind=k, shape=s) for i, k, s in SUBSET]


def _constrained(deck) -> set[int]:
    return {g for s in deck.spc1s for g in s.grids}


def test_studies_are_valid_and_blind(studies):
    for st in studies:
        names = sorted(p.name for p in st.folder.iterdir())
        assert names == ["loads.csv", "measurements.csv", "model.bdf", "study.toml"], names
        assert not st.hidden.is_relative_to(st.folder) and (st.hidden / "planted.json").is_file()
        study = load_study(st.folder)                       # every check of the study reader passes
        p = st.planted
        assert [j.name for j in study.config.joints] == [j["name"] for j in p["joints"]]
        assert 1 <= len(p["joints"]) <= 2
        for j in study.config.joints:
            assert 2 <= len(j.grids) <= 5
        assert 8 <= p["n_cases"] <= 20 and set(p["holdout_cases"]) <= set(study.loads.cases)
        assert study.config.identification.holdout_cases == p["holdout_cases"]
        assert 0.01 <= p["noise"]["relative"] <= 0.05
        assert p["n_measurements"] == len(study.measurements.values)


def test_threshold_multiples_in_range(studies):
    for st in studies:
        p = st.planted
        if p["kind"] == "none":
            assert "multiple" not in p
            continue
        assert 0.5 * 0.99 <= p["multiple"] <= 5.0 * 1.01
        assert p["multiple"] == pytest.approx(p["multiple_drawn"], rel=0.02)
        # the threshold: 50 % power of the chi2 test of the effect's parameters at 0.01 / M
        crit = stats.chi2.isf(gen.ALPHA / p["n_candidates"], p["params"])
        assert stats.ncx2.sf(crit, p["params"], p["threshold_noncentrality"]) == pytest.approx(0.5, abs=1e-6)
        assert p["noncentrality"] == pytest.approx(p["multiple"] ** 2 * p["threshold_noncentrality"])
        assert 0 < p["size"] <= gen.SIZE_MAX[p["kind"]]


def test_planted_effect_in_truth_not_in_declared(studies):
    for st in studies:
        p = st.planted
        declared = read_deck(st.folder / "model.bdf")
        truth = read_deck(st.hidden / "truth" / "truth.bdf")
        kind, where = p["kind"], p.get("where")
        joint_springs = {(s.g1, s.g2) for s in truth.springs.values()}
        assert not declared.springs and joint_springs        # the joints' truth: springs only there
        if kind == "support_flexibility":
            assert where in _constrained(declared) and where not in _constrained(truth)
            assert any(s.g1 == where and s.g2 == 0 for s in truth.springs.values())
        elif kind == "member_stiffness":
            e_decl = declared.mat1s[declared.pbars[declared.cbars[where].pid].mid].e
            e_true = truth.mat1s[truth.pbars[truth.cbars[where].pid].mid].e
            assert e_true / e_decl == pytest.approx(p["factor"]) and p["factor"] != pytest.approx(1.0)
        elif kind == "undeclared_joint":
            assert where not in {r.gn for r in declared.rbe2s.values()}
            assert where in {r.gn for r in truth.rbe2s.values()}
            assert len(truth.grids) > len(declared.grids)
        elif kind == "joint_translation":
            grids = next(j["grids"] for j in p["joints"] if j["name"] == where)
            tied = lambda d: {g for r in d.rbe2s.values() if r.gn == grids[0] for g in r.gm}  # noqa: E731
            assert set(grids[1:]) <= tied(declared) and not set(grids[1:]) & tied(truth)
        elif kind == "joint_coupling":                  # springs across the axes: a coupled K_C
            grids = next(j["grids"] for j in p["joints"] if j["name"] == where)
            assert any(s.g1 in grids and s.g2 in grids and s.c1 != s.c2 for s in truth.springs.values())
            assert p["coupling"] == p["size"] < 1.0
        else:                                           # an effect on the values: the decks agree
            def cards(d):                                # the cards without their source lines
                return ({e: (b.pid, b.ga, b.gb) for e, b in d.cbars.items()},
                        sorted((s.components, s.grids) for s in d.spc1s),
                        {e: (r.gn, r.cm, r.gm) for e, r in d.rbe2s.items()}, d.grids.keys())
            assert cards(truth) == cards(declared)


def _values_against_truth(st):
    """``{(grid, component): (true, measured, sigma) arrays}`` of a study."""
    from blackbox.commands.simulate import run as simulate

    truth = simulate(st.folder, st.hidden / "truth" / "truth.toml", adapter="reference")
    true = {(c, g, comp): v for c, g, comp, v, _, _ in truth.rows}
    meas = load_study(st.folder).measurements
    rows: dict = {}
    for c, (g, comp), v, s in zip(meas.cases, meas.dofs, meas.values, meas.sigma):
        rows.setdefault((g, comp), []).append((true[(c, g, comp)], v, s))
    return {k: tuple(np.array(x) for x in zip(*r)) for k, r in rows.items()}


def test_sensor_gain_in_the_values(studies):
    """The gain grid's values are the truth times the planted gain (weighted least squares
    within 4 standard errors); every other grid reads gain 1."""
    st = next(s for s in studies if s.planted["kind"] == "sensor_gain")
    p = st.planted
    by_grid: dict = {}
    for (g, _), (t, v, s) in _values_against_truth(st).items():
        by_grid.setdefault(g, []).append((t, v, s))
    for g, parts in by_grid.items():
        t, v, s = (np.concatenate(x) for x in zip(*parts))
        w = t * t / (s * s)
        est, se = (t * v / (s * s)).sum() / w.sum(), 1.0 / math.sqrt(w.sum())
        expect = p["factor"] if g == p["where"] else 1.0
        assert abs(est - expect) < 4 * se, (g, est, expect, se)


def test_sensor_offset_in_the_values(studies):
    """The offset channel reads the truth plus the planted offset in every case (within 4
    standard errors of the weighted mean); no other channel is offset."""
    st = next(s for s in studies if s.planted["kind"] == "sensor_offset")
    p = st.planted
    assert p["offset"] != 0.0
    for ch, (t, v, s) in _values_against_truth(st).items():
        w = 1.0 / (s * s)
        est, se = ((v - t) * w).sum() / w.sum(), 1.0 / math.sqrt(w.sum())
        expect = p["offset"] if ch == (p["where"], p["component"]) else 0.0
        assert abs(est - expect) < 4 * se, (ch, est, expect, se)


def test_score_matching():
    planted = {"kind": "load_scale", "where": ["L2"], "multiple": 2.5}
    doc = {"added": [{"effect": "load_scale", "where": ["L2"],
                      "parameters": [{"name": "s_L2", "value": 1.1, "std": 0.01}]}],
           "before": {"reduced_chi2": 3.0, "in_band": False, "holdout_rms": 2.0},
           "after": {"reduced_chi2": 1.0, "in_band": True, "holdout_rms": 1.0}}
    s = score(planted, doc)
    assert s["detected"] and s["correct"] and s["first_correct"] and s["extra"] == 0 and s["bin"] == "2-5x"
    assert s["params_with_std"] and s["in_band_after"] and not s["false_alarm"]
    assert not is_match(planted, {"effect": "load_scale", "where": ["L3"]})
    assert not is_match(planted, {"effect": "sensor_gain", "where": ["L2"]})
    assert is_match({"kind": "member_stiffness", "where": 17}, {"effect": "member_stiffness", "where": [17]})
    assert is_match({"kind": "load_scale", "where": ["L1", "L2"]}, {"effect": "load_scale", "where": ["L2", "L1"]})
    offset = {"kind": "sensor_offset", "where": 12, "component": 4}
    assert is_match(offset, {"effect": "sensor_offset", "where": [12], "parameters": [{"name": "o_12_4"}]})
    assert not is_match(offset, {"effect": "sensor_offset", "where": [12], "parameters": [{"name": "o_12_5"}]})
    none = score({"kind": "none"}, {**doc, "added": doc["added"] + [{"effect": "sensor_gain", "where": [3],
                                                                    "parameters": [{"value": 1.0, "std": None}]}]})
    assert none["false_alarm"] and none["extra"] == 2 and not none["correct"] and not none["params_with_std"]
    assert [size_bin(m) for m in (0.5, 0.99, 1.0, 1.99, 2.0, 5.0)] == ["0.5-1x"] * 2 + ["1-2x"] * 2 + ["2-5x"] * 2


def test_scoring_of_real_diagnoses(tmp_path):
    """Two studies through ``blackbox diagnose``: a member 4x its threshold is found at its place,
    a study without an effect gets nothing; the summary and its table read the scores."""
    recs = []
    for i, kind, mult in [(0, "member_stiffness", 4.0), (1, "none", None)]:
        st = gen.generate_study(i, SEED, tmp_path, kind=kind, shape="star", multiple=mult)
        from blackbox.commands.diagnose import run as diagnose
        doc = diagnose(st.folder, adapter="reference", plots=False).document
        recs.append({"study": st.folder.name, "index": i, **score(st.planted, doc), "diagnose_s": 0.0})
        assert recs[-1]["detected"] == bool(doc["added"])
        assert recs[-1]["after_reduced_chi2"] == doc["after"]["reduced_chi2"]
    assert recs[0]["correct"] and recs[0]["bin"] == "2-5x" and recs[0]["params_with_std"]
    assert not recs[1]["false_alarm"]
    summary = summarize(recs)
    assert summary["goals"]["correct_at_2x"]["k"] == 1 and summary["goals"]["false_alarm"]["k"] == 0
    text = markdown(summary, {"n": 2, "seed": SEED})
    assert "| member_stiffness | 1 |" in text and "false alarms 0/1" in text


def test_run_one_records_and_cleans_up(tmp_path):
    rec = run_one(3, SEED, tmp_path)
    assert rec["study"] == "s0003" and "diagnose_s" in rec and not rec.get("error")
    assert not (tmp_path / "studies" / "s0003").exists() and (tmp_path / "hidden" / "s0003" / "planted.json").is_file()


def test_explanations_the_data_hardly_tell_apart_are_named(tmp_path):
    """Blind study 118 of seed 1: a flexible support at grid 1, whose data a factor on member 1
    (ending at that support) explains almost as well. Whichever the diagnosis adds, the other is
    named beside it as an alternative (evidence within 10: not a "very strong" difference)."""
    from blackbox.commands.diagnose import run as diagnose

    st = gen.generate_study(118, 1, tmp_path)
    assert st.planted["kind"] == "support_flexibility" and st.planted["where"] == 1
    d = diagnose(st.folder, adapter="reference", plots=False).document
    first = d["added"][0]
    pair = {("support_flexibility", (1,)), ("member_stiffness", (1,))}
    assert (first["effect"], tuple(first["where"])) in pair
    other = pair - {(first["effect"], tuple(first["where"]))}
    named = {(a["effect"], tuple(a["where"])) for a in first["alternatives"]}
    assert other <= named, first["alternatives"]
    assert all(0 <= a["evidence_gap"] < 10 for a in first["alternatives"])
