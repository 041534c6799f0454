"""What the search's refit guarantee costs: every candidate that could win refitted, against only
the ``refit_top`` best by score.

    python benchmarks/refit_schedule.py [STUDY ...] [--tube 12x16 ...] [--adapter reference|mystran]

For each study (a folder, or ``--tube N_LONGxN_AROUND``: the generated body of
``benchmarks/diagnose_parallel.py``, ``6 N_LONG N_AROUND`` DOFs and more) the three decks are run
once (``blackbox.commands.diagnose.prepare``) and the search (``blackbox.diagnosis.search.diagnose``)
runs twice on that one prepared study: with the guarantee (``complete_refits=True``, the default)
and without it (the ``refit_top`` best only). Prints, per search: the refits per round, the solver
runs and right-hand sides the refits needed (members' unit-load columns), the search's wall time
and whether the two added the same effects. Ratios are the figure (one machine, one run); the
wall times depend on the machine's load, printed too.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))


def _search(pr, complete: bool) -> tuple[object, float, int, int]:
    from blackbox.commands.diagnose import load_magnitudes
    from blackbox.diagnosis import search

    runs0, rhs0 = len(pr.base.log), sum(r.right_hand_sides for r in pr.base.log)
    ident = pr.ident
    t0 = time.perf_counter()
    d = search.diagnose(pr.base, pr.boundary, pr.K_deck, pr.joints, ident.k if ident else np.zeros(0),
                        pr.fit_obs, pr.hold_obs, pr.candidates,
                        declared_prediction=ident.predicted if ident else None,
                        load_magnitudes=load_magnitudes(pr.study.loads), complete_refits=complete)
    wall = time.perf_counter() - t0
    return (d, wall, len(pr.base.log) - runs0,
            sum(r.right_hand_sides for r in pr.base.log) - rhs0)


def _summary(d) -> dict:
    return {"refits_per_round": [sum(1 for c in s.scores if c.refit is not None) for s in d.steps],
            "added": [f"{c.effect.kind}@{','.join(map(str, c.effect.where))}" for c in d.added],
            "verdict": d.verdict, "reduced_chi2": round(d.final.reduced_chi2, 4)}


def main(argv=None) -> int:
    from blackbox.commands import diagnose as dc

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("studies", nargs="*", type=Path)
    ap.add_argument("--tube", action="append", default=[], help="a generated body, e.g. 12x16 (repeatable)")
    ap.add_argument("--adapter", default="reference")
    args = ap.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory(prefix="blackbox-schedule-") as tmp:
        from diagnose_parallel import build_study

        studies = list(args.studies)
        for size in args.tube:
            n_long, n_around = (int(x) for x in size.lower().split("x"))
            studies.append(build_study(Path(tmp) / f"tube-{size}", n_long, n_around)[0])
        for i, study in enumerate(studies):
            decks = Path(tmp) / f"decks-{i}"
            decks.mkdir()
            t0 = time.perf_counter()
            pr = dc.prepare(study, decks, adapter=args.adapter)
            prep = time.perf_counter() - t0
            top, w_top, runs_top, rhs_top = _search(pr, False)
            full, w_full, runs_full, rhs_full = _search(pr, True)
            n_dof = sum(6 for _ in pr.deck.grids)
            print(json.dumps({"study": str(study), "dof": n_dof, "candidates": len(pr.candidates),
                              "prepare_s": round(prep, 2),
                              "top_only": {**_summary(top), "search_s": round(w_top, 2), "solver_runs": runs_top,
                                           "right_hand_sides": rhs_top},
                              "guarantee": {**_summary(full), "search_s": round(w_full, 2), "solver_runs": runs_full,
                                            "right_hand_sides": rhs_full},
                              "search_time_ratio": round(w_full / max(w_top, 1e-9), 2),
                              "same_effects": _summary(top)["added"] == _summary(full)["added"]}))
    print(f"load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
