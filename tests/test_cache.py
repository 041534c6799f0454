"""The solver-run cache (``solver_adapters.cache``) and resuming a command from it.

Exactness: a hit returns the stored float64 bytes, so "identical" below is bit-for-bit
(``tobytes`` equality), not a tolerance.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
import scipy.sparse as sp

from solver_adapters.cache import (MAGIC, CachedAdapter, CorruptEntry, entry_path, read_entry,
                                   write_entry)
from solver_adapters.conformance import read_loads_csv, write_generated_deck
from solver_adapters.legacy import FRAMESOLVE, LegacyAdapter
from solver_adapters.protocol import (Displacements, LoadMatrix, ScalarSpring, SolverRunError,
                                      UnknownDofError)
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.subprocess import CommandAdapter

from conftest import ROOT, copy_fixture


pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


@pytest.fixture(autouse=True)
def _own_config_dir(tmp_path_factory, monkeypatch):
    """The cache's secret key goes to a folder of the test (subprocesses inherit it), never to
    the real user's configuration."""
    monkeypatch.setenv("BLACKBOX_CONFIG_DIR", str(tmp_path_factory.mktemp("config")))


@pytest.fixture
def cube(tmp_path):
    """A copy of the cube study (decks may be edited) and its loads."""
    study = tmp_path / "cube"
    copy_fixture("cube", study)
    return study, read_loads_csv(study / "loads.csv")


def entries(cache_dir: Path) -> list[Path]:
    return sorted(Path(cache_dir).rglob("*.bbc")) if Path(cache_dir).exists() else []


def same_bytes(a: Displacements, b: Displacements) -> bool:
    return a.values.tobytes() == b.values.tobytes() and a.dofs == b.dofs and a.cases == b.cases


# --------------------------------------------------------------------------------------------
# hits and misses
# --------------------------------------------------------------------------------------------
def test_second_identical_solve_makes_no_run_and_returns_identical_arrays(cube, tmp_path):
    study, loads = cube
    inner = ReferenceAdapter(study / "model.bdf")
    a = CachedAdapter(inner, tmp_path / "c")
    first = a.solve(loads, a.dofs())
    assert inner.stats.runs == 1 and a.cache_stats.misses == 1 and a.cache_stats.stores == 1
    second = a.solve(loads, a.dofs())
    assert inner.stats.runs == 1 and inner.stats.right_hand_sides == loads.n_cases
    assert a.cache_stats.hits == 1 and same_bytes(first, second)
    assert a.stats is inner.stats                      # the solver's counters, unchanged by a hit
    # a new process (a new adapter object) finds it too
    b = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    third = b.solve(loads, b.dofs())
    assert b.inner.stats.runs == 0 and b.cache_stats.hits == 1 and same_bytes(first, third)
    assert len(entries(tmp_path / "c")) == 1


def test_a_hit_equals_a_fresh_solve(cube, tmp_path):
    study, loads = cube
    a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    a.solve(loads, a.dofs())
    hit = a.solve(loads, a.dofs())
    fresh = ReferenceAdapter(study / "model.bdf").solve(loads, a.dofs())
    assert same_bytes(hit, fresh)


def test_different_loads_report_or_labels_miss(cube, tmp_path):
    study, loads = cube
    inner = ReferenceAdapter(study / "model.bdf")
    a = CachedAdapter(inner, tmp_path / "c")
    report = a.dofs()
    a.solve(loads, report)
    scaled = LoadMatrix(loads.dofs, loads.values * (1 + 1e-15), loads.cases)   # one ulp-ish apart
    renamed = LoadMatrix(loads.dofs, loads.values, tuple(f"x{c}" for c in loads.cases))
    for variant, rep in [(scaled, report), (renamed, report), (loads.select([0, 1]), report),
                         (loads, report[:6]), (loads, tuple(reversed(report)))]:
        runs = inner.stats.runs
        out = a.solve(variant, rep)
        assert inner.stats.runs == runs + 1, variant.cases[:2]
        assert out.cases == variant.cases and out.dofs == tuple(rep)
    assert a.cache_stats.hits == 0 and len(entries(tmp_path / "c")) == 6


