"""Any finite-element code as a black box: run it as a subprocess, one working directory per run.

Three layers, each usable alone:

* :func:`run_solver` starts a command in a directory, polls the whole process tree (wall clock,
  resident memory summed over the tree every ~50 ms), kills the *tree* on timeout and returns a
  :class:`RunRecord`. It never leaves a process behind.
* A :class:`Dialect` knows one input/output format: it writes the run deck (the user's bulk data
  plus loads, output requests and extra springs) and reads the displacements back. The NASTRAN
  dialect lives in :mod:`solver_adapters.nastran`; users add their own through the entry-point
  group ``blackbox.dialects`` (:func:`get_dialect`).
* :class:`CommandAdapter` implements :class:`~solver_adapters.protocol.SolverAdapter` for any
  (command, dialect) pair: one run per ``solve`` call (chunked only above the dialect's
  ``max_cases_per_run``), a fresh directory per run, so runs may go in parallel.

A legacy code's exit status means little (MYSTRAN exits 0 after fatal errors, ``MYSTRAN.md``
"Running it"), so deciding success is the dialect's job; the runner only reports what happened.
"""

from __future__ import annotations

import copy
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Protocol, Sequence, runtime_checkable

import numpy as np
import psutil

from solver_adapters.protocol import (Displacements, DofLabel, LoadMatrix, ScalarSpring, SolverError,
                                      SolverRunError, SolverStats, SolverTimeoutError, UnknownDofError)

POLL_S = 0.05
"""Process-tree polling interval (memory, timeout); the first polls come sooner (from 2 ms,
doubling) so that a 10 ms run does not wait 50 ms to be noticed."""

TAIL_LINES = 40


# --------------------------------------------------------------------------------------------
# the runner
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunRecord:
    """What one external run did.

    ``peak_rss_bytes``: the largest of the polled sums of RSS over the process tree and of any one
    process's own high-water mark; a lower bound of the true peak (runs shorter than a poll may
    be sampled once or not at all).
    """

    command: tuple[str, ...]
    returncode: int
    wall_s: float
    peak_rss_bytes: int
    stdout_tail: str
    stderr_tail: str
    workdir: Path
    stdout_path: Path
    stderr_path: Path

    def log_tail(self) -> str:
        """stdout and stderr tails, labelled (for error messages)."""
        parts = []
        if self.stdout_tail.strip():
            parts.append(f"[stdout]\n{self.stdout_tail.rstrip()}")
        if self.stderr_tail.strip():
            parts.append(f"[stderr]\n{self.stderr_tail.rstrip()}")
        return "\n".join(parts)


