"""Defects of test data that no effect kind describes: does ``blackbox diagnose`` say so?

    python benchmarks/unlisted_defects.py --out DIR [--n 4] [--seed 7] [--defects drift dead ...] [--in-holdout]

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
* ``swapped_cases``: the readings of two cases are exchanged (files mixed up);
* ``misplaced_load``: one fitted case's load went into the structure at a neighbouring grid (the
  other end of a member at the declared load point: the actuator on the wrong node), the
  readings measured again from the truth with the study's own noise draws;
* ``tilted_load``: one fitted case's load is turned 15 degrees off its declared direction (an
  actuator mounted askew), measured again the same way;
* ``saturated``: one channel reads at most 60 % of its largest reading (a transducer past its
  range: the larger readings clipped, sign kept);
* ``reversed_case``: one fitted case was loaded the other way (an actuator pushing where the log
  says pull): its readings are the declared ones' negatives;
* ``rig_slip``: in one fitted case the whole specimen moved as a rigid body (the test frame or a
  support base slid): every reading of the case gets one small rigid translation and rotation,
  sized to a noncentrality drawn log-uniform in :data:`LAMBDA_RANGE`;
* ``tilted_sensor``: one translation channel's transducer is mounted 20 degrees off its axis,
  towards another translation measured at the same grid: it reads ``cos 20 u_c + sin 20
  u_c'`` in every case (its readings made from the two channels' recorded ones);
* ``duplicated_case``: one fitted case's readings are a copy of another fitted case's (a file
  saved twice under two case names).
* ``load_cell``: the load at one grid is 15 % less than logged in every case that loads it (the
  load cell of that actuator reads high), measured again from the truth with the study's own
  noise draws; its place is the cases that load the grid.

The last two were first run on a diagnosis that was not changed afterwards, and nothing was
changed for them.
``load_cell`` was first run on the diagnosis of 2026-11-27 (after seed 54).

The case defects go into a fitted case; with ``--in-holdout`` into a hold-out case instead
(:data:`CASE_DEFECTS`; for two cases, the one written over is a hold-out case), where the
search, which never fits a hold-out case, cannot see them and only the hold-out check
(:mod:`blackbox.diagnosis.holdout`) reads them. Its findings are listed with what was added
(``holdout_outlier``, ``holdout_case`` with the factor that fits it or "not predicted").

The two load defects are placed where they move the readings by a noncentrality between 60 and
1e4 (whitened, before any refit), as the unlisted defects of the structure are.

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
import functools
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.blind.frames import TUNED                               # noqa: E402
from benchmarks.blind import generate as gen                            # noqa: E402
from benchmarks.blind.generate import NONE, generate_study              # noqa: E402
from blackbox.study import load_study                                   # noqa: E402
from solver_adapters.bdf import read_deck                               # noqa: E402

DEFECTS = ("drift", "slip", "noisy", "dead", "units", "swapped_cases", "misplaced_load", "tilted_load",
           "saturated", "reversed_case", "rig_slip", "tilted_sensor", "duplicated_case", "load_cell")
TILT = 20.0                         # a tilted sensor's angle off its axis, degrees
LOAD_DEFECTS = ("misplaced_load", "tilted_load", "load_cell")
LOAD_CELL = 0.85                    # the load an actuator whose load cell reads high really applied
CASE_DEFECTS = ("units", "swapped_cases", "misplaced_load", "tilted_load", "reversed_case", "rig_slip",
                "duplicated_case")    # defects of one case (or two), which --in-holdout puts in a hold-out case
LAMBDA_RANGE = (60.0, 1e4)          # noncentrality of a planted defect: clearly detectable, not absurd


def _read(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as f:
        r = csv.DictReader(f)
        return list(r.fieldnames or []), list(r)


def _write(path: Path, fields: list[str], rows: list[dict]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)


def plant(folder: Path, defect: str, rng: np.random.Generator, in_holdout: bool = False) -> dict | None:
    """Write ``defect`` into ``folder/measurements.csv``; returns where it went. ``in_holdout``:
    a case defect goes into a hold-out case (``None`` when the study has none)."""
    fields, rows = _read(folder / "measurements.csv")
    cases = list(dict.fromkeys(r["case"] for r in rows))
    channels = list(dict.fromkeys((r["grid"], r["component"]) for r in rows))
    if defect == "tilted_sensor":
        return _tilted_sensor(folder, fields, rows, rng)
    if defect in ("units", "swapped_cases", "reversed_case", "rig_slip", "duplicated_case"):
        pick = held_cases(folder, cases) if in_holdout else fitted_cases(folder, cases)
        if not pick:
            return None
        if in_holdout and defect in ("duplicated_case", "swapped_cases"):
            # the case written over (or one of the two) is a hold-out case, the other any other
            b = str(rng.choice(pick))
            a = str(rng.choice([c for c in cases if c != b]))
            pick = [a, b]
        if defect == "duplicated_case":
            a, b = pick if in_holdout else (str(x) for x in rng.choice(pick, 2, replace=False))
            va = {(r["grid"], r["component"]): r["value"] for r in rows if r["case"] == a}
            for r in rows:
                if r["case"] == b and (r["grid"], r["component"]) in va:
                    r["value"] = va[(r["grid"], r["component"])]
            where = {"case": b, "copy_of": a}
        elif defect == "rig_slip":
            where = _rig_slip(folder, rows, str(rng.choice(pick)), rng)
        elif defect == "reversed_case":
            c = str(rng.choice(pick))
            for r in rows:
                if r["case"] == c:
                    r["value"] = repr(-float(r["value"]))
            where = {"case": c}
        elif defect == "units":
            c = str(rng.choice(pick))
            for r in rows:
                if r["case"] == c:
                    r["value"] = repr(float(r["value"]) * 1000.0)
            where = {"case": c}
        else:
            a, b = pick if in_holdout else (str(x) for x in rng.choice(pick, 2, replace=False))
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
    peak = max(abs(float(r["value"])) for r in rr)
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
        elif defect == "saturated":
            v = math.copysign(min(abs(v), SATURATION * peak), v)
        r["value"] = repr(v)
    _write(folder / "measurements.csv", fields, rows)
    return {"grid": int(ch[0]), "component": int(ch[1])}


SATURATION = 0.6                    # a saturated channel's range, as a share of its largest reading


def _tilted_sensor(folder: Path, fields: list[str], rows: list[dict], rng: np.random.Generator) -> dict:
    """One translation channel read ``TILT`` degrees off its axis towards another translation
    measured at its grid (module docstring), the channel drawn among those whose mix moves
    most (the largest other component); every case."""
    by = {(r["grid"], r["component"], r["case"]): r for r in rows}
    chans = list(dict.fromkeys((r["grid"], r["component"]) for r in rows if r["component"] in ("1", "2", "3")))
    cases = list(dict.fromkeys(r["case"] for r in rows))
    pairs = [(g, c, c2) for g, c in chans for g2, c2 in chans if g2 == g and c2 != c
             and all((g, c, k) in by and (g, c2, k) in by for k in cases)]
    if not pairs:
        raise ValueError("no grid with two measured translations")
    size = [sum((float(by[(g, c2, k)]["value"]) / float(by[(g, c, k)]["sigma"])) ** 2 for k in cases)
            for g, c, c2 in pairs]
    top = np.argsort(size)[::-1][:max(1, len(pairs) // 4)]
    g, c, c2 = pairs[int(rng.choice(top))]
    t = math.radians(TILT)
    for k in cases:
        a, b = by[(g, c, k)], by[(g, c2, k)]
        a["value"] = repr(math.cos(t) * float(a["value"]) + math.sin(t) * float(b["value"]))
    _write(folder / "measurements.csv", fields, rows)
    return {"grid": int(g), "component": int(c), "towards": int(c2), "degrees": TILT}


def _rig_slip(folder: Path, rows: list[dict], case: str, rng: np.random.Generator) -> dict:
    """Add one rigid-body motion of the whole specimen to ``case``'s readings (module docstring):
    a translation ``t`` and a rotation ``w`` about the measured grids' centre, ``|w| L = |t|``
    (``L`` their largest distance from it), scaled to the drawn noncentrality; each reading in its
    grid's CD system."""
    deck = read_deck(folder / "model.bdf")
    mine = [r for r in rows if r["case"] == case]
    grids = sorted({int(r["grid"]) for r in mine})
    xyz = {g: np.asarray(deck.grids[g].xyz, float) for g in grids}
    frame = dict(zip(grids, deck.displacement_frames(grids)))      # rows: CD axes in basic
    c0 = np.mean(list(xyz.values()), axis=0)
    size = max(float(np.linalg.norm(x - c0)) for x in xyz.values()) or 1.0
    t, w = rng.normal(size=3), rng.normal(size=3)
    t, w = t / np.linalg.norm(t), w / np.linalg.norm(w) / size

    def motion(r) -> float:
        g, k = int(r["grid"]), int(r["component"])
        u = t + np.cross(w, xyz[g] - c0) if k <= 3 else w
        return float(frame[g][(k - 1) % 3] @ u)

    unit = np.array([motion(r) / float(r["sigma"]) for r in mine])
    lam = float(np.exp(rng.uniform(*np.log(LAMBDA_RANGE))))
    a = math.sqrt(lam / float(unit @ unit))
    for r in mine:
        r["value"] = repr(float(r["value"]) + a * motion(r))
    return {"case": case, "noncentrality": lam, "translation": [float(v) for v in a * t],
            "rotation_rad": [float(v) for v in a * w], "about": [float(v) for v in c0]}


