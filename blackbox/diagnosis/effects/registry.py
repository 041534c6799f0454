"""The effect families by name: :func:`register` a class, :func:`get` it back, :func:`kinds` in
the order they were registered (which is the order candidates are listed and cut in the split deck)."""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

from blackbox.errors import DiagnosisError

if TYPE_CHECKING:
    from blackbox.diagnosis.effects.base import Effect

__all__ = ["register", "get", "kinds", "families"]

_FAMILIES: dict[str, type["Effect"]] = {}
E = TypeVar("E", bound=type)


def register(cls: E) -> E:
    """Class decorator: make the family ``cls`` (with its ``kind``) known by name."""
    kind = getattr(cls, "kind", None)
    if not isinstance(kind, str) or not kind:
        raise TypeError(f"{cls.__name__} has no 'kind' name to register under")
    if kind in _FAMILIES and _FAMILIES[kind] is not cls:
        raise ValueError(f"effect kind {kind!r} is already registered by {_FAMILIES[kind].__name__}")
    _FAMILIES[kind] = cls
    return cls


def get(kind: str) -> type["Effect"]:
    """The family registered as ``kind``."""
    try:
        return _FAMILIES[kind]
    except KeyError:
        raise DiagnosisError(f"unknown effect kind {kind!r}; known: {', '.join(_FAMILIES)}") from None


def kinds() -> tuple[str, ...]:
    """Every registered kind, in registration order."""
    return tuple(_FAMILIES)


def families(selected: tuple[str, ...] | list[str] | None = None) -> list[type["Effect"]]:
    """The registered families (all, or those named in ``selected``), in registration order;
    an unknown name is an error that lists the known ones."""
    if selected is None:
        return list(_FAMILIES.values())
    unknown = sorted(set(selected) - set(_FAMILIES))
    if unknown:
        raise DiagnosisError(f"unknown effect kind(s) {unknown}; known: {', '.join(_FAMILIES)}")
    return [cls for k, cls in _FAMILIES.items() if k in selected]
