"""Like-for-like diagnosis time of two checkouts: the same generated studies diagnosed by each,
back to back per study, so that both see the same machine load.

    python benchmarks/diagnose_checkouts.py OUT OLD_TREE NEW_TREE [--n 19] [--seed 3]

Study ``i`` (``i = 0 .. n-1``) is ``benchmarks.blind.generate.generate_study(100 + i, seed, ...)``
with the ``i``-th family and kind in turn (plain decks). Each checkout runs ``blackbox diagnose``
in a process of its own (``PYTHONPATH`` = the tree, one BLAS thread). Prints per study the two
wall times and whether the two added the same effects, then the median and total ratio: a ratio
from one run on one machine, not a time to carry elsewhere.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def diagnose_with(tree: str, study: Path) -> tuple[float, object]:
    """Wall time and the added ``(effect, where)`` of ``blackbox diagnose`` from ``tree``."""
    out = Path(str(study) + "_out")
    env = dict(os.environ, PYTHONPATH=tree, OMP_NUM_THREADS="1")
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "blackbox.cli", "diagnose", str(study), "--out", str(out)],
                   env=env, capture_output=True, cwd=tree)
    wall = time.perf_counter() - t0
    try:
        doc = json.loads((out / "diagnosis.json").read_text())
        return wall, [(a["effect"], a["where"]) for a in doc["added"]]
    except (OSError, ValueError, KeyError) as exc:
        return wall, f"no diagnosis.json: {exc}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("old", help="the first checkout (its top folder)")
    ap.add_argument("new", help="the second checkout")
    ap.add_argument("--n", type=int, default=19)
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args(argv)
    from benchmarks.blind import generate as gen
    from benchmarks.blind.frames import FAMILIES

    fams, kinds = list(FAMILIES), list(gen.KINDS) + list(gen.DATA_KINDS)
    ratios, totals, same = [], [0.0, 0.0], 0
    for i in range(a.n):
        fam, kind = fams[i % len(fams)], kinds[i % len(kinds)]
        st = gen.generate_study(100 + i, a.seed, a.out / "gen", kind, fam, style="plain")
        res = []
        for tag, tree in (("old", a.old), ("new", a.new)):
            f = a.out / tag / st.folder.name
            for g in (f, Path(str(f) + "_out")):
                if g.exists():
                    shutil.rmtree(g)
            shutil.copytree(st.folder, f)
            res.append(diagnose_with(tree, f))
        (t_old, add_old), (t_new, add_new) = res
        ratios.append(t_new / t_old)
        totals[0] += t_old
        totals[1] += t_new
        same += add_old == add_new
        print(f"{st.folder.name} {fam} {kind}: {t_old:.1f} s, {t_new:.1f} s; same additions: {add_old == add_new} "
              f"{add_old} {add_new}", flush=True)
    print(f"\n{a.n} studies: median ratio new/old {statistics.median(ratios):.3f}, total {totals[0]:.1f} s -> "
          f"{totals[1]:.1f} s ({totals[1] / totals[0]:.3f}x); the same additions in {same} of {a.n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
