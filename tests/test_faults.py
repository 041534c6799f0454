"""Fault injection on the whole command (docs/faults.md lists every fault with its outcome).

Each test runs the real ``blackbox`` command line (in-process or as a subprocess) and checks what
the user is left with: the exit code, the message, the output folder (old output kept, no partial
files) and, for a killed run, that no solver process survives (psutil).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from blackbox.cli import main
from blackbox.commands.output import MARKER



def _legacy(study: Path, misbehave: str, timeout_s: float = 60.0) -> None:
    toml = study / "study.toml"
    toml.write_text(toml.read_text().replace('adapter = "reference"', f'adapter = "legacy"\n'
                                             f'options = {{ misbehave = "{misbehave}" }}')
                    .replace("timeout_s = 600", f"timeout_s = {timeout_s}"))


def _solvers(marker: str) -> list[psutil.Process]:
    out = []
    for p in psutil.process_iter(["cmdline"]):
        try:
            if any("framesolve" in c for c in p.info["cmdline"] or ()) and any(marker in c for c in p.info["cmdline"]):
                out.append(p)
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            continue
    return out


def _solver_tree_alive(run_root: Path) -> list[psutil.Process]:
    """Solver processes whose working directory lies under ``run_root``."""
    out = []
    for p in psutil.process_iter():
        try:
            if "framesolve" in " ".join(p.cmdline()) and Path(p.cwd()).is_relative_to(run_root):
                out.append(p)
        except (psutil.NoSuchProcess, psutil.AccessDenied, FileNotFoundError):
            continue
    return out


@pytest.mark.parametrize("mode,code", [("crash", 3), ("garbage", 3), ("nan", 3), ("truncate", 3)])
def test_misbehaving_solver_is_a_solver_failure_and_writes_nothing(cube, tmp_path, capsys, mode, code):
    _legacy(cube, mode)
    assert main(["solve", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == code
    assert "solver failure" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["cube"]            # no partial output folder


def test_hanging_solver_is_killed_at_its_timeout(cube, tmp_path, capsys):
    _legacy(cube, "hang", timeout_s=2.0)
    t0 = time.perf_counter()
    assert main(["solve", str(cube), "--out", str(tmp_path / "o"), "--no-cache"]) == 3
    assert time.perf_counter() - t0 < 30.0
    assert "SolverTimeoutError" in capsys.readouterr().err
    assert not _solvers(str(cube))


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGKILL])
def test_signal_to_blackbox_mid_run_leaves_no_solver(cube, tmp_path, sig):
    """``blackbox solve`` on a hanging solver is signalled while the solver runs: no solver process
    is left (the guard process kills the tree even when blackbox dies by SIGKILL), and --out holds
    nothing."""
    _legacy(cube, "hang", timeout_s=120.0)
    runs = tmp_path / "runs"
    runs.mkdir()
    env = dict(os.environ, TMPDIR=str(runs))
    proc = subprocess.Popen([sys.executable, "-m", "blackbox.cli", "solve", str(cube), "--out", str(tmp_path / "o"),
                             "--no-cache"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30.0
        while not _solver_tree_alive(runs):
            assert time.monotonic() < deadline, "the solver never started"
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.1)
        proc.send_signal(sig)
        proc.wait(timeout=30)
        deadline = time.monotonic() + 10.0
        while _solver_tree_alive(runs) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _solver_tree_alive(runs)
        assert not (tmp_path / "o").exists()
        if sig != signal.SIGKILL:
            assert proc.returncode == 130                      # handled like Ctrl-C
            assert not any(runs.iterdir())                     # its run folder removed too
    finally:
        if proc.poll() is None:
            proc.kill()
        for p in _solver_tree_alive(runs):
            p.kill()


def test_interrupted_output_keeps_the_earlier_output(cube, tmp_path, monkeypatch):
    out = tmp_path / "o"
    assert main(["identify", str(cube), "--out", str(out), "--no-cache"]) == 0
    before = (out / "result.json").read_text()
    from blackbox.reports import identify as report

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "identification_plots", interrupted)
    assert main(["identify", str(cube), "--out", str(out), "--no-cache"]) == 130
    assert (out / "result.json").read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cube", "o"]


def _tmpfs(path: Path, size: str, *options: str) -> bool:
    path.mkdir(parents=True, exist_ok=True)
    opts = ",".join((f"size={size}",) + options)
    return subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(path)],
                          capture_output=True).returncode == 0


def test_full_disk_during_output(cube, tmp_path, capsys):
    """A disk that fills while the outputs are written: the command fails with the system's
    message, and nothing half-written is left."""
    disk = tmp_path / "disk"
    if not _tmpfs(disk, "64k"):
        pytest.skip("cannot mount a small tmpfs here (needs root)")
    try:
        assert main(["identify", str(cube), "--out", str(disk / "o"), "--no-cache"]) == 2
        assert "No space left on device" in capsys.readouterr().err
        assert list(disk.iterdir()) == []
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_read_only_output_folder(cube, tmp_path, capsys):
    ro = tmp_path / "ro"
    if not _tmpfs(ro, "1m", "ro"):
        pytest.skip("cannot mount a read-only tmpfs here (needs root)")
    try:
        t0 = time.perf_counter()
        assert main(["identify", str(cube), "--out", str(ro / "o"), "--no-cache"]) == 2
        err = capsys.readouterr().err
        assert "parent folder of --out" in err or "Read-only file system" in err
        assert time.perf_counter() - t0 < 5.0                 # refused before the computation
    finally:
        subprocess.run(["umount", str(ro)], check=False)


def test_corrupt_cache_entry_is_recomputed_not_trusted(cube, tmp_path, monkeypatch, capsys):
    """A cache entry with flipped bytes is not used: the batch is solved again and the result is
    the same. (An entry planted with a recomputed checksum but no key is refused the same way:
    tests/test_safety_solver.py.)"""
    monkeypatch.setenv("BLACKBOX_CONFIG_DIR", str(tmp_path / "config"))
    out = tmp_path / "o"
    assert main(["identify", str(cube), "--out", str(out)]) == 0
    good = json.loads((out / "result.json").read_text())["parameters"]
    entries = [p for p in (cube / ".blackbox_cache").rglob("*") if p.is_file()]
    assert entries
    for p in entries:                                # garble every entry as an attacker would
        raw = bytearray(p.read_bytes())
        raw[len(raw) // 2] ^= 0xFF
        p.write_bytes(bytes(raw))
    capsys.readouterr()
    assert main(["identify", str(cube), "--out", str(out)]) == 0
    assert "1 solver run(s)" in capsys.readouterr().out           # solved again, not read back
    assert json.loads((out / "result.json").read_text())["parameters"] == good
    assert json.loads((out / MARKER).read_text())["command"] == "identify"
