"""Defects of test data that no effect kind describes: does ``blackbox diagnose`` say so?

    python benchmarks/unlisted_defects.py --out DIR [--n 4] [--seed 7] [--defects drift dead ...]

Clean studies of the blind benchmark's generator (``benchmarks/blind/generate.py``, no planted
effect, families drawn in turn) get one defect written into their ``measurements.csv`` that is
in no list of the diagnosis, each of a kind real static tests have:

* ``drift``: one channel's zero drifts linearly over the test (case order), to 3x its largest
  reading's noise band at the last case (a thermal drift of a transducer);
* ``slip``: one channel's zero jumps by the same amount from the middle case on (a sensor
  knocked during the test);
* ``noisy``: one channel's noise is 6x its declared sigma (a loose mount, a bad cable);
* ``dead``: one channel reads only noise around zero (an unplugged transducer);
* ``units``: one case's readings are in millimetres where the others are in metres (x 1000);
* ``swapped_cases``: the readings of two cases are exchanged (files mixed up).

What the tool should say: the defect as a defect of the data at its place (a sensor offset,
gain or outliers at the channel, a load scale of the case), or "unexplained" with the misfit
located there; what it must not do is add effects of the structure and call the data
explained. Each row says what was added, whether any structural effect was among it, the
verdict, and the largest hotspot. No tuning was done on these defects: they are a check of
what the diagnosis does with data it has no words for.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.blind.frames import TUNED                               # noqa: E402
from benchmarks.blind.generate import NONE, generate_study              # noqa: E402

DEFECTS = ("drift", "slip", "noisy", "dead", "units", "swapped_cases")


def _read(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as f:
        r = csv.DictReader(f)
        return list(r.fieldnames or []), list(r)


def _write(path: Path, fields: list[str], rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)


def plant(folder: Path, defect: str, rng: np.random.Generator) -> dict:
    """Write ``defect`` into ``folder/measurements.csv``; returns where it went."""
    fields, rows = _read(folder / "measurements.csv")
    cases = list(dict.fromkeys(r["case"] for r in rows))
    channels = list(dict.fromkeys((r["grid"], r["component"]) for r in rows))
    fitted = set(cases)
    toml = (folder / "study.toml").read_text()
    hold = [c for c in cases if f'"{c}"' in toml.split("holdout_cases", 1)[-1].split("]", 1)[0]] \
        if "holdout_cases" in toml else []
    fitted -= set(hold)
    if defect in ("units", "swapped_cases"):
        pick = sorted(fitted, key=cases.index)
        if defect == "units":
            c = str(rng.choice(pick))
            for r in rows:
                if r["case"] == c:
                    r["value"] = repr(float(r["value"]) * 1000.0)
            where = {"case": c}
        else:
            a, b = (str(x) for x in rng.choice(pick, 2, replace=False))
            va = {(r["grid"], r["component"]): r["value"] for r in rows if r["case"] == a}
            vb = {(r["grid"], r["component"]): r["value"] for r in rows if r["case"] == b}
            for r in rows:
                k = (r["grid"], r["component"])
                if r["case"] == a and k in vb:
                    r["value"] = vb[k]
                elif r["case"] == b and k in va:
                    r["value"] = va[k]
            where = {"cases": [a, b]}
        _write(folder / "measurements.csv", fields, rows)
        return where
    # a channel that moves: its largest reading at least 20 sigma
    big = []
    for ch in channels:
        rr = [r for r in rows if (r["grid"], r["component"]) == ch]
        peak = max(abs(float(r["value"])) for r in rr)
        sig = float(np.median([float(r["sigma"]) for r in rr]))
        if peak > 20 * sig:
            big.append(ch)
    ch = big[int(rng.integers(len(big)))] if big else channels[int(rng.integers(len(channels)))]
    rr = [r for r in rows if (r["grid"], r["component"]) == ch]
    sig = float(np.median([float(r["sigma"]) for r in rr]))
    n = len(cases)
    for r in rr:
        i = cases.index(r["case"])
        v, s = float(r["value"]), float(r["sigma"])
        if defect == "drift":
            v += 3.0 * sig * 3.0 * i / max(n - 1, 1)
        elif defect == "slip":
            v += 9.0 * sig * (i >= n // 2)
        elif defect == "noisy":
            v += float(rng.normal(0.0, 6.0 * s))
        elif defect == "dead":
            v = float(rng.normal(0.0, s))
        r["value"] = repr(v)
    _write(folder / "measurements.csv", fields, rows)
    return {"grid": int(ch[0]), "component": int(ch[1])}


STRUCTURE_OF = "structure"


def diagnosed(st, family: str, defect: str, where) -> tuple[dict | None, dict | None, float]:
    """``(document, error row, wall s)``: the study's diagnosis (its JSON document) with default
    settings, or, when it raises, the row that reports the error (reported, not hidden)."""
    from blackbox.commands.diagnose import run

    t0 = time.perf_counter()
    try:
        res = run(st.folder, plots=False)
        return json.loads(json.dumps(res.document, default=float)), None, time.perf_counter() - t0
    except Exception as exc:
        return None, {"study": st.folder.name, "family": family, "defect": defect, "where": where,
                      "error": f"{type(exc).__name__}: {exc}"[:300]}, time.perf_counter() - t0


def run_one(index: int, seed: int, family: str, defect: str, out: Path) -> dict:
    st = generate_study(index, seed, out / defect, kind=NONE, shape=family, style="plain")
    where = plant(st.folder, defect, np.random.default_rng([seed, index, DEFECTS.index(defect)]))
    doc, error, wall = diagnosed(st, family, defect, where)
    if error is not None:
        return error
    added = [(a["effect"], a["where"], a.get("of"), a.get("component"), a.get("pattern")) for a in doc["added"]]
    hot = (doc.get("hotspots") or [None])[0]
    return {"study": st.folder.name, "family": family, "defect": defect, "where": where,
            "verdict": doc["verdict"], "added": added,
            "structural": [a for a in added if a[2] == STRUCTURE_OF],
            "before": doc["before"]["reduced_chi2"], "after": doc["after"]["reduced_chi2"],
            "hotspot": hot, "wall_s": wall}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--n", type=int, default=4, help="studies per defect")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--defects", nargs="+", choices=DEFECTS, default=list(DEFECTS))
    args = ap.parse_args(argv)
    run_defects(run_one, table, DEFECTS, args.defects, args.n, args.seed, args.out)
    return 0


def run_defects(run_one, table, all_defects, defects, n: int, seed: int, out: Path, tries: int | None = None,
                families: tuple[str, ...] = TUNED) -> list:
    """``n`` studies per defect (``run_one(index, seed, family, defect, out)``, ``families`` (the
    tuned ones by default) in turn from the defect's place in ``all_defects``; a ``None`` row, a
    study with no place for the defect, is skipped, at most ``tries`` indices per defect), each
    row printed as it comes; ``out/results.json`` and the table at the end."""
    rows = []
    fams = list(families)
    for defect in defects:
        done = 0
        for i in range(tries or n):
            if done == n:
                break
            r = run_one(i, seed, fams[(i + all_defects.index(defect)) % len(fams)], defect, out)
            if r is None:
                continue
            done += 1
            rows.append(r)
            print(json.dumps(r, default=str), flush=True)
    (out / "results.json").write_text(json.dumps(rows, indent=1, default=str))
    print(table(rows))
    return rows


def table(rows: list[dict]) -> str:
    """One line per study: the defect and where, what was added (with the pattern named), the
    verdict, and whether it was put on the data at the defect's place with nothing of the
    structure added."""
    out = ["| study | family | defect | at | added | verdict | on the data, at its place, nothing else |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("error"):
            out.append(f"| {r['study']} | {r['family']} | {r['defect']} | {r['where']} | error: {r['error'][:80]} | | no |")
            continue
        w = r["where"]
        at = f"{w['grid']}/{w['component']}" if "grid" in w else ", ".join(w.get("cases") or [w.get("case")])
        added = "; ".join(f"{a[0]} @ {','.join(map(str, a[1]))}" + (f" ({a[4]})" if a[4] else "") for a in r["added"]) or "nothing"
        if "grid" in w:
            placed = bool(r["added"]) and all(a[2] == "data" and a[1][:1] == [w["grid"]] for a in r["added"])
        else:
            cases = set(w.get("cases") or [w.get("case")])
            placed = bool(r["added"]) and all(a[2] == "data" and set(map(str, a[1])) <= cases for a in r["added"])
        out.append(f"| {r['study']} | {r['family']} | {r['defect']} | {at} | {added} | {r['verdict']} | "
                   f"{'yes' if placed else 'no'} |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