def test_equal_load_matrices_hit_whatever_their_sparse_layout(cube, tmp_path):
    """Explicit zeros and duplicate entries do not change the key (canonical CSC)."""
    study, loads = cube
    inner = ReferenceAdapter(study / "model.bdf")
    a = CachedAdapter(inner, tmp_path / "c")
    a.solve(loads, a.dofs())
    v = loads.values.tocsc()
    a0, b0 = v.indptr[0], v.indptr[1]
    # column 0 rewritten unsorted, its first entry split into two exact halves, plus an explicit zero
    idx0 = np.r_[len(loads.dofs) - 1, v.indices[a0:b0], v.indices[a0]]
    val0 = np.r_[0.0, v.data[a0:b0], v.data[a0] / 2]
    val0[1] /= 2
    messy = sp.csc_matrix((np.r_[val0, v.data[b0:]], np.r_[idx0, v.indices[b0:]],
                           np.r_[0, v.indptr[1:] + 2]), shape=v.shape)
    same = LoadMatrix(loads.dofs, messy, loads.cases)
    assert same.values.nnz == v.nnz + 2 and abs(same.values - v).max() == 0
    a.solve(same, a.dofs())
    assert inner.stats.runs == 1 and a.cache_stats.hits == 1


def test_springs_miss_and_with_springs_is_cached_too(cube, tmp_path):
    study, loads = cube
    a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    s1 = [ScalarSpring((7, 4), (71, 4), 1.0e4)]
    s2 = [ScalarSpring((7, 4), (71, 4), 2.0e4)]
    base = a.solve(loads, a.dofs())
    w1 = a.with_springs(s1)
    assert isinstance(w1, CachedAdapter) and w1.cache_stats is a.cache_stats
    u1 = w1.solve(loads, a.dofs())
    assert w1.inner.stats.runs == 1 and not same_bytes(base, u1)
    w2 = a.with_springs(s2)
    w2.solve(loads, a.dofs())
    assert w2.inner.stats.runs == 1                       # other stiffness: a miss
    again = a.with_springs(s1)
    u1b = again.solve(loads, a.dofs())
    assert again.inner.stats.runs == 0 and same_bytes(u1, u1b)
    # springs added in two steps are the same model as in one step
    two_steps = a.with_springs(s1[:0]).with_springs(s1)
    two_steps.solve(loads, a.dofs())
    assert two_steps.inner.stats.runs == 0
    assert a.cache_stats.hits == 2 and a.cache_stats.misses == 3


def test_deck_content_decides_not_its_path(tmp_path):
    deck, loads = write_generated_deck(tmp_path / "g1")
    a = CachedAdapter(ReferenceAdapter(deck), tmp_path / "c")
    u = a.solve(loads, a.dofs())
    # a copy of the deck folder elsewhere: same bytes, same key
    shutil.copytree(tmp_path / "g1", tmp_path / "g2")
    b = CachedAdapter(ReferenceAdapter(tmp_path / "g2" / deck.name), tmp_path / "c")
    assert same_bytes(b.solve(loads, b.dofs()), u) and b.inner.stats.runs == 0
    # an edit of the INCLUDEd property file only: a miss, and another answer
    props = tmp_path / "g2" / "generated_props.bdf"
    props.write_text(props.read_text().replace("2.+6", "3.+6"))
    c = CachedAdapter(ReferenceAdapter(tmp_path / "g2" / deck.name), tmp_path / "c")
    v = c.solve(loads, c.dofs())
    assert c.inner.stats.runs == 1 and not same_bytes(u, v)


