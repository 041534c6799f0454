"""How fast a whole NASTRAN input file is read: ``blackbox import`` and the study reader on a large deck.

    python benchmarks/import_speed.py [--n 26] [--repeat 3]

Writes into a temporary folder a space-frame lattice of ``n x n x (n + 1)`` grids (bars along the
three axes between neighbours, one PBAR/MAT1, the bottom layer clamped by SPC1) as a whole input
file: executive and case control with 5 SUBCASEs, each selecting its own FORCE set (a force at
every 10th grid), small-field bulk data. Times, best of ``--repeat``:

* ``blackbox import`` of the input file (cards, model checks, case control, loads, ``model.bdf``);
* the study reader alone (:func:`solver_adapters.bdf.read_deck`) on the written ``model.bdf``,
  which every command pays when it loads the study.

Cards per second count every bulk-data card of the file (continuations not counted separately).
"""

from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from blackbox.commands import import_deck      # noqa: E402
from solver_adapters.bdf import read_deck       # noqa: E402


def lattice_deck(n: int, subcases: int = 5) -> tuple[str, int]:
    """The input file's text and its number of bulk-data cards."""
    nz = n + 1
    gid = {}
    bulk = []
    for k in range(nz):
        for j in range(n):
            for i in range(n):
                g = len(gid) + 1
                gid[i, j, k] = g
                bulk.append(f"GRID    {g:<8d}        {0.5 * i:<8.3f}{0.5 * j:<8.3f}{0.4 * k:<8.3f}")
    eid = 0
    for (i, j, k), g in gid.items():
        for di, dj, dk, v in ((1, 0, 0, "0.0     0.0     1.0"), (0, 1, 0, "0.0     0.0     1.0"),
                              (0, 0, 1, "1.0     0.0     0.0")):
            h = gid.get((i + di, j + dj, k + dk))
            if h is not None:
                eid += 1
                bulk.append(f"CBAR    {eid:<8d}1       {g:<8d}{h:<8d}{v}")
    bulk += ["PBAR    1       1       1.0-3   2.0-7   2.0-7   4.0-7",
             "MAT1    1       2.1+11          0.3"]
    base = [gid[i, j, 0] for j in range(n) for i in range(n)]
    for s in range(0, len(base), 6):
        bulk.append("SPC1    1       123456  " + "".join(f"{g:<8d}" for g in base[s:s + 6]))
    case = ["SOL 101", "CEND", "TITLE = lattice", "SPC = 1", "DISPLACEMENT = ALL"]
    grids = list(gid.values())
    for c in range(1, subcases + 1):
        case += [f"SUBCASE {c}", f"  LOAD = {c}"]
        for g in grids[c * 7::10]:
            bulk.append(f"FORCE   {c:<8d}{g:<8d}        {100.0 * c:<8.1f}0.0     0.0     -1.0")
    text = "\n".join(case + ["BEGIN BULK"] + bulk + ["ENDDATA", ""])
    return text, len(bulk)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=26)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "lattice.dat"
        text, n_cards = lattice_deck(args.n)
        path.write_text(text)
        best_import = best_read = float("inf")
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            res = import_deck.run(path)
            best_import = min(best_import, time.perf_counter() - t0)
        model = Path(tmp) / "model.bdf"
        model.write_text(res.model_bdf)
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            deck = read_deck(model)
            best_read = min(best_read, time.perf_counter() - t0)
    print(f"{platform.platform()}, {platform.python_version()}: lattice n={args.n}: {len(deck.grids)} GRID, "
          f"{len(deck.cbars)} CBAR, {n_cards} bulk cards, {len(res.cases)} subcases, "
          f"{len(text) / 1e6:.1f} MB")
    print(f"blackbox import: {best_import:.2f} s = {n_cards / best_import:,.0f} cards/s (best of {args.repeat})")
    print(f"study reader (model.bdf): {best_read:.2f} s = {(n_cards) / best_read:,.0f} cards/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
