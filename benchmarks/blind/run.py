"""The blind benchmark of ``blackbox diagnose``: generate N random studies, diagnose each, score.

    python -m benchmarks.blind.run --n 600 --seed 1 --out out/blind --workers 2 --docs

Study ``i`` (seeded by ``--seed`` and ``i``) is written by :mod:`benchmarks.blind.generate`: the
study folder and, outside it, ``planted.json``. Its family is drawn first, from its own random
stream; ``--n`` counts the studies of the families tuned on, and the held-out family's
(``frames.HELD_OUT``: ``jacket``) are skipped unless ``--include-held-out`` adds those among them,
so the tuned studies and their draws are the same in every run. :func:`blackbox.commands.diagnose.run` (the study's own adapter,
in-process, default settings) diagnoses the folder, and only its result document is read
(``added``: kind, where, details, parameters; ``before``/``after``; ``verdict``). The score of
each study is appended to ``OUT/results.jsonl`` as soon as it is known, so an interrupted run
continues where it stopped. ``OUT/blind.json`` and ``OUT/blind.md`` hold the summary; ``--docs``
writes them to ``docs/blind.json`` and ``docs/blind.md`` as well.

Scoring of one study (:func:`score`):

* **correct**: every planted effect (one, or both of two) is among the added effects, of its
  kind at its place (:func:`is_match`); a study without an effect is correct when nothing is
  added, else it is a **false alarm**;
* **first correct**: the first effect added is a planted one;
* **extra**: added effects that match no planted one; **over the limit**: more effects added
  than planted plus one;
* **reported as data**: a matched defect of the test data (``outlier``, ``sign_flip``,
  ``channel_swap``, ``misplaced_sensor``) whose entry says it is one (:func:`reported_as_data`);
* a diagnosis that fails (an exception, e.g. a deck it wrote and could not read) is an
  **error**: it counts as not correct (and, for a study without an effect, not clean);
* chi2 before and after, hold-out RMS before and after, whether every added effect's parameters
  carry a finite standard error, the verdict.

The size bins are the threshold multiples' (0.5-1, 1-2, 2-5, 5-20x, and beyond 20x for discrete
defects no place of which is within 20x); a two-effect study is binned by its smaller multiple.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import time
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.blind.frames import FAMILIES, HELD_OUT                       # noqa: E402
from benchmarks.blind.generate import (ALL_KINDS, BIN_NAMES, OVER, generate_study,  # noqa: E402
                                       size_bin, study_family)
from blackbox.parallel import SerialExecutor, make_executor                # noqa: E402

ALL_BINS = BIN_NAMES + (OVER,)
AT_2X = ("2-5x", "5-20x", OVER)
SENSOR_DEFECTS = ("outlier", "sign_flip", "channel_swap", "misplaced_sensor")
GOALS = {"correct_at_2x": 0.97, "false_alarm": 0.03, "first_correct": 0.95, "over_limit": 0}
MAX_LISTED = 60                 # rows of the misses and errors tables in the report (all in the JSON)


# --------------------------------------------------------------------------------------------
# matching
# --------------------------------------------------------------------------------------------
def _norm_where(where) -> tuple[str, ...]:
    if where is None:
        return ()
    if isinstance(where, (list, tuple)):
        return tuple(sorted(str(w) for w in where))
    return (str(where),)


_NOT_DETAILS = {"effect", "where", "parameters", "alternatives", "delta_bic", "p_value", "details"}


def details(effect: dict) -> dict:
    """An added effect's details: its ``details`` table and the keys beside ``where`` (the
    document flattens them: a sensor offset's ``component``)."""
    out = {k: v for k, v in effect.items() if k not in _NOT_DETAILS}
    out.update(effect.get("details") or {})
    return out


def _component(effect: dict):
    """The component an added channel effect names: in its details, else from a parameter name
    ``o_G_C`` (a sensor offset's)."""
    c = details(effect).get("component")
    if c is None:
        for p in effect.get("parameters") or ():
            name = str(p.get("name", ""))
            if name.startswith("o_") and name.count("_") == 2:
                c = name.rsplit("_", 1)[1]
    return None if c is None else str(c)


def is_match(planted: dict, effect: dict, holdout=()) -> bool:
    """The added ``effect`` (an entry of the document's ``added``) is the planted effect: same
    kind at the same place. The place per kind: the joint (``joint_coupling``,
    ``joint_translation``, ``joint_gap``), the grid (``undeclared_joint``,
    ``support_flexibility``, ``sensor_gain``), the channel (``sensor_offset``, ``sign_flip``:
    grid and component), the element (``member_stiffness``), the scaled cases that were fitted
    (``load_scale``: a group found from the data holds only fitted cases), the reading
    (``outlier``: grid, case and component), the two channels (``channel_swap``: grids and
    component), the grid and the grid it was read at (``misplaced_sensor``; the components too
    when the effect names them)."""
    kind = planted["kind"]
    if effect.get("effect") != kind:
        return False
    if kind == "load_scale":
        hold = {str(c) for c in holdout}
        return ({str(c) for c in effect.get("where") or ()} - hold) == ({str(c) for c in planted["where"]} - hold)
    if _norm_where(effect.get("where")) != _norm_where(planted.get("where")):
        return False
    det = details(effect)
    if kind in ("sensor_offset", "sign_flip", "channel_swap", "outlier"):
        if _component(effect) != str(planted["component"]):
            return False
    if kind == "outlier" and str(det.get("case")) != str(planted["case"]):
        return False
    if kind == "misplaced_sensor":
        if str(det.get("read_at")) != str(planted["read_at"]):
            return False
        if det.get("components") is not None and sorted(map(int, det["components"])) != sorted(planted["components"]):
            return False
    return True


