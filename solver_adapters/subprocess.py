"""Any finite-element code as a black box: run it as a subprocess, one working directory per run.

Three layers, each usable alone:

* :func:`run_solver` starts a command in a directory, polls the whole process tree (wall clock,
  resident memory summed over the tree every ~50 ms, an optional heartbeat callback), kills the
  *tree* on timeout and returns a :class:`RunRecord`. It never leaves a process behind, not even
  when the calling process is killed (a guard process, :mod:`solver_adapters._guard`);
  :func:`install_termination_handlers` makes SIGTERM/SIGHUP end a run the way Ctrl-C does.
* A :class:`Dialect` knows one input/output format: it writes the run deck (the user's bulk data
  plus loads, output requests and extra springs) and reads the displacements back. The NASTRAN
  dialect lives in :mod:`solver_adapters.nastran`; users add their own through the entry-point
  group ``blackbox.dialects`` (:func:`get_dialect`).
* :class:`CommandAdapter` implements :class:`~solver_adapters.protocol.SolverAdapter` for any
  (command, dialect) pair: one run per ``solve`` call (chunked only above the dialect's
  ``max_cases_per_run``), a fresh directory per run, so runs may go in parallel. It runs a
  command only with the user's consent (:func:`check_command_consent`), removes failed runs'
  folders unless asked to keep them and cleans the stale folders of killed runs.

A legacy code's exit status means little (MYSTRAN exits 0 after fatal errors, ``docs/mystran.md``), so deciding success is the dialect's job; the runner only reports what happened.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import os
import re
import select
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Protocol, Sequence, runtime_checkable

import numpy as np
import psutil

from solver_adapters.errors import ConsentError
from solver_adapters.protocol import (Displacements, DofLabel, LoadMatrix, ScalarSpring, SolverError,
                                      SolverRunError, SolverStats, SolverTimeoutError, UnknownDofError)
from solver_adapters.userconfig import config_file, read_config

POLL_S = 0.05
"""Process-tree polling interval (memory, timeout); the first polls come sooner (from 2 ms,
doubling) so that a 10 ms run does not wait 50 ms to be noticed."""

TAIL_LINES = 40

MAX_LOCAL_PROCESSES = 4
"""At most this many solver processes of one batch side by side on one machine without an
executor (:meth:`CommandAdapter.local_processes`): each repeats the start, reading and
factorization, so beyond a few the shares of the substitutions shrink below that fixed cost."""

MIN_CASES_PER_CHUNK = 50
"""With an executor and no explicit ``chunks``, or side by side on this machine
(:meth:`CommandAdapter.local_processes`), a batch is cut into no chunk of fewer load cases:
every chunk is a whole solver run that repeats the start, the deck's reading, the assembly and
the factorization (``F``), and only the substitutions (``r`` per case) are shared out. MYSTRAN
measured ``F`` ~ 50-150 ``r`` from 1e3 to 1e5 DOFs (docs/parallel.md), so two chunks save a
third of the wall time or more only from ~100 cases; a 24-case batch on a 1e5-DOF model took
22 s as one run and 37 s in two chunks on a loaded 2-core machine."""


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


GUARD = Path(__file__).resolve().with_name("_guard.py")
"""The guard process each solver runs under (see :mod:`solver_adapters._guard`)."""

HEARTBEAT_S = 5.0
"""Default interval of the ``progress`` callback of :func:`run_solver` (seconds)."""

STATUS_WAIT_S = 30.0
"""How long :func:`run_solver` waits for the guard to report that the solver started."""

ProgressCallback = Callable[[float, str], None]
"""``progress(elapsed_s, last_line)``: called during a run with the seconds since its start and
the last non-blank line the solver wrote (stdout, else stderr; '' before any output)."""


def last_line(path: Path, max_bytes: int = 4096) -> str:
    """The last non-blank line of a text file, reading only its last ``max_bytes`` ('' if none)."""
    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            fh.seek(max(0, size - max_bytes))
            data = fh.read()
    except OSError:
        return ""
    for row in reversed(data.decode("utf-8", errors="replace").splitlines()):
        if row.strip():
            return row.rstrip()
    return ""


def _pdeathsig_preexec() -> Callable[[], None] | None:
    """A ``preexec_fn`` that gives the child SIGKILL when this thread dies (Linux), for the rare
    case that the guard cannot be used; None elsewhere. ``prctl`` is looked up here, in the
    parent, so the child only makes the call."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec() -> None:
        prctl(1, signal.SIGKILL, 0, 0, 0)          # PR_SET_PDEATHSIG
        if os.getppid() != parent:                  # the parent died before the call: do not run
            os.kill(os.getpid(), signal.SIGKILL)
    return preexec


def _start(cmd: tuple[str, ...], workdir: Path, out, err, env: dict[str, str] | None
           ) -> tuple[subprocess.Popen, int]:
    """Start ``cmd`` under the guard; return the guard's Popen and the solver's PID.
    ``OSError`` (with the solver's errno) when the command cannot be executed."""
    if not (os.name == "posix" and sys.executable and GUARD.is_file()):
        proc = subprocess.Popen(cmd, cwd=workdir, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                                env=env, start_new_session=True, preexec_fn=_pdeathsig_preexec())
        return proc, proc.pid
    r, w = os.pipe()
    try:
        proc = subprocess.Popen([sys.executable, "-I", "-S", str(GUARD), str(os.getpid()), str(w), "--", *cmd],
                                cwd=workdir, stdin=subprocess.DEVNULL, stdout=out, stderr=err, env=env,
                                start_new_session=True, pass_fds=(w,))
    except BaseException:
        os.close(r)
        raise
    finally:
        os.close(w)
    try:
        status = b""
        deadline = time.monotonic() + STATUS_WAIT_S
        with os.fdopen(r, "rb", buffering=0) as fh:
            while b"\n" not in status and time.monotonic() < deadline:
                ready, _, _ = select.select([fh], [], [], 0.5)
                if ready:
                    chunk = fh.read(4096)
                    if not chunk:
                        break
                    status += chunk
    except BaseException:
        _stop_guard(proc)
        raise
    word, _, rest = status.decode(errors="replace").strip().partition(" ")
    if word == "started":
        return proc, int(rest)
    _stop_guard(proc)
    if word == "error":
        code, _, text = rest.partition(" ")
        raise OSError(int(code), f"{text}: {cmd[0]!r}")
    raise OSError(f"the solver guard did not start the command (status {status!r}, exit code "
                  f"{proc.returncode})")