def study_loads(folder: Path) -> list[tuple[str, int, int, float]]:
    """The study's load rows ``(case, grid, component, value)`` in its case order (the order the
    generator drew the noise in)."""
    L = load_study(folder).loads
    V = L.values.tocoo()
    rows = sorted(zip(V.col.tolist(), V.row.tolist(), V.data.tolist()))
    return [(L.cases[j], L.dofs[i][0], L.dofs[i][1], v) for j, i, v in rows]


def fitted_cases(folder: Path, cases: list[str]) -> list[str]:
    """``cases`` (in their order) less the study's hold-out cases (study.toml ``holdout_cases``)."""
    toml = (folder / "study.toml").read_text()
    hold = toml.split("holdout_cases", 1)[-1].split("]", 1)[0] if "holdout_cases" in toml else ""
    return [c for c in cases if f'"{c}"' not in hold]


def held_cases(folder: Path, cases: list[str]) -> list[str]:
    """``cases`` (in their order) that are the study's hold-out cases."""
    fitted = fitted_cases(folder, cases)
    return [c for c in cases if c not in fitted]


def _turned(v: np.ndarray, rng: np.random.Generator, degrees: float) -> np.ndarray:
    """``v`` turned by ``degrees`` about a random axis perpendicular to it."""
    n = float(np.linalg.norm(v))
    if n == 0.0:
        return v
    a = np.cross(v / n, rng.normal(size=3))
    a /= np.linalg.norm(a)
    t = math.radians(degrees)
    return v * math.cos(t) + np.cross(a, v) * math.sin(t)