def tail_text(path: Path, lines: int = TAIL_LINES, max_bytes: int = 64_000) -> str:
    """The last ``lines`` lines of a text file ('' if it does not exist), trailing blanks stripped."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - max_bytes))
            data = fh.read().decode("utf-8", errors="replace")
    except OSError:
        return ""
    rows = [r.rstrip() for r in data.splitlines()]
    while rows and not rows[-1]:
        rows.pop()
    return "\n".join(rows[-lines:])


def _tree(root: psutil.Process) -> list[psutil.Process]:
    try:
        return [root, *root.children(recursive=True)]
    except psutil.Error:
        return [root]


def _tree_rss(procs: list[psutil.Process]) -> int:
    total = 0
    for p in procs:
        try:
            total += p.memory_info().rss
        except psutil.Error:
            pass
    return total


def _high_water(pid: int) -> int:
    """The kernel's peak RSS of one live process (Linux ``VmHWM``; 0 elsewhere or once exited).

    Catches a peak between two polls. (``wait4``'s ``ru_maxrss`` is no use: it keeps the
    pre-exec RSS of the forked Python parent.)
    """
    try:
        with open(f"/proc/{pid}/status", "rb") as fh:
            for line in fh:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def kill_tree(procs: Sequence[psutil.Process], grace_s: float = 2.0) -> None:
    """terminate, wait ``grace_s``, then kill whatever is left (psutil refuses reused PIDs)."""
    alive = []
    for p in procs:
        try:
            p.terminate()
            alive.append(p)
        except psutil.Error:
            pass
    _, alive = psutil.wait_procs(alive, timeout=grace_s)
    for p in alive:
        try:
            p.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(alive, timeout=grace_s)


def run_solver(command: Sequence[str], workdir: Path, timeout_s: float, log_name: str = "solver",
               env: dict[str, str] | None = None) -> RunRecord:
    """Run ``command`` in ``workdir`` with a wall-clock limit; return a :class:`RunRecord`.

    stdout and stderr go to ``<log_name>.stdout`` / ``<log_name>.stderr`` in ``workdir`` (files,
    not pipes: a chatty solver cannot block). The child starts in its own session; every
    descendant seen while polling is remembered, and at the end (normal exit, timeout or an
    interrupt of this call) any of them still alive, and the child's process group, are killed.

    Raises :class:`SolverRunError` if the command cannot be started and
    :class:`SolverTimeoutError` (with the log tail) after ``timeout_s`` seconds.
    A nonzero exit code is *not* an error here; the caller decides.
    """
    workdir = Path(workdir)
    cmd = tuple(str(c) for c in command)
    if not cmd:
        raise ValueError("command is empty")
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
    out_path, err_path = workdir / f"{log_name}.stdout", workdir / f"{log_name}.stderr"
    t0 = time.perf_counter()
    with open(out_path, "wb") as out, open(err_path, "wb") as err:
        try:
            proc = subprocess.Popen(cmd, cwd=workdir, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                                    env=env, start_new_session=True)
        except OSError as exc:
            raise SolverRunError(f"cannot start solver command {list(cmd)}: {exc}",
                                 workdir=str(workdir)) from exc
    seen: dict[int, psutil.Process] = {}
    peak = 0
    timed_out = False
    root: psutil.Process | None = None
    pause = 0.002
    try:
        root = psutil.Process(proc.pid)
        while True:
            procs = _tree(root)
            for p in procs[1:]:
                seen.setdefault(p.pid, p)
            peak = max(peak, _tree_rss(procs), *(_high_water(p.pid) for p in procs))
            if proc.poll() is not None:
                break
            if time.perf_counter() - t0 > timeout_s:
                timed_out = True
                break
            time.sleep(pause)
            pause = min(2 * pause, POLL_S)
    finally:
        leftovers = [p for p in seen.values() if p.is_running()]
        if proc.returncode is None and root is not None:  # timeout or interrupted: the root too
            leftovers.insert(0, root)
        kill_tree(leftovers)
        _killpg(proc.pid)
        if proc.returncode is None:
            proc.wait()
    wall = time.perf_counter() - t0
    record = RunRecord(cmd, proc.returncode, wall, peak, tail_text(out_path), tail_text(err_path),
                       workdir, out_path, err_path)
    if timed_out:
        raise SolverTimeoutError(f"solver exceeded its time limit of {timeout_s:g} s after "
                                 f"{wall:.1f} s and was killed with its process tree: {list(cmd)}",
                                 log_tail=record.log_tail(), workdir=str(workdir))
    return record


def _killpg(pgid: int) -> None:
    """Kill what is left in the child's own process group (daemons it forked and forgot)."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError, OSError):
        pass


# --------------------------------------------------------------------------------------------
# dialects
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BaseDeck:
    """The user's model as a dialect receives it: the file and its parsed form (``bdf.read_deck``)."""

    path: Path
    model: Any  # solver_adapters.deck.Deck (kept untyped: no import of the reader here)


@runtime_checkable
class Dialect(Protocol):
    """One solver input/output format. ``max_cases_per_run`` (optional attribute) chunks batches."""

    name: str

    def write_deck(self, workdir: Path, base: BaseDeck, loads: LoadMatrix, report: Sequence[DofLabel],
                   springs: Sequence[ScalarSpring]) -> Path:
        """Write the run's input file into ``workdir`` and return its path."""
        ...

    def command(self, deck_path: Path) -> list[str] | None:
        """The default command for this format (``None``: the user must give one)."""
        ...

    def read_results(self, workdir: Path, deck_path: Path, loads: LoadMatrix, report: Sequence[DofLabel],
                     record: RunRecord) -> np.ndarray:
        """Displacements ``(len(report), loads.n_cases)``; :class:`SolverRunError` on any failure."""
        ...


BUILTIN_DIALECTS = {"nastran": "solver_adapters.nastran:NastranDialect",
                    "legacy": "solver_adapters.legacy:LegacyDialect"}
DIALECT_GROUP = "blackbox.dialects"


def _load(target: str) -> Any:
    module, _, attr = target.partition(":")
    obj = __import__(module, fromlist=[attr])
    return getattr(obj, attr)


