"""Every error class of ``solver_adapters``, in one module that imports nothing of the project.

:class:`SolverError` is the base of everything a solver adapter raises when the solver, its
input or its configuration fails: a crash, garbage output, a timeout or a singular stiffness
is always a :class:`SolverError` subclass, whichever adapter or dialect saw it (foreign failure
codes, exceptions and exit statuses are translated into these). ``solver_adapters.protocol``
re-exports all of them; the method modules of ``blackbox`` import them from there.

The classes below the hierarchy's ``SolverError`` branch are deliberately *not* solver errors:
the solver did not fail (a run-cache file that cannot be used is recomputed; a conformance check
is a test assertion; a bad table or configuration file is the user's input).

Hierarchy::

    SolverError
    +-- DeckFormatError            unreadable deck: file, line, card, field
    +-- ModelError                 readable but inconsistent model
    |   +-- UnsupportedFeatureError  a card the adapter's code cannot express (refused before a run)
    +-- UnstableStructureError     singular stiffness (mechanism, missing support)
    +-- UnknownDofError            a load or output label the adapter does not have
    +-- SolverRunError             an external run failed (exit code, log tail, kept run dir)
    |   +-- SolverTimeoutError     ... by exceeding its wall-clock limit
    +-- FactorizationError         an in-process sparse factorization failed (library error code)
    +-- RegistryError (ValueError) an adapter or dialect cannot be found, loaded or configured
        +-- UnknownPluginError     no such name (lists the known names)
        +-- PluginLoadError        an entry point or built-in target fails to import
        +-- PluginConflictError    one name, two different targets (names both)
        +-- OptionError            options the adapter or dialect does not accept
    CorruptEntry (ValueError)      a run-cache file that cannot be used (recomputed)
    +-- UnauthenticEntry           ... whose authentication does not verify
    CheckFailure (AssertionError)  a conformance check failed
    FeatureRefused                 a conformance feature check passed by a typed refusal
    NumberFieldError (ValueError)  deck reader internal, always re-raised as DeckFormatError
    IrregularTable, ReaderFallback  deck reader internal: the bulk path hands over to the reference path
    ElementLoadError (ValueError)  element-load internal, always re-raised as a located DeckFormatError
    TableFormatError (ValueError)  a CSV table (loads) that cannot be used
    InsecureFileError (PermissionError)  a user configuration file others could change
    ConsentError                   an external command would run without the user's consent
"""

from __future__ import annotations

from typing import Sequence

COMPONENT_NAMES = {1: "T1", 2: "T2", 3: "T3", 4: "R1", 5: "R2", 6: "R3"}
"""NASTRAN names of the six components of a DOF label ``(grid, component)``."""


class SolverError(Exception):
    """Base class of every error raised by a solver adapter or while reading its input."""


class DeckFormatError(SolverError):
    """A bulk-data deck that cannot be read: says file, line, card and field."""

    def __init__(self, message: str, *, file: str | None = None, line: int | None = None,
                 card: str | None = None, field: int | str | None = None, value: str | None = None):
        self.file, self.line, self.card, self.field, self.value = file, line, card, field, value
        where = []
        if file is not None:
            where.append(f"{file}" + (f":{line}" if line is not None else ""))
        if card is not None:
            where.append(f"card {card}")
        if field is not None:
            where.append(f"field {field}")
        if value is not None:
            where.append(f"value {value!r}")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class ModelError(SolverError):
    """A deck that reads fine but describes an inconsistent model (missing IDs, conflicts)."""


