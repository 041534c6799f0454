"""The generic subprocess runner and CommandAdapter, with a toy solver written in Python.

The toy "solver" reads a JSON deck and answers u = f / k for a diagonal stiffness k (one value per
grid), so every expected number here is exact arithmetic.
"""

from __future__ import annotations

import importlib.metadata
import json
import sys
import threading
import time
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import psutil
import pytest

from solver_adapters import subprocess as sa
from solver_adapters.protocol import (LoadMatrix, ScalarSpring, SolverAdapter, SolverRunError,
                                      SolverTimeoutError, UnknownDofError)
from solver_adapters.subprocess import CommandAdapter, get_dialect, run_solver

PY = sys.executable


def _gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def _wait_gone(pid: int, within_s: float = 5.0) -> bool:
    """A killed orphan is reaped by init shortly after the kill: allow it a moment."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < within_s:
        if _gone(pid):
            return True
        time.sleep(0.02)
    return False


# --------------------------------------------------------------------------------------------
# run_solver
# --------------------------------------------------------------------------------------------
SPAWNER = """
import subprocess, sys, time
kids = [subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']),
        subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'], start_new_session=True)]
open('pids.txt', 'w').write(' '.join(str(k.pid) for k in kids))
print('spawned children', flush=True)
time.sleep(60)
"""


def test_timeout_kills_whole_tree(tmp_path):
    t0 = time.perf_counter()
    with pytest.raises(SolverTimeoutError) as info:
        run_solver([PY, "-c", SPAWNER], tmp_path, timeout_s=1.5)
    assert time.perf_counter() - t0 < 10  # 1.5 s limit + terminate grace; never the 60 s sleep
    assert "spawned children" in info.value.log_tail
    assert info.value.workdir == str(tmp_path)
    pids = [int(p) for p in (tmp_path / "pids.txt").read_text().split()]
    assert len(pids) == 2  # one in the solver's process group, one in a session of its own
    assert all(_wait_gone(p) for p in pids), [(p, psutil.Process(p).cmdline()) for p in pids if not _gone(p)]


def test_children_left_behind_after_normal_exit_are_killed(tmp_path):
    script = ("import subprocess, sys\n"
              "k = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
              "open('pids.txt', 'w').write(str(k.pid))\n")
    rec = run_solver([PY, "-c", script], tmp_path, timeout_s=30)
    assert rec.returncode == 0
    assert _wait_gone(int((tmp_path / "pids.txt").read_text()))


def test_peak_memory_recorded(tmp_path):
    mb = 80
    rec = run_solver([PY, "-c", f"import time; b = bytearray({mb} * 2**20); time.sleep(0.3)"],
                     tmp_path, timeout_s=30)
    assert rec.returncode == 0
    assert rec.peak_rss_bytes > mb * 2**20  # the buffer is touched (zero-filled) when created
    assert rec.wall_s >= 0.3


def test_short_run_still_reports_memory(tmp_path):
    rec = run_solver([PY, "-c", "pass"], tmp_path, timeout_s=30)
    assert rec.peak_rss_bytes > 0


def test_nonzero_exit_and_logs_recorded(tmp_path):
    rec = run_solver([PY, "-c", "import sys; print('to out'); print('to err', file=sys.stderr); sys.exit(3)"],
                     tmp_path, timeout_s=30, log_name="toy")
    assert rec.returncode == 3
    assert rec.stdout_tail == "to out" and rec.stderr_tail == "to err"
    assert (tmp_path / "toy.stdout").exists() and "[stderr]\nto err" in rec.log_tail()


def test_missing_executable_is_a_solver_run_error(tmp_path):
    with pytest.raises(SolverRunError, match="cannot start solver"):
        run_solver([str(tmp_path / "no-such-solver")], tmp_path, timeout_s=5)


def test_tail_text_keeps_last_lines(tmp_path):
    p = tmp_path / "log"
    p.write_text("".join(f"line {i}\n" for i in range(100)) + "\n\n")
    assert sa.tail_text(p, lines=3) == "line 97\nline 98\nline 99"
    assert sa.tail_text(tmp_path / "missing") == ""


# --------------------------------------------------------------------------------------------
# a toy dialect: JSON in, JSON out, u = f / k per grid
# --------------------------------------------------------------------------------------------
TOY_SOLVER = """
import json, sys
deck = json.load(open(sys.argv[1]))
if deck.get("fail"):
    print("toy solver: singular matrix", flush=True); sys.exit(3)
if deck.get("sleep"):
    import time; time.sleep(deck["sleep"])
k = {int(g): v for g, v in deck["k"].items()}
for s in deck["springs"]:
    k[s[0]] += s[1]
u = [[deck["f"][j].get(f"{g},{c}", 0.0) / k[g] for j in range(deck["n"])] for g, c in deck["report"]]
json.dump(u, open("out.json", "w"))
"""

GRIDS = "\n".join(f"GRID,{g},,{float(g)},0.,0." for g in (1, 2, 3, 4)) + "\n"


class ToyDialect:
    name = "toy"

    def __init__(self, max_cases_per_run=None, fail=False, sleep=0.0):
        self.max_cases_per_run, self.fail, self.sleep = max_cases_per_run, fail, sleep

    def write_deck(self, workdir, base, loads, report, springs):
        dense = loads.values.toarray()
        f = [{f"{g},{c}": dense[i, j] for i, (g, c) in enumerate(loads.dofs) if dense[i, j]}
             for j in range(loads.n_cases)]
        deck = {"k": {g: 10.0 * g for g in base.model.grids}, "n": loads.n_cases, "f": f,
                "report": list(report), "springs": [[s.a[0], s.k] for s in springs],
                "fail": self.fail, "sleep": self.sleep}
        path = Path(workdir) / "deck.json"
        path.write_text(json.dumps(deck))
        return path

    def command(self, deck_path):
        return None

    def read_results(self, workdir, deck_path, loads, report, record):
        if record.returncode != 0:
            raise SolverRunError("toy solver failed", returncode=record.returncode, log_tail=record.log_tail())
        return np.array(json.loads((Path(workdir) / "out.json").read_text())).reshape(len(report), -1)


@pytest.fixture
def toy(tmp_path):
    solver = tmp_path / "toy_solver.py"
    solver.write_text(TOY_SOLVER)
    deck = tmp_path / "model.bdf"
    deck.write_text(GRIDS)
    runs = tmp_path / "runs"

    def make(**kw):
        dialect = ToyDialect(**{k: kw.pop(k) for k in ("max_cases_per_run", "fail", "sleep") if k in kw})
        kw.setdefault("trusted", True)  # consent is tested in test_safety_solver.py
        return CommandAdapter(deck, [PY, str(solver), "{deck}"], dialect, workdir_root=runs, name="toy", **kw)
    make.runs = runs
    return make


def _loads():
    dofs = [(1, 1), (2, 3), (4, 6)]
    vals = np.array([[1.0, 0.0, 2.0, 0.0, 5.0], [0.0, 3.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 7.0, 1.0]])
    return LoadMatrix.from_dense(dofs, vals, [f"c{j}" for j in range(5)])


def test_command_adapter_solves_and_cleans_up(toy):
    a = toy()
    assert isinstance(a, SolverAdapter)
    assert a.dofs() == tuple((g, c) for g in (1, 2, 3, 4) for c in range(1, 7))
    assert a.grid_xyz()[3] == (3.0, 0.0, 0.0)
    d = a.solve(_loads(), [(1, 1), (4, 6), (3, 2)])
    expected = np.array([[0.1, 0, 0.2, 0, 0.5], [0, 0, 0, 7 / 40, 1 / 40], [0, 0, 0, 0, 0]])
    np.testing.assert_allclose(d.values, expected, rtol=1e-15)  # u = f / k, exact
    assert d.cases == _loads().cases
    assert (a.stats.runs, a.stats.right_hand_sides, a.stats.factorizations) == (1, 5, 1)
    assert a.stats.wall_s > 0 and a.stats.peak_rss_bytes > 0 and a.stats.history[0]["ok"]
    assert list(toy.runs.iterdir()) == []  # success: run directory removed


def test_chunked_batches_equal_one_run(toy):
    whole = toy().solve(_loads(), [(1, 1), (2, 3), (4, 6)])
    chunked = toy(max_cases_per_run=2)
    part = chunked.solve(_loads(), [(1, 1), (2, 3), (4, 6)])
    np.testing.assert_array_equal(part.values, whole.values)
    assert (chunked.stats.runs, chunked.stats.right_hand_sides) == (3, 5)


def test_unknown_labels_rejected_before_running(toy):
    a = toy()
    with pytest.raises(UnknownDofError):
        a.solve(LoadMatrix.unit([(9, 1)]), [(1, 1)])
    with pytest.raises(UnknownDofError):
        a.solve(LoadMatrix.unit([(1, 1)]), [(1, 7)])
    with pytest.raises(UnknownDofError):
        a.with_springs([ScalarSpring((8, 1), None, 1.0)])
    assert a.stats.runs == 0 and not toy.runs.exists()


def test_failed_run_keeps_directory_and_carries_exit_code(toy):
    a = toy(fail=True, keep_failed=True)
    with pytest.raises(SolverRunError) as info:
        a.solve(_loads(), [(1, 1)])
    err = info.value
    assert err.returncode == 3 and "singular matrix" in err.log_tail
    assert err.workdir and Path(err.workdir).is_dir() and (Path(err.workdir) / "deck.json").exists()
    assert err.workdir in str(err)
    assert a.stats.runs == 1 and a.stats.right_hand_sides == 0 and not a.stats.history[0]["ok"]


def test_failed_run_directory_removed_by_default(toy):
    with pytest.raises(SolverRunError) as info:
        toy(fail=True).solve(_loads(), [(1, 1)])
    assert list(toy.runs.iterdir()) == []
    assert info.value.workdir is None and "singular matrix" in str(info.value)  # the tail survived
    assert "run directory removed" in str(info.value)


def test_adapter_timeout(toy):
    with pytest.raises(SolverTimeoutError) as info:
        toy(sleep=30, timeout_s=0.5, keep_failed=True).solve(_loads(), [(1, 1)])
    assert Path(info.value.workdir).is_dir()


def test_with_springs_appends_and_keeps_original(toy):
    a = toy()
    b = a.with_springs([ScalarSpring((1, 1), None, 10.0)])
    c = b.with_springs([ScalarSpring((1, 1), None, 20.0)])
    assert (len(a.springs), len(b.springs), len(c.springs)) == (0, 1, 2)
    loads = LoadMatrix.unit([(1, 1)])
    assert a.solve(loads, [(1, 1)]).values[0, 0] == pytest.approx(1 / 10)
    assert b.solve(loads, [(1, 1)]).values[0, 0] == pytest.approx(1 / 20)
    assert c.solve(loads, [(1, 1)]).values[0, 0] == pytest.approx(1 / 40)
    assert (a.stats.runs, b.stats.runs, c.stats.runs) == (1, 1, 1)  # separate counters


def test_parallel_solves_use_separate_directories(toy):
    a = toy(sleep=0.3)
    loads = _loads()
    results, errors = [], []

    def work(scale):
        try:
            scaled = LoadMatrix(loads.dofs, loads.values * scale, loads.cases)
            results.append((scale, a.solve(scaled, [(1, 1), (4, 6)]).values))
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(s,)) for s in (1.0, 2.0, 3.0, 4.0)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert time.perf_counter() - t0 < 4 * 0.3 + 1.0  # overlapped, not serial (each run sleeps 0.3 s)
    base = dict(results)[1.0]
    for scale, vals in results:
        np.testing.assert_allclose(vals, scale * base, rtol=1e-15)
    assert a.stats.runs == 4 and a.stats.right_hand_sides == 20


def test_command_placeholders_and_default_append(toy, tmp_path):
    a = toy()
    deck = tmp_path / "w" / "run.bdf"
    a.command = ["solver", "--in={deck}", "{deck_name}", "{workdir}"]
    assert a._command_for(deck) == ["solver", f"--in={deck}", "run.bdf", str(deck.parent)]
    a.command = ["solver", "-v"]
    assert a._command_for(deck) == ["solver", "-v", str(deck)]


# --------------------------------------------------------------------------------------------
# dialect registry
# --------------------------------------------------------------------------------------------
def test_builtin_dialect_by_name():
    assert get_dialect("nastran").name == "nastran"
    assert get_dialect("nastran", max_cases_per_run=7).max_cases_per_run == 7


def test_unknown_dialect_lists_known_names():
    with pytest.raises(ValueError, match="unknown solver dialect 'abaqus'.*nastran.*blackbox.dialects"):
        get_dialect("abaqus")


def test_dialect_from_entry_point(monkeypatch):
    ep = EntryPoint(name="toy-nastran", value="solver_adapters.nastran:NastranDialect",
                    group="blackbox.dialects")

    def fake_entry_points(group=None):
        return [ep] if group == "blackbox.dialects" else []

    monkeypatch.setattr(importlib.metadata, "entry_points", fake_entry_points)
    assert "toy-nastran" in sa.known_dialects()
    assert get_dialect("toy-nastran", epsilon_tol=1e-3).epsilon_tol == 1e-3
    with pytest.raises(ValueError, match="solver dialect 'toy-nastran' has no option 'tolerance'"):
        get_dialect("toy-nastran", tolerance=1e-3)


def test_command_required_when_dialect_has_no_default(tmp_path):
    deck = tmp_path / "model.bdf"
    deck.write_text(GRIDS)
    with pytest.raises(ValueError, match="no default command"):
        CommandAdapter(deck, None, ToyDialect())