def _moved_loads(truth, loads, case: str, defect: str, rng: np.random.Generator):
    """``loads`` with ``case``'s load misplaced or tilted (module docstring); ``None`` when it
    cannot be (no free neighbour)."""
    rows = [r for r in loads if r[0] == case]
    others = [r for r in loads if r[0] != case]
    if defect == "tilted_load":
        out = []
        for g in dict.fromkeys(r[1] for r in rows):
            for base in (1, 4):                     # forces, then moments, as vectors
                v = np.zeros(3)
                for _, gg, c, val in rows:
                    if gg == g and base <= c < base + 3:
                        v[c - base] += val
                w = _turned(v, rng, 15.0)
                out += [(case, g, base + i, float(w[i])) for i in range(3) if w[i] != 0.0]
        return others + out
    if defect == "load_cell":
        g = int(rng.choice(list(dict.fromkeys(r[1] for r in rows))))
        return [(c, gg, k, v * LOAD_CELL if gg == g else v) for c, gg, k, v in loads]
    held = {g: set(s.components) for s in truth.spc1s for g in s.grids}
    nbr: dict[int, set[int]] = {}
    for m in [*truth.cbars.values(), *truth.rods.values()]:
        nbr.setdefault(m.ga, set()).add(m.gb)
        nbr.setdefault(m.gb, set()).add(m.ga)
    moved = {}
    for g in dict.fromkeys(r[1] for r in rows):
        free = sorted(n for n in nbr.get(g, ()) if not held.get(n))
        if not free:
            return None
        moved[g] = int(rng.choice(free))
    return others + [(case, moved[g], c, v) for _, g, c, v in rows]


