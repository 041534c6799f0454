"""``blackbox diagnose`` of a 1e5-DOF body through MYSTRAN: one solver process at a time against
the default (a large batch's solver processes side by side, one per physical core).

    python benchmarks/diagnose_processes.py [--size 167x100] [--json FILE]

The study of ``benchmarks/diagnose_parallel.py`` (``build_study``: ``tube_body(167, 100)`` is
100,215 DOFs, the roof joint declared, the front-left suspension point elastic and not declared,
``adapter = "mystran"``), diagnosed twice in this process with the command's defaults and no run
cache (the default of ``run``): first with ``[solver.options] processes = 1``, then without it. Prints each run's wall
time, each batched solver run (cases, processes, wall), and whether both reach the same
conclusions (the same effects at the same places, verdict, chi2 to 1e-9 relative): the split
run's right-hand sides are solved one at a time by MYSTRAN whichever process holds them, so the
values are identical. One pair on one machine: the ratio is the figure, not the seconds.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.diagnose_parallel import build_study        # noqa: E402


def diagnose_once(study: Path, processes: int | None) -> dict:
    from blackbox.commands.diagnose import run

    toml = study / "study.toml"
    text = toml.read_text().split("\n[solver.options]")[0]
    toml.write_text(text + (f"\n[solver.options]\nprocesses = {processes}\n" if processes else ""))
    t0 = time.perf_counter()
    res = run(study, plots=False)
    wall = time.perf_counter() - t0
    doc = json.loads(json.dumps(res.document, default=float))
    return {"processes": processes or "default", "wall_s": wall, "verdict": doc["verdict"],
            "added": [(a["effect"], a["where"]) for a in doc["added"]],
            "chi2_after": doc["after"]["reduced_chi2"], "solver": res.solver_json()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="167x100")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    n_long, n_around = (int(v) for v in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory(prefix="blackbox-processes-") as tmp:
        study, info = build_study(Path(tmp) / "study", n_long, n_around)
        one = diagnose_once(study, 1)
        print(json.dumps(one, default=str), flush=True)
        default = diagnose_once(study, None)
        print(json.dumps(default, default=str), flush=True)
    same = (one["added"] == default["added"] and one["verdict"] == default["verdict"]
            and abs(one["chi2_after"] - default["chi2_after"]) <= 1e-9 * abs(one["chi2_after"]))
    out = {"study": info, "one_process": one, "default": default, "ratio": default["wall_s"] / one["wall_s"],
           "same_conclusions": same}
    print(f"one process at a time {one['wall_s']:.1f} s, default {default['wall_s']:.1f} s: ratio "
          f"{out['ratio']:.2f}; same conclusions: {same}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