_DATA_KEYS = ("of", "category", "source", "origin", "defect_of")


def reported_as_data(effect: dict) -> bool | None:
    """Whether an added effect is reported as a defect of the data: one of the keys ``of``
    (the diagnosis document's), ``category``, ``source``, ``origin`` or ``defect_of`` (beside ``where`` or in its details)
    says ``"data"``; None when the entry has none of them (the document does not say)."""
    det = details(effect)
    vals = [det[k] for k in _DATA_KEYS if k in det]
    if not vals:
        return None
    return any(str(v).lower() == "data" for v in vals)


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def score(planted: dict, doc: dict) -> dict:
    """One study's score from its ``planted.json`` and the diagnosis document."""
    added = list(doc.get("added") or [])
    effects = list(planted.get("effects") or [])
    hold = planted.get("holdout_cases") or ()
    match = [next((i for i, p in enumerate(effects) if is_match(p, a, hold)), None) for a in added]
    found = [any(m == i for m in match) for i in range(len(effects))]
    # a planted effect the diagnosis did not add but named beside what it added, as an
    # explanation the data hardly tell apart (the added effect's ``alternatives``)
    named = [found[i] or any(is_match(p, alt, hold) for a in added for alt in a.get("alternatives") or ())
             for i, p in enumerate(effects)]
    before, after = doc.get("before") or {}, doc.get("after") or {}
    params_ok = [bool(a.get("parameters")) and all(_finite(p.get("value")) and _finite(p.get("std"))
                                                   for p in a["parameters"]) for a in added]
    as_data = []
    for i, p in enumerate(effects):
        if p["kind"] in SENSOR_DEFECTS and found[i]:
            a = added[match.index(i)]
            as_data.append(reported_as_data(a))
    return {
        "kind": planted["kind"],
        "kinds": [p["kind"] for p in effects],
        "n_effects": len(effects),
        "where": [p.get("where") for p in effects],
        "multiple": planted.get("multiple"),
        "multiples": [p.get("multiple") for p in effects],
        "bin": size_bin(planted.get("multiple")) if effects else None,
        "bins": [p.get("bin") for p in effects],
        "family": planted.get("family"),
        "style": planted.get("style"),
        "adapter": planted.get("adapter"),
        "placement": [p.get("placement") for p in effects],
        "branches": planted.get("branches"),
        "n_members": planted.get("n_members"),
        "added": [{"effect": a.get("effect"), "where": a.get("where"), "details": details(a),
                   "parameters": a.get("parameters")} for a in added],
        "found": found,
        "detected": bool(added),
        "correct": all(found) and bool(effects) if effects else not added,
        "correct_or_named": all(named) and bool(effects) if effects else not added,
        "alternatives": [[(alt.get("effect"), alt.get("where"), alt.get("evidence_gap"))
                          for alt in a.get("alternatives") or ()] for a in added],
        "first_correct": bool(effects) and bool(match) and match[0] is not None,
        "extra": sum(1 for m in match if m is None),
        "over_limit": len(added) > len(effects) + 1,
        "false_alarm": not effects and bool(added),
        "reported_as_data": as_data,
        "params_with_std": all(params_ok) if added else None,
        "before_reduced_chi2": before.get("reduced_chi2"),
        "after_reduced_chi2": after.get("reduced_chi2"),
        "in_band_before": before.get("in_band"),
        "in_band_after": after.get("in_band"),
        "holdout_rms_before": before.get("holdout_rms"),
        "holdout_rms_after": after.get("holdout_rms"),
        "verdict": doc.get("verdict"),
        "validation": (doc.get("validation") or {}).get("method"),
        # the hold-out cases read against the final model (blackbox.diagnosis.holdout)
        "holdout_predicted": (doc.get("holdout_check") or {}).get("predicted"),
        "holdout_findings": (doc.get("holdout_check") or {}).get("findings"),
        # above the band: whether the misfit looked like noise larger than declared
        "noise_like": (doc.get("noise_level") or {}).get("noise_like"),
        "noise_factor": (doc.get("noise_level") or {}).get("factor"),
        "load_group": next((p.get("group") for p in effects if p["kind"] == "load_scale"), None),
    }


# --------------------------------------------------------------------------------------------
# summary
# --------------------------------------------------------------------------------------------
def _rate(rows, key) -> dict:
    n = len(rows)
    k = sum(1 for r in rows if r.get(key))
    return {"k": k, "n": n, "rate": (k / n) if n else None}


def _median(vals):
    v = [x for x in vals if _finite(x)]
    return float(np.median(v)) if v else None


def _block(rows: list[dict]) -> dict:
    """The goal figures of a set of studies (errors count as not correct)."""
    eff = [r for r in rows if r.get("n_effects")]
    none = [r for r in rows if r.get("n_effects") == 0]
    at2 = [r for r in eff if r.get("bin") in AT_2X]
    detected = [r for r in eff if r.get("detected")]
    return {"n": len(rows), "n_effect": len(eff), "n_none": len(none),
            "errors": sum(1 for r in rows if r.get("error")),
            "correct": _rate(eff, "correct"), "correct_at_2x": _rate(at2, "correct"),
            "correct_or_named_at_2x": _rate(at2, "correct_or_named"),
            "first_correct_at_2x": _rate(at2, "first_correct"),
            "first_correct_when_detected": _rate(detected, "first_correct"),
            "false_alarm": _rate(none, "false_alarm"),
            "none_errors": sum(1 for r in none if r.get("error")),
            "over_limit": _rate(rows, "over_limit"),
            "diagnose_median_s": _median([r.get("diagnose_s") for r in rows]),
            "diagnose_max_s": max((r.get("diagnose_s") or 0.0 for r in rows), default=None),
            "members_median": _median([r.get("n_members") for r in rows])}


