"""What `blackbox identify` costs beyond the solver run it needs: its CPU against one plain
`blackbox solve` of the same study through the same adapter.

    python benchmarks/identify_overhead.py [--study fixtures/car] [--adapter mystran] [--repeats 5]

Each repeat runs `blackbox solve` and `blackbox identify` (both ``--no-cache``: every solver run
is made) as fresh processes, one after the other, and reads each one's CPU time (user + system,
the solver subprocess included) from ``getrusage(RUSAGE_CHILDREN)``. Paired in one run and
alternated, so the ratio holds on a noisy machine; the medians are printed with the ratio.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cpu_of(cmd: list[str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--study", type=Path, default=ROOT / "fixtures" / "car")
    ap.add_argument("--adapter", default="mystran")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", type=Path, help="also write the figures here")
    args = ap.parse_args(argv)
    exe = [sys.executable, "-m", "blackbox.cli"]
    solve, ident = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeats):
            solve.append(cpu_of(exe + ["solve", str(args.study), "--adapter", args.adapter, "--no-cache",
                                       "--out", f"{tmp}/s{i}"]))
            ident.append(cpu_of(exe + ["identify", str(args.study), "--adapter", args.adapter, "--no-cache",
                                       "--out", f"{tmp}/i{i}"]))
    s, d = statistics.median(solve), statistics.median(ident)
    doc = {"study": str(args.study), "adapter": args.adapter, "repeats": args.repeats,
           "solve_cpu_s": solve, "identify_cpu_s": ident, "ratio_of_medians": d / s}
    print(f"{args.study.name} through {args.adapter}, {args.repeats} pairs: solve CPU median {s:.3f} s, "
          f"identify CPU median {d:.3f} s, ratio {d / s:.2f}")
    if args.json:
        args.json.write_text(json.dumps(doc, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
