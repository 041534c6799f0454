"""Independent work of a command run side by side: serially here, or on a Dask cluster.

One small interface, :class:`Executor`: ``map(fn, items)`` returns ``[fn(x) for x in items]`` in
the order of ``items`` and reports ``progress(done, total, failed)`` as tasks finish. A large value
that every task of a map needs travels once: ``with executor.share(value) as h:
executor.map_shared(fn, h, items)`` returns ``[fn(x, value) for x in items]``, the value sent to
each worker once (Dask: scattered with ``broadcast=True``) and not with every task.

* :class:`SerialExecutor` runs the tasks one after the other in this process (the default, and
  what every command does without dask installed);
* :class:`DaskExecutor` runs them on a ``distributed`` cluster: ``workers=N`` starts a
  ``LocalCluster`` of N single-threaded worker processes on this machine (loopback TCP only),
  ``scheduler=ADDRESS`` connects to an existing scheduler. A worker that dies mid-task (killed,
  out of memory) makes the scheduler run the task again on another worker, up to
  ``allowed_failures`` times; a task whose function raises is not retried (the work is
  deterministic, a second attempt would fail the same way).

No shared file system is assumed between the client and the workers: what a task needs travels
with it (:func:`pack_study` reads a study folder into memory, :func:`unpack_study` rebuilds it in
a worker-local temporary folder) and what it produces travels back as bytes. Functions and
items are pickled (cloudpickle), so a task function must be importable on the workers (a
function of this package) and its items plain data.

Also here, on top of the interface:

* :func:`coverage_study` -- the coverage test of the identification's confidence intervals
  (seeded noise replicates in the condensed space) with the replicates mapped in chunks;
* :func:`bootstrap_samples` -- the parametric bootstrap of ``identify(..., bootstrap=N)`` with
  the same draws, the refits mapped in chunks.

The external solvers' right-hand-side chunks use the same interface through the hook of
:class:`solver_adapters.subprocess.CommandAdapter` (its ``executor`` attribute), so a large
batch runs as several solver processes side by side.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Protocol, Sequence

import numpy as np

__all__ = ["INSTALL_HINT", "Executor", "SerialExecutor", "DaskExecutor", "TaskFailure", "make_executor",
           "dask_available", "terminal_progress", "StudyPackage", "pack_study", "unpack_study",
           "coverage_study", "CoverageResult", "bootstrap_samples", "chunked", "use_executor"]

INSTALL_HINT = "pip install 'blackbox-joints[distributed]'"
"""How to get dask for ``--workers`` / ``--scheduler``."""

Progress = Callable[[int, int, int], None]
"""``progress(done, total, failed)``: called once at the start and after every finished task."""


def dask_available() -> bool:
    """Whether ``dask.distributed`` can be imported."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class TaskFailure:
    """What ``map(..., errors="return")`` puts in place of the result of a task that failed:
    its position, the exception's type name and message (``lost``: the task's worker died more
    often than the scheduler allows, the work was never finished)."""
    index: int
    error_type: str
    message: str
    lost: bool = False

    def __str__(self) -> str:
        return f"{self.error_type}: {self.message}"


class Executor(Protocol):
    """What the commands use to run independent work."""
    workers: int
    """How many tasks run at the same time (1 for serial)."""
    description: str

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any], *, errors: str = "raise",
            progress: Progress | None = None) -> list:
        """``[fn(x) for x in items]`` in order. ``errors="raise"``: the first failure (in item
        order) is raised after every task has ended; ``"return"``: a :class:`TaskFailure` takes
        the failed task's place."""

    def share(self, value: Any) -> contextlib.AbstractContextManager:
        """A context manager giving a handle to ``value`` for :meth:`map_shared`: the value is
        sent to every worker once, and dropped there when the block ends."""

    def map_shared(self, fn: Callable[[Any, Any], Any], shared: Any, items: Iterable[Any], *,
                   errors: str = "raise", progress: Progress | None = None) -> list:
        """``[fn(x, value) for x in items]`` in order, ``shared`` a handle from :meth:`share`
        (``errors`` and ``progress`` as :meth:`map`)."""

    def close(self) -> None: ...