def kept_readings(folder: Path, sim, clean) -> float | None:
    """The noncentrality of the readings ``sim`` against the ``clean`` ones (whitened, before any
    refit); when it is in :data:`LAMBDA_RANGE` they are written as ``folder``'s measurements,
    else ``None`` and nothing written."""
    lam = float(np.sum(((sim.rows.true - clean.rows.true) / clean.rows.sigma) ** 2))
    if not LAMBDA_RANGE[0] <= lam <= LAMBDA_RANGE[1]:
        return None
    rows = ["case,grid,component,value,sigma"]
    rows += [f"{sim.cases[ci]},{g},{c},{float(v)!r},{float(s)!r}"
             for (g, c), ci, v, s in zip(sim.rows.dofs, sim.rows.case_index, sim.values, sim.rows.sigma)]
    (folder / "measurements.csv").write_text("\n".join(rows) + "\n")
    return lam


def plant_load(st, defect: str, rng: np.random.Generator, in_holdout: bool = False) -> dict | None:
    """Measure the study again with one fitted case's load misplaced or tilted, or the load at
    one of its grids scaled in every case (``load_cell``; loads.csv keeps the declared loads;
    ``in_holdout``: a hold-out case's); ``None`` when no case qualifies."""
    p = st.planted
    truth = read_deck(st.hidden / "truth" / "truth.bdf")
    seed = json.loads((st.hidden / "truth.json").read_text())["seed"]
    noise = gen.NoiseConfig(**p["noise"])
    loads = study_loads(st.folder)
    cases = list(dict.fromkeys(r[0] for r in loads))
    rest = (p["joints"], p["away_grids"], [], noise, seed)
    clean = gen.simulate_study(truth, loads, *rest)
    eligible = held_cases(st.folder, cases) if in_holdout else fitted_cases(st.folder, cases)
    for i in rng.permutation(len(cases)).tolist():
        case = cases[i]
        if case not in eligible:
            continue
        changed = _moved_loads(truth, loads, case, defect, rng)
        if changed is None:
            continue
        mine = [r for r in loads if r[0] == case]
        # each declared grid and where its load went in (the case's rows come last, in order)
        moved = sorted({(r[1], m[1]) for r, m in zip(mine, changed[len(changed) - len(mine):])})
        # the load cell's grid and the cases that load it
        scaled = sorted({r[1] for r, m in zip(loads, changed) if m[3] != r[3]}) if defect == "load_cell" else []
        changed.sort(key=lambda r: cases.index(r[0]))
        sim = gen.simulate_study(truth, changed, *rest)
        lam = kept_readings(st.folder, sim, clean)
        if lam is None:
            continue
        if defect == "load_cell":
            return {"cases": sorted({r[0] for r in loads if r[1] in scaled}, key=cases.index), "load_at": scaled,
                    "factor": LOAD_CELL, "noncentrality": lam}
        return {"case": case, "noncentrality": lam,
                **({"moved": [list(p) for p in moved]} if defect == "misplaced_load" else {})}
    return None


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


