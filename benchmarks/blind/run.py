"""The blind benchmark of ``blackbox diagnose``: generate N random studies, diagnose each, score.

    python -m benchmarks.blind.run --n 200 --seed 1 --out out/blind --docs

For study ``i`` (seeded by ``--seed`` and ``i``) :mod:`benchmarks.blind.generate` writes the study
folder and, outside it, ``planted.json``; :func:`blackbox.commands.diagnose.run` (reference
adapter, in-process, default settings) diagnoses the folder, and only its result document is
read (``added``: kind, where, parameters; ``before``/``after``; ``verdict`` when present). The
score of each study is appended to ``OUT/results.jsonl`` as soon as it is known, so an
interrupted run continues where it stopped. ``OUT/blind.json`` and ``OUT/blind.md`` hold the
summary; ``--docs`` writes them to ``docs/blind.json`` and ``docs/blind.md`` as well.

Scoring of one study (:func:`score`):

* **detected**: the diagnosis added at least one effect;
* **correct**: one of the added effects is the planted kind at the planted place. The place
  per kind: ``joint_coupling`` and ``joint_translation`` the declared joint's name;
  ``undeclared_joint`` and ``support_flexibility`` the grid; ``sensor_gain`` the grid;
  ``sensor_offset`` the grid and component (the channel);
  ``member_stiffness`` the element; ``load_scale`` the scaled cases that were fitted (every case,
  one case, or a test day: the day's fitted cases, since a group found from the data holds only
  fitted cases);
* **first correct**: the first effect added is the right one; **extra**: effects added besides
  the right one (or every added effect of a none-study: a false alarm);
* chi2 back in band (``after.in_band``), hold-out RMS before and after, whether every added
  effect's parameters carry a finite standard error (the intervals), and the verdict if the
  document has one.

The threshold multiple of a planted effect is defined in :mod:`benchmarks.blind.generate`;
results are binned 0.5-1x, 1-2x and 2-5x.
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

from benchmarks.blind.generate import KINDS, NONE, generate_study   # noqa: E402
from blackbox.parallel import SerialExecutor, make_executor         # noqa: E402

BINS = ((0.5, 1.0), (1.0, 2.0), (2.0, 5.0 + 1e-9))
BIN_NAMES = ("0.5-1x", "1-2x", "2-5x")
GOALS = {"correct_at_2x": 0.95, "false_alarm": 0.05}


def size_bin(multiple: float | None) -> str | None:
    if multiple is None:
        return None
    for (lo, hi), name in zip(BINS, BIN_NAMES):
        if lo <= multiple < hi:
            return name
    return BIN_NAMES[0] if multiple < BINS[0][0] else BIN_NAMES[-1]


def _norm_where(where) -> tuple[str, ...]:
    if where is None:
        return ()
    if isinstance(where, (list, tuple)):
        return tuple(sorted(str(w) for w in where))
    return (str(where),)


def is_match(planted: dict, effect: dict) -> bool:
    """The added ``effect`` (an entry of the document's ``added``) is the planted one: same kind,
    same place (:func:`_norm_where` compares joint names, grid and element ids, case groups; a
    sensor offset's component too, from its parameter name ``o_G_C``)."""
    if effect.get("effect") != planted["kind"]:
        return False
    if planted["kind"] == "load_scale":
        # the scaled cases that were fitted: a group found from the data holds only fitted cases,
        # a group named in loads.csv (and the all-cases factor) its hold-out cases too
        hold = {str(c) for c in planted.get("holdout_cases") or ()}
        return ({str(c) for c in effect.get("where") or ()} - hold) == ({str(c) for c in planted["where"]} - hold)
    if _norm_where(effect.get("where")) != _norm_where(planted.get("where")):
        return False
    if planted["kind"] == "sensor_offset" and effect.get("parameters"):
        names = {p.get("name") for p in effect["parameters"]}
        return f"o_{planted['where']}_{planted['component']}" in names
    return True


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def score(planted: dict, doc: dict) -> dict:
    """One study's score from its ``planted.json`` and the diagnosis document."""
    added = list(doc.get("added") or [])
    kind = planted["kind"]
    matches = [is_match(planted, a) for a in added] if kind != NONE else [False] * len(added)
    before, after = doc.get("before") or {}, doc.get("after") or {}
    params_ok = [bool(a.get("parameters")) and all(_finite(p.get("value")) and _finite(p.get("std"))
                                                   for p in a["parameters"]) for a in added]
    return {
        "kind": kind,
        "where": planted.get("where"),
        "multiple": planted.get("multiple"),
        "bin": size_bin(planted.get("multiple")) if kind != NONE else None,
        "shape": planted.get("shape"),
        "branches": planted.get("branches"),
        "added": [{"effect": a.get("effect"), "where": a.get("where"),
                   "parameters": a.get("parameters")} for a in added],
        "detected": bool(added),
        "correct": any(matches),
        "first_correct": bool(matches and matches[0]),
        "extra": sum(1 for m in matches if not m),
        "false_alarm": kind == NONE and bool(added),
        "params_with_std": all(params_ok) if added else None,
        "before_reduced_chi2": before.get("reduced_chi2"),
        "after_reduced_chi2": after.get("reduced_chi2"),
        "in_band_before": before.get("in_band"),
        "in_band_after": after.get("in_band"),
        "holdout_rms_before": before.get("holdout_rms"),
        "holdout_rms_after": after.get("holdout_rms"),
        "verdict": doc.get("verdict"),
        "validation": (doc.get("validation") or {}).get("method"),
        "load_group": planted.get("group") if kind == "load_scale" else None,
        "group_column": planted.get("group_column"),
    }


# --------------------------------------------------------------------------------------------
# summary
# --------------------------------------------------------------------------------------------
def _rate(rows, key) -> dict:
    n = len(rows)
    k = sum(1 for r in rows if r.get(key))
    return {"k": k, "n": n, "rate": (k / n) if n else None}


def summarize(results: list[dict]) -> dict:
    ok = [r for r in results if not r.get("error")]
    out: dict = {"n_studies": len(results), "n_errors": len(results) - len(ok), "kinds": {}}
    for kind in (NONE,) + KINDS:
        rows = [r for r in ok if r["kind"] == kind]
        if not rows:
            continue
        ratios = _holdout_ratios(rows)
        det = [r for r in rows if r["detected"]]
        s = {"n": len(rows),
             "detected": _rate(rows, "detected"),
             "correct": _rate(rows, "correct"),
             "first_correct": _rate(rows, "first_correct"),
             "wrong_when_detected": {"k": sum(1 for r in det if not r["correct"]), "n": len(det)},
             "with_extra_effects": _rate(rows, "extra"),
             "in_band_before": _rate(rows, "in_band_before"),
             "in_band_after": _rate(rows, "in_band_after"),
             "params_with_std": {"k": sum(1 for r in det if r["params_with_std"]), "n": len(det)},
             "holdout_rms_before_median": _median([r["holdout_rms_before"] for r in rows]),
             "holdout_rms_after_median": _median([r["holdout_rms_after"] for r in rows]),
             "holdout_ratio_median": _median(ratios),
             "holdout_ratio_median_when_added": _median(_holdout_ratios(det)),
             "by_bin": {}}
        if kind != NONE:
            for b in BIN_NAMES:
                br = [r for r in rows if r["bin"] == b]
                s["by_bin"][b] = {"n": len(br), "detected": _rate(br, "detected"), "correct": _rate(br, "correct"),
                                  "in_band_after": _rate(br, "in_band_after")}
        out["kinds"][kind] = s
    eff = [r for r in ok if r["kind"] != NONE]
    at2 = [r for r in eff if r["bin"] == "2-5x"]
    none = [r for r in ok if r["kind"] == NONE]
    found = [r for r in ok if r["detected"]]
    # outside the band above (the model still lacks something) and below (chi2 too small: the
    # noise was overstated or the model overfits; no effect can explain that)
    out_band = [r for r in ok if r["in_band_after"] is False and _finite(r["after_reduced_chi2"])
                and r["after_reduced_chi2"] > 1.0]
    below = [r for r in ok if r["in_band_after"] is False and r not in out_band]
    has_verdict = any(r.get("verdict") is not None for r in ok)
    out["goals"] = {
        "correct_at_2x": {**_rate(at2, "correct"), "goal": GOALS["correct_at_2x"]},
        "false_alarm": {**_rate(none, "false_alarm"), "goal": GOALS["false_alarm"]},
        "params_with_std": {"k": sum(1 for r in found if r["params_with_std"]), "n": len(found), "goal": 1.0},
        "unexplained_when_out_of_band": (
            {"k": sum(1 for r in out_band if r.get("verdict") == "unexplained"), "n": len(out_band), "goal": 1.0}
            if has_verdict else {"k": None, "n": len(out_band), "goal": 1.0,
                                 "note": "the diagnosis document has no verdict yet"}),
    }
    out["verdicts"] = {
        "in_band": _counts(r.get("verdict") for r in ok if r["in_band_after"]),
        "above_band": _counts(r.get("verdict") for r in out_band),
        "below_band": _counts(r.get("verdict") for r in below)}
    out["out_of_band_above"] = [{"study": r["study"], "kind": r["kind"], "multiple": r.get("multiple"),
                                 "after_reduced_chi2": r["after_reduced_chi2"], "verdict": r.get("verdict"),
                                 "added": [(a["effect"], a["where"]) for a in r["added"]]} for r in out_band]
    out["bins_all_kinds"] = {b: {"detected": _rate([r for r in eff if r["bin"] == b], "detected"),
                                 "correct": _rate([r for r in eff if r["bin"] == b], "correct")}
                             for b in BIN_NAMES}
    out["wall_s"] = {"total": float(sum(r.get("wall_s", 0.0) for r in results)),
                     "diagnose_median": _median([r.get("diagnose_s") for r in ok]),
                     "diagnose_max": max((r.get("diagnose_s") or 0.0 for r in ok), default=None)}
    out["misses_at_2x"] = [{"study": r["study"], "kind": r["kind"], "where": r["where"], "multiple": r["multiple"],
                            "added": [(a["effect"], a["where"]) for a in r["added"]]}
                           for r in at2 if not r["correct"]]
    out["false_alarms"] = [{"study": r["study"], "added": [(a["effect"], a["where"]) for a in r["added"]]}
                           for r in none if r["false_alarm"]]
    out["errors"] = [{"study": r["study"], "kind": r.get("kind"), "error": r["error"]}
                     for r in results if r.get("error")]
    conf: dict[str, dict[str, int]] = {}
    for r in eff:
        if r["detected"] and not r["correct"]:
            first = r["added"][0]
            label = first["effect"] + (" (other place)" if first["effect"] == r["kind"] else "")
            conf.setdefault(r["kind"], {}).setdefault(label, 0)
            conf[r["kind"]][label] += 1
    out["confusions"] = conf
    out["by_validation"] = {}
    for method in sorted({r.get("validation") for r in ok if r.get("validation")}):
        rs = [r for r in ok if r.get("validation") == method]
        out["by_validation"][method] = {
            "n": len(rs), "correct_at_2x": _rate([r for r in rs if r["bin"] == "2-5x"], "correct"),
            "false_alarm": _rate([r for r in rs if r["kind"] == NONE], "false_alarm")}
    out["load_scale_groups"] = {}
    for label, pick in (("all cases", lambda r: r.get("load_group") == "all"),
                        ("one case", lambda r: r.get("load_group") == "case"),
                        ("test day, group column", lambda r: r.get("load_group") == "day" and r.get("group_column")),
                        ("test day, found from the data",
                         lambda r: r.get("load_group") == "day" and not r.get("group_column"))):
        rs = [r for r in ok if r["kind"] == "load_scale" and pick(r)]
        if rs:
            out["load_scale_groups"][label] = {"n": len(rs), "correct": _rate(rs, "correct"),
                                               "correct_at_2x": _rate([r for r in rs if r["bin"] == "2-5x"],
                                                                      "correct")}
    out["by_shape"] = {}
    for shape in sorted({r["shape"] for r in ok if r.get("shape")}):
        rs = [r for r in ok if r.get("shape") == shape]
        out["by_shape"][shape] = {
            "n": len(rs), "correct_at_2x": _rate([r for r in rs if r["bin"] == "2-5x"], "correct"),
            "false_alarm": _rate([r for r in rs if r["kind"] == NONE], "false_alarm")}
    return out


def _holdout_ratios(rows) -> list[float]:
    return [r["holdout_rms_after"] / r["holdout_rms_before"] for r in rows
            if _finite(r["holdout_rms_after"]) and _finite(r["holdout_rms_before"]) and r["holdout_rms_before"] > 0]


def _counts(vals) -> dict[str, int]:
    out: dict[str, int] = {}
    for v in vals:
        out[str(v)] = out.get(str(v), 0) + 1
    return out


def _median(vals):
    v = [x for x in vals if _finite(x)]
    return float(np.median(v)) if v else None


def _frac(d: dict) -> str:
    if not d or not d.get("n"):
        return "-"
    return f"{d['k']}/{d['n']} ({100.0 * d['k'] / d['n']:.0f} %)"


def _fmt_counts(c: dict) -> str:
    return ", ".join(f"{k} {n}" for k, n in sorted(c.items(), key=lambda kv: -kv[1])) or "none"


def _g(v) -> str:
    return "-" if v is None else f"{v:.3g}"


def markdown(summary: dict, settings: dict) -> str:
    g = summary["goals"]
    lines = [
        "# Blind benchmark of `blackbox diagnose`",
        "",
        f"{summary['n_studies']} random studies (seed {settings['seed']}), reference adapter, default "
        f"diagnosis settings; {summary['n_errors']} diagnosis error(s). The diagnosis searched "
        f"{', '.join(settings.get('diagnosis_families') or ['?'])}. Reproduce with",
        "",
        "```",
        f"python -m benchmarks.blind.run --n {settings['n']} --seed {settings['seed']} --out out/blind --docs"
        + (f" --workers {settings['workers']}" if settings.get("workers", 1) > 1 else ""),
        "```",
        "",
        *([f"(`--workers {settings['workers']}`: the studies side by side on a local Dask cluster; each study "
           "is diagnosed as serially, but a worker runs BLAS single-threaded, so a serial run can differ "
           "in rounding.)"] if settings.get("workers", 1) > 1 else []),
        "",
        "Each study is a random frame (portal, ladder, space-frame box, tube body, star frame) with "
        "1-2 flexible joints of 2-5 branches (2-3 each when there are two), 8-20 load cases (in two "
        "studies of three a fifth of them hold-out, in the third none: K-fold over the cases), the joints' "
        "DOFs and 3-8 further grids measured with 1-5 % proportional noise and a 2-10 % floor, and "
        "one planted effect of random kind and place (or none) of 0.5-5 times its detection "
        "threshold (`benchmarks/blind/generate.py`). The threshold is the size at which the chi2 excess "
        "the effect causes beyond what the declared joints absorb has the noncentrality at which a "
        "likelihood-ratio test of the effect's parameters at level 0.01 / M (M candidates, "
        "Bonferroni) has 50 % power; the multiple is sqrt(noncentrality / threshold noncentrality). "
        "The diagnosis sees only the study folder; what was planted is kept beside it.",
        "",
        "Right place, per kind: `joint_coupling`, `joint_translation` the declared joint; "
        "`undeclared_joint`, `support_flexibility`, `sensor_gain` the grid; `sensor_offset` the grid "
        "and component; `member_stiffness` the element; `load_scale` the scaled cases that were fitted "
        "(all cases, one case, or a test day: a run of consecutive cases, named by a `group` column of "
        "`loads.csv` in half of those studies, else to be found from the data). A study counts as correct when one of the effects added is the planted kind "
        "at the planted place; effects added besides it are counted as extra.",
        "",
        "## Goals",
        "",
        "| goal | measured | target |",
        "|---|---|---|",
        f"| right kind at the right place, effects >= 2x threshold | {_frac(g['correct_at_2x'])} | >= 95 % |",
        f"| false alarms on no-effect studies | {_frac(g['false_alarm'])} | <= 5 % |",
        f"| added effects reported with parameters and finite standard errors | {_frac(g['params_with_std'])} | all |",
    ]
    u = g["unexplained_when_out_of_band"]
    if u.get("k") is None:
        lines.append(f"| verdict \"unexplained\" when chi2 stays above its band | not measurable: no "
                     f"`verdict` in the document ({u['n']} studies above the band) | all |")
    else:
        lines.append(f"| verdict \"unexplained\" when chi2 stays above its band | {_frac(u)} | all |")
    v = summary.get("verdicts", {})
    if v:
        lines += ["", "Verdicts by the reduced chi2 after the diagnosis: in its band "
                  + _fmt_counts(v["in_band"]) + "; above " + _fmt_counts(v["above_band"]) + "; below "
                  + _fmt_counts(v["below_band"]) + "."]
    lines += ["", "## Per kind", "",
              "Detected: any effect added. Correct: the planted kind at the planted place among the added "
              "effects. In band: reduced chi2 before / after the diagnosis inside its 99 % band. Hold-out: "
              "median ratio of the hold-out RMS after / before, over all studies of the kind and over "
              "those where an effect was added (the hold-out RMS is mostly the noise).", "",
              "| kind | n | detected 0.5-1x | 1-2x | 2-5x | correct 0.5-1x | 1-2x | 2-5x | wrong when detected "
              "| in band before | after | hold-out after/before | (when added) | params with std |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for kind, s in summary["kinds"].items():
        if kind == NONE:
            continue
        bb = s["by_bin"]
        lines.append(" | ".join([f"| {kind}", str(s["n"])] + [_frac(bb[b]["detected"]) for b in BIN_NAMES]
                                + [_frac(bb[b]["correct"]) for b in BIN_NAMES]
                                + [_frac(s["wrong_when_detected"]), _frac(s["in_band_before"]),
                                   _frac(s["in_band_after"]), _g(s["holdout_ratio_median"]),
                                   _g(s["holdout_ratio_median_when_added"]), _frac(s["params_with_std"])]) + " |")
    allb = summary["bins_all_kinds"]
    lines.append(" | ".join(["| all effects", str(sum(s["n"] for k, s in summary["kinds"].items() if k != NONE))]
                            + [_frac(allb[b]["detected"]) for b in BIN_NAMES]
                            + [_frac(allb[b]["correct"]) for b in BIN_NAMES] + [""] * 6) + " |")
    if NONE in summary["kinds"]:
        s = summary["kinds"][NONE]
        lines += ["", f"No-effect studies: {s['n']}; false alarms {_frac(s['detected'])}; reduced chi2 in band "
                      f"{_frac(s['in_band_before'])}; median hold-out RMS ratio {_g(s['holdout_ratio_median'])}."]
    if summary.get("out_of_band_above"):
        lines += ["", "## Reduced chi2 still above its band after the diagnosis", "",
                  "| study | planted | multiple | added | reduced chi2 | verdict |", "|---|---|---|---|---|---|"]
        for m in summary["out_of_band_above"]:
            added = ", ".join(f"{e} @ {w}" for e, w in m["added"]) or "nothing"
            mult = "-" if m["multiple"] is None else f"{m['multiple']:.2f}"
            lines.append(f"| {m['study']} | {m['kind']} | {mult} | {added} | "
                         f"{m['after_reduced_chi2']:.3f} | {m['verdict']} |")
    if summary["misses_at_2x"]:
        lines += ["", "## Misses at >= 2x", "", "| study | planted | where | multiple | added |",
                  "|---|---|---|---|---|"]
        for m in summary["misses_at_2x"]:
            added = ", ".join(f"{e} @ {w}" for e, w in m["added"]) or "nothing"
            lines.append(f"| {m['study']} | {m['kind']} | {m['where']} | {m['multiple']:.2f} | {added} |")
    if summary["false_alarms"]:
        lines += ["", "## False alarms", "", "| study | added |", "|---|---|"]
        for m in summary["false_alarms"]:
            lines.append(f"| {m['study']} | {', '.join(f'{e} @ {w}' for e, w in m['added'])} |")
    if summary.get("confusions"):
        lines += ["", "## Wrong effect when detected (first effect added)", "", "| planted | added instead | studies |",
                  "|---|---|---|"]
        for kind, c in summary["confusions"].items():
            for label, k in sorted(c.items(), key=lambda kv: -kv[1]):
                lines.append(f"| {kind} | {label} | {k} |")
    if summary.get("by_validation"):
        lines += ["", "## Per check against unfitted data", "",
                  "`holdout`: the study declares hold-out cases; `kfold`: it declares none, every case is "
                  "fitted and additions are checked by K-fold cross-validation over the load cases.", "",
                  "| check | studies | correct at >= 2x | false alarms |", "|---|---|---|---|"]
        for m, b in summary["by_validation"].items():
            lines.append(f"| {m} | {b['n']} | {_frac(b['correct_at_2x'])} | {_frac(b['false_alarm'])} |")
    if summary.get("load_scale_groups"):
        lines += ["", "## Load scale by the cases scaled", "",
                  "| scaled | studies | correct (all sizes) | correct at >= 2x |", "|---|---|---|---|"]
        for m, b in summary["load_scale_groups"].items():
            lines.append(f"| {m} | {b['n']} | {_frac(b['correct'])} | {_frac(b['correct_at_2x'])} |")
    if summary.get("by_shape"):
        lines += ["", "## Per structure", "", "| structure | studies | correct at >= 2x | false alarms |",
                  "|---|---|---|---|"]
        for shape, b in summary["by_shape"].items():
            lines.append(f"| {shape} | {b['n']} | {_frac(b['correct_at_2x'])} | {_frac(b['false_alarm'])} |")
    if summary.get("errors"):
        lines += ["", "## Errors", "", "| study | kind | error |", "|---|---|---|"]
        for e in summary["errors"]:
            lines.append(f"| {e['study']} | {e['kind']} | {e['error'][:200]} |")
    w = summary["wall_s"]
    lines += ["", f"Wall time: {_g(w['total'])} s in all (generation and diagnosis); diagnosis median "
                  f"{_g(w['diagnose_median'])} s, largest {_g(w['diagnose_max'])} s per study.", ""]
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
        return {"study": f"s{index:04d}", "index": index, "kind": None, "error": f"generation: {exc}",
                "traceback": traceback.format_exc(limit=5), "diagnose_s": 0.0, "wall_s": time.perf_counter() - t0}
    t1 = time.perf_counter()
    rec: dict = {"study": st.folder.name, "index": index}
    try:
        res = diagnose(st.folder, adapter="reference", plots=False)
        doc = res.document
        rec.update(score(st.planted, doc))
    except Exception as exc:                 # a failed diagnosis is a result of the benchmark too
        rec.update({"kind": st.planted["kind"], "where": st.planted.get("where"),
                    "multiple": st.planted.get("multiple"), "error": f"{type(exc).__name__}: {exc}",
                    "traceback": traceback.format_exc(limit=5)})
    t2 = time.perf_counter()
    rec.update({"generate_s": t1 - t0, "diagnose_s": t2 - t1, "wall_s": t2 - t0,
                "threshold_noncentrality": st.planted.get("threshold_noncentrality"),
                "n_candidates": st.planted.get("n_candidates"), "n_measurements": st.planted.get("n_measurements")})
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


def _record(fh, rec: dict, done: dict, args, t0: float) -> None:
    fh.write(json.dumps(rec, default=float) + "\n")
    fh.flush()
    done[rec["index"]] = rec
    mark = ("ERROR " + rec["error"][:60]) if rec.get("error") else (
        "false alarm" if rec["false_alarm"] else
        ("ok" if rec["kind"] == NONE or rec["correct"] else ("wrong" if rec["detected"] else "missed")))
    added = ", ".join(f"{a['effect']}@{a['where']}" for a in rec.get("added", [])) or "-"
    mult = f" x{rec['multiple']:.2f}" if rec.get("multiple") else ""
    print(f"[{len(done):4d}/{args.n}] {rec['study']} {rec['kind']}{mult} @ {rec.get('where')}: "
          f"{added} -> {mark} ({rec['diagnose_s']:.1f} s, {time.perf_counter() - t0:.0f} s so far)",
          flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="blind benchmark of blackbox diagnose")
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("out/blind"))
    ap.add_argument("--docs", action="store_true", help="also write docs/blind.md and docs/blind.json")
    ap.add_argument("--keep", action="store_true", help="keep the study folders (default: only hidden/)")
    ap.add_argument("--workers", type=int, default=1,
                    help="studies side by side on a local Dask cluster of this many workers (results as serial)")
    ap.add_argument("--report-only", action="store_true",
                    help="write the summary of the studies already in OUT/results.jsonl, run nothing")
    args = ap.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.jsonl"
    done = {i: r for i, r in load_results(path).items() if r.get("seed", args.seed) == args.seed}
    t0 = time.perf_counter()
    todo = [] if args.report_only else [i for i in range(args.n) if i not in done]
    # worker processes import this module by name: they need the project on their path
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH", "")]))
    executor = make_executor(workers=args.workers) if args.workers > 1 and todo else SerialExecutor()
    with path.open("a") as fh, executor:
        # blocks of studies, each block mapped over the workers and appended as it comes back
        block = max(1, 2 * executor.workers)
        for b0 in range(0, len(todo), block):
            recs = executor.map(_run_task, [(i, args.seed, str(out), args.keep) for i in todo[b0:b0 + block]])
            for rec in recs:
                _record(fh, rec, done, args, t0)

    results = [done[i] for i in sorted(done) if i < args.n]
    summary = summarize(results)
    settings = {"n": args.n, "seed": args.seed, "workers": args.workers,
                "diagnosis_families": sorted({f for r in results for f in r.get("families", [])})}
    doc = {"settings": settings, "summary": summary, "studies": results}
    (out / "blind.json").write_text(json.dumps(doc, indent=1, default=float))
    md = markdown(summary, settings)
    (out / "blind.md").write_text(md)
    if args.docs:              # the studies one per line, without parameter values: a smaller file
        slim = [{**{k: v for k, v in r.items() if k not in ("added", "traceback", "families")},
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