def summarize(results: list[dict]) -> dict:
    """Per family (held-out apart), per kind and size bin, two-effect studies, styles, adapters,
    placements, the goals of issue 18 and the lists of misses, false alarms and errors."""
    rows = [r for r in results if r.get("kind") is not None]
    tuned = [r for r in rows if r.get("family") not in HELD_OUT]
    held = [r for r in rows if r.get("family") in HELD_OUT]
    out: dict = {"n_studies": len(results), "n_errors": sum(1 for r in results if r.get("error")),
                 "generation_errors": [r for r in results if r.get("kind") is None],
                 "tuned": _block(tuned), "held_out": _block(held) if held else None,
                 "held_out_families": list(HELD_OUT)}
    out["families"] = {f: _block([r for r in rows if r.get("family") == f])
                       for f in FAMILIES if any(r.get("family") == f for r in rows)}
    single = [r for r in tuned if r.get("n_effects") == 1]
    out["kinds"] = {}
    for kind in ALL_KINDS:
        ks = [r for r in single if r["kinds"] == [kind]]
        if not ks:
            continue
        s = _block(ks)
        s["by_bin"] = {b: {"correct": _rate([r for r in ks if r["bin"] == b], "correct"),
                           "detected": _rate([r for r in ks if r["bin"] == b], "detected")} for b in ALL_BINS}
        s["detected"] = _rate(ks, "detected")
        det = [r for r in ks if r.get("detected")]
        s["wrong_when_detected"] = {"k": sum(1 for r in det if not r["correct"]), "n": len(det)}
        if kind in SENSOR_DEFECTS:
            flags = [f for r in ks for f in r.get("reported_as_data") or []]
            s["reported_as_data"] = {"k": sum(1 for f in flags if f), "n": len(flags),
                                     "unknown": sum(1 for f in flags if f is None)}
        out["kinds"][kind] = s
    two = [r for r in tuned if r.get("n_effects") == 2]
    out["two_effects"] = _block(two) if two else None
    if two:
        out["two_effects"]["by_bin"] = {b: _rate([r for r in two if r["bin"] == b], "correct") for b in ALL_BINS}
        out["two_effects"]["one_of_two"] = _rate([{"x": any(r["found"]) and not r.get("error")} for r in two], "x")
    out["none"] = _block([r for r in tuned if r.get("n_effects") == 0])
    out["bins_all_kinds"] = {b: _rate([r for r in tuned if r.get("n_effects") and r["bin"] == b], "correct")
                             for b in ALL_BINS}
    out["styles"] = {s: _block([r for r in tuned if r.get("style") == s])
                     for s in ("plain", "user", "import") if any(r.get("style") == s for r in tuned)}
    out["adapters"] = {a: _block([r for r in rows if r.get("adapter") == a])
                       for a in sorted({r.get("adapter") for r in rows if r.get("adapter")})}
    out["placement"] = {}
    for pl in sorted({p for r in single for p in r.get("placement") or [] if p}):
        rs = [r for r in single if (r.get("placement") or [None])[0] == pl]
        out["placement"][pl] = {"n": len(rs), "kinds": sorted({r["kinds"][0] for r in rs}),
                                "correct_at_2x": _rate([r for r in rs if r["bin"] in AT_2X], "correct")}
    searched = {f for r in rows for f in r.get("families") or []}
    if searched:      # like for like with a benchmark of the searched kinds on plain decks only
        like = [r for r in single if r.get("style") == "plain" and r["kinds"][0] in searched]
        out["searched_kinds_plain"] = {
            "kinds": sorted(searched), "all": _rate([r for r in like if r["bin"] in AT_2X], "correct"),
            "families": {f: _rate([r for r in like if r["family"] == f and r["bin"] in AT_2X], "correct")
                         for f in FAMILIES if any(r["family"] == f for r in like)},
            "false_alarm": _rate([r for r in tuned if r.get("style") == "plain" and r.get("n_effects") == 0],
                                 "false_alarm")}
    flags = [f for r in tuned for f in r.get("reported_as_data") or []]
    out["reported_as_data"] = {"k": sum(1 for f in flags if f), "n": len(flags),
                               "unknown": sum(1 for f in flags if f is None)}
    eff = [r for r in tuned if r.get("n_effects")]
    out["misses_at_2x"] = [{"study": r["study"], "family": r["family"], "kind": r["kind"], "where": r["where"],
                            "multiple": r["multiple"], "error": (r.get("error") or "")[:120],
                            "added": [(a["effect"], a["where"]) for a in r.get("added", [])]}
                           for r in eff if r["bin"] in AT_2X and not r["correct"]]
    # the hold-out check on studies whose final model is the truth (nothing planted and nothing
    # added, or the planted effects found and nothing else): whatever it says there is a false alarm
    right = [r for r in rows if r.get("holdout_predicted") is not None and not r.get("error")
             and (r.get("correct") and not r.get("extra"))]
    out["holdout_check"] = {
        "right_model": {"n": len(right), "flagged": sum(1 for r in right if r.get("holdout_findings")),
                        "not_predicted": sum(1 for r in right if r.get("holdout_predicted") is False)},
        "other": {"n": sum(1 for r in rows if r.get("holdout_predicted") is not None) - len(right),
                  "flagged": sum(1 for r in rows if r.get("holdout_findings") and r not in right),
                  "not_predicted": sum(1 for r in rows if r.get("holdout_predicted") is False and r not in right)},
        "flagged_studies": [{"study": r["study"], "family": r["family"], "kind": r.get("kind"),
                             "correct": r.get("correct"), "findings": r["holdout_findings"]}
                            for r in rows if r.get("holdout_findings")]}
    # every study of this benchmark has its declared sigma right: above the band with the true
    # final model the misfit is noise (chance put the study there); with a planted effect not
    # found it is that effect's, and "looks like noise" is a reading the test could not refute
    above = [r for r in rows if r.get("noise_like") is not None and not r.get("error")]
    truth = [r for r in above if r.get("correct") and not r.get("extra")]
    out["noise_level"] = {"above_band": len(above), "noise_like": sum(1 for r in above if r["noise_like"]),
                          "true_model": len(truth), "true_model_noise_like": sum(1 for r in truth if r["noise_like"]),
                          "studies": [{"study": r["study"], "family": r["family"], "kind": r.get("kind"),
                                       "factor": r.get("noise_factor"), "true_model": r in truth}
                                      for r in above if r["noise_like"]]}
    out["false_alarms"] = [{"study": r["study"], "family": r["family"],
                            "added": [(a["effect"], a["where"]) for a in r["added"]]}
                           for r in tuned if r.get("false_alarm")]
    out["over_limit_studies"] = [{"study": r["study"], "kind": r["kind"], "n_added": len(r.get("added", []))}
                                 for r in rows if r.get("over_limit")]
    out["errors"] = [{"study": r["study"], "family": r.get("family"), "style": r.get("style"),
                      "kind": r.get("kind"), "error": " ".join(r["error"].split())[:300]}
                     for r in results if r.get("error")]
    conf: dict[str, dict[str, int]] = {}
    for r in single:
        if r.get("detected") and not r["correct"]:
            first = r["added"][0]
            label = first["effect"] + (" (other place)" if first["effect"] == r["kind"] else "")
            conf.setdefault(r["kind"], {}).setdefault(label, 0)
            conf[r["kind"]][label] += 1
    out["confusions"] = conf
    out["wall_s"] = {"total": float(sum(r.get("wall_s", 0.0) for r in results)),
                     "generate_total": float(sum(r.get("generate_s", 0.0) for r in results)),
                     "generate_median": _median([r.get("generate_s") for r in results]),
                     "generate_max": max((r.get("generate_s") or 0.0 for r in results), default=None),
                     "diagnose_median": _median([r.get("diagnose_s") for r in rows]),
                     "diagnose_max": max((r.get("diagnose_s") or 0.0 for r in rows), default=None),
                     "diagnose_median_finished": _median([r.get("diagnose_s") for r in rows if not r.get("error")]),
                     "diagnose_mean_finished": (float(np.mean([r["diagnose_s"] for r in rows if not r.get("error")]))
                                                if any(not r.get("error") for r in rows) else None)}
    return out