def _check_errors(errors: str) -> None:
    if errors not in ("raise", "return"):
        raise ValueError(f"errors must be 'raise' or 'return', got {errors!r}")


class SerialExecutor:
    """Every task in this process, one after the other."""
    workers = 1
    description = "serial"

    def __init__(self, progress: Progress | None = None):
        self.progress = progress

    def map(self, fn, items, *, errors: str = "raise", progress: Progress | None = None) -> list:
        _check_errors(errors)
        items = list(items)
        say = progress or self.progress or (lambda done, total, failed: None)
        out, failed = [], 0
        say(0, len(items), 0)
        for i, x in enumerate(items):
            try:
                out.append(fn(x))
            except Exception as exc:
                if errors == "raise":
                    raise
                failed += 1
                out.append(TaskFailure(i, type(exc).__name__, str(exc)))
            say(i + 1, len(items), failed)
        return out

    @contextlib.contextmanager
    def share(self, value):
        yield value                     # in this process: the value itself

    def map_shared(self, fn, shared, items, *, errors: str = "raise", progress: Progress | None = None) -> list:
        return self.map(functools.partial(_with_shared, fn, shared), items, errors=errors, progress=progress)

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _with_shared(fn, shared, x):
    return fn(x, shared)


class DaskExecutor:
    """Tasks on a ``distributed`` cluster (module docstring).

    ``workers=N``: a ``LocalCluster`` of N worker processes with ``threads_per_worker`` threads
    each, listening on 127.0.0.1 only, no dashboard; closed by :meth:`close`. ``scheduler``: the
    address of a running scheduler (``tcp://host:8786``); :meth:`close` then only disconnects.
    ``allowed_failures``: how often a task may be on a worker that died before it counts as lost
    (the local cluster's scheduler; a remote scheduler keeps its own setting).
    """

    def __init__(self, workers: int | None = None, scheduler: str | None = None, *,
                 threads_per_worker: int = 1, allowed_failures: int = 3, progress: Progress | None = None,
                 memory_limit: str | int | None = "auto", timeout_s: float = 30.0):
        if (workers is None) == (scheduler is None):
            raise ValueError("give either workers (a local cluster) or scheduler (an address), not both")
        if workers is not None and int(workers) < 1:
            raise ValueError(f"workers must be at least 1, got {workers!r}")
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise ValueError(f"--workers/--scheduler need dask.distributed, which is not installed: "
                             f"{INSTALL_HINT}") from None
        self.progress = progress
        self.cluster = None
        if workers is not None:
            self.cluster = LocalCluster(n_workers=int(workers), threads_per_worker=int(threads_per_worker),
                                        processes=True, host="127.0.0.1", dashboard_address=None,
                                        memory_limit=memory_limit,
                                        scheduler_kwargs={"allowed_failures": int(allowed_failures),
                                                          # its HTTP endpoint (health, metrics): loopback, any free port
                                                          "dashboard_address": "127.0.0.1:0"})
            try:
                self.client = Client(self.cluster, timeout=timeout_s)
            except BaseException:
                self.cluster.close()
                raise
            self.description = f"local Dask cluster, {int(workers)} worker process(es) on 127.0.0.1"
        else:
            try:
                self.client = Client(scheduler, timeout=timeout_s)
            except OSError as exc:
                raise ValueError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}") from None
            self.description = f"Dask scheduler {scheduler}"
        self.allowed_failures = int(allowed_failures)

    @property
    def workers(self) -> int:
        """Worker threads of the cluster right now (at least 1)."""
        try:
            info = self.client.scheduler_info()["workers"]
            return max(1, sum(int(w.get("nthreads", 1)) for w in info.values()))
        except Exception:
            return 1

    def worker_pids(self) -> dict[str, int]:
        """``{worker address: process id}`` (for tests and diagnostics)."""
        return self.client.run(os.getpid)

    def map(self, fn, items, *, errors: str = "raise", progress: Progress | None = None) -> list:
        return self._map(fn, items, None, errors, progress)

    @contextlib.contextmanager
    def share(self, value):
        """The value scattered to every worker (``broadcast=True``) as one object; released when
        the block ends. A worker that joins later gets it from another worker when a task needs it."""
        (fut,) = self.client.scatter([value], broadcast=True, hash=False)
        try:
            yield fut
        finally:
            fut.release()

    def map_shared(self, fn, shared, items, *, errors: str = "raise", progress: Progress | None = None) -> list:
        return self._map(fn, items, shared, errors, progress)

    def _map(self, fn, items, shared, errors: str, progress: Progress | None) -> list:
        _check_errors(errors)
        from distributed import as_completed
        from distributed.scheduler import KilledWorker

        items = list(items)
        say = progress or self.progress or (lambda done, total, failed: None)
        total = len(items)
        say(0, total, 0)
        if not items:
            return []
        # pure=False: equal items are still separate tasks (a replicate is not a cache hit); a
        # shared value is a future of scattered data, resolved on the worker (not sent again)
        futures = (self.client.map(fn, items, pure=False) if shared is None else
                   self.client.map(fn, items, [shared] * total, pure=False))
        position = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * total
        failures: dict[int, BaseException] = {}
        done = 0
        try:
            for fut in as_completed(futures):
                i = position[fut.key]
                try:
                    results[i] = fut.result()
                except Exception as exc:
                    failures[i] = exc
                    lost = isinstance(exc, KilledWorker)
                    results[i] = TaskFailure(i, type(exc).__name__, str(exc), lost)
                done += 1
                say(done, total, len(failures))
                fut.release()
        except BaseException:
            self.client.cancel(futures)
            raise
        if failures and errors == "raise":
            raise failures[min(failures)]
        return results

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def make_executor(workers: int | None = None, scheduler: str | None = None, *,
                  progress: Progress | None = None, warn: Callable[[str], None] | None = None) -> Executor:
    """The executor the command line asks for: serial without ``--workers``/``--scheduler``;
    ``workers`` without dask installed runs serially after ``warn`` says how to install it (a
    ``scheduler`` without dask is an error: the user named a cluster to use)."""
    if workers is not None and scheduler is not None:
        raise ValueError("give --workers or --scheduler, not both")
    if workers is None and scheduler is None:
        return SerialExecutor(progress)
    if not dask_available():
        if scheduler is not None:
            raise ValueError(f"--scheduler needs dask.distributed, which is not installed: {INSTALL_HINT}")
        (warn or (lambda msg: None))(f"--workers {workers}: dask.distributed is not installed, running "
                                     f"serially (to run in parallel: {INSTALL_HINT})")
        return SerialExecutor(progress)
    return DaskExecutor(workers=workers, scheduler=scheduler, progress=progress)