class UnsupportedFeatureError(ModelError):
    """The adapter's code cannot express a feature of the deck (a card, or a field of one: a pin
    flag, an offset, a coordinate system), so it refuses the deck before running rather than
    solve another structure. ``code`` names the code; ``features`` lists ``(card, where, why)``
    (``card`` e.g. ``"CBAR 12"``, ``where`` ``"file:line"``), every one in the message."""

    def __init__(self, code: str, features: Sequence[tuple[str, str, str]], hint: str = ""):
        self.code = code
        self.features = tuple((str(c), str(w), str(y)) for c, w, y in features)
        self.cards = tuple(c for c, _, _ in self.features)
        shown = "; ".join(f"{c}{f' ({w})' if w else ''}: {y}" for c, w, y in self.features[:20])
        more = f"; ... and {len(self.features) - 20} more" if len(self.features) > 20 else ""
        super().__init__(f"{code} cannot express {len(self.features)} feature(s) of this deck, so it "
                         f"refuses the deck instead of solving another structure: {shown}{more}"
                         + (f". {hint}" if hint else ""))


class UnstableStructureError(SolverError):
    """The stiffness is singular: a mechanism or an unconstrained DOF. ``dofs`` names them."""

    def __init__(self, message: str, dofs: Sequence[tuple[int, int]] = ()):
        self.dofs = tuple(dofs)
        shown = ", ".join(f"{g}:{COMPONENT_NAMES.get(c, c)}" for g, c in self.dofs[:12])
        more = f" (+{len(self.dofs) - 12} more)" if len(self.dofs) > 12 else ""
        super().__init__(f"{message}" + (f" [grid:component {shown}{more}]" if shown else ""))


class UnknownDofError(SolverError):
    """A load or a requested output names a DOF label the adapter does not have."""

    def __init__(self, dofs: Sequence[tuple[int, int]], what: str = "DOF"):
        self.dofs = tuple(dofs)
        shown = ", ".join(f"({g},{c})" for g, c in self.dofs[:10])
        super().__init__(f"unknown {what} label(s) {shown}" + (" ..." if len(self.dofs) > 10 else ""))


class SolverRunError(SolverError):
    """An external solver run failed. Carries the exit code and the tail of its log."""

    def __init__(self, message: str, *, returncode: int | None = None, log_tail: str = "",
                 workdir: str | None = None):
        self.returncode, self.log_tail, self.workdir = returncode, log_tail, workdir
        extra = f" (exit code {returncode})" if returncode is not None else ""
        kept = f"\nrun directory kept for inspection: {workdir}" if workdir else ""
        tail = f"\n--- solver log tail ---\n{log_tail}" if log_tail else ""
        super().__init__(f"{message}{extra}{kept}{tail}")


class SolverTimeoutError(SolverRunError):
    """An external solver run exceeded its wall-clock limit and was killed (whole process tree)."""


class FactorizationError(SolverError):
    """An in-process sparse factorization failed for a reason other than a mechanism (out of
    memory, an index overflow, a library error code). ``code`` and ``phase`` are the library's,
    None when it gave none."""

    def __init__(self, message: str, *, code: int | None = None, phase: int | None = None):
        self.code, self.phase = code, phase
        super().__init__(message)


# ---- finding adapters and dialects by name (solver_adapters.registry) -------------------------
class RegistryError(SolverError, ValueError):
    """An adapter or dialect cannot be found, loaded or configured. Also a ``ValueError``: the
    name or the options came from the user's input (study.toml, the command line)."""


class UnknownPluginError(RegistryError):
    """No adapter or dialect of that name; the message lists the known names."""


class PluginLoadError(RegistryError):
    """A registered target (an entry point or a built-in whose optional package is missing)
    cannot be imported; the message names it and the import error."""


class PluginConflictError(RegistryError):
    """One name registered with two different targets (e.g. an installed entry point with the
    name of a built-in); the message names both."""


class OptionError(RegistryError):
    """Options an adapter or dialect does not accept, or a required one missing; the message
    names the offending option(s) and lists the accepted ones."""


AdapterNotFound = RegistryError
"""Former name of the registry's error (unknown or unavailable adapter)."""


# ---- not solver errors -----------------------------------------------------------------------
class CorruptEntry(ValueError):
    """A cache file that is not a complete, valid entry for the requested key."""


