"""``blackbox population``: coverage of its intervals, and its cost on the car fixture.

    python benchmarks/population.py [--workers 2] [--part coverage|car|all] [--out docs/population.json]

**Coverage** (``blackbox.population.coverage.population_coverage``): repeated simulated
populations, every specimen's ``log k`` drawn per parameter from ``N(log centre, tau^2)``, its
measurements simulated with relative noise (the noise model of ``blackbox simulate``), every
specimen fitted from one tenth of the centre, then the population; the share of replicates whose
interval holds the true centre (median) and the true spread (coefficient of variation), pooled
over the parameters and per parameter, with the binomial band. Two generated structures (one
condensation each; every specimen of every replicate shares it):

* ``star``: one 3-branch joint (9 springs, ``blackbox.structures.star_joint_frame(3, seed=2)``,
  12 random load cases, the joint's 12 DOFs measured), centre 5e4 N m/rad, spread 20 %;
* ``portal``: two 2-branch joints (6 springs, ``braced_portal()``, 12 random load cases, both
  joints' 18 DOFs measured), centres 1e5 / 8e4 / 1.2e5, spreads 20 / 10 / 30 %.

Each at 4, 8 and 30 specimens and two noise levels: one where every specimen likelihood passes the
quadratic check (``--replicates``, 400, for 4 and 8 specimens, half for 30), one where the exact
profile likelihoods are tabulated (portal 2 %, star 10 %; half as many replicates: each costs
more), and at 30 specimens there once more with the quadratic approximation forced everywhere
(what the exact likelihood changes).

**Car**: ``--specimens`` (30) studies simulated from the car fixture (``fixtures/car``, 9 springs
of joint JB; centre 1e5 N m/rad, spread 20 %, its own noise model and measured DOFs), then
``blackbox population`` on the first 8 and on all of them, serially and on a local Dask cluster
of ``--workers`` processes (loopback), each without the solver cache: wall time, solver runs
(one per specimen), the specimen and population stages.

The result goes to ``--out`` (JSON) and is summarised on stdout; docs/population.md quotes it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))


def designs():
    """The two coverage structures: ``{name: (model, dofs, centre, spread)}``."""
    from blackbox.condensation import CondensedModel, condense
    from blackbox.joints import make_joint
    from blackbox.structures import braced_portal, random_loads, star_joint_frame
    from conftest import adapter_of, load_matrix

    out = {}
    for name, f, centre, spread in (
            ("star", star_joint_frame(3, seed=2), np.full(9, 5e4), np.full(9, 0.2)),
            ("portal", braced_portal(), np.array([1e5, 8e4, 1.2e5, 1e5, 8e4, 1.2e5]),
             np.array([0.2, 0.1, 0.3, 0.2, 0.1, 0.3]))):
        joints = [make_joint(n, g, "simple") for n, g in f.joints]
        boundary = [d for j in joints for d in j.dofs]
        c = condense(adapter_of(f), load_matrix(random_loads(f, 12, seed=1 if name == "star" else 3)), boundary)
        out[name] = (CondensedModel(c, joints), boundary, centre, spread)
    return out


def coverage_part(executor, replicates: int, say) -> list[dict]:
    from blackbox.population.coverage import binomial_band, population_coverage

    rows = []
    for name, (model, dofs, centre, spread) in designs().items():
        low, high = {"star": (0.01, 0.1), "portal": (0.003, 0.02)}[name]
        for S in (4, 8, 30):
            runs = [(low, 0.05, "quadratic likelihoods", 1), (high, 0.05, "exact where needed", 2)]
            if S == 30:
                runs.append((high, np.inf, "quadratic forced", 2))
            for noise, qrtol, label, fewer in runs:
                R = (replicates if S < 30 else replicates // 2) // fewer
                t = population_coverage(model, dofs, range(len(model.c.cases)), centre, spread, S, replicates=R,
                                        noise=noise, seed=7, quadratic_rtol=qrtol, executor=executor)
                p = len(centre)
                row = {"structure": name, "joints": len(set(model.assembly.param_joint)), "parameters": p,
                       "specimens": S, "noise": noise, "likelihoods": label, "replicates": R,
                       "exact_share": t.exact_share,
                       "centre_coverage": float(t.centre_hit.mean()), "spread_coverage": float(t.spread_hit.mean()),
                       "centre_per_parameter": t.centre_coverage().tolist(),
                       "spread_per_parameter": t.spread_coverage().tolist(),
                       "band_pooled": binomial_band(R * p), "band_per_parameter": binomial_band(R),
                       "median_centre_ratio": float(np.median(t.centre_width)),
                       "median_spread_high": float(np.median(t.spread_high)), "wall_s": t.wall_s}
                rows.append(row)
                say(f"{name:6s} S={S:2d} noise={noise:<5g} {label:22s} R={R}: centre {row['centre_coverage']:.3f} "
                    f"spread {row['spread_coverage']:.3f} (band {row['band_pooled'][0]:.3f}-"
                    f"{row['band_pooled'][1]:.3f}; per parameter centre {min(row['centre_per_parameter']):.2f}-"
                    f"{max(row['centre_per_parameter']):.2f}, spread {min(row['spread_per_parameter']):.2f}-"
                    f"{max(row['spread_per_parameter']):.2f}, band {row['band_per_parameter'][0]:.2f}-"
                    f"{row['band_per_parameter'][1]:.2f}); exact {t.exact_share:.2f}; {t.wall_s:.0f} s")
    return rows


def car_part(workers: int, n_specimens: int, say) -> dict:
    from blackbox.commands.population import simulate_specimens as make_specimens

    tmp = Path(tempfile.mkdtemp(prefix="blackbox-population-bench-"))
    try:
        t0 = time.perf_counter()
        folders = make_specimens(ROOT / "fixtures" / "car", tmp / "specimens", n_specimens, 1e5, 0.2, seed=11)
        say(f"car: {n_specimens} specimen studies simulated in {time.perf_counter() - t0:.1f} s")
        runs = []
        for n in (8, n_specimens):
            for w in (None, workers):
                out = tmp / f"out_{n}_{w or 0}"
                cmd = [sys.executable, "-m", "blackbox.cli", "population", *map(str, folders[:n]), "--out", str(out),
                       "--no-cache"] + (["--workers", str(w)] if w else [])
                t1 = time.perf_counter()
                proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp)
                wall = time.perf_counter() - t1
                if proc.returncode not in (0, 4):
                    raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr}")
                doc = json.loads((out / "population.json").read_text())
                row = {"specimens": n, "workers": w or 1, "executor": doc["executor"], "exit": proc.returncode,
                       "wall_s_command": wall, "wall_s": doc["wall_s"], "solver_runs": doc["solver"]["runs"],
                       "right_hand_sides": doc["solver"]["right_hand_sides"],
                       "solver_wall_s": doc["solver"]["wall_s"],
                       "exact_likelihoods": sum(p["likelihood"] == "exact profile" for s in doc["specimens"]
                                                for p in s["parameters"]),
                       "differ_p": doc["specimens_differ"]["p_value"],
                       "centres": [p["center"] for p in doc["parameters"]],
                       "spreads": [p["spread"] for p in doc["parameters"]],
                       "command": "blackbox population " + " ".join(f.name for f in folders[:n][:2])
                                  + " ... --out OUT --no-cache" + (f" --workers {w}" if w else "")}
                runs.append(row)
                say(f"car: {n} specimens, {row['executor']}: {wall:.1f} s (command; specimens "
                    f"{doc['wall_s']['specimens']:.1f} s, population fit {doc['wall_s']['population']:.1f} s), "
                    f"{row['solver_runs']} solver runs, exit {proc.returncode}")
        return {"specimens": n_specimens, "centre": 1e5, "spread": 0.2, "seed": 11, "runs": runs}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def markdown(doc: dict) -> str:
    """The coverage table and the car table of docs/population.md, from the JSON."""
    out = []
    cov = doc.get("coverage")
    if cov:
        out += ["| structure | specimens | noise | likelihoods | exact | replicates | centre | spread | band (pooled) | "
                "centre per parameter | spread per parameter | band (per parameter) | median centre hi/lo | "
                "median spread high |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in cov["rows"]:
            cp, sp, b1, b2 = r["centre_per_parameter"], r["spread_per_parameter"], r["band_pooled"], r["band_per_parameter"]
            out.append(f"| {r['structure']} ({r['joints']} joint{'s' if r['joints'] > 1 else ''}, {r['parameters']} springs) "
                       f"| {r['specimens']} | {100 * r['noise']:g} % | {r['likelihoods']} | {r['exact_share']:.2f} | "
                       f"{r['replicates']} | {r['centre_coverage']:.3f} | {r['spread_coverage']:.3f} | "
                       f"{b1[0]:.3f}-{b1[1]:.3f} | {min(cp):.2f}-{max(cp):.2f} | {min(sp):.2f}-{max(sp):.2f} | "
                       f"{b2[0]:.2f}-{b2[1]:.2f} | {r['median_centre_ratio']:.2f} | {100 * r['median_spread_high']:.0f} % |")
        out += ["", f"({cov['executor']}; {doc['machine']['cpus']} CPUs, load average at the start "
                    f"{doc['machine']['load_average_at_start'][0]:.1f}.)", ""]
    car = doc.get("car")
    if car:
        out += ["| specimens | executor | command wall (s) | specimens stage (s) | population fit (s) | solver runs | "
                "right-hand sides | solver wall (s) | exact likelihoods | exit |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in car["runs"]:
            out.append(f"| {r['specimens']} | {r['executor']} | {r['wall_s_command']:.1f} | {r['wall_s']['specimens']:.1f} | "
                       f"{r['wall_s']['population']:.1f} | {r['solver_runs']} | {r['right_hand_sides']} | "
                       f"{r['solver_wall_s']:.2f} | {r['exact_likelihoods']} | {r['exit']} |")
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--replicates", type=int, default=400)
    ap.add_argument("--specimens", type=int, default=30)
    ap.add_argument("--part", choices=["coverage", "car", "all"], default="all")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "population.json")
    ap.add_argument("--markdown", action="store_true", help="print the tables of docs/population.md from --out")
    args = ap.parse_args(argv)
    if args.markdown:
        print(markdown(json.loads(args.out.read_text())), end="")
        return 0

    def say(s):
        print(s, flush=True)

    doc = json.loads(args.out.read_text()) if args.out.is_file() else {}
    doc["machine"] = {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count(),
                      "load_average_at_start": os.getloadavg()}
    if args.part in ("coverage", "all"):
        from blackbox.parallel import make_executor
        with make_executor(args.workers if args.workers > 1 else None) as ex:
            doc["coverage"] = {"replicates": args.replicates, "executor": ex.description,
                               "rows": coverage_part(ex, args.replicates, say)}
    if args.part in ("car", "all"):
        doc["car"] = car_part(args.workers, args.specimens, say)
    args.out.write_text(json.dumps(doc, indent=2) + "\n")
    say(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