def test_a_deck_edited_after_wrapping_bypasses_the_cache(cube, tmp_path):
    """The inner adapter parsed the old deck; caching its answer under the new deck's key would
    poison the cache, so that solve neither reads nor writes."""
    study, loads = cube
    a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    deck = study / "model.bdf"
    deck.write_text(deck.read_text() + "$ edited\n")
    a.solve(loads, a.dofs())
    a.solve(loads, a.dofs())
    assert a.cache_stats.bypassed == 2 and entries(tmp_path / "c") == [] and a.inner.stats.runs == 2


def test_other_adapter_misses(cube, tmp_path):
    study, loads = cube
    ref = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    ref.solve(loads, ref.dofs())
    leg = CachedAdapter(LegacyAdapter(study / "model.bdf"), tmp_path / "c")
    leg.solve(loads, leg.dofs())
    assert leg.inner.stats.runs == 1 and len(entries(tmp_path / "c")) == 2
    leg2 = CachedAdapter(LegacyAdapter(study / "model.bdf"), tmp_path / "c")
    leg2.solve(loads, leg2.dofs())
    assert leg2.inner.stats.runs == 0


def test_unknown_labels_still_raise_and_store_nothing(cube, tmp_path):
    study, loads = cube
    a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    with pytest.raises(UnknownDofError):
        a.solve(loads, [(999, 1)])
    assert entries(tmp_path / "c") == [] and a.inner.stats.runs == 0


def test_adapter_without_a_deck_identity_is_refused():
    class Opaque:
        name = "opaque"

    with pytest.raises(TypeError, match="cache_token"):
        CachedAdapter(Opaque(), "unused")


def test_cache_token_replaces_the_deck(cube, tmp_path):
    study, loads = cube

    class Tokened(ReferenceAdapter):
        token = "v1"

        def cache_token(self):
            return self.token

    a = CachedAdapter(Tokened(study / "model.bdf"), tmp_path / "c")
    a.solve(loads, a.dofs())
    b_inner = Tokened(study / "model.bdf")
    b_inner.token = "v2"
    b = CachedAdapter(b_inner, tmp_path / "c")
    b.solve(loads, b.dofs())
    assert b_inner.stats.runs == 1


