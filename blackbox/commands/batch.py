"""``blackbox batch STUDY...``: one command (identify or diagnose) on many studies, side by side.

Every study is one task of an :class:`~blackbox.parallel.Executor` (serial, or a Dask cluster
with ``--workers N`` / ``--scheduler ADDRESS``). No shared file system is assumed: the client
reads each study folder into memory (:func:`blackbox.parallel.pack_study`), the task rebuilds it
in a worker-local temporary folder, runs the command there with the worker's own solver, writes
the command's usual outputs into another temporary folder and sends them back as bytes; the
client writes them (:meth:`BatchResult.write`): one sub-folder per study, named after the study
folder, plus ``summary.csv``, ``summary.md`` and ``summary.png`` across the studies.

A study that fails (bad input, a solver failure, a worker lost more often than the scheduler
allows) is a row with its status and error; the other studies' work is kept. The solver-run
cache is the one the command would use without ``batch`` (``STUDY/.blackbox_cache/`` or
``--cache-dir``), shared by the workers of one machine (its entries are written atomically); a
worker on a machine that does not see that folder runs without the cache.
"""

from __future__ import annotations

import json
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from blackbox.errors import BlackboxError
from blackbox.parallel import (Executor, SerialExecutor, StudyPackage, TaskFailure, pack_study, read_tree,
                               scratch, unpack_study, write_tree)

__all__ = ["COMMANDS", "StudyTask", "StudyOutcome", "BatchResult", "run", "run_task", "STATUSES"]

COMMANDS = ("identify", "diagnose")
STATUSES = ("ok", "unusable", "bad_input", "solver_failure", "error", "lost")
"""A study's status: ``ok`` (the command's exit 0), ``unusable`` (finished, but not converged /
not identifiable / unexplained: the command's exit 4), ``bad_input`` (exit 2), ``solver_failure``
(exit 3), ``error`` (an unexpected exception: a bug), ``lost`` (its worker died more often than
the scheduler allows)."""


@dataclass(frozen=True)
class StudyTask:
    """What travels to a worker for one study."""
    name: str                       # the study's sub-folder in --out
    package: StudyPackage
    command: str = "identify"
    adapter: str | None = None
    cache: str | None = None        # cache folder on the client's machine; None: no cache
    trust_command: bool = False
    options: dict = field(default_factory=dict)


@dataclass(frozen=True)
class StudyOutcome:
    """What comes back: status, the summary numbers, the command's output files as bytes."""
    name: str
    origin: str
    status: str
    message: str = ""
    reduced_chi2: float | None = None
    parameters: tuple[dict, ...] = ()       # {"joint", "name", "value", "ci_low", "ci_high", "std"}
    files: dict = field(default_factory=dict, repr=False)
    wall_s: float = 0.0
    worker: str = ""
    solver: dict = field(default_factory=dict)
    cache: str = ""
    cpu_s: float = 0.0                      # CPU time of the task (its process and solver runs)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (an external solver's runs)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _status_of(exc: BaseException) -> str:
    """The status of an exception that ended a study (the CLI's exit-code rules)."""
    from blackbox.errors import BlackboxError
    from solver_adapters.errors import ConsentError
    from solver_adapters.protocol import DeckFormatError, ModelError, SolverError, UnknownDofError

    if isinstance(exc, SolverError) and not isinstance(exc, (DeckFormatError, ModelError, UnknownDofError,
                                                             ValueError)):
        return "solver_failure"
    if isinstance(exc, (BlackboxError, SolverError, ConsentError, ValueError, OSError)):
        return "bad_input"
    return "error"


def _cache_for_worker(cache: str | None) -> tuple[bool | Path, str]:
    """The cache folder a worker uses: the client's, when this machine sees the folder it lives
    in (the same machine, or a shared file system); else none."""
    if cache is None:
        return False, "off"
    p = Path(cache)
    if p.is_dir() or p.parent.is_dir():
        return p, str(p)
    return False, f"off (folder {p.parent} not visible on {socket.gethostname()})"


