"""Large measurement sets: time and peak memory of ``blackbox identify`` on ~200k rows.

Builds a copy of the car fixture with N random load cases (3 loaded DOFs each, seeded), simulates
measurements at the joint's DOFs and at a few grids away from it (5 % noise, ``blackbox
simulate``), then runs ``blackbox identify`` as a subprocess and reads its wall time and peak
resident memory (the child's ``ru_maxrss``). The plots are written as for any study.

    python benchmarks/large_data.py --cases 4200 --out /tmp/large   # ~200k measurement rows

Prints one Markdown table row per run; the figures quoted in the docs come from this script.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def build(out: Path, n_cases: int, seed: int = 7) -> Path:
    """A car study with ``n_cases`` random load cases and its simulated measurements."""
    from blackbox.commands import simulate
    from blackbox.commands.output import write_output
    from blackbox.study import load_study

    src = out / "src"
    if src.exists():
        shutil.rmtree(src)
    shutil.copytree(ROOT / "fixtures" / "car", src, ignore=shutil.ignore_patterns(
        ".blackbox_cache", "measurements.csv", "truth.json", "*.png"))
    study = load_study(src)
    rng = np.random.default_rng(seed)
    free = sorted(g for g, grid in study.deck.grids.items() if not grid.ps)
    rows = ["case,grid,component,value"]
    for i in range(n_cases):
        for g in rng.choice(free, 3, replace=False):
            rows.append(f"C{i + 1},{int(g)},{int(rng.integers(1, 4))},{float(rng.normal(0, 500.0))!r}")
    (src / "loads.csv").write_text("\n".join(rows) + "\n")
    away = [int(g) for g in rng.choice(free, 5, replace=False)]
    truth = src / "truth.toml"
    truth.write_text(f"seed = {seed}\n[[joints]]\nname = \"{study.config.joints[0].name}\"\nmodel = \"simple\"\n"
                     f"value = 1.15e5\n[noise]\nrelative = 0.05\nfloor = 0.02\n[measure]\njoint = true\n"
                     f"away_grids = {away}\n")
    res = simulate.run(src, truth)
    dst = out / "study"
    if dst.exists():
        shutil.rmtree(dst)
    write_output(dst, "simulate", res.write)
    return dst


def identify(study: Path, out: Path) -> dict:
    if out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "blackbox.cli", "identify", str(study), "--out", str(out),
                           "--no-cache"], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    if proc.returncode not in (0, 4):
        raise SystemExit(f"identify failed ({proc.returncode}):\n{proc.stderr}")
    res = json.loads((out / "result.json").read_text())
    sizes = {p.name: _png_size(p) for p in out.glob("*.png")}
    return {"wall_s": wall, "peak_rss_mb": peak / 2**20, "n_obs": res["fit"]["n_obs"],
            "iterations": res["iterations"], "exit": proc.returncode, "png_px": sizes}


def _png_size(p: Path) -> tuple[int, int]:
    head = p.read_bytes()[:24]
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=4200)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    study = build(args.out, args.cases)
    t_build = time.perf_counter() - t0
    r = identify(study, args.out / "identify")
    print("| cases | rows | build + simulate s | identify wall s | peak RSS MB | iterations | exit | largest plot px |")
    print("|---|---|---|---|---|---|---|---|")
    big = max(r["png_px"].values(), key=lambda wh: wh[0] * wh[1]) if r["png_px"] else (0, 0)
    print(f"| {args.cases} | {r['n_obs']} | {t_build:.1f} | {r['wall_s']:.1f} | {r['peak_rss_mb']:.0f} | "
          f"{r['iterations']} | {r['exit']} | {big[0]}x{big[1]} |")


if __name__ == "__main__":
    main()