def known_dialects() -> dict[str, str]:
    """Name -> ``module:object`` for the builtin dialects and those of entry-point group
    ``blackbox.dialects`` (builtins win on a name clash)."""
    found = {ep.name: ep.value for ep in entry_points(group=DIALECT_GROUP)}
    return {**found, **BUILTIN_DIALECTS}


def get_dialect(name: str, **options: Any) -> Dialect:
    """A dialect instance by name: builtin first, then entry-point group ``blackbox.dialects``."""
    known = known_dialects()
    if name not in known:
        raise ValueError(f"unknown solver dialect {name!r}; known: {', '.join(sorted(known))}. "
                         f"A package can add one with an entry point in group {DIALECT_GROUP!r} "
                         f"(name = 'module:DialectClass').")
    if name in BUILTIN_DIALECTS:
        factory = _load(BUILTIN_DIALECTS[name])
    else:
        factory = next(ep for ep in entry_points(group=DIALECT_GROUP) if ep.name == name).load()
    return factory(**options)


# --------------------------------------------------------------------------------------------
# the adapter
# --------------------------------------------------------------------------------------------
def _note_workdir(exc: SolverError, workdir: Path) -> None:
    """Add the kept run directory to an error raised without it (message and attribute)."""
    if getattr(exc, "workdir", None):
        return
    exc.workdir = str(workdir)
    exc.args = (f"{exc.args[0] if exc.args else exc}\nrun directory kept for inspection: {workdir}",
                *exc.args[1:])


