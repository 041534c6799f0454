"""Does sending a diagnosis's refits to the workers pay? Each round's refits timed three ways.

    python benchmarks/diagnose_refits.py [STUDY ...] [--tube 12x16 ...] [--workers 2]
    OPENBLAS_NUM_THREADS=1 python benchmarks/diagnose_refits.py ...     # the client single-threaded

For each study (a folder, or ``--tube N_LONGxN_AROUND``: the generated body of
``benchmarks/diagnose_parallel.py``, built in a temporary folder) the decks are run once with the
reference solver (``blackbox.commands.diagnose.prepare``) and the search loop
(``blackbox.diagnosis.search.diagnose``) is run on that one prepared study three times:
serially; with every round's refits mapped over a local Dask cluster (``always_map_refits``; the
cluster warmed up by one such loop first); and with the default rule
(``blackbox.diagnosis.search.refits_pay``). Prints the time of each round's refits
(``search.map_refits``) for the three, the size of the split base that travels
(``SplitBase.detached``), and whether the three loops added the same effects (and the largest
relative parameter difference between the serial and the mapped loop).

The workers run single-threaded BLAS (Dask's nanny sets it); the client uses what the
environment says, hence the second form above.
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


def _loop(pr, executor, force: bool, rounds: list) -> object:
    from blackbox.diagnosis import search

    rounds.clear()
    ident = pr.ident
    return search.diagnose(pr.base, pr.boundary, pr.K_deck, pr.joints, ident.k if ident else np.zeros(0),
                           pr.fit_obs, pr.hold_obs, pr.candidates,
                           declared_prediction=ident.predicted if ident else None, executor=executor,
                           always_map_refits=force)


def _added(d) -> list:
    return [(s.added.effect.key, s.added.effect.variant) if s.added else None for s in d.steps]


def main(argv=None) -> int:
    from blackbox.commands import diagnose as dc
    from blackbox.diagnosis import search
    from blackbox.parallel import DaskExecutor

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("studies", nargs="*", type=Path)
    ap.add_argument("--tube", action="append", default=[], help="a generated body, e.g. 12x16 (repeatable)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)

    rounds: list = []
    orig = search.map_refits

    def timed(*a, **kw):
        t0 = time.perf_counter()
        out = orig(*a, **kw)
        rounds.append(round(time.perf_counter() - t0, 3))
        return out
    search.map_refits = timed

    print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'default')}, "
          f"load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory(prefix="blackbox-refits-") as tmp, DaskExecutor(workers=args.workers) as ex:
        from diagnose_parallel import build_study

        studies = list(args.studies)
        for size in args.tube:
            n_long, n_around = (int(x) for x in size.lower().split("x"))
            studies.append(build_study(Path(tmp) / f"tube-{size}", n_long, n_around)[0])
        for i, study in enumerate(studies):
            decks = Path(tmp) / f"decks-{i}"
            decks.mkdir()
            pr = dc.prepare(study, decks, adapter="reference")
            serial = _loop(pr, None, False, rounds)
            r_serial = list(rounds)
            _loop(pr, ex, True, rounds)                     # the workers' imports, once
            mapped = _loop(pr, ex, True, rounds)
            r_mapped = list(rounds)
            rule = _loop(pr, ex, False, rounds)
            r_rule = list(rounds)
            dx = max((float(np.max(np.abs(a.after.x - b.after.x) / np.maximum(np.abs(a.after.x), 1e-300)))
                      for a, b in zip(serial.steps, mapped.steps)), default=0.0)
            print(json.dumps({"study": study.name if study.name != "study" else study.parent.name,
                              "base_MB": round(pr.base.detached_nbytes() / 1e6, 1),
                              "n_obs": serial.declared.n_obs, "n_params": serial.declared.n_params,
                              "serial_s": r_serial, "mapped_s": r_mapped, "rule_s": r_rule,
                              "same_effects": _added(serial) == _added(mapped) == _added(rule),
                              "max_relative_parameter_difference": dx}))
    print(f"load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