def _stop_guard(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()  # the guard kills what it started, then exits
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run_solver(command: Sequence[str], workdir: Path, timeout_s: float, log_name: str = "solver",
               env: dict[str, str] | None = None, *, progress: ProgressCallback | None = None,
               progress_every_s: float = HEARTBEAT_S) -> RunRecord:
    """Run ``command`` in ``workdir`` with a wall-clock limit; return a :class:`RunRecord`.

    stdout and stderr go to ``<log_name>.stdout`` / ``<log_name>.stderr`` in ``workdir`` (files,
    not pipes: a chatty solver cannot block). The command runs below a small guard process
    (:mod:`solver_adapters._guard`) in a session of its own; every descendant seen while polling
    is remembered, and at the end (normal exit, timeout or an interrupt of this call) any of them
    still alive, the guard and its process group are killed.

    No solver process outlives the calling process, however it ends: on Linux the guard is a
    child subreaper (no descendant can escape to init) and gets a parent-death signal, so a
    SIGKILL of this process still ends the whole solver tree; the death signal is tied to the
    *thread* that called this function, which stays blocked here until the run is over. SIGTERM
    and SIGHUP take the interrupt path once :func:`install_termination_handlers` was called.

    ``progress`` (optional) is called from this thread about every ``progress_every_s`` seconds
    as ``progress(elapsed_s, last_line)`` (see :data:`ProgressCallback`); an exception it raises
    ends the run like an interrupt.

    Raises :class:`SolverRunError` if the command cannot be started and
    :class:`SolverTimeoutError` (with the log tail; ``workdir`` attribute set) after
    ``timeout_s`` seconds. A nonzero exit code is *not* an error here; the caller decides.
    """
    workdir = Path(workdir)
    cmd = tuple(str(c) for c in command)
    if not cmd:
        raise ValueError("command is empty")
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
    if progress is not None and not progress_every_s > 0:
        raise ValueError(f"progress_every_s must be > 0, got {progress_every_s!r}")
    out_path, err_path = workdir / f"{log_name}.stdout", workdir / f"{log_name}.stderr"
    t0 = time.perf_counter()
    with open(out_path, "wb") as out, open(err_path, "wb") as err:
        try:
            proc, solver_pid = _start(cmd, workdir, out, err, env)
        except OSError as exc:
            raise SolverRunError(f"cannot start solver command {list(cmd)}: {exc}") from exc
    seen: dict[int, psutil.Process] = {}
    peak = 0
    timed_out = False
    root: psutil.Process | None = None
    pause = 0.002
    beat = t0 + progress_every_s
    try:
        root = psutil.Process(proc.pid)
        try:
            seen[solver_pid] = psutil.Process(solver_pid)
        except psutil.Error:
            pass
        while True:
            tree = _tree(root)
            procs = tree if solver_pid == proc.pid else tree[1:]  # the guard's memory is not the solver's
            for p in procs:
                seen.setdefault(p.pid, p)
            if procs:
                peak = max(peak, _tree_rss(procs), *(_high_water(p.pid) for p in procs))
            if proc.poll() is not None:
                break
            now = time.perf_counter()
            if now - t0 > timeout_s:
                timed_out = True
                break
            if progress is not None and now >= beat:
                beat = now + progress_every_s
                progress(now - t0, last_line(out_path) or last_line(err_path))
            time.sleep(pause)
            pause = min(2 * pause, POLL_S)
    finally:
        leftovers = [p for p in seen.values() if p.is_running()]
        if proc.returncode is None and root is not None:  # timeout or interrupted: the guard too
            leftovers.insert(0, root)
        kill_tree(leftovers)
        _killpg(proc.pid)
        if proc.returncode is None:
            proc.wait()
    wall = time.perf_counter() - t0
    record = RunRecord(cmd, proc.returncode, wall, peak, tail_text(out_path), tail_text(err_path),
                       workdir, out_path, err_path)
    if timed_out:
        exc = SolverTimeoutError(f"solver exceeded its time limit of {timeout_s:g} s after "
                                 f"{wall:.1f} s and was killed with its process tree: {list(cmd)}",
                                 log_tail=record.log_tail())
        exc.workdir = str(workdir)  # attribute only: whether the folder is kept is the caller's choice
        raise exc
    return record


def _killpg(pgid: int) -> None:
    """Kill what is left in the child's own process group (daemons it forked and forgot)."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError, OSError):
        pass


def install_termination_handlers(signals: Sequence[int] = (signal.SIGTERM, signal.SIGHUP)) -> dict[int, Any]:
    """Make SIGTERM and SIGHUP interrupt the program as Ctrl-C (SIGINT) does: a
    ``KeyboardInterrupt`` in the main thread, so a running :func:`run_solver` kills its solver
    tree and the adapter removes (or keeps, see ``keep_failed``) its run folder before the
    program ends. A second such signal ends the program at once (the default action); the guard
    still takes the solvers with it.

    Call it once from the main thread (``signal.signal`` works only there), e.g. at the start of
    the command-line entry point. Returns the previous handlers by signal number.
    """
    previous: dict[int, Any] = {}

    def handler(signum: int, frame: Any) -> None:
        signal.signal(signum, signal.SIG_DFL)
        raise KeyboardInterrupt(f"terminated by {signal.Signals(signum).name}")

    for sig in signals:
        previous[int(sig)] = signal.signal(sig, handler)
    return previous


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


DIALECT_GROUP = "blackbox.dialects"


def known_dialects() -> dict[str, str]:
    """Name -> ``module:object`` of the built-in dialects and those of entry-point group
    ``blackbox.dialects`` (one :class:`solver_adapters.registry.Registry` for both)."""
    from solver_adapters.registry import DIALECTS
    return DIALECTS.targets()


def get_dialect(name: str, **options: Any) -> Dialect:
    """A dialect instance by name (built-in or entry point of group ``blackbox.dialects``) made
    with ``options``, which are checked against what the dialect accepts first.

    Raises the registry's errors (all :class:`~solver_adapters.protocol.RegistryError`, a
    ``ValueError``): an unknown name lists the known ones, an entry point that fails to import
    or clashes with a built-in is named, an unknown option is named with the accepted ones.
    """
    from solver_adapters.registry import DIALECTS
    return DIALECTS.create(name, **options)


# --------------------------------------------------------------------------------------------
# consent: an external command runs only when the user said so
# --------------------------------------------------------------------------------------------
TRUST_FLAG = "--trust-command"
"""The command-line flag that gives consent for one run (wired by the CLI)."""


def locate_program(program: str, env: dict[str, str] | None = None) -> Path | None:
    """The absolute path of the program a command line would execute, *as named*: a name
    without a slash is searched on ``PATH`` (of ``env`` when given), a path is taken relative to
    the current directory; symbolic links are kept (a virtual environment's ``bin/python`` is a
    link to the base interpreter but runs inside its environment only when started through the
    link). None when there is no such executable file."""
    if os.sep in program or (os.altsep and os.altsep in program):
        p = Path(program).expanduser()
        return Path(os.path.abspath(p)) if p.is_file() else None
    path = (env or os.environ).get("PATH", os.defpath)
    found = shutil.which(program, path=path)
    return Path(os.path.abspath(found)) if found else None


def resolve_program(program: str, env: dict[str, str] | None = None) -> Path | None:
    """:func:`locate_program` with every symbolic link resolved: the file that is executed in
    the end (what consent and the cache key name)."""
    found = locate_program(program, env)
    return found.resolve() if found is not None else None


PLACEHOLDERS = ("{deck}", "{deck_name}", "{workdir}")
"""What blackbox puts into a command line (:meth:`CommandAdapter._command_for`): an argument made
of these alone carries nothing the study chose."""

LAUNCHERS = re.compile(
    r"(python|pypy|perl|ruby|node|nodejs|deno|bun|php|lua|luajit|tclsh|wish|julia|octave|octave-cli|matlab|"
    r"rscript|r|java|scilab|sage|maxima|mono|dotnet|wine|osascript|pwsh|powershell|sh|bash|dash|zsh|ksh|mksh|"
    r"csh|tcsh|fish|busybox|env|xargs|nice|nohup|timeout|stdbuf|setsid|sudo|doas|su|awk|gawk|mawk|sed|make|"
    r"cmake|gdb)[0-9.]*(\.exe)?", re.IGNORECASE)
"""Programs that run whatever their arguments name (interpreters, shells, launchers): one of them
alone is never a trusted command, only a whole command line is."""


@dataclass(frozen=True)
class TrustedCommand:
    """One entry of ``trusted_commands``: ``program`` (absolute, symlink-free) and, for a whole
    command line, its ``arguments`` exactly as the study gives them (None: a program alone)."""

    program: Path
    arguments: tuple[str, ...] | None
    given: Any

    def allows(self, program: Path, arguments: Sequence[str]) -> bool:
        if program != self.program:
            return False
        if self.arguments is not None:
            return tuple(arguments) == self.arguments
        return not is_launcher(program) and only_placeholders(arguments)


def is_launcher(program: Path) -> bool:
    """Whether ``program`` (by its name) is an interpreter, shell or launcher (:data:`LAUNCHERS`)."""
    return LAUNCHERS.fullmatch(Path(program).name) is not None


def only_placeholders(arguments: Sequence[str]) -> bool:
    """Whether every argument is made of :data:`PLACEHOLDERS` alone (nothing the study chose)."""
    def empty(arg: str) -> str:
        for p in PLACEHOLDERS:
            arg = arg.replace(p, "")
        return arg
    return all(arg and not empty(arg) for arg in arguments)


def trusted_commands(config_dir: str | os.PathLike | None = None) -> list[TrustedCommand]:
    """The entries under ``trusted_commands`` in the user's ``config.toml``: a whole command line
    (a list: the program's absolute path, then the arguments as the study gives them) or a
    program alone (a string: trusted only with nothing but the deck as its arguments, and never
    an interpreter). ``ValueError`` for a malformed list."""
    cfg = read_config(config_dir)
    listed = cfg.get("trusted_commands", [])
    where = config_file(config_dir)
    shape = ("a list whose entries are whole command lines, e.g. [\"/opt/solver/bin/solve\", \"{deck}\"], "
             "or absolute paths of programs")
    if not isinstance(listed, list):
        raise ValueError(f"{where}: trusted_commands must be {shape}")
    out = []
    for entry in listed:
        words = [entry] if isinstance(entry, str) else entry
        if not (isinstance(words, list) and words and all(isinstance(w, str) for w in words)):
            raise ValueError(f"{where}: trusted_commands entry {entry!r} is not a command line; each entry is "
                             f"{shape}")
        p = Path(words[0]).expanduser()
        if not p.is_absolute():
            raise ValueError(f"{where}: trusted_commands entry {entry!r} does not start with an absolute path; "
                             f"write the full path of the program, e.g. "
                             f"{shutil.which(words[0]) or '/path/to/' + words[0]!r}")
        out.append(TrustedCommand(p.resolve(), None if isinstance(entry, str) else tuple(words[1:]), entry))
    return out


def _toml_list(words: Sequence[str]) -> str:
    return "[" + ", ".join(json.dumps(w) for w in words) + "]"


def check_command_consent(command: Sequence[str], *, trusted: bool,
                          config_dir: str | os.PathLike | None = None) -> Path | None:
    """Refuse to prepare a run of ``command`` the user has not agreed to.

    Passes when ``trusted`` (the CLI's ``--trust-command``: consent for this run) or when the
    user's own ``config.toml`` (``config_dir`` or :func:`~solver_adapters.userconfig.config_dir`;
    never a file of the study) lists the command under ``trusted_commands``
    (:func:`trusted_commands`): the whole command line -- the program, resolved to an absolute
    path (:func:`resolve_program`), and every argument exactly as given -- or the program alone
    when the arguments are nothing but the deck (:data:`PLACEHOLDERS`) and the program is no
    interpreter (:data:`LAUNCHERS`). Trusting ``python`` therefore trusts no script: a script
    is an argument, and the entry must name it. Returns the resolved program (None if it cannot
    be found and ``trusted``). Raises :class:`~solver_adapters.errors.ConsentError` saying how to
    give consent, and why an older entry naming a program alone no longer covers this command.
    """
    cmd = [str(c) for c in command]
    if not cmd:
        raise ValueError("command is empty")
    program = resolve_program(cmd[0])
    if trusted:
        return program
    where = config_file(config_dir)
    shown = " ".join(cmd)
    if program is None:
        raise ConsentError(f"the external command `{shown}` will not run: its program {cmd[0]!r} is "
                           f"not an executable file{'' if os.sep in cmd[0] else ' on PATH'}, so it "
                           f"cannot be checked against your trusted commands. Give its absolute "
                           f"path in the command, then consent as described when you run it again "
                           f"(or pass {TRUST_FLAG} to run it without the check).")
    entries = trusted_commands(config_dir)
    if any(e.allows(program, cmd[1:]) for e in entries):
        return program
    line = [str(program), *cmd[1:]]
    alone = [e for e in entries if e.program == program and e.arguments is None]
    why = ""
    if alone:
        why = (f"Your configuration lists the program {json.dumps(str(program))} alone, which trusts it only "
               + ("with nothing but the deck as its arguments; this command line gives it more. "
                  if not is_launcher(program) else
                  "-- never, for an interpreter, shell or launcher like this one: trusting it would trust "
                  "any script a study names for it. ")
               + "Consent names the whole command line now: replace that entry by the line below.\n")
    raise ConsentError(
        f"the external command `{shown}` will not run without your consent: it executes the "
        f"program {program} with the arguments {cmd[1:]} on this machine, and this command line "
        f"comes from the study (or its caller), not from you.\n" + why +
        f"If you trust this command line, either\n"
        f"  * pass {TRUST_FLAG} (consent for this run only), or\n"
        f"  * list the whole command line -- program and arguments, as the study gives them; a "
        f"program alone, such as an interpreter, is not enough -- in your own configuration file {where}"
        + (" (add it to the existing trusted_commands list):" if where.is_file() else ":") + "\n"
        f"        trusted_commands = [{_toml_list(line)}]")


# --------------------------------------------------------------------------------------------
# run folders
# --------------------------------------------------------------------------------------------
RUN_PREFIX = "blackbox-run-"
"""Name prefix of every run folder :class:`CommandAdapter` makes."""

RUN_MARKER = ".blackbox-run.json"
"""File in every run folder (and every temporary folder made by :func:`owned_tempdir`), written
at creation: JSON with ``blackbox_run``, the creating process (``pid``, ``pid_created``: its start
time as psutil reports it), the machine (``host``, ``boot_time``), ``created`` (epoch seconds)
and the ``command``. A folder is recognised as ours only with both the prefix and a valid marker."""

STALE_RUN_S = 24 * 3600.0
"""Age after which a run folder with a marker that does not name this machine (an older
blackbox's, or one made on another machine sharing the folder) counts as left by a killed run
once its pid is not running. A marker naming this machine needs no age: its process is either
running (same pid, same start time) or gone."""

_CLEANED_ROOTS: set[tuple[str, str]] = set()
_CLEAN_LOCK = threading.Lock()


def _marker_for(command: Sequence[str]) -> dict[str, Any]:
    me = psutil.Process()
    return {"blackbox_run": 1, "pid": me.pid, "pid_created": me.create_time(), "host": socket.gethostname(),
            "boot_time": psutil.boot_time(), "created": time.time(), "command": [str(c) for c in command]}


def make_owned_dir(prefix: str, root: str | os.PathLike | None = None, command: Sequence[str] = ()) -> Path:
    """A fresh folder ``<root>/<prefix>XXXX`` (root: the system temporary folder by default)
    holding its :data:`RUN_MARKER`, so that the next run can tell it was ours and whether its
    process is gone (:func:`clean_stale_run_dirs`)."""
    if root is not None:
        Path(root).mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix=prefix, dir=root))
    (folder / RUN_MARKER).write_text(json.dumps(_marker_for(command)))
    return folder


def make_run_dir(root: str | os.PathLike | None, name: str, command: Sequence[str] = ()) -> Path:
    """A fresh run folder ``<root>/blackbox-run-<name>-XXXX`` (root: the system temporary
    folder by default) with its :data:`RUN_MARKER`."""
    safe = "".join(c if c.isascii() and (c.isalnum() or c in "-_.") else "_" for c in name) or "run"
    return make_owned_dir(f"{RUN_PREFIX}{safe}-", root, command)


def _run_dir_age(folder: Path, now: float, max_age_s: float = STALE_RUN_S) -> float | None:
    """Whether ``folder`` is one of ours whose process is gone: its age in seconds when it may be
    removed, None otherwise (not ours, not this user's, a symbolic link, its process still
    running, or a marker of another machine younger than ``max_age_s``)."""
    try:
        st = os.lstat(folder)
        if not stat.S_ISDIR(st.st_mode) or (hasattr(os, "getuid") and st.st_uid != os.getuid()):
            return None
        mst = os.lstat(folder / RUN_MARKER)
        if not stat.S_ISREG(mst.st_mode) or mst.st_size > 1 << 20:
            return None
        marker = json.loads((folder / RUN_MARKER).read_text())
        if not (isinstance(marker, dict) and marker.get("blackbox_run") == 1):
            return None
        created = float(marker["created"])
        pid, pid_created = int(marker["pid"]), float(marker["pid_created"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    here = marker.get("host") == socket.gethostname()
    try:
        rebooted = here and abs(float(marker["boot_time"]) - psutil.boot_time()) > 1.0
    except (KeyError, TypeError, ValueError):
        here, rebooted = False, False
    if rebooted:
        return max(now - created, 0.0)    # every process of an earlier boot is gone
    try:
        if abs(psutil.Process(pid).create_time() - pid_created) < 1.0:
            return None  # the process that made it is still running
    except psutil.Error:
        pass
    if not here and now - created <= max_age_s:
        return None      # cannot be sure the pid was this machine's: wait for max_age_s
    return max(now - created, 0.0)


def clean_stale_run_dirs(root: str | os.PathLike | None = None, *, max_age_s: float = STALE_RUN_S,
                         now: float | None = None, prefix: str = RUN_PREFIX) -> list[Path]:
    """Remove our folders named ``<prefix>*`` under ``root`` (default: the system temporary
    folder) whose process has ended, i.e. left behind by a killed run; return them.

    Only folders that hold a valid :data:`RUN_MARKER` and belong to this user are considered; a
    folder of a run still in progress (its pid running with the recorded start time) is never
    touched. ``max_age_s`` applies to markers that do not name this machine (:data:`STALE_RUN_S`).
    """
    folder = Path(root) if root is not None else Path(tempfile.gettempdir())
    now = time.time() if now is None else now
    removed = []
    try:
        candidates = [p for p in folder.iterdir() if p.name.startswith(prefix)]
    except OSError:
        return removed
    for p in sorted(candidates):
        if _run_dir_age(p, now, max_age_s) is not None:
            shutil.rmtree(p, ignore_errors=True)
            if not p.exists():
                removed.append(p)
    return removed


def _clean_stale_once(root: Path | None, prefix: str = RUN_PREFIX) -> list[Path]:
    """:func:`clean_stale_run_dirs` the first time a folder root is used in this process (per
    prefix), reported as a warning when it removed anything."""
    key = str(Path(root).resolve() if root is not None else Path(tempfile.gettempdir()).resolve())
    with _CLEAN_LOCK:
        if (key, prefix) in _CLEANED_ROOTS:
            return []
        _CLEANED_ROOTS.add((key, prefix))
    removed = clean_stale_run_dirs(root, prefix=prefix)
    if removed:
        warnings.warn(f"removed {len(removed)} stale blackbox folder(s) left by killed runs in {key}: "
                      f"{', '.join(p.name for p in removed[:5])}{' ...' if len(removed) > 5 else ''}",
                      RuntimeWarning, stacklevel=3)
    return removed


@contextlib.contextmanager
def owned_tempdir(prefix: str, root: str | os.PathLike | None = None) -> Iterator[Path]:
    """A temporary folder ``<prefix>XXXX`` with a :data:`RUN_MARKER`, removed at the end (a
    context manager). Folders of the same prefix left by killed processes are removed first
    (:func:`clean_stale_run_dirs`, once per process and root)."""
    _clean_stale_once(Path(root) if root is not None else None, prefix)
    folder = make_owned_dir(prefix, root)
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# --------------------------------------------------------------------------------------------
# the solver's identity (part of the cache key)
# --------------------------------------------------------------------------------------------
_DIGESTS: dict[tuple, str] = {}
_DIGEST_LOCK = threading.Lock()


def file_sha256(path: Path) -> str:
    """sha256 of a file's bytes, remembered per (path, inode, size, mtime) for this process."""
    st = os.stat(path)
    key = (str(path), st.st_ino, st.st_size, st.st_mtime_ns)
    with _DIGEST_LOCK:
        hit = _DIGESTS.get(key)
    if hit is None:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        hit = h.hexdigest()
        with _DIGEST_LOCK:
            _DIGESTS[key] = hit
    return hit


def program_files(command: Sequence[str]) -> list[Path]:
    """The files a command line executes or reads as code: its program (resolved on PATH) and
    every other argument that names an existing file (an interpreter's script), placeholders
    excepted. Absolute, symlink-free, in order, without repeats."""
    out: list[Path] = []
    cmd = [str(c) for c in command]
    first = resolve_program(cmd[0]) if cmd else None
    if first is not None:
        out.append(first)
    for arg in cmd[1:]:
        if "{" in arg or not arg or arg.startswith("-"):
            continue
        p = Path(arg).expanduser()
        try:
            if p.is_file():
                p = p.resolve()
                if p not in out:
                    out.append(p)
        except OSError:
            continue
    return out


# --------------------------------------------------------------------------------------------
# the adapter
# --------------------------------------------------------------------------------------------
def _add_line(exc: BaseException, line: str) -> None:
    """Append ``line`` to an exception's message unless it is there already."""
    msg = str(exc.args[0]) if exc.args else str(exc)
    if line not in msg:
        exc.args = (f"{msg}\n{line}", *exc.args[1:])


def _note_workdir(exc: SolverError, workdir: Path) -> None:
    """Name the kept run directory in the error (message and ``workdir`` attribute)."""
    exc.workdir = str(workdir)
    _add_line(exc, f"run directory kept for inspection: {workdir}")


def _note_removed(exc: SolverError, record: RunRecord | None) -> None:
    """The run directory is about to be deleted: keep its log tail in the error if the error has
    none yet, and say that the folder is gone and how to keep it."""
    exc.workdir = None
    if record is not None and isinstance(exc, SolverRunError) and not exc.log_tail:
        exc.log_tail = record.log_tail()
        if exc.log_tail:
            _add_line(exc, f"--- solver log tail ---\n{exc.log_tail}")
    _add_line(exc, "(run directory removed; keep_failed=True keeps failed runs for inspection)")


def _deck_bytes(deck: Path) -> dict[str, bytes]:
    """The deck and the files it INCLUDEs, ``{absolute path: bytes}`` (a chunk's travel kit)."""
    from solver_adapters.cache import deck_files

    return {str(p): p.read_bytes() for p in deck_files(deck) if p.is_file()}


def _on_dask_worker() -> bool:
    """Whether this code runs in a task on a Dask worker."""
    dist = sys.modules.get("distributed")
    if dist is None:
        return False
    try:
        dist.get_worker()
    except (ValueError, AttributeError):
        return False
    return True


def _run_chunk(args) -> tuple[np.ndarray, SolverStats]:
    """One column block of :meth:`CommandAdapter.solve` run by a copy of the adapter (on a
    worker, or in this process): its values and the copy's stats. When the deck files are not
    where the client had them, with the same bytes (no shared file system), they are written
    into a temporary folder with the same layout and the copy runs from there."""
    adapter, files, loads, report = args
    own = copy.copy(adapter)
    own.stats, own._lock, own.executor = SolverStats(), threading.Lock(), None
    same = all(Path(p).is_file() and Path(p).read_bytes() == data for p, data in files.items())
    if same:
        return own._run(loads, report), own.stats
    base = Path(os.path.commonpath([str(Path(p).parent) for p in files]))
    with tempfile.TemporaryDirectory(prefix="blackbox-deck-") as tmp:
        for p, data in files.items():
            target = Path(tmp) / Path(p).relative_to(base)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        moved = Path(tmp) / Path(own.deck_path).relative_to(base)
        own.deck_path = moved
        own._base = BaseDeck(moved, own._base.model)
        return own._run(loads, report), own.stats


UNMODELLED = ("error", "pass")
"""What a :class:`CommandAdapter` does with a card the reader does not model: ``"error"`` (the
reader's own message, the default) or ``"pass"`` (kept apart and handed to the solver by a
dialect that can, re-written field by field; ``blackbox`` builds external adapters this way)."""


class CommandAdapter:
    """:class:`SolverAdapter` for any external code: a command line plus a :class:`Dialect`.

    ``command`` is a list of arguments in which ``{deck}`` is replaced by the absolute path of the
    run deck, ``{deck_name}`` by its file name and ``{workdir}`` by the run directory (the command
    runs with the run directory as its working directory); without a ``{deck...}`` placeholder
    the deck path is appended. ``command=None`` takes the dialect's default.

    Each ``solve`` is one run (several only when the batch exceeds the dialect's
    ``max_cases_per_run``) in a fresh run folder ``blackbox-run-<name>-*`` under ``workdir_root``
    (default: the system temporary folder; :func:`make_run_dir`), deleted on success. A failed
    run's folder is deleted too, after its log tail went into the error, unless ``keep_failed``
    (then its path is in the error). Run folders that a killed process left behind (its marker
    says which process made it; that process is gone) are removed, with a warning, the first
    time a root is used (:func:`clean_stale_run_dirs`).

    Consent: the command runs only when ``trusted`` (the CLI's ``--trust-command``) or its
    program is listed in the user's own ``config.toml`` (:func:`check_command_consent`, checked
    here, before anything runs: :class:`~solver_adapters.errors.ConsentError` otherwise). The
    dialect's own default command (``command=None`` or equal to it) is installed code and needs
    no consent.

    ``unmodelled`` (:data:`UNMODELLED`): ``"pass"`` reads the deck keeping the cards the reader
    does not model (shells, solids) for a dialect that hands them to its solver
    (``carries_unmodelled``, the nastran dialect); the default ``"error"`` is the reader's verdict.

    ``progress``: an optional ``progress(elapsed_s, last_line)`` callback called about every
    ``progress_every_s`` seconds while the solver runs (:func:`run_solver`); an attribute, so a
    caller can set it after construction.

    ``processes``: how many solver processes one large batch may run side by side on this
    machine when no executor is set (:meth:`local_processes`; default: one per physical core, at
    most :data:`MAX_LOCAL_PROCESSES`); 1 keeps every batch in one process at a time.
    """

    def __init__(self, deck_path: str | os.PathLike, command: Sequence[str] | None = None,
                 dialect: str | Dialect = "nastran", timeout_s: float = 600.0, keep_failed: bool = False,
                 workdir_root: str | os.PathLike | None = None, name: str = "command",
                 springs: Sequence[ScalarSpring] = (), *, trusted: bool = False,
                 progress: ProgressCallback | None = None, progress_every_s: float = HEARTBEAT_S,
                 unmodelled: str = "error", processes: int | None = None):
        if processes is not None and int(processes) < 1:
            raise ValueError(f"processes must be >= 1, got {processes!r}")
        self.processes = None if processes is None else int(processes)
        if unmodelled not in UNMODELLED:
            raise ValueError(f"unmodelled must be one of {UNMODELLED}, got {unmodelled!r}")
        self.unmodelled = unmodelled
        self.deck_path = Path(deck_path).resolve()
        self.dialect = get_dialect(dialect) if isinstance(dialect, str) else dialect
        default = self.dialect.command(self.deck_path)
        if command is None:
            command = default
            if command is None:
                raise ValueError(f"dialect {self.dialect.name!r} has no default command: give one, "
                                 f"e.g. ['my-solver', '{{deck}}']")
        self.command = [str(c) for c in command]
        if not self.command:
            raise ValueError("command is empty")
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
        if not progress_every_s > 0:
            raise ValueError(f"progress_every_s must be > 0, got {progress_every_s!r}")
        own_default = default is not None and self.command == [str(c) for c in default]
        program = check_command_consent(self.command, trusted=bool(trusted) or own_default)
        # the program runs as named (a venv's python stays in its venv), by its absolute path so
        # that the run folder as working directory or another PATH cannot change what runs
        located = locate_program(self.command[0]) if program is not None else None
        self._argv0 = (self.command[0], str(located) if located is not None else self.command[0])
        self.timeout_s = float(timeout_s)
        self.keep_failed = bool(keep_failed)
        self.workdir_root = Path(workdir_root) if workdir_root is not None else None
        self.name = name
        self.progress = progress
        self.progress_every_s = float(progress_every_s)
        self._solver_identity: dict[str, Any] | None = None
        _clean_stale_once(self.workdir_root)
        self.stats = SolverStats()
        self._lock = threading.Lock()
        self._base = BaseDeck(self.deck_path, self._read_model(self.deck_path))
        check = getattr(self.dialect, "check_model", None)
        if callable(check):   # a card the code cannot express is refused before anything runs
            check(self._base.model)
        grids = self._base.model.grids
        self._xyz = {int(g): tuple(float(v) for v in grids[g].xyz) for g in sorted(grids)}
        self._dofs = tuple((g, c) for g in self._xyz for c in range(1, 7))
        self._dofset = frozenset(self._dofs)
        self.springs = self._checked_springs(springs)

    def _read_model(self, path: Path) -> Any:
        """The parsed model of the deck (``bdf.read_deck``). With ``unmodelled="pass"`` the cards
        the reader does not model (shells, solids) are kept apart for a dialect that hands them
        to its solver (``carries_unmodelled``, the NASTRAN dialect); a dialect that writes its
        decks from the model alone (FRAMESOLVE) cannot, and such a deck is the reader's error."""
        from solver_adapters.bdf import read_deck, unsupported_error  # the reader is only needed here
        model = read_deck(path, unmodelled="keep" if self.unmodelled == "pass" else "error")
        if model.unmodelled and not getattr(self.dialect, "carries_unmodelled", False):
            raise unsupported_error([(n, k, src) for n, (k, src) in model.unmodelled_counts().items()],
                                    external_hint=False,
                                    lead=f"the {self.dialect.name!r} dialect writes its decks from the "
                                         f"modelled cards alone and cannot hand these to its solver; ")
        runs = getattr(self.dialect, "runs_cards", None)
        if runs is not None:
            cannot = [(n, k, src) for n, (k, src) in model.unmodelled_counts().items() if n not in runs]
            if cannot:
                raise unsupported_error(cannot, external_hint=False, keeping=True,
                                        lead=f"the {self.name or self.dialect.name} adapter cannot run "
                                             f"these cards (its solver does not read them; "
                                             f"refused before it runs): ")
        return model

    # ---- protocol ------------------------------------------------------------------------
    def dofs(self) -> tuple[DofLabel, ...]:
        return self._dofs

    def grid_xyz(self) -> dict[int, tuple[float, float, float]]:
        return dict(self._xyz)

    def identity(self) -> dict[str, Any]:
        """What identifies the solver program (part of the cache key, computed once): the sha256
        of every file the command executes (:func:`program_files`: the program, an interpreter's
        script) and the solver's version when the adapter (``version``) or the dialect
        (``solver_version(command)``) can tell."""
        if self._solver_identity is None:
            files = program_files(self.command)
            ident: dict[str, Any] = {"programs": [{"name": f.name, "sha256": file_sha256(f)} for f in files]}
            version = getattr(self, "version", None)
            ask = getattr(self.dialect, "solver_version", None)
            if version is None and callable(ask):
                version = ask(self.command)
            if version is not None:
                ident["version"] = str(version)
            self._solver_identity = ident
        return self._solver_identity

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
        executor = self.executor
        side_by_side = executor is not None and loads.n_cases > 1
        if side_by_side:      # one run per worker (or per ``chunks``), each a separate solver process
            n = int(self.chunks or getattr(executor, "workers", 1))
            if not self.chunks:             # by default no chunk below MIN_CASES_PER_CHUNK cases
                n = min(n, loads.n_cases // MIN_CASES_PER_CHUNK)
            chunk = min(chunk, -(-loads.n_cases // max(1, n)))
            side_by_side = chunk < loads.n_cases
        local = 1 if executor is not None else self.local_processes(loads.n_cases)
        if local > 1:
            chunk = min(chunk, -(-loads.n_cases // local))
        ranges = [range(j, min(j + chunk, loads.n_cases)) for j in range(0, loads.n_cases, chunk)]
        if local > 1 and len(ranges) > 1:
            # each chunk a solver process of its own, started from a thread that waits for it
            with ThreadPoolExecutor(min(local, len(ranges)), thread_name_prefix=f"{self.name}-run") as pool:
                blocks = list(pool.map(lambda r: self._run(loads.select(r), report), ranges))
        elif not side_by_side:
            blocks = [self._run(loads.select(r), report) for r in ranges]
        else:
            files = _deck_bytes(self.deck_path)
            outs = executor.map(_run_chunk, [(self, files, loads.select(r), report) for r in ranges])
            blocks = []
            for values, stats in outs:          # the copies' runs counted here, in order
                self._merge_stats(stats)
                blocks.append(values)
        return Displacements(report, np.hstack(blocks), loads.cases)

    def local_processes(self, n_cases: int) -> int:
        """How many solver processes a batch of ``n_cases`` runs side by side here (module
        constants): ``processes`` (default one per physical core, at most
        :data:`MAX_LOCAL_PROCESSES`), none with fewer than :data:`MIN_CASES_PER_CHUNK` cases,
        and no more than 70 % of the free memory holds at the largest run's peak so far. On a
        Dask worker (a study of a batch) one: the cluster already shares the cores out."""
        if _on_dask_worker():
            return 1
        n = self.processes if self.processes is not None else \
            min(MAX_LOCAL_PROCESSES, psutil.cpu_count(logical=False) or os.cpu_count() or 1)
        n = min(n, n_cases // MIN_CASES_PER_CHUNK)
        peak = self.stats.peak_rss_bytes
        if n > 1 and peak > 0:
            n = min(n, int(0.7 * psutil.virtual_memory().available // peak))
        return max(1, n)

    # ---- runs side by side (``executor``) ---------------------------------------------------
    executor: Any = None
    """An object with ``map(fn, items) -> list`` (:mod:`blackbox.parallel`): when set, a ``solve``
    with several cases is cut into ``chunks`` contiguous column blocks (default: ``executor.workers``,
    but none of fewer than :data:`MIN_CASES_PER_CHUNK` cases), each run as a separate solver
    process through ``executor.map``; the blocks are put back in order. Each column is solved on
    its own by the solver either way, so the result is the serial one (for a solver whose answer
    for one load case does not depend on the others in its run)."""
    chunks: int | None = None

    def __getstate__(self) -> dict:
        # sent to a worker: no lock, no executor (a cluster client), no terminal callback
        state = self.__dict__.copy()
        state.pop("_lock", None)
        state["executor"] = None
        state["progress"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def _merge_stats(self, other: SolverStats) -> None:
        with self._lock:
            s = self.stats
            s.runs += other.runs
            s.factorizations += other.factorizations
            s.right_hand_sides += other.right_hand_sides
            s.wall_s += other.wall_s
            s.peak_rss_bytes = max(s.peak_rss_bytes, other.peak_rss_bytes)
            s.history.extend(other.history)

    # ---- one run -------------------------------------------------------------------------
    def _checked_springs(self, springs: Sequence[ScalarSpring]) -> tuple[ScalarSpring, ...]:
        springs = tuple(springs)
        self._check_known([s.a for s in springs] + [s.b for s in springs if s.b is not None],
                          "spring DOF")
        bad = [s for s in springs if not np.isfinite(s.k)]
        if bad:
            raise ValueError(f"spring stiffness must be finite, got {bad[:3]}")
        check = getattr(self.dialect, "check_springs", None)
        if springs and callable(check):
            check(self._base.model, springs)
        return springs

    def _check_known(self, labels: Sequence[DofLabel], what: str) -> None:
        unknown = [tuple(d) for d in labels if tuple(d) not in self._dofset]
        if unknown:
            raise UnknownDofError(unknown, what)

    def _command_for(self, deck: Path) -> list[str]:
        subs = {"{deck}": str(deck), "{deck_name}": deck.name, "{workdir}": str(deck.parent)}
        if not any(k in arg for arg in self.command for k in ("{deck}", "{deck_name}")):
            out = [*self.command, str(deck)]
        else:
            out = []
            for arg in self.command:
                for k, v in subs.items():
                    arg = arg.replace(k, v)
                out.append(arg)
        if out and out[0] == self._argv0[0]:  # run the very program consent was given for
            out[0] = self._argv0[1]
        return out

    def _run(self, loads: LoadMatrix, report: tuple[DofLabel, ...]) -> np.ndarray:
        workdir = make_run_dir(self.workdir_root, self.name, self.command)
        record = None
        times = {}
        try:
            t0 = time.perf_counter()
            deck = self.dialect.write_deck(workdir, self._base, loads, report, self.springs)
            times["write_s"] = time.perf_counter() - t0
            record = run_solver(self._command_for(Path(deck)), workdir, self.timeout_s,
                                log_name=self.name, progress=self.progress,
                                progress_every_s=self.progress_every_s)
            t0 = time.perf_counter()
            try:
                values = np.asarray(self.dialect.read_results(workdir, Path(deck), loads, report, record),
                                    dtype=float)
            except SolverError:
                raise
            except Exception as exc:  # garbage output is a solver failure, whatever the dialect raised
                raise SolverRunError(f"dialect {self.dialect.name!r} could not read the solver's output: "
                                     f"{type(exc).__name__}: {exc}", returncode=record.returncode,
                                     log_tail=record.log_tail()) from exc
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
            keep = self.keep_failed and isinstance(exc, SolverError)
            self._account(loads, record, workdir if keep else None, ok=False, error=type(exc).__name__)
            if keep:
                _note_workdir(exc, workdir)
            else:  # an interrupt, or not asked to keep: the error already holds the log tail
                if isinstance(exc, SolverError):
                    _note_removed(exc, record)
                shutil.rmtree(workdir, ignore_errors=True)
            raise
        self._account(loads, record, workdir, ok=True, times=times)
        shutil.rmtree(workdir, ignore_errors=True)
        return values

    def _account(self, loads: LoadMatrix, record: RunRecord | None, workdir: Path | None, ok: bool,
                 error: str | None = None, times: dict | None = None) -> None:
        with self._lock:
            s = self.stats
            entry = {"ok": ok, "cases": loads.n_cases, "workdir": None if ok or workdir is None else str(workdir),
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