def terminal_progress(label: str, print_fn: Callable[[str], None] = print, every_s: float = 2.0) -> Progress:
    """A ``progress`` that prints ``label: done/total done, failed`` at most every ``every_s``
    seconds, and always the first and the last line."""
    state = {"last": -1e9}
    lock = threading.Lock()

    def progress(done: int, total: int, failed: int) -> None:
        now = time.perf_counter()
        with lock:
            if done in (0, total) or now - state["last"] >= every_s:
                state["last"] = now
                print_fn(f"  {label}: {done}/{total} done, {failed} failed")
    return progress


def chunked(n: int, chunks: int) -> list[range]:
    """``range(n)`` cut into at most ``chunks`` contiguous, nearly equal, non-empty ranges."""
    chunks = max(1, min(int(chunks), int(n)))
    bounds = np.linspace(0, n, chunks + 1).round().astype(int)
    return [range(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def use_executor(adapter: Any, executor: Executor | None, chunks: int | None = None) -> Any:
    """Give an external-solver adapter the executor for its right-hand-side chunks: every
    ``solve`` with more than one case is cut into ``chunks`` solver runs mapped through
    ``executor`` (default: the executor's workers, but no chunk of fewer than
    :data:`solver_adapters.subprocess.MIN_CASES_PER_CHUNK` cases: a small batch stays one run).
    Reaches through a cache wrapper (``inner``). An adapter without the hook (the in-process
    reference solver) is returned unchanged."""
    target = adapter
    while not hasattr(target, "executor") and hasattr(target, "inner"):
        target = target.inner
    if hasattr(target, "executor") and executor is not None and executor.workers > 1:
        target.executor = executor
        target.chunks = chunks
    return adapter


# --------------------------------------------------------------------------------------------
# a study folder that travels with its task
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StudyPackage:
    """A study folder in memory: ``files`` maps relative paths (POSIX) to bytes. ``origin``: the
    folder on the client; ``deck``: the deck's path inside the package when it came from outside
    the folder (``study.toml`` is then rewritten to name it)."""
    name: str
    origin: str
    files: dict[str, bytes] = field(repr=False)

    @property
    def size(self) -> int:
        return sum(len(b) for b in self.files.values())

    def digest(self) -> str:
        h = hashlib.sha256()
        for k in sorted(self.files):
            h.update(k.encode() + b"\0" + hashlib.sha256(self.files[k]).digest())
        return h.hexdigest()


_SKIP_DIRS = {".blackbox_cache", "__pycache__", ".git"}


def pack_study(folder: str | os.PathLike, *, skip: Sequence[str] = ()) -> StudyPackage:
    """Read a study folder into memory: every regular file under it (the run cache and symbolic
    links leading out of it left out), and a deck (with its INCLUDEs) that lives outside the
    folder -- in a folder the user allows (:func:`blackbox.study.study_file`) -- under
    ``_external/``, ``study.toml`` rewritten to point there. ``ValueError`` for a folder that is
    not a study (no ``study.toml``); :class:`~blackbox.errors.StudyError` for a study file
    (``study.toml``, ``loads.csv``, ``measurements.csv``, ``truth.json``, the deck and its
    INCLUDEs) that leads out of the folder without that permission."""
    import tomllib

    from blackbox.study import study_file

    root = Path(folder).resolve()
    if not (root / "study.toml").is_file():
        raise ValueError(f"{folder}: not a study folder (no study.toml)")
    for name in ("study.toml", "loads.csv", "measurements.csv", "truth.json"):
        study_file(root, name)          # a link leading out of the study is refused, not left out
    files: dict[str, bytes] = {}
    for here, dirs, names in os.walk(root, followlinks=False):
        rel = Path(here).relative_to(root)
        dirs[:] = sorted(d for d in dirs if d not in _SKIP_DIRS and not (Path(here) / d).is_symlink())
        for n in sorted(names):
            if rel == Path(".") and n in skip:
                continue
            p = Path(here) / n
            real = p.resolve()
            if real.is_relative_to(root) and real.is_file():
                files[(rel / n).as_posix()] = real.read_bytes()
    cfg = tomllib.loads(files["study.toml"].decode("utf-8-sig"))
    deck_name = str(cfg.get("solver", {}).get("deck", "model.bdf"))
    deck = study_file(root, deck_name, f"[solver] deck = {deck_name!r}", named_in=root / "study.toml")
    if deck.is_file():
        from solver_adapters.cache import deck_files

        deck_set = [study_file(root, p, f"the deck's INCLUDE {p}") for p in deck_files(deck) if p.is_file()]
        if any(not p.is_relative_to(root) for p in deck_set):
            # the deck or one of its INCLUDEs lives outside the folder: the whole deck travels
            # under _external/ with the layout of its files, and study.toml points there
            base = Path(os.path.commonpath([str(p.parent) for p in deck_set]))
            for p in deck_set:
                files[f"_external/{p.relative_to(base).as_posix()}"] = p.read_bytes()
            new = f"_external/{deck.relative_to(base).as_posix()}"
            files["study.toml"] = _with_deck(files["study.toml"].decode("utf-8-sig"), new).encode()
    return StudyPackage(root.name, str(root), files)


def _with_deck(text: str, new: str) -> str:
    """``study.toml`` text whose ``[solver] deck`` is ``new`` (the key replaced, or added)."""
    import json
    import re

    lines = text.splitlines()
    table, solver_at = None, None
    for i, ln in enumerate(lines):
        head = re.match(r"^\s*\[\s*([^\]\s]+)\s*\]", ln)
        if head:
            table = head.group(1)
            if table == "solver":
                solver_at = i
            continue
        if table == "solver" and re.match(r"^\s*deck\s*=", ln):
            lines[i] = f"deck = {json.dumps(new)}"
            return "\n".join(lines) + "\n"
    if solver_at is None:
        return "\n".join(lines) + f"\n\n[solver]\ndeck = {json.dumps(new)}\n"
    lines.insert(solver_at + 1, f"deck = {json.dumps(new)}")
    return "\n".join(lines) + "\n"


def unpack_study(pkg: StudyPackage, dst: str | os.PathLike) -> Path:
    """Write a package into the folder ``dst/<name>`` (created) and return that folder."""
    root = Path(dst) / pkg.name
    root.mkdir(parents=True, exist_ok=False)
    for rel, data in pkg.files.items():
        target = (root / rel).resolve()
        if not target.is_relative_to(root.resolve()):
            raise ValueError(f"package {pkg.name!r}: path {rel!r} leads out of the study folder")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    return root


def read_tree(folder: str | os.PathLike) -> dict[str, bytes]:
    """Every file under ``folder`` as ``{relative POSIX path: bytes}`` (outputs travelling back)."""
    folder = Path(folder)
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[p.relative_to(folder).as_posix()] = p.read_bytes()
    return out


def write_tree(files: dict[str, bytes], folder: str | os.PathLike) -> list[str]:
    """Write ``{relative path: bytes}`` under ``folder`` (no path may lead out of it)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    base = folder.resolve()
    for rel, data in files.items():
        target = (folder / rel).resolve()
        if not target.is_relative_to(base):
            raise ValueError(f"output path {rel!r} leads out of {folder}")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    return sorted(files)


class scratch:
    """A worker-local temporary folder for one task, removed afterwards (context manager)."""

    def __init__(self, prefix: str = "blackbox-task-"):
        self.prefix = prefix

    def __enter__(self) -> Path:
        self._tmp = tempfile.TemporaryDirectory(prefix=self.prefix)
        return Path(self._tmp.name)

    def __exit__(self, *exc) -> None:
        self._tmp.cleanup()


# --------------------------------------------------------------------------------------------
# replicates: coverage of the confidence intervals, parametric bootstrap
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CoverageResult:
    """Per replicate: the estimate, the reported interval, convergence, reduced chi-square."""
    k: np.ndarray              # (n, p)
    ci_low: np.ndarray         # (n, p)
    ci_high: np.ndarray        # (n, p)
    converged: np.ndarray      # (n,)
    reduced_chi2: np.ndarray   # (n,)
    truth: np.ndarray          # (p,)
    wall_s: float
    executor: str
    task_cpu_s: tuple[float, ...] = ()     # CPU time of each chunk where it ran

    @property
    def n(self) -> int:
        return len(self.converged)

    def coverage(self) -> np.ndarray:
        """Share of the replicates whose interval holds the truth, per parameter."""
        hit = (self.ci_low <= self.truth) & (self.truth <= self.ci_high)
        return hit.mean(axis=0)


def _coverage_chunk(args) -> tuple[list[tuple], float]:
    """Replicates ``seeds`` of :func:`coverage_study` (runs on a worker), and the CPU time taken."""
    from blackbox.identification import Observations, identify

    cpu0 = time.process_time()

    model, truth, dofs, cases, noise, k0, holdout, opts, seeds = args
    U = model.pick(model.response(np.asarray(truth, float)), list(dofs))[:, list(cases)]
    trans = np.array([c <= 3 for _, c in dofs])
    floor = np.zeros(len(dofs))
    for kind in (True, False):
        if np.any(trans == kind):
            floor[trans == kind] = 0.01 * np.sqrt(np.mean(U[trans == kind] ** 2))
    sigma = noise * np.maximum(np.abs(U), floor[:, None])
    n_rows, n_cases = U.shape
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        values = U + sigma * rng.standard_normal(U.shape)
        obs = Observations(tuple(d for _ in range(n_cases) for d in dofs),
                           np.repeat(np.asarray(list(cases)), n_rows), values.T.ravel(), sigma.T.ravel(),
                           tuple(model.c.cases))
        fit_obs, hold = obs.split(list(holdout)) if holdout else (obs, None)
        r = identify(model, fit_obs, np.asarray(k0, float), holdout=hold, **opts)
        out.append((r.k, r.ci_low, r.ci_high, bool(r.converged), float(r.reduced_chi2)))
    return out, time.process_time() - cpu0


def coverage_study(model, truth, dofs: Sequence[tuple[int, int]], cases: Sequence[int], k0, *,
                   replicates: int = 400, noise: float = 0.05, holdout: Sequence[str] = (),
                   seed: int = 2024, executor: Executor | None = None, chunks: int | None = None,
                   **identify_options) -> CoverageResult:
    """Seeded replicates of simulated measurements, each identified as ``blackbox identify``
    would, to check how often the reported interval holds ``truth`` (Sec. 4.4).

    ``model``: a :class:`~blackbox.condensation.CondensedModel`; every DOF of ``dofs`` is measured
    in every case index of ``cases`` with ``sigma = noise * |u|`` (floored at ``noise`` x 1 %
    of the RMS of the same kind: translations, rotations), replicate ``r`` drawn from
    ``numpy.random.default_rng([seed, r])``; ``holdout``: case labels predicted, not fitted.
    The replicates are cut into ``chunks`` (default: 4 per worker) mapped through ``executor``
    (default serial); each replicate depends only on its seed, so the result is the same
    whatever the executor and the chunking."""
    executor = executor or SerialExecutor()
    n = int(replicates)
    n_chunks = chunks or (4 * executor.workers if executor.workers > 1 else 1)
    seeds = [[int(seed), r] for r in range(n)]
    tasks = [(model, np.asarray(truth, float), tuple(tuple(d) for d in dofs), tuple(cases), float(noise),
              np.asarray(k0, float), tuple(holdout), dict(identify_options), [seeds[i] for i in rg])
             for rg in chunked(n, n_chunks)]
    t0 = time.perf_counter()
    parts = executor.map(_coverage_chunk, tasks)
    rows = [row for part, _ in parts for row in part]
    wall = time.perf_counter() - t0
    return CoverageResult(np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                          np.array([r[2] for r in rows]), np.array([r[3] for r in rows]),
                          np.array([r[4] for r in rows]), np.asarray(truth, float), wall,
                          executor.description, tuple(cpu for _, cpu in parts))


def _bootstrap_chunk(args) -> list[np.ndarray | None]:
    """Refits of the bootstrap data ``ys`` from ``phi`` (runs on a worker); None: not converged."""
    from blackbox.identification.newton import _newton
    from blackbox.identification.problem import _Problem

    model, obs, phi, ys, max_iterations, xtol, ftol = args
    prob = _Problem(model, obs)
    out = []
    for y in ys:
        b = _newton(prob, phi, y=y, max_iterations=int(max_iterations), xtol=xtol, ftol=ftol)
        out.append(b.k if b.status in (1, 2, 3) else None)
    return out


def bootstrap_samples(model, obs, result, n: int, *, seed: int = 0, max_iterations: int = 30,
                      xtol: float = 1e-8, ftol: float = 1e-10, executor: Executor | None = None,
                      chunks: int | None = None) -> np.ndarray:
    """The parametric bootstrap of ``identify(model, obs, ..., bootstrap=n, seed=seed)``
    (:func:`blackbox.identification.uncertainty.parametric_bootstrap`) with its refits mapped
    through ``executor``: the same draws (``default_rng(seed)``, one vector per replicate, in
    order) and the same refits from the estimate ``result`` (an ``IdentificationResult`` of that
    call's options), the converged estimates one per row, in replicate order.

    The refits start from the estimate's coordinates recomputed from ``result.k``; ``identify``
    starts from the coordinates its iteration ended with, which can differ in the last bit
    (log/exp round trip), so the samples agree to round-off, not always bit for bit."""
    from blackbox.identification.problem import _Problem

    executor = executor or SerialExecutor()
    prob = _Problem(model, obs)
    rng = np.random.default_rng(seed)
    f = result.predicted
    ys = [f + prob.sigma * rng.standard_normal(len(f)) for _ in range(int(n))]
    phi = prob.to_phi(np.asarray(result.k, float))
    n_chunks = chunks or (4 * executor.workers if executor.workers > 1 else 1)
    tasks = [(model, obs, phi, [ys[i] for i in rg], max_iterations, xtol, ftol)
             for rg in chunked(len(ys), n_chunks)] if ys else []
    ks = [k for part in executor.map(_bootstrap_chunk, tasks) for k in part if k is not None]
    return np.array(ks).reshape(-1, prob.p)