def run_one(index: int, seed: int, family: str, defect: str, out: Path, in_holdout: bool = False) -> dict | None:
    st = generate_study(index, seed, out / defect, kind=NONE, shape=family, style="plain")
    rng = np.random.default_rng([seed, index, DEFECTS.index(defect)])
    where = (plant_load(st, defect, rng, in_holdout) if defect in LOAD_DEFECTS
             else plant(st.folder, defect, rng, in_holdout))
    if where is None:
        return None
    doc, error, wall = diagnosed(st, family, defect, where)
    if error is not None:
        return error
    added = [(a["effect"], a["where"], a.get("of"), a.get("component"), a.get("pattern"), a.get("case"))
             for a in doc["added"]]
    # what the hold-out check found in the hold-out cases (blackbox.diagnosis.holdout)
    hc = doc.get("holdout_check") or {}
    added += [("holdout_outlier", [o["grid"]], "data", o["component"], None, o["case"]) for o in hc.get("outliers", [])]
    added += [("holdout_case", [c["case"]], c["of"], None, _reads_as(c), c["case"]) for c in hc.get("cases", [])]
    hot = (doc.get("hotspots") or [None])[0]
    return {"study": st.folder.name, "family": family, "defect": defect, "where": where,
            "verdict": doc["verdict"], "added": added,
            "structural": [a for a in added if a[2] == STRUCTURE_OF],
            "before": doc["before"]["reduced_chi2"], "after": doc["after"]["reduced_chi2"],
            "hotspot": hot, "wall_s": wall}


def _reads_as(c: dict) -> str:
    """What the hold-out check read a hold-out case as, in a few words."""
    how = c.get("reads_as")
    if how in ("load_scale", "readings_scale"):
        return f"{how.split('_')[0]} x {c['scale']:.3g}"
    other = f"case {c.get('other')}'s " + ("response, its readings set aside" if c.get("other_response") else "readings")
    if how in ("load_tilt", "misplaced_load"):
        loads = c["load"]["loads"]
        return "; ".join(f"load at {x['grid']} turned {x['angle_deg']:.3g} deg" if how == "load_tilt"
                         else f"load at {x['grid']} put in at {x['moved_to']}" for x in loads)
    return {"other_case": other, "rigid_motion": "rigid motion"}.get(how, "not predicted")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--n", type=int, default=4, help="studies per defect")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--defects", nargs="+", choices=DEFECTS, default=None)
    ap.add_argument("--in-holdout", action="store_true",
                    help="put each case defect into a hold-out case (studies without one are skipped); "
                         "the channel defects, which touch every case, are left out")
    args = ap.parse_args(argv)
    defects = args.defects or list(CASE_DEFECTS if args.in_holdout else DEFECTS)
    if args.in_holdout and set(defects) - set(CASE_DEFECTS):
        ap.error(f"--in-holdout takes the case defects only: {', '.join(CASE_DEFECTS)}")
    one = functools.partial(run_one, in_holdout=True) if args.in_holdout else run_one
    run_defects(one, table, DEFECTS, defects, args.n, args.seed, args.out, tries=5 * args.n)
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
    """One line per study: the defect and where, what was added (with the pattern named; the
    hold-out check's findings too), the verdict, whether it was put on the data at the defect's
    place with nothing of the structure added, and whether everything added or found is at the
    defect's place (of the data or not: a hold-out case found not predicted is located but not
    said to be the data)."""
    out = ["| study | family | defect | at | added | verdict | on the data, at its place, nothing else | at its place, nothing else |",
           "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.get("error"):
            out.append(f"| {r['study']} | {r['family']} | {r['defect']} | {r['where']} | error: {r['error'][:80]} | | no | no |")
            continue
        w = r["where"]
        at = f"{w['grid']}/{w['component']}" if "grid" in w else ", ".join(w.get("cases") or [w.get("case")])
        added = "; ".join(f"{a[0]} @ {','.join(map(str, a[1]))}" + (f" ({a[4]})" if a[4] else "") for a in r["added"]) or "nothing"
        if "grid" in w:
            here = [a[1][:1] == [w["grid"]] for a in r["added"]]
        else:
            # the case: set aside, scaled or read as another, or one reading of it an outlier; a
            # load cell's grid (its cases are the cases that load it)
            cases = set(w.get("cases") or [w.get("case")])
            grids = set(w.get("load_at") or [])
            here = [set(map(str, a[1])) <= cases or a[5] in cases or bool(grids and set(a[1]) <= grids)
                    for a in r["added"]]
        located = bool(here) and all(here)
        placed = located and all(a[2] == "data" for a in r["added"])
        out.append(f"| {r['study']} | {r['family']} | {r['defect']} | {at} | {added} | {r['verdict']} | "
                   f"{'yes' if placed else 'no'} | {'yes' if located else 'no'} |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