# --------------------------------------------------------------------------------------------
# corruption
# --------------------------------------------------------------------------------------------
def _truncate_half(p: Path, other: Path) -> None:
    data = p.read_bytes()
    p.write_bytes(data[:len(data) // 2])


def _empty(p: Path, other: Path) -> None:
    p.write_bytes(b"")


def _flip_value_byte(p: Path, other: Path) -> None:
    data = bytearray(p.read_bytes())
    data[-3] ^= 0x01
    p.write_bytes(bytes(data))


def _flip_header_byte(p: Path, other: Path) -> None:
    data = bytearray(p.read_bytes())
    i = data.find(b'"dofs"') + 12          # inside the report labels
    data[i] ^= 0x01
    p.write_bytes(bytes(data))


def _flip_magic(p: Path, other: Path) -> None:
    data = bytearray(p.read_bytes())
    data[0] ^= 0x20
    p.write_bytes(bytes(data))


def _append(p: Path, other: Path) -> None:
    p.write_bytes(p.read_bytes() + b"\x00" * 8)


def _other_entry(p: Path, other: Path) -> None:
    """A complete, checksum-valid entry, but for another key."""
    p.write_bytes(other.read_bytes())


def _half_written_by_a_dead_writer(p: Path, other: Path) -> None:
    """What a writer killed before os.replace leaves: only its temp file; plus the entry gone."""
    (p.parent / ".tmp-dead.part").write_bytes(p.read_bytes()[:100])
    p.unlink()


CORRUPTIONS = [_truncate_half, _empty, _flip_value_byte, _flip_header_byte, _flip_magic, _append,
               _other_entry, _half_written_by_a_dead_writer]


@pytest.mark.parametrize("corrupt", CORRUPTIONS, ids=[f.__name__.strip("_") for f in CORRUPTIONS])
def test_a_corrupt_entry_is_detected_recomputed_and_rewritten(corrupt, cube, tmp_path):
    study, loads = cube
    inner = ReferenceAdapter(study / "model.bdf")
    a = CachedAdapter(inner, tmp_path / "c")
    good = a.solve(loads, a.dofs())
    a.solve(loads.select([0]), a.dofs())          # another entry, for _other_entry
    path = entry_path(tmp_path / "c", a.key(loads, a.dofs()))
    other = entry_path(tmp_path / "c", a.key(loads.select([0]), a.dofs()))
    corrupt(path, other)
    again = a.solve(loads, a.dofs())
    assert inner.stats.runs == 3                  # recomputed, never read as valid
    assert same_bytes(again, good)
    if corrupt is not _half_written_by_a_dead_writer:
        assert a.cache_stats.corrupt == 1
    third = a.solve(loads, a.dofs())              # the rewritten entry is valid again
    assert inner.stats.runs == 3 and same_bytes(third, good)


def test_read_entry_checks_every_field(tmp_path):
    d = Displacements(((1, 1), (1, 2)), np.array([[1.0, 2.0], [3.0, 4.0]]), ("a", "b"))
    p = tmp_path / "e.bbc"
    write_entry(p, "k" * 64, d)
    assert same_bytes(read_entry(p, "k" * 64, d.dofs, d.cases), d)
    for key, dofs, cases in [("j" * 64, d.dofs, d.cases), ("k" * 64, ((1, 1), (1, 3)), d.cases),
                             ("k" * 64, d.dofs, ("a", "c")), ("k" * 64, d.dofs[:1], d.cases)]:
        with pytest.raises(CorruptEntry):
            read_entry(p, key, dofs, cases)
    assert p.read_bytes().startswith(MAGIC)
    assert [f.name for f in tmp_path.iterdir()] == ["e.bbc"]     # no temp file left


def test_an_unwritable_cache_never_fails_a_solve(cube, tmp_path):
    study, loads = cube
    blocker = tmp_path / "c"
    blocker.write_text("a file where the cache folder should be")
    a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), blocker)
    with pytest.warns(RuntimeWarning, match="is not a folder; the cache is off"):
        u = a.solve(loads, a.dofs())
    assert u.values.shape == (60, 20) and a.cache_stats.bypassed == 1 and a.cache_stats.stores == 0
    assert blocker.read_text() == "a file where the cache folder should be"


# --------------------------------------------------------------------------------------------
# failed runs are never cached
# --------------------------------------------------------------------------------------------
def test_a_crashing_legacy_run_leaves_no_entry(cube, tmp_path):
    study, loads = cube
    a = CachedAdapter(LegacyAdapter(study / "model.bdf", misbehave="crash", workdir_root=tmp_path / "runs",
                                    trusted=True),
                      tmp_path / "c")
    for _ in range(2):
        with pytest.raises(SolverRunError):
            a.solve(loads, a.dofs())
    assert entries(tmp_path / "c") == [] and a.cache_stats.misses == 2 and a.cache_stats.stores == 0


@pytest.mark.parametrize("switch", ["garbage", "nan", "wrong_cases", "truncate"])
def test_no_misbehaviour_is_ever_cached(switch, cube, tmp_path):
    study, loads = cube
    a = CachedAdapter(LegacyAdapter(study / "model.bdf", misbehave=switch, workdir_root=tmp_path / "runs",
                                    trusted=True),
                      tmp_path / "c")
    with pytest.raises(SolverRunError):
        a.solve(loads.select([0, 1]), a.dofs())
    assert entries(tmp_path / "c") == []


def test_a_command_running_false_leaves_no_entry(cube, tmp_path):
    study, loads = cube
    a = CachedAdapter(CommandAdapter(study / "model.bdf", command=["false"], workdir_root=tmp_path / "runs",
                                     trusted=True),
                      tmp_path / "c")
    with pytest.raises(SolverRunError):
        a.solve(loads, a.dofs())
    assert entries(tmp_path / "c") == [] and a.cache_stats.stores == 0


