"""Choosing and building a study's solver adapter (wiring: the only place in ``blackbox`` besides
the CLI that imports adapters other than through the protocol)."""

from __future__ import annotations

from contextvars import ContextVar
from pathlib import Path

from blackbox.errors import StudyError
from blackbox.study import Study
from solver_adapters.protocol import SolverAdapter

__all__ = ["ADAPTER_CACHE", "TRUST_COMMAND", "SOLVER_PROGRESS", "make_adapter_for"]

SOLVER_PROGRESS: ContextVar = ContextVar("blackbox_solver_progress", default=None)
"""A heartbeat ``progress(elapsed_s, last_line)`` for external solvers while they run (the CLI
prints one line every few seconds); None for silence."""

TRUST_COMMAND: ContextVar[bool] = ContextVar("blackbox_trust_command", default=False)
"""The user's consent (``--trust-command``) for the running command to start a study's external
command adapter; without it the program must be listed in the user's own configuration."""


ADAPTER_CACHE: ContextVar[bool | Path] = ContextVar("blackbox_adapter_cache", default=False)
"""What ``make_adapter_for(..., cache=None)`` does: False (no cache), True (``STUDY/.blackbox_cache``)
or a cache folder. The CLI sets it from ``--no-cache`` / ``--cache-dir`` for the command's duration."""


def make_adapter_for(study: Study, name: str | None = None, deck: Path | None = None,
                     cache: bool | str | Path | None = None) -> SolverAdapter:
    """The study's adapter (or ``name``), optionally on another deck (a truth deck).

    ``cache``: True wraps the adapter in :class:`solver_adapters.cache.CachedAdapter` with the
    study's ``.blackbox_cache/`` folder (a repeated batch is read back instead of solved, so an
    interrupted command resumes); a path uses that folder instead; False returns the bare
    adapter; None (default) takes :data:`ADAPTER_CACHE` (False unless the CLI set it).
    """
    from solver_adapters.registry import make_adapter

    if cache is None:
        cache = ADAPTER_CACHE.get()

    cfg = study.config.solver
    name = name or cfg.adapter
    own_deck = deck is None or Path(deck) == study.deck_path
    deck = deck or study.deck_path
    if name == "reference":
        opts = {"backend": cfg.backend, "parsed": study.deck if own_deck else None}
    elif name == "command":
        if not cfg.command:
            raise StudyError("adapter 'command' needs [solver] command = [\"program\", \"{deck}\"]",
                             file=str(study.root / "study.toml"))
        opts = {"command": cfg.command, "dialect": cfg.dialect, "timeout_s": cfg.timeout_s,
                "trusted": TRUST_COMMAND.get()}
    else:
        opts = {"timeout_s": cfg.timeout_s} if _accepts(name, "timeout_s") else {}
    if "trusted" not in opts and _accepts(name, "trusted"):      # any adapter that starts programs
        opts["trusted"] = TRUST_COMMAND.get()
    if name != "reference" and "unmodelled" not in cfg.options and _accepts(name, "unmodelled"):
        # an external adapter needs only the grids, joints and loads from the deck: cards the
        # reader does not model (shells, solids) go to its solver (its dialect says whether it
        # can); the reference adapter refuses them with the reader's message listing them all
        opts["unmodelled"] = "pass"
    clash = sorted(set(cfg.options) & set(opts))
    if clash:
        raise StudyError(f"[solver.options] {clash} are set by the [solver] table itself; set them there",
                         file=str(study.root / "study.toml"))
    opts.update(cfg.options)
    adapter = make_adapter(name, deck, **opts)
    beat = SOLVER_PROGRESS.get()
    if beat is not None and hasattr(adapter, "progress"):
        adapter.progress = beat
    if cache is False:
        return adapter
    from solver_adapters.cache import CACHE_DIRNAME, CachedAdapter
    return CachedAdapter(adapter, study.root / CACHE_DIRNAME if cache is True else Path(cache))


def _accepts(name: str, option: str) -> bool:
    """Whether adapter ``name`` takes ``option`` (its constructor chain or ``options`` declaration)."""
    from solver_adapters.registry import adapter_options

    spec = adapter_options(name)
    return spec.open or option in spec.names
