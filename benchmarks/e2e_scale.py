"""A large study end to end: `blackbox identify` of a generated car-body-like frame with one
flexible joint, from its study folder to its report, with profile intervals.

    python benchmarks/e2e_scale.py --size 834x200 [--keep DIR] [--json OUT]

The study (untimed) is written as ``blackbox.structures.write_study`` writes the generated body
(``tube_body(n_long, n_around)``: ``6 n_long n_around`` DOFs and the roof joint's branch grids;
12 load cases of random forces and moments at the 40 free grids nearest the joint, as a test
loads the region it is about), its measurements simulated by ``blackbox simulate`` with the
joint at 1e5 N m/rad (3 % noise, the joint's DOFs and the 20 grids nearest it measured). Then
``blackbox identify STUDY --out OUT --no-cache`` runs as a fresh process (the backend as the
study's ``auto`` chooses: PARDISO from 2e4 DOFs when pypardiso is installed), and the script
reports its wall time, its CPU time, its peak resident memory (``ru_maxrss`` of the child), the
solver's share (``result.json``'s ``solver.wall_s``: reading the deck, assembling, factorizing
and solving the batch) and the estimate against the truth. One run on one machine: the shares,
not the seconds, carry to another.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def build(folder: Path, n_long: int, n_around: int) -> Path:
    from blackbox.commands.simulate import run as simulate
    from blackbox.structures import tube_body, write_study

    import numpy as np

    f = tube_body(n_long, n_around)
    (jname, jgrids), = f.joints
    # a test loads and reads the body near the joint it is about (loads at random grids of a
    # million DOFs hardly reach it): 12 cases of random forces and moments at the 40 free grids
    # nearest the joint, the joint's DOFs and the 20 grids nearest it read
    centre = np.array(f.grids[jgrids[0]])
    taken = set(jgrids) | set(f.spcs)
    near = sorted((g for g in f.grids if g not in taken), key=lambda g: np.linalg.norm(np.array(f.grids[g]) - centre))
    rng = np.random.default_rng(3)
    loads = []
    for c in range(12):
        for g in rng.choice(near[:40], size=3, replace=False):
            comp = int(rng.integers(1, 7))
            loads.append((f"L{c + 1}", int(g), comp, float((100.0 if comp <= 3 else 10.0) * rng.uniform(-1, 1))))
    src = write_study(folder / "source", f, loads, f"tube-{n_long}x{n_around}", initial=1.0e4)
    away = sorted(near[:20])
    (src / "truth.toml").write_text(
        f"seed = 1\n\n[[joints]]\nname = \"{jname}\"\nvalue = 1.0e5\n\n"
        f"[noise]\nrelative = 0.03\nfloor = 0.05\n\n[measure]\njoint = true\naway_grids = {away}\n")
    study = folder / "study"
    simulate(src, src / "truth.toml", adapter="reference").write(study)
    return study


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", default="834x200", help="N_LONGxN_AROUND (834x200: about 1e6 DOFs)")
    ap.add_argument("--keep", type=Path, help="build the study here and keep it")
    ap.add_argument("--json", type=Path, help="also write the figures here")
    args = ap.parse_args(argv)
    n_long, n_around = (int(x) for x in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory(prefix="blackbox-e2e-") as tmp:
        base = args.keep or Path(tmp)
        t0 = time.perf_counter()
        study = base / "study" if (base / "study" / "study.toml").exists() else build(base, n_long, n_around)
        build_s = time.perf_counter() - t0
        out = base / "identify"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "blackbox.cli", "identify", str(study), "--out", str(out),
                              "--no-cache"], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if run.returncode not in (0, 4):
            print(run.stdout, run.stderr, file=sys.stderr)
            return 1
        res = json.loads((out / "result.json").read_text())
        solver = res.get("solver") or {}
        dofs = 6 * len([ln for ln in (study / "model.bdf").read_text().splitlines() if ln.startswith("GRID")])
        doc = {"size": args.size, "dofs_approx": dofs, "build_s": round(build_s, 1), "identify_wall_s": round(wall, 2),
               "identify_cpu_s": round((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), 2),
               "peak_rss_gb": round(after.ru_maxrss / 2**20, 2), "solver_wall_s": solver.get("wall_s"),
               "solver": {k: solver.get(k) for k in ("adapter", "runs", "right_hand_sides", "backend") if k in solver},
               "exit": run.returncode, "converged": res.get("converged"),
               "estimates": [{k: p.get(k) for k in ("joint", "name", "value", "ci_low", "ci_high")}
                             for p in res.get("parameters", [])][:9]}
        if doc["solver_wall_s"]:
            doc["solver_share"] = round(doc["solver_wall_s"] / wall, 3)
        print(json.dumps(doc, indent=1))
        if args.json:
            args.json.write_text(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