def _identify(study, task: StudyTask, out: Path) -> tuple[str, str, float | None, list[dict], dict]:
    from blackbox.commands import identify

    opts = dict(task.options)
    model = opts.pop("model", None)
    res = identify.run(study, adapter=task.adapter, model=model, **opts)
    res.write(out)
    r = res.result
    params = [{"joint": j, "name": n, "value": float(v), "std": float(s), "ci_low": float(lo),
               "ci_high": float(hi)}
              for j, n, v, s, lo, hi in zip(r.param_joint, r.param_names, r.k, r.std, r.ci_low, r.ci_high)]
    why = []
    if not r.converged:
        why.append(f"not converged ({r.message})")
    bad = [f"{j}.{n}" for j, n, ok in zip(r.param_joint, r.param_names, r.identifiable) if not ok]
    if bad:
        why.append(f"not identifiable: {', '.join(bad)}")
    status = "ok" if res.ok else "unusable"
    msg = "; ".join(why) if why else f"converged in {r.iterations} iterations"
    return status, msg, float(r.reduced_chi2), params, res.solver.to_json()


def _diagnose(study, task: StudyTask, out: Path) -> tuple[str, str, float | None, list[dict], dict]:
    from blackbox.commands import diagnose

    res = diagnose.run(study, adapter=task.adapter, **task.options)
    res.write(out)
    d = json.loads((out / "diagnosis.json").read_text())
    params = []
    final = d.get("joint_parameters", {}).get("final", {})
    for joint, rec in final.items():
        for name, p in rec.get("parameters", {}).items():
            params.append({"joint": joint, "name": name, "value": p.get("value"), "std": p.get("std"),
                           "ci_low": None, "ci_high": None})
    verdict = d.get("verdict", "")
    added = ", ".join(f"{e['effect']} @ {', '.join(map(str, e['where']))[:40]}" for e in d.get("added", []))
    status = "unusable" if verdict == "unexplained" else "ok"
    msg = f"{verdict}" + (f"; added {added}" if added else "")
    return status, msg, d.get("after", {}).get("reduced_chi2"), params, d.get("solver", {})


def run_task(task: StudyTask) -> StudyOutcome:
    """One study, where the task runs (a worker): rebuild the folder, run the command, send the
    outputs back. Never raises for the study's own failures: they are its status."""
    from blackbox.adapters import ADAPTER_CACHE, TRUST_COMMAND
    from blackbox.study import load_study

    t0, cpu0 = time.perf_counter(), _cpu()
    where = f"{socket.gethostname()}:{os.getpid()}"
    cache, cache_note = _cache_for_worker(task.cache)
    tokens = (ADAPTER_CACHE.set(cache), TRUST_COMMAND.set(bool(task.trust_command)))
    try:
        with scratch() as tmp:
            root = unpack_study(task.package, tmp / "study")
            out = tmp / "out"
            out.mkdir()
            try:
                study = load_study(root, need_measurements=True)
                fn = {"identify": _identify, "diagnose": _diagnose}[task.command]
                status, msg, red, params, solver = fn(study, task, out)
            except Exception as exc:
                status = _status_of(exc)
                msg = f"{type(exc).__name__}: {exc}"
                if status == "error":
                    msg += "\n" + traceback.format_exc(limit=8)
                return StudyOutcome(task.name, task.package.origin, status, msg,
                                    wall_s=time.perf_counter() - t0, worker=where, cache=cache_note,
                                    cpu_s=_cpu() - cpu0)
            files = read_tree(out)
    finally:
        ADAPTER_CACHE.reset(tokens[0])
        TRUST_COMMAND.reset(tokens[1])
    return StudyOutcome(task.name, task.package.origin, status, msg, red, tuple(params), files,
                        time.perf_counter() - t0, where, solver, cache_note, _cpu() - cpu0)