class UnauthenticEntry(CorruptEntry):
    """A cache file whose HMAC does not verify with this user's key: planted, altered or
    written by someone else. Never trusted."""


class EquationError(ValueError):
    """A DEQATN equation that cannot be read or evaluated (:mod:`solver_adapters.bdf.equations`);
    the message says what. The design reader turns it into a located :class:`DeckFormatError`."""


class CheckFailure(AssertionError):
    """A conformance check saw the adapter break the protocol (message: what and where)."""


class FeatureRefused(Exception):
    """A conformance feature check that the adapter passed by refusing the deck with an
    :class:`UnsupportedFeatureError` (message: what it refused); the suite reports it as
    ``REFUSED``, a pass."""


class NumberFieldError(ValueError):
    """A field's text is not the number its field needs (message says why). Internal to the deck
    reader, which re-raises it as :class:`DeckFormatError` with the file, line and card."""


class IrregularTable(Exception):
    """The deck reader's card table cannot be built (the reference tokenizer reads the deck, and
    raises the located error). Internal to solver_adapters.bdf."""


class ReaderFallback(Exception):
    """The deck reader's bulk path met something only its reference path reports right.
    Internal to solver_adapters.bdf."""


class ElementLoadError(ValueError):
    """A load on an element that cannot be applied: ``args = (field, message)``, the NASTRAN
    field of its card; re-raised by the card's reader as a located DeckFormatError."""


def located(message: str, file: str | None = None, line: int | None = None, column: str | None = None) -> str:
    """``file:line column 'c': message`` (the parts that are known), for errors about an input file."""
    where = ""
    if file:
        where = str(file) + (f":{line}" if line is not None else "")
        if column:
            where += f" column '{column}'"
    return f"{where}: {message}" if where else message


class TableFormatError(ValueError):
    """A CSV table that cannot be used: says file, line, column and what was given."""

    def __init__(self, message: str, *, file: str | None = None, line: int | None = None,
                 column: str | None = None):
        self.message, self.file, self.line, self.column = message, file, line, column
        super().__init__(located(message, file, line, column))


class InsecureFileError(PermissionError):
    """A file of the user's configuration that others could read or change; the message says
    how to fix it. A ``PermissionError`` (so an ``OSError``): the file cannot be used."""


__all__ = ["located", "COMPONENT_NAMES", "SolverError", "DeckFormatError", "ModelError",
           "UnsupportedFeatureError", "UnstableStructureError",
           "UnknownDofError", "SolverRunError", "SolverTimeoutError", "FactorizationError",
           "RegistryError", "UnknownPluginError", "PluginLoadError", "PluginConflictError",
           "OptionError", "AdapterNotFound", "CorruptEntry", "UnauthenticEntry", "CheckFailure", "FeatureRefused", "NumberFieldError", "EquationError",
           "TableFormatError", "InsecureFileError"]


# ---- consent before an external command runs (solver_adapters.subprocess) --------------------
class ConsentError(Exception):
    """An external command would run without the user's consent (neither ``--trust-command`` nor
    listed under ``trusted_commands`` in the user's own ``config.toml``). Not a solver error: the
    solver never ran. The message says exactly how to give consent."""


__all__ += ["ConsentError"]


# ---- what the run cache will not open (solver_adapters.cache) ----------------------------------
class UnsafeEntry(CorruptEntry):
    """A cache entry that is not a regular file owned by this user, or larger than any entry for
    the request can be: never opened for reading (a planted named pipe would block, a link to a
    device would never end). Ignored and recomputed."""


class UnsafeCacheFolder(OSError):
    """A cache folder (or one of its sub-folders) that is not a real directory: a symbolic link
    would make the cache read and write elsewhere. The cache is off for that run."""


__all__ += ["UnsafeEntry", "UnsafeCacheFolder"]
