"""Deck read time against pyNastran's ``read_bdf``, paired in one run on the same files.

    python benchmarks/read_speed.py [--n 27] [--repeat 5] [--pynastran-python PATH]

Writes into a temporary folder the space-frame lattice of ``benchmarks/import_speed.py`` with
``n x n x (n + 1)`` grids (n = 27: 20,412 GRIDs, 59,049 CBARs, 80,000+ bulk cards), small field:

* ``model.bdf``: the frame alone (GRID, CBAR, PBAR, MAT1, SPC1), what a study's reader reads;
* ``lattice.dat``: the same frame as a whole input file (executive and case control, 5 SUBCASEs,
  a FORCE set each), what ``blackbox import`` reads.

Times, each the best of ``--repeat`` runs taken in turns (ours, then pyNastran's, and again), so
that both see the same load of a shared machine:

* the study reader, :func:`solver_adapters.bdf.read_deck` on ``model.bdf``, against pyNastran's
  ``read_bdf(model.bdf, punch=True)`` (bulk data only);
* ``blackbox import`` (cards, model checks, case control, loads, ``model.bdf``) against
  ``read_bdf(lattice.dat)``.

pyNastran (1.4: ``pip install pyNastran``) is not a dependency of this project; it is run by
the interpreter ``--pynastran-python`` (default: this one), in a child process that reads the
file when asked, so its own import is not timed. pyNastran 1.4 needs numpy < 2: give it an
environment of its own if this one has numpy 2. Without it the pyNastran side is skipped with a
message and only our times are printed.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "benchmarks"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from import_speed import lattice_deck              # noqa: E402

from blackbox.commands import import_deck           # noqa: E402
from solver_adapters.bdf import read_deck           # noqa: E402

# the child: reads the file named on each line of stdin, answers with the seconds it took
_CHILD = r"""
import sys, time, logging
logging.disable(logging.CRITICAL)
from pyNastran.bdf.bdf import read_bdf
print("ready", flush=True)
for line in sys.stdin:
    path, punch = line.rstrip("\n").rsplit(" ", 1)
    t0, c0 = time.perf_counter(), time.process_time()
    model = read_bdf(path, punch=punch == "1", debug=None)
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    print(f"{dt} {dc} {len(model.nodes)} {len(model.elements)}", flush=True)
"""


class PyNastran:
    """pyNastran's read_bdf in a child process (None if it cannot be started)."""

    def __init__(self, python: str) -> None:
        self.proc = subprocess.Popen([python, "-c", _CHILD], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        first = self.proc.stdout.readline().strip()
        if first != "ready":
            err = self.proc.stderr.read().strip().splitlines()
            self.proc.wait()
            raise RuntimeError(err[-1] if err else "the child process did not start")

    def read(self, path: Path, punch: bool) -> tuple[float, float, int, int]:
        """(wall seconds, CPU seconds, nodes, elements) of one read_bdf."""
        self.proc.stdin.write(f"{path} {int(punch)}\n")
        self.proc.stdin.flush()
        answer = self.proc.stdout.readline().split()
        if len(answer) != 4:
            raise RuntimeError(self.proc.stderr.read().strip().splitlines()[-1])
        return float(answer[0]), float(answer[1]), int(answer[2]), int(answer[3])

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=27)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--pynastran-python", default=sys.executable,
                    help="the Python interpreter that has pyNastran (default: this one)")
    args = ap.parse_args(argv)
    try:
        pyn = PyNastran(args.pynastran_python)
    except (RuntimeError, OSError) as exc:
        print(f"pyNastran skipped: cannot run it with {args.pynastran_python} ({exc})")
        pyn = None
    with tempfile.TemporaryDirectory() as tmp:
        deck = Path(tmp) / "lattice.dat"
        text, n_cards = lattice_deck(args.n)
        deck.write_text(text)
        model = Path(tmp) / "model.bdf"
        res = import_deck.run(deck)
        model.write_text(res.model_bdf)
        n_model = sum(1 for ln in res.model_bdf.splitlines() if ln and ln[0] not in "$ +*")
        best = {k: float("inf") for k in ("read", "pyn_read", "import", "pyn_import")}
        cpu = dict(best)

        def timed(key, f):
            t0, c0 = time.perf_counter(), time.process_time()
            out = f()
            best[key] = min(best[key], time.perf_counter() - t0)
            cpu[key] = min(cpu[key], time.process_time() - c0)
            return out

        for _ in range(args.repeat):
            d = timed("read", lambda: read_deck(model))
            if pyn is not None:
                dt, dc, nodes, elems = pyn.read(model, punch=True)
                assert (nodes, elems) == (len(d.grids), len(d.cbars)), (nodes, elems)
                best["pyn_read"], cpu["pyn_read"] = min(best["pyn_read"], dt), min(cpu["pyn_read"], dc)
            timed("import", lambda: import_deck.run(deck))
            if pyn is not None:
                dt, dc, _, _ = pyn.read(deck, punch=False)
                best["pyn_import"], cpu["pyn_import"] = min(best["pyn_import"], dt), min(cpu["pyn_import"], dc)
        if pyn is not None:
            pyn.close()
    print(f"{platform.platform()}, Python {platform.python_version()}: lattice n={args.n}: "
          f"{len(d.grids)} GRID, {len(d.cbars)} CBAR; model.bdf {n_model} bulk cards, "
          f"input file {n_cards} bulk cards ({len(text) / 1e6:.1f} MB), best of {args.repeat}")
    rows = [("study reader, model.bdf", "read", n_model), ("blackbox import, input file", "import", n_cards)]
    for label, key, n in rows:
        print(f"{label}: {best[key]:.3f} s wall, {cpu[key]:.3f} s CPU = {n / best[key]:,.0f} cards/s")
        if pyn is not None:
            p = f"pyn_{key}"
            print(f"  pyNastran read_bdf: {best[p]:.3f} s wall, {cpu[p]:.3f} s CPU = {n / best[p]:,.0f} "
                  f"cards/s; ratio {best[key] / best[p]:.3f} wall, {cpu[key] / cpu[p]:.3f} CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