def test_non_finite_results_are_returned_but_not_stored(cube, tmp_path):
    study, loads = cube

    class NaNs(ReferenceAdapter):
        def solve(self, loads, report):
            out = super().solve(loads, report)
            return Displacements(out.dofs, out.values * np.nan, out.cases)

    a = CachedAdapter(NaNs(study / "model.bdf"), tmp_path / "c")
    a.solve(loads, a.dofs())
    assert entries(tmp_path / "c") == [] and a.cache_stats.not_stored == 1


# --------------------------------------------------------------------------------------------
# concurrency
# --------------------------------------------------------------------------------------------
WRITER = """
import sys, numpy as np
from pathlib import Path
from solver_adapters.cache import write_entry
from solver_adapters.protocol import Displacements
path, key, n = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
rng = np.random.default_rng(7)                     # both writers write the same result
dofs = tuple((g, c) for g in range(1, 2001) for c in range(1, 7))
d = Displacements(dofs, rng.standard_normal((len(dofs), 8)), tuple(f"L{j}" for j in range(8)))
for _ in range(n):
    write_entry(path, key, d)
"""


def test_two_processes_writing_one_key_leave_one_valid_entry(tmp_path):
    key = "ab" * 32
    path = entry_path(tmp_path / "c", key)
    procs = [subprocess.Popen([sys.executable, "-c", WRITER, str(path), key, "25"], cwd=ROOT)
             for _ in range(2)]
    dofs = tuple((g, c) for g in range(1, 2001) for c in range(1, 7))
    cases = tuple(f"L{j}" for j in range(8))
    reads = 0
    while any(p.poll() is None for p in procs):    # a reader never sees a partial entry
        try:
            read_entry(path, key, dofs, cases)
            reads += 1
        except FileNotFoundError:
            pass
    assert [p.returncode for p in procs] == [0, 0]
    assert reads > 0
    out = read_entry(path, key, dofs, cases)
    assert out.values.shape == (12000, 8)
    assert sorted(f.name for f in path.parent.iterdir()) == [path.name]   # no temp file left


RACER = """
import sys, time
from pathlib import Path
from solver_adapters.cache import CachedAdapter
from solver_adapters.conformance import read_loads_csv
from solver_adapters.reference import ReferenceAdapter
study, cache, start = Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3])
a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), cache)
loads = read_loads_csv(study / "loads.csv")
while time.time() < start:
    time.sleep(0.001)
a.solve(loads, a.dofs())
print(a.inner.stats.runs, a.cache_stats.hits, a.cache_stats.stores)
"""


def test_two_processes_solving_the_same_batch_end_with_one_valid_entry(cube, tmp_path):
    study, loads = cube
    start = time.time() + 2.0
    procs = [subprocess.Popen([sys.executable, "-c", RACER, str(study), str(tmp_path / "c"), str(start)],
                              cwd=ROOT, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=60)[0].split() for p in procs]
    assert all(p.returncode == 0 for p in procs)
    assert len(entries(tmp_path / "c")) == 1
    a = CachedAdapter(ReferenceAdapter(study / "model.bdf"), tmp_path / "c")
    a.solve(loads, a.dofs())
    assert a.inner.stats.runs == 0 and a.cache_stats.corrupt == 0, outs


# --------------------------------------------------------------------------------------------
# the study wiring and resuming a command
# --------------------------------------------------------------------------------------------
def test_make_adapter_for_wraps_only_when_asked(cube, tmp_path):
    from blackbox.study import load_study
    from blackbox.adapters import ADAPTER_CACHE, make_adapter_for

    study = load_study(cube[0])
    assert not isinstance(make_adapter_for(study), CachedAdapter)            # library default: off
    a = make_adapter_for(study, cache=True)
    assert isinstance(a, CachedAdapter) and a.cache_dir == study.root / ".blackbox_cache"
    b = make_adapter_for(study, "legacy", cache=tmp_path / "elsewhere")
    assert isinstance(b, CachedAdapter) and b.cache_dir == tmp_path / "elsewhere" and b.name == "legacy"
    assert not isinstance(make_adapter_for(study, cache=False), CachedAdapter)
    token = ADAPTER_CACHE.set(True)
    try:
        assert isinstance(make_adapter_for(study), CachedAdapter)
    finally:
        ADAPTER_CACHE.reset(token)