# --------------------------------------------------------------------------------------------
# the report
# --------------------------------------------------------------------------------------------
def _frac(d: dict | None) -> str:
    if not d or not d.get("n"):
        return "-"
    return f"{d['k']}/{d['n']} ({100.0 * d['k'] / d['n']:.0f} %)"


def _g(v) -> str:
    return "-" if v is None else f"{v:.3g}"


def _added(a) -> str:
    return ", ".join(f"{e} @ {w}" for e, w in a) or "nothing"


def markdown(summary: dict, settings: dict) -> str:
    t = summary["tuned"]
    cmd = (f"python -m benchmarks.blind.run --n {settings['n']} --seed {settings['seed']} --out out/blind --docs"
           + (f" --workers {settings['workers']}" if settings.get("workers", 1) > 1 else "")
           + (" --include-held-out" if settings.get("include_held_out") else ""))
    lines = [
        "# Blind benchmark of `blackbox diagnose`",
        "",
        f"{summary['n_studies']} random studies (seed {settings['seed']}), each diagnosed with default settings "
        f"through its own adapter; {summary['n_errors']} diagnosis error(s). The diagnosis searched "
        f"{', '.join(settings.get('diagnosis_families') or ['?'])}. Held-out family: "
        f"{', '.join(summary['held_out_families'])} ("
        + ("included, reported apart" if settings.get("include_held_out") else "not run: `--include-held-out`")
        + "). Reproduce with",
        "",
        "```",
        cmd,
        "```",
        "",
        "Each study (`benchmarks/blind/generate.py`, structures in `benchmarks/blind/frames.py`) is a frame "
        "of one family: `ladder` (chassis rails, cross members), `truss` (bar chords and cross frames, rod "
        "diagonals), `storey` (multi-storey frames of PBARL I sections, rod bracing), `tube` (a body of "
        "tubes), `imported` (the 216-member tower of a public deck, `benchmarks/blind/decks/`), `portal`, "
        "`box`, `star` (the small frames of the first benchmark), `hall` (portal frames with haunched "
        "rafters, purlins, bracing rods, bases pinned in a rotated system), `bus` (a bus body of thin "
        "rectangular tubes and channels: floor ladder, side walls with pillars, waist and cant rails, roof "
        "bows, end frames; on its suspension mounts, loaded as on a body test rig), and the held-out `jacket` "
        "(an offshore jacket platform: 3-8 battered tubular legs, horizontal frames, X- or K-braced faces, a "
        "deck frame of I or box girders on deck legs; on its piles at the mudline, loaded by waves, wind, "
        "deck loads, torsion and a boat impact). A third of the "
        "studies are written as users write decks (CORD2R/CORD1R chains, grids in CP and CD systems, "
        "GRDSET, PBARL, offsets, CONM2, SPC1 sets in an SPCADD; half of them whole input files made into "
        "the study by `blackbox import`); a few percent run through MYSTRAN. 1-3 joints of 2-6 "
        "branches, 8-20 load cases, 4-10 grids measured beside the joints, 1-5 % noise with a 2-10 % "
        "floor; none, one or two planted effects (13 kinds, data defects included), 0.5-20 times their "
        "detection threshold (the noncentrality at which a likelihood-ratio test of the effect's "
        "parameters at the level the diagnosis spends on one hypothesis of its kind in its first round, 0.01 / (2 K M_k), has 50 % power), placed where a member or "
        "a neighbouring joint could mimic them in half of the studies that have such places.",
        "",
        "Correct: every planted effect added, of its kind at its place (two-effect studies: both). A "
        "diagnosis error counts as not correct. Bins by threshold multiple (two effects: the smaller).",
        "",
        "## Goals (issue 18), families tuned on",
        "",
        "| goal | measured | target |",
        "|---|---|---|",
        f"| right kind at the right place, effects >= 2x threshold | {_frac(t['correct_at_2x'])} "
        "| >= 97 % in every family |",
        f"| false alarms on no-effect studies | {_frac(t['false_alarm'])}"
        + (f" ({t['none_errors']} more ended in an error)" if t["none_errors"] else "") + " | <= 3 % |",
        f"| right kind at the right place, or named beside the effect added as an explanation the data "
        f"hardly tell apart (evidence gap < 10), >= 2x | {_frac(t['correct_or_named_at_2x'])} | (not a goal) |",
        f"| first added effect a planted one, effects >= 2x | {_frac(t['first_correct_at_2x'])} | >= 95 % |",
        f"| studies ending with more effects than planted + 1 | {_frac(t['over_limit'])} | none |",
    ]
    rd = summary["reported_as_data"]
    if rd["n"] and rd["unknown"] == rd["n"]:
        lines.append(f"| test-data defects found reported as data | not measurable: no entry says "
                     f"({rd['n']} found) | all |")
    else:
        lines.append(f"| test-data defects found reported as data | {_frac(rd)} | all |")
    lines.append(f"| diagnosis errors | {t['errors']}/{t['n']} | none |")
    h = summary.get("held_out")
    if h:
        lines += ["", f"Held-out family ({', '.join(summary['held_out_families'])}), not tuned on: correct at >= 2x "
                      f"{_frac(h['correct_at_2x'])} (or named beside the effect added: "
                      f"{_frac(h['correct_or_named_at_2x'])}), false alarms {_frac(h['false_alarm'])}, first added effect "
                      f"planted {_frac(h['first_correct_at_2x'])}, over the limit {_frac(h['over_limit'])}, errors "
                      f"{h['errors']}/{h['n']}."]
    like = summary.get("searched_kinds_plain")
    if like:
        lines += ["", f"Like for like with a benchmark of the kinds the diagnosis searches on the project's own "
                      f"deck writing: one-effect studies of those kinds, plain decks, >= 2x: {_frac(like['all'])} ("
                      + ", ".join(f"{f} {_frac(b)}" for f, b in like["families"].items())
                      + f"); false alarms on plain no-effect studies {_frac(like['false_alarm'])}."]
    lines += ["", "## Per family", "",
              "| family | studies | members (median) | correct at >= 2x | or named beside, >= 2x "
              "| correct (all sizes) "
              "| first added planted (>= 2x) "
              "| false alarms | over the limit | errors | diagnosis median s | largest s |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for f, b in summary["families"].items():
        tag = " (held out)" if f in summary["held_out_families"] else ""
        lines.append(f"| {f}{tag} | {b['n']} | {_g(b['members_median'])} | {_frac(b['correct_at_2x'])} | "
                     f"{_frac(b['correct_or_named_at_2x'])} | "
                     f"{_frac(b['correct'])} | {_frac(b['first_correct_at_2x'])} | {_frac(b['false_alarm'])} | "
                     f"{b['over_limit']['k']} | {b['errors']} | {_g(b['diagnose_median_s'])} | "
                     f"{_g(b['diagnose_max_s'])} |")
    lines += ["", "## Per kind (one-effect studies, families tuned on)", "",
              "Correct per size bin; wrong when detected: something was added, but not the planted effect.", "",
              "| kind | n | 0.5-1x | 1-2x | 2-5x | 5-20x | >20x | correct at >= 2x | first added planted (>= 2x) "
              "| wrong when detected | errors | as data |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for kind, s in summary["kinds"].items():
        bb = s["by_bin"]
        rd = s.get("reported_as_data")
        data = "-" if not rd else ("not said" if rd["n"] and rd["unknown"] == rd["n"] else _frac(rd))
        lines.append(" | ".join([f"| {kind}", str(s["n"])] + [_frac(bb[b]["correct"]) for b in ALL_BINS]
                                + [_frac(s["correct_at_2x"]), _frac(s["first_correct_at_2x"]),
                                   _frac(s["wrong_when_detected"]), str(s["errors"]), data]) + " |")
    ab = summary["bins_all_kinds"]
    lines.append(" | ".join(["| all one- and two-effect studies", str(sum(d["n"] for d in ab.values()))]
                            + [_frac(ab[b]) for b in ALL_BINS] + [""] * 5) + " |")
    nb = summary["none"]
    lines += ["", f"No-effect studies: {nb['n']}; false alarms {_frac(nb['false_alarm'])}; errors {nb['errors']}."]
    hc = summary.get("holdout_check")
    if hc and (hc["right_model"]["n"] or hc["other"]["n"]):
        rm, ot = hc["right_model"], hc["other"]
        lines += ["", "## Hold-out check", "",
                  "The hold-out cases read against the final model (an outlier, a case of another size or "
                  "another case's, a rigid motion, or not predicted; docs/commands.md). On studies whose "
                  "final model is the truth (nothing planted and nothing added, or the planted effects "
                  f"found and nothing else) any finding is a false alarm: {rm['flagged']} of {rm['n']} "
                  f"(not predicted: {rm['not_predicted']}). On the other studies with hold-out cases: "
                  f"{ot['flagged']} of {ot['n']} with a finding, {ot['not_predicted']} not predicted."]
        for f in hc["flagged_studies"][:20]:
            lines.append(f"- {f['study']} ({f['family']}, {f['kind']}, {'right' if f['correct'] else 'wrong'} "
                         f"model): " + "; ".join(f["findings"])[:300])
    nlv = summary.get("noise_level")
    if nlv and nlv["above_band"]:
        tm, other = nlv["true_model"], nlv["above_band"] - nlv["true_model"]
        lines += ["", "## Noise larger than declared?", "",
                  f"Studies ending above their noise band: {nlv['above_band']} (docs/measurements.md, \"Noise "
                  "larger than declared\"). Every study here declares its sigma right. With the truth as the "
                  f"final model ({tm}) the misfit is noise that chance put above the band, and "
                  f"{nlv['true_model_noise_like']} of them are said to look like noise; with a planted effect "
                  f"not found ({other}), {nlv['noise_like'] - nlv['true_model_noise_like']} are, a reading the "
                  "test could not refute (the sentence names the model lacking something spread evenly as the "
                  "other)"
                  + (": " + ", ".join(f"{x['study']} ({x['family']}, {x['kind']}, factor {x['factor']:.3g}"
                                      f"{', true model' if x['true_model'] else ''})"
                                      for x in nlv["studies"][:20]) if nlv["studies"] else "") + "."]
    te = summary.get("two_effects")
    if te:
        lines += ["", "## Two effects", "",
                  f"{te['n']} studies with two planted effects of different kinds at different places: both found "
                  f"{_frac(te['correct'])} (at >= 2x of the smaller: {_frac(te['correct_at_2x'])}), at least one found "
                  f"{_frac(te['one_of_two'])}, first added effect a planted one (>= 2x) "
                  f"{_frac(te['first_correct_at_2x'])}, "
                  f"over the limit {te['over_limit']['k']}, errors {te['errors']}. Per bin of the smaller multiple: "
                  + ", ".join(f"{b} {_frac(d)}" for b, d in te["by_bin"].items() if d["n"]) + "."]
    lines += ["", "## Deck style and adapter", "",
              "`plain`: the project's own writing; `user`: a user's bulk data (coordinate systems, GRDSET, PBARL, "
              "offsets, CONM2, SPCADD); `import`: a whole input file made into the study by `blackbox import`.", "",
              "| studies | n | correct at >= 2x | false alarms | errors | diagnosis median s |",
              "|---|---|---|---|---|---|"]
    for name, b in list(summary["styles"].items()) + [(f"adapter {a}", b) for a, b in summary["adapters"].items()]:
        lines.append(f"| {name} | {b['n']} | {_frac(b['correct_at_2x'])} | {_frac(b['false_alarm'])} | {b['errors']} | "
                     f"{_g(b['diagnose_median_s'])} |")
    if summary.get("placement"):
        lines += ["", "## Placement", "",
                  "`near_joint`: an undeclared joint one grid from a declared joint; `joint_or_support_member`: a "
                  "member factor on a member framing into a joint or a support; `one_bar_support`: a flexible support "
                  "where one bar ends; `neighbour`: a misplaced sensor "
                  "(read at a grid one member away); `anywhere`: the kind's whole pool.", "",
                  "| placement | studies | kinds | correct at >= 2x |", "|---|---|---|---|"]
        for pl, b in summary["placement"].items():
            lines.append(f"| {pl} | {b['n']} | {', '.join(b['kinds'])} | {_frac(b['correct_at_2x'])} |")
    if summary.get("confusions"):
        lines += ["", "## Wrong effect when detected (first effect added, one-effect studies)", "",
                  "| planted | added first instead | studies |", "|---|---|---|"]
        for kind, c in summary["confusions"].items():
            for label, k in sorted(c.items(), key=lambda kv: -kv[1]):
                lines.append(f"| {kind} | {label} | {k} |")
    ms = summary["misses_at_2x"]
    if ms:
        shown = [m for m in ms if not m["error"]]
        lines += ["", f"## Misses at >= 2x ({len(ms)}, {len(ms) - len(shown)} of them errors: see Errors)", "",
                  "| study | family | planted | where | multiple | added |", "|---|---|---|---|---|---|"]
        for m in shown[:MAX_LISTED]:
            where = "; ".join(str(w) for w in m["where"])
            lines.append(f"| {m['study']} | {m['family']} | {m['kind']} | {where} | {_g(m['multiple'])} | "
                         f"{_added(m['added']).replace('|', '/')} |")
        if len(shown) > MAX_LISTED:
            lines.append(f"| ... | {len(shown) - MAX_LISTED} more in `docs/blind.json` | | | | |")
    if summary["false_alarms"]:
        lines += ["", "## False alarms", "", "| study | family | added |", "|---|---|---|"]
        for m in summary["false_alarms"]:
            lines.append(f"| {m['study']} | {m['family']} | {_added(m['added'])} |")
    if summary["over_limit_studies"]:
        lines += ["", "## More effects than planted + 1", "", "| study | planted | effects added |", "|---|---|---|"]
        for m in summary["over_limit_studies"]:
            lines.append(f"| {m['study']} | {m['kind']} | {m['n_added']} |")
    if summary.get("errors"):
        kinds: dict[str, int] = {}
        for e in summary["errors"]:
            key = e["error"].split(":")[0] + (": SPCADD" if "SPCADD" in e["error"] else "")
            kinds[key] = kinds.get(key, 0) + 1
        lines += ["", f"## Errors ({len(summary['errors'])})", "",
                  "By type: " + ", ".join(f"{k} x{n}" for k, n in sorted(kinds.items(), key=lambda kv: -kv[1])) + ".",
                  "", "| study | family | style | planted | error |", "|---|---|---|---|---|"]
        for e in summary["errors"][:MAX_LISTED]:
            lines.append(f"| {e['study']} | {e['family']} | {e['style']} | {e['kind']} | "
                         f"{' '.join(e['error'][:200].replace('|', '/').split())} |")
        if len(summary["errors"]) > MAX_LISTED:
            lines.append(f"| ... | {len(summary['errors']) - MAX_LISTED} more in `docs/blind.json` | | | |")
    w = summary["wall_s"]
    lines += ["", f"Wall time: {_g(w['total'])} s of study time in all (generation {_g(w['generate_total'])} s: "
                  f"median {_g(w['generate_median'])} s, largest {_g(w['generate_max'])} s per study); diagnosis "
                  f"median {_g(w['diagnose_median'])} s, largest {_g(w['diagnose_max'])} s per study (of the "
                  f"diagnoses that ran to the end, without an error: median {_g(w.get('diagnose_median_finished'))} "
                  f"s, mean {_g(w.get('diagnose_mean_finished'))} s)"
                  + (f"; {_g(settings['run_wall_s'])} s from start to end on {settings.get('workers', 1)} worker(s)"
                     if settings.get("run_wall_s") else "") + ".", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# the run
# --------------------------------------------------------------------------------------------
def run_one(index: int, seed: int, out: Path, keep: bool = False) -> dict:
    """Generate, diagnose and score study ``index``; the study files are removed unless ``keep``."""
    from blackbox.commands.diagnose import run as diagnose

    t0 = time.perf_counter()
    try:
        st = generate_study(index, seed, out)
    except Exception as exc:                 # recorded, so that one bad draw does not stop the run
        return {"study": f"s{index:04d}", "index": index, "kind": None, "family": study_family(seed, index),
                "error": f"generation: {exc}", "traceback": traceback.format_exc(limit=5),
                "generate_s": time.perf_counter() - t0, "diagnose_s": 0.0, "wall_s": time.perf_counter() - t0}
    t1 = time.perf_counter()
    p = st.planted
    rec: dict = {"study": st.folder.name, "index": index}
    try:
        res = diagnose(st.folder, plots=False)          # the study's own adapter
        rec.update(score(p, res.document))
    except Exception as exc:                 # a failed diagnosis is a result of the benchmark too
        rec.update(score(p, {}))
        rec.update({"correct": False, "first_correct": False, "false_alarm": False,
                    "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(limit=5)})
    t2 = time.perf_counter()
    rec.update({"generate_s": t1 - t0, "diagnose_s": t2 - t1, "wall_s": t2 - t0,
                "n_candidates": p.get("n_candidates"), "n_measurements": p.get("n_measurements")})
    if not keep:
        shutil.rmtree(st.folder, ignore_errors=True)
    return rec


def _families() -> list[str]:
    """The effect kinds the diagnosis searches (recorded: a planted kind it lacks cannot be found)."""
    from blackbox.diagnosis.effects import families

    return sorted(f.kind for f in families(None))


def load_results(path: Path) -> dict[int, dict]:
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                done[r["index"]] = r
    return done


def _run_task(item: tuple[int, int, str, bool]) -> dict:
    i, seed, out, keep = item
    return {**run_one(i, seed, Path(out), keep=keep), "seed": seed, "families": _families()}


def study_indices(seed: int, n: int, include_held_out: bool, families: list[str] | None = None) -> list[int]:
    """The indices of the first ``n`` studies of the tuned families (``families`` restricts
    them); with ``include_held_out`` also the held-out family's studies among them (those
    before the last one taken), so that the tuned studies are the same with and without it.
    When only held-out families are named, ``n`` counts theirs."""
    tuned = [f for f in FAMILIES if f not in HELD_OUT and (not families or f in families)]
    held = [f for f in HELD_OUT if include_held_out and (not families or f in families)]
    out, i, count = [], 0, 0
    while count < n and (tuned or held):
        f = study_family(seed, i)
        if f in tuned or f in held:
            out.append(i)
            count += 1 if (f in tuned or not tuned) else 0
        i += 1
    return out


def _record(fh, rec: dict, done: dict, total: int, t0: float) -> None:
    fh.write(json.dumps(rec, default=float) + "\n")
    fh.flush()
    done[rec["index"]] = rec
    mark = ("ERROR " + rec["error"][:60].replace("\n", " ")) if rec.get("error") else (
        "false alarm" if rec.get("false_alarm") else
        ("ok" if rec.get("correct") else ("wrong" if rec.get("detected") else "missed")))
    added = ", ".join(f"{a['effect']}@{a['where']}" for a in rec.get("added", [])) or "-"
    mult = f" x{rec['multiple']:.2f}" if rec.get("multiple") else ""
    print(f"[{len(done):4d}/{total}] {rec['study']} {rec.get('family')} {rec.get('kind')}{mult}: "
          f"{added} -> {mark} ({rec.get('generate_s', 0):.1f} + {rec['diagnose_s']:.1f} s, "
          f"{time.perf_counter() - t0:.0f} s so far)", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="blind benchmark of blackbox diagnose")
    ap.add_argument("--n", type=int, default=600, help="studies of the families run")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("out/blind"))
    ap.add_argument("--docs", action="store_true", help="also write docs/blind.md and docs/blind.json")
    ap.add_argument("--keep", action="store_true", help="keep the study folders (default: only hidden/)")
    ap.add_argument("--workers", type=int, default=1,
                    help="studies side by side on a local Dask cluster of this many workers")
    ap.add_argument("--include-held-out", action="store_true",
                    help=f"run the held-out family ({', '.join(HELD_OUT)}) too, reported apart")
    ap.add_argument("--families", nargs="+", choices=tuple(FAMILIES), help="run only these families")
    ap.add_argument("--report-only", action="store_true",
                    help="write the summary of the studies already in OUT/results.jsonl, run nothing")
    args = ap.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.jsonl"
    indices = study_indices(args.seed, args.n, args.include_held_out, args.families)
    done = {i: r for i, r in load_results(path).items() if r.get("seed", args.seed) == args.seed}
    t0 = time.perf_counter()
    todo = [] if args.report_only else [i for i in indices if i not in done]
    # worker processes import this module by name: they need the project on their path
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH", "")]))
    executor = make_executor(workers=args.workers) if args.workers > 1 and todo else SerialExecutor()
    items = [(i, args.seed, str(out), args.keep) for i in todo]
    with path.open("a") as fh, executor:
        if hasattr(executor, "client"):
            # every study submitted at once and appended as it finishes: a long study holds up
            # no other worker
            from distributed import as_completed
            futures = executor.client.map(_run_task, items, pure=False)
            index = {f.key: item[0] for f, item in zip(futures, items)}
            for fut in as_completed(futures):
                try:
                    rec = fut.result()
                except Exception as exc:     # a worker lost (memory): that study's error
                    i = index[fut.key]
                    rec = {"study": f"s{i:04d}", "index": i, "seed": args.seed, "kind": None,
                           "family": study_family(args.seed, i), "error": f"worker: {type(exc).__name__}: {exc}",
                           "generate_s": 0.0, "diagnose_s": 0.0, "wall_s": 0.0}
                _record(fh, rec, done, len(indices), t0)
                fut.release()
        else:
            for item in items:
                _record(fh, _run_task(item), done, len(indices), t0)
    run_wall = time.perf_counter() - t0
    wall_path = out / "run_wall.json"
    walls = json.loads(wall_path.read_text()) if wall_path.exists() else []
    if todo:
        walls.append({"studies": len(todo), "wall_s": run_wall, "workers": args.workers})
        wall_path.write_text(json.dumps(walls))
    results = [done[i] for i in indices if i in done]
    for r in results:          # scored before the document's key was read: from the stored entries
        if r.get("reported_as_data") and all(f is None for f in r["reported_as_data"]):
            found = [a for a in r.get("added") or [] if a.get("effect") in SENSOR_DEFECTS]
            r["reported_as_data"] = [reported_as_data(a) for a in found][:len(r["reported_as_data"])]
    summary = summarize(results)
    settings = {"n": args.n, "seed": args.seed, "workers": args.workers, "include_held_out": args.include_held_out,
                "families_run": args.families, "run_wall_s": sum(w["wall_s"] for w in walls) or None,
                "diagnosis_families": sorted({f for r in results for f in r.get("families", [])})}
    doc = {"settings": settings, "summary": summary, "studies": results}
    (out / "blind.json").write_text(json.dumps(doc, indent=1, default=float))
    md = markdown(summary, settings)
    (out / "blind.md").write_text(md)
    if args.docs:              # the studies one per line, without parameter values: a smaller file
        slim = [{**{k: v for k, v in r.items() if k not in ("added", "traceback", "families", "error")},
                 **({"error": " ".join(r["error"].split())[:300]} if r.get("error") else {}),
                 "added": [{"effect": a["effect"], "where": a["where"],
                            "parameters": [p.get("name") for p in a.get("parameters") or []]}
                           for a in r.get("added", [])]} for r in results]
        head = json.dumps({"settings": settings, "summary": summary}, indent=1, default=float)
        rows = ",\n".join(json.dumps(r, separators=(",", ":"), default=float) for r in slim)
        (ROOT / "docs" / "blind.md").write_text(md)
        (ROOT / "docs" / "blind.json").write_text(head[:-2] + ',\n "studies": [\n' + rows + "\n ]\n}\n")
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
