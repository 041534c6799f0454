"""``blackbox diagnose`` through MYSTRAN, serially against ``--workers N``, on a generated frame.

    python benchmarks/diagnose_parallel.py [--size 12x16] [--workers 2]

Builds a study in a temporary folder: ``blackbox.structures.tube_body(n_long, n_around)`` (a
car-body-like tube frame, ``6 * n_long * n_around`` DOFs plus the roof joint's branch grids, the
joint ``JR`` declared as the simple model), 12 seeded load cases
(``blackbox.structures.random_loads``), measurements simulated by the reference solver from the
joint at 1e5 with 3 % noise (floor 5 %) on the joint and 20 grids spread over the frame, then
``adapter = "mystran"``. Runs ``blackbox.commands.diagnose.run`` on it serially and with a local
Dask cluster of ``--workers`` processes (started and warmed up before the clock starts; no run
cache either way), checks that the two documents agree apart from timings and solver-run counts,
and prints the wall times, the speed-up ``S`` and the Karp-Flatt serial fraction
``e = (1/S - 1/p) / (1 - 1/p)``, with each batched run's wall time.

The element run's result is dense (six unit loads per member, every member's end DOFs
reported), so its memory grows with the square of the member count: ~1e3 DOFs is what a
diagnosis of this frame handles in a minute; 1e4 DOFs (4000 members) would need a 24000 x 24000
matrix from one run.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def build_study(folder: Path, n_long: int, n_around: int) -> Path:
    """The study described in the module docstring, in ``folder`` (created)."""
    from blackbox.commands.simulate import run as simulate
    from blackbox.structures import random_loads, tube_body, write_study

    f = tube_body(n_long, n_around)
    src = write_study(folder / "source", f, random_loads(f, 12, seed=3), f"tube-{n_long}x{n_around}",
                      initial=1.0e3)
    grids = sorted(f.grids)
    away = grids[:: max(1, len(grids) // 20)][:20]
    (src / "truth.toml").write_text(
        f'seed = 1\n\n[[joints]]\nname = "JR"\nmodel = "simple"\nvalue = 1.0e5\n\n'
        f"[noise]\nrelative = 0.03\nfloor = 0.05\n\n[measure]\njoint = true\naway_grids = {away}\n")
    study = folder / "study"
    simulate(src, src / "truth.toml", adapter="reference").write(study)
    toml = (study / "study.toml").read_text()
    (study / "study.toml").write_text(toml.replace('adapter = "reference"', 'adapter = "mystran"'))
    return study


def _comparable(doc: dict) -> dict:
    """The diagnosis document without timings and run counts (chunks are runs of their own)."""
    return {k: v for k, v in doc.items() if k not in ("wall_s", "solver", "method_wall_s")}


def main(argv=None) -> int:
    from blackbox.commands import diagnose
    from blackbox.parallel import DaskExecutor

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="12x16", help="n_long x n_around of tube_body (default 12x16)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    n_long, n_around = (int(x) for x in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory(prefix="blackbox-diagnose-bench-") as tmp:
        study = build_study(Path(tmp), n_long, n_around)
        t0 = time.perf_counter()
        serial = diagnose.run(study, plots=False)
        t_serial = time.perf_counter() - t0
        t0 = time.perf_counter()
        with DaskExecutor(workers=args.workers) as ex:
            ex.map(abs, list(range(args.workers)))            # workers up before the clock starts
            t_start = time.perf_counter() - t0
            t0 = time.perf_counter()
            par = diagnose.run(study, plots=False, executor=ex)
            t_par = time.perf_counter() - t0
    same = json.dumps(_comparable(serial.document), sort_keys=True) == \
        json.dumps(_comparable(par.document), sort_keys=True)
    p = args.workers
    s = t_serial / t_par
    e = (1 / s - 1 / p) / (1 - 1 / p)
    dofs = 6 * len(serial.prepared.deck.grids)
    print(f"tube_body({n_long}, {n_around}): {dofs} DOF, {len(serial.prepared.deck.cbars)} members, MYSTRAN")
    print(f"serial {t_serial:.2f} s, {p} workers {t_par:.2f} s (cluster start {t_start:.2f} s, not included): "
          f"S = {s:.2f}, e = {e:.3f}; same document apart from timings and run counts: {same}")
    for a, b in zip(serial.diagnosis.runs, par.diagnosis.runs):
        print(f"  {a.purpose:<45s} {a.right_hand_sides:6d} rhs  {a.wall_s:7.2f} s  ->  {b.wall_s:7.2f} s")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