def _blackbox(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "blackbox.cli", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, env=env)


def _runs(stdout: str) -> int:
    m = re.search(r"\((\d+) solver run\(s\)\)", stdout)
    assert m, stdout
    return int(m.group(1))


def test_blackbox_solve_resumes_from_the_cache(cube, tmp_path):
    study, _ = cube
    first = _blackbox("solve", str(study), "--out", str(tmp_path / "o1"))
    assert first.returncode == 0, first.stderr
    assert _runs(first.stdout) == 1 and len(entries(study / ".blackbox_cache")) == 1
    second = _blackbox("solve", str(study), "--out", str(tmp_path / "o2"))
    assert second.returncode == 0 and _runs(second.stdout) == 0           # no new solver run
    assert (tmp_path / "o1" / "displacements.csv").read_bytes() == (tmp_path / "o2" / "displacements.csv").read_bytes()
    bypass = _blackbox("solve", str(study), "--no-cache", "--out", str(tmp_path / "o3"))
    assert _runs(bypass.stdout) == 1
    elsewhere = _blackbox("solve", str(study), "--cache-dir", str(tmp_path / "cc"), "--out", str(tmp_path / "o4"))
    assert _runs(elsewhere.stdout) == 1 and len(entries(tmp_path / "cc")) == 1
    assert len(entries(study / ".blackbox_cache")) == 1


def test_cli_in_process_resets_the_cache_choice(cube, tmp_path):
    from blackbox.cli import main
    from blackbox.adapters import ADAPTER_CACHE

    study, _ = cube
    assert main(["solve", str(study), "--out", str(tmp_path / "o")]) == 0
    assert ADAPTER_CACHE.get() is False and len(entries(study / ".blackbox_cache")) == 1


def _framesolve_under(folder: Path) -> list[psutil.Process]:
    out = []
    for p in psutil.process_iter(["cmdline", "status"]):
        try:
            if p.info["status"] != psutil.STATUS_ZOMBIE and str(FRAMESOLVE) in " ".join(p.info["cmdline"] or []) \
                    and p.cwd().startswith(str(folder)):
                out.append(p)
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            pass
    return out


def test_a_run_killed_mid_solve_leaves_no_entry_and_the_rerun_solves(cube, tmp_path):
    """SIGKILL ``blackbox solve`` while FRAMESOLVE hangs: nothing is cached; the next run solves
    (one run) and the one after reads the cache (no run)."""
    study, _ = cube
    runs_root = tmp_path / "tmp"
    runs_root.mkdir()
    env = {**os.environ, "FRAMESOLVE_MISBEHAVE": "hang", "TMPDIR": str(runs_root)}
    proc = subprocess.Popen([sys.executable, "-m", "blackbox.cli", "solve", str(study), "--adapter", "legacy",
                             "--out", str(tmp_path / "o")], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        t0 = time.monotonic()
        while not _framesolve_under(runs_root) and time.monotonic() - t0 < 60:
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        assert _framesolve_under(runs_root), "FRAMESOLVE never started"
        time.sleep(0.5)                                 # mid-run: banner printed, child started
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
        for p in _framesolve_under(runs_root):          # the orphans of the killed command
            try:
                p.kill()
            except psutil.Error:
                pass
    assert proc.returncode == -signal.SIGKILL
    assert entries(study / ".blackbox_cache") == []
    resumed = _blackbox("solve", str(study), "--adapter", "legacy", "--out", str(tmp_path / "o"))
    assert resumed.returncode == 0, resumed.stderr
    assert _runs(resumed.stdout) == 1 and len(entries(study / ".blackbox_cache")) == 1
    again = _blackbox("solve", str(study), "--adapter", "legacy", "--out", str(tmp_path / "o2"))
    assert _runs(again.stdout) == 0
