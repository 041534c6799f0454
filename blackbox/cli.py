"""The ``blackbox`` command (CONTRACT.md section 2).

Every sub-command exits non-zero with a one-paragraph message on bad input; ``--debug`` shows
the traceback instead.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

from blackbox.errors import IdentificationError, StudyError
from solver_adapters.protocol import SolverError


def _write_csv(path: Path, header: list[str], rows) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)


# --------------------------------------------------------------------------------------------
# sub-commands
# --------------------------------------------------------------------------------------------
def cmd_solve(args) -> int:
    from blackbox.study import load_study
    from blackbox.workflows import make_adapter_for

    study = load_study(args.study)
    adapter = make_adapter_for(study, args.adapter)
    report = adapter.dofs()
    t0 = time.perf_counter()
    out = adapter.solve(study.loads, report)
    wall = time.perf_counter() - t0
    if not np.all(np.isfinite(out.values)):
        raise SolverError(f"adapter {adapter.name!r} returned non-finite displacements")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = ((case, g, c, repr(float(out.values[i, j])))
            for j, case in enumerate(out.cases) for i, (g, c) in enumerate(out.dofs))
    _write_csv(args.out / "displacements.csv", ["case", "grid", "component", "value"], rows)
    print(f"solved {len(out.cases)} case(s) x {len(report)} DOFs with {adapter.name!r} in "
          f"{wall:.3f} s ({adapter.stats.runs} solver run(s)) -> {args.out / 'displacements.csv'}")
    return 0


def cmd_simulate(args) -> int:
    from blackbox.workflows import simulate_study

    rec = simulate_study(args.study, args.truth, args.out, args.adapter)
    print(f"simulated {rec['n_measurements']} measurements over {len(rec['cases'])} case(s) "
          f"({rec['solver_runs']} solver run(s)) -> {args.out / 'measurements.csv'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="blackbox", description=__doc__.splitlines()[0])
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("solve", help="solve the study's load cases, no joint model added")
    s.add_argument("study", type=Path)
    s.add_argument("--adapter", default=None, help="override [solver] adapter")
    s.add_argument("--out", type=Path, required=True)
    s.set_defaults(func=cmd_solve)

    s = sub.add_parser("simulate", help="a copy of the study with simulated measurements (Sec. 5.2)")
    s.add_argument("study", type=Path)
    s.add_argument("--truth", type=Path, required=True, help="truth TOML: joints, noise, bias, what to measure")
    s.add_argument("--adapter", default=None)
    s.add_argument("--out", type=Path, required=True)
    s.set_defaults(func=cmd_simulate)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (StudyError, SolverError, IdentificationError, ValueError, OSError) as exc:
        if args.debug:
            raise
        kind = type(exc).__name__
        print(f"blackbox {args.command}: {kind}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"blackbox {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