# --------------------------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BatchResult:
    """Every study's outcome, in the order given, and how the batch ran."""
    outcomes: tuple[StudyOutcome, ...]
    sub_command: str
    executor: str
    wall_s: float
    command: str = "batch"

    @property
    def ok(self) -> bool:
        return all(o.ok for o in self.outcomes)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for o in self.outcomes:
            out[o.status] = out.get(o.status, 0) + 1
        return out

    def write(self, out: Path) -> list[str]:
        from blackbox.reports.batch import summary_csv, summary_markdown, summary_plot

        out = Path(out)
        files = []
        for o in self.outcomes:
            sub = out / o.name
            sub.mkdir()
            write_tree(o.files, sub)
            if not o.ok:
                (sub / "error.txt").write_text(f"status: {o.status}\n{o.message}\n")
            files.append(f"{o.name}/")
        (out / "summary.csv").write_text(summary_csv(self.outcomes))
        plot = summary_plot(self.outcomes, out / "summary.png")
        (out / "summary.md").write_text(summary_markdown(self, ["summary.png"] if plot else []))
        files += ["summary.csv", "summary.md"] + (["summary.png"] if plot else [])
        return files


def _names(folders: Sequence[Path]) -> list[str]:
    """Sub-folder names: the study folder's name, ``-2``, ``-3``... for repeats."""
    seen: dict[str, int] = {}
    out = []
    for f in folders:
        base = Path(f).resolve().name or "study"
        n = seen.get(base, 0) + 1
        seen[base] = n
        out.append(base if n == 1 else f"{base}-{n}")
    return out


def run(studies: Sequence[str | Path], *, command: str = "identify", executor: Executor | None = None,
        adapter: str | None = None, cache: bool | str | Path | None = None, trust_command: bool | None = None,
        options: dict | None = None, say: Callable[[str], None] | None = None) -> BatchResult:
    """Run ``command`` on every study folder through ``executor`` (default serial).

    ``cache``: as ``make_adapter_for`` takes it (True: each study's own ``.blackbox_cache/``; a
    folder; False: none); None takes what the CLI set (:data:`blackbox.adapters.ADAPTER_CACHE`).
    ``trust_command``: consent for a study's external command (default: the CLI's
    ``--trust-command``). ``options``: keyword arguments of the command's ``run`` (identify:
    ``model`` and the ``[identification]`` overrides; diagnose: ``alpha``, ``max_steps``...)."""
    from blackbox.adapters import ADAPTER_CACHE, TRUST_COMMAND

    if command not in COMMANDS:
        raise ValueError(f"batch --command must be one of {', '.join(COMMANDS)}, got {command!r}")
    if not studies:
        raise ValueError("batch needs at least one study folder")
    say = say or (lambda msg: None)
    executor = executor or SerialExecutor()
    cache = ADAPTER_CACHE.get() if cache is None else cache
    trust = TRUST_COMMAND.get() if trust_command is None else bool(trust_command)
    folders = [Path(s) for s in studies]
    names = _names(folders)
    outcomes: list[StudyOutcome | None] = [None] * len(folders)
    tasks, where = [], []
    for i, (folder, name) in enumerate(zip(folders, names)):
        try:
            pkg = pack_study(folder)
        except (OSError, ValueError, KeyError, BlackboxError) as exc:
            outcomes[i] = StudyOutcome(name, str(folder), "bad_input", f"{type(exc).__name__}: {exc}")
            continue
        if cache is True:
            c = str(Path(pkg.origin) / ".blackbox_cache")
        elif cache:
            c = str(Path(cache).absolute())
        else:
            c = None
        tasks.append(StudyTask(name, pkg, command, adapter, c, trust, dict(options or {})))
        where.append(i)
    say(f"batch {command}: {len(folders)} stud{'y' if len(folders) == 1 else 'ies'} "
        f"({len(folders) - len(tasks)} unreadable) on {executor.description}")
    t0 = time.perf_counter()
    results = executor.map(run_task, tasks, errors="return")
    for i, task, res in zip(where, tasks, results):
        if isinstance(res, TaskFailure):
            status = "lost" if res.lost else "error"
            outcomes[i] = StudyOutcome(task.name, task.package.origin, status, str(res))
        else:
            outcomes[i] = res
    return BatchResult(tuple(outcomes), command, executor.description, time.perf_counter() - t0)