class CommandAdapter:
    """:class:`SolverAdapter` for any external code: a command line plus a :class:`Dialect`.

    ``command`` is a list of arguments in which ``{deck}`` is replaced by the absolute path of the
    run deck, ``{deck_name}`` by its file name and ``{workdir}`` by the run directory (the command
    runs with the run directory as its working directory); without a ``{deck...}`` placeholder
    the deck path is appended. ``command=None`` takes the dialect's default.

    Each ``solve`` is one run (several only when the batch exceeds the dialect's
    ``max_cases_per_run``) in a fresh ``tempfile.mkdtemp`` directory under ``workdir_root``,
    deleted on success and kept on failure when ``keep_failed`` (its path is in the error).
    """

    def __init__(self, deck_path: str | os.PathLike, command: Sequence[str] | None = None,
                 dialect: str | Dialect = "nastran", timeout_s: float = 600.0, keep_failed: bool = True,
                 workdir_root: str | os.PathLike | None = None, name: str = "command",
                 springs: Sequence[ScalarSpring] = ()):
        self.deck_path = Path(deck_path).resolve()
        self.dialect = get_dialect(dialect) if isinstance(dialect, str) else dialect
        if command is None:
            command = self.dialect.command(self.deck_path)
            if command is None:
                raise ValueError(f"dialect {self.dialect.name!r} has no default command: give one, "
                                 f"e.g. ['my-solver', '{{deck}}']")
        self.command = [str(c) for c in command]
        if not self.command:
            raise ValueError("command is empty")
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
        self.timeout_s = float(timeout_s)
        self.keep_failed = bool(keep_failed)
        self.workdir_root = Path(workdir_root) if workdir_root is not None else None
        self.name = name
        self.stats = SolverStats()
        self._lock = threading.Lock()
        from solver_adapters.bdf import read_deck  # the reader is only needed here
        self._base = BaseDeck(self.deck_path, read_deck(self.deck_path))
        grids = self._base.model.grids
        self._xyz = {int(g): tuple(float(v) for v in grids[g].xyz) for g in sorted(grids)}
        self._dofs = tuple((g, c) for g in self._xyz for c in range(1, 7))
        self._dofset = frozenset(self._dofs)
        self.springs = self._checked_springs(springs)

    # ---- protocol ------------------------------------------------------------------------
    def dofs(self) -> tuple[DofLabel, ...]:
        return self._dofs

    def grid_xyz(self) -> dict[int, tuple[float, float, float]]:
        return dict(self._xyz)

    def with_springs(self, springs: Sequence[ScalarSpring]) -> "CommandAdapter":
        """Same model, command and dialect with ``springs`` appended (written by the dialect).

        The copy keeps the parsed deck and any subclass attributes, and starts fresh stats.
        """
        clone = copy.copy(self)
        clone.springs = self.springs + self._checked_springs(springs)
        clone.stats, clone._lock = SolverStats(), threading.Lock()
        return clone

    def solve(self, loads: LoadMatrix, report: Sequence[DofLabel]) -> Displacements:
        report = tuple((int(g), int(c)) for g, c in report)
        self._check_known(loads.dofs, "load DOF")
        self._check_known(report, "reported DOF")
        if loads.n_cases == 0 or not report:
            return Displacements(report, np.zeros((len(report), loads.n_cases)), loads.cases)
        chunk = getattr(self.dialect, "max_cases_per_run", None) or loads.n_cases
        blocks = [self._run(loads.select(range(j, min(j + chunk, loads.n_cases))), report)
                  for j in range(0, loads.n_cases, chunk)]
        return Displacements(report, np.hstack(blocks), loads.cases)

    # ---- one run -------------------------------------------------------------------------
    def _checked_springs(self, springs: Sequence[ScalarSpring]) -> tuple[ScalarSpring, ...]:
        springs = tuple(springs)
        self._check_known([s.a for s in springs] + [s.b for s in springs if s.b is not None],
                          "spring DOF")
        bad = [s for s in springs if not np.isfinite(s.k)]
        if bad:
            raise ValueError(f"spring stiffness must be finite, got {bad[:3]}")
        return springs

    def _check_known(self, labels: Sequence[DofLabel], what: str) -> None:
        unknown = [tuple(d) for d in labels if tuple(d) not in self._dofset]
        if unknown:
            raise UnknownDofError(unknown, what)

    def _command_for(self, deck: Path) -> list[str]:
        subs = {"{deck}": str(deck), "{deck_name}": deck.name, "{workdir}": str(deck.parent)}
        if not any(k in arg for arg in self.command for k in ("{deck}", "{deck_name}")):
            return [*self.command, str(deck)]
        out = []
        for arg in self.command:
            for k, v in subs.items():
                arg = arg.replace(k, v)
            out.append(arg)
        return out

    def _run(self, loads: LoadMatrix, report: tuple[DofLabel, ...]) -> np.ndarray:
        if self.workdir_root is not None:
            self.workdir_root.mkdir(parents=True, exist_ok=True)
        workdir = Path(tempfile.mkdtemp(prefix=f"{self.name}-", dir=self.workdir_root))
        record = None
        times = {}
        try:
            t0 = time.perf_counter()
            deck = self.dialect.write_deck(workdir, self._base, loads, report, self.springs)
            times["write_s"] = time.perf_counter() - t0
            record = run_solver(self._command_for(Path(deck)), workdir, self.timeout_s,
                                log_name=self.name)
            t0 = time.perf_counter()
            values = np.asarray(self.dialect.read_results(workdir, Path(deck), loads, report, record),
                                dtype=float)
            times["parse_s"] = time.perf_counter() - t0
            expected = (len(report), loads.n_cases)
            if values.shape != expected:
                raise SolverRunError(f"dialect {self.dialect.name!r} returned shape {values.shape}, "
                                     f"expected {expected}", returncode=record.returncode,
                                     log_tail=record.log_tail())
            if not np.all(np.isfinite(values)):
                raise SolverRunError("solver returned non-finite displacements",
                                     returncode=record.returncode, log_tail=record.log_tail())
        except BaseException as exc:
            self._account(loads, record, workdir, ok=False, error=type(exc).__name__)
            if self.keep_failed and isinstance(exc, SolverError):
                _note_workdir(exc, workdir)
            else:
                shutil.rmtree(workdir, ignore_errors=True)
            raise
        self._account(loads, record, workdir, ok=True, times=times)
        shutil.rmtree(workdir, ignore_errors=True)
        return values

    def _account(self, loads: LoadMatrix, record: RunRecord | None, workdir: Path, ok: bool,
                 error: str | None = None, times: dict | None = None) -> None:
        with self._lock:
            s = self.stats
            entry = {"ok": ok, "cases": loads.n_cases, "workdir": None if ok else str(workdir),
                     "error": error, **(times or {})}
            if record is not None:
                s.runs += 1
                s.factorizations += 1
                s.wall_s += record.wall_s
                s.peak_rss_bytes = max(s.peak_rss_bytes, record.peak_rss_bytes)
                entry.update(wall_s=record.wall_s, peak_rss_bytes=record.peak_rss_bytes,
                             returncode=record.returncode)
            if ok:
                s.right_hand_sides += loads.n_cases
            s.history.append(entry)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(deck={str(self.deck_path)!r}, command={self.command!r}, "
                f"dialect={self.dialect.name!r}, springs={len(self.springs)})")
