"""Every error class the tool raises, in one place.

The solver errors (:class:`SolverError` and its subclasses) are defined in
``solver_adapters.errors`` and re-exported here from ``solver_adapters.protocol``. The errors of
the method and of the study files all derive from :class:`BlackboxError`; the ones that describe
a bad argument or option are also ``ValueError`` so that callers catching ``ValueError`` keep
working. This module imports nothing of ``blackbox`` (every other module may import it).
"""

from solver_adapters.protocol import (located, DeckFormatError, FactorizationError, ModelError, OptionError,
                                      PluginConflictError, PluginLoadError, RegistryError, SolverError,
                                      SolverRunError, SolverTimeoutError, UnknownDofError,
                                      UnknownPluginError, UnstableStructureError)


class BlackboxError(Exception):
    """Base class of every error of the method and of the study files (not of the solvers)."""


class StudyError(BlackboxError):
    """A study folder that cannot be used: says file, line, column and what was given."""

    def __init__(self, message: str, *, file: str | None = None, line: int | None = None,
                 column: str | None = None):
        self.file, self.line, self.column = file, line, column
        super().__init__(located(message, file, line, column))


class IdentificationError(BlackboxError):
    """The estimation cannot proceed (too few observations, non-finite residuals...)."""


class JointModelError(BlackboxError, ValueError):
    """A joint description or a parameter vector that cannot be used (says what and what was given)."""


class ComparisonError(BlackboxError, ValueError):
    """The comparison cannot be made (a mechanism, mismatched models...); says what was given."""


class DiagnosisError(BlackboxError, ValueError):
    """The diagnosis cannot run: an option it does not know or cannot use, or a study it cannot
    diagnose (says which and what was given)."""


class EditedDeckError(BlackboxError):
    """An edited deck the diagnosis ran (its split deck) is not the study's structure: at its
    rigid state it does not reproduce the declared model beyond the solver's rounding. Not bad
    input of the user's and not a finding about the structure: the command stops with the
    solver-failure exit code (3), naming where the two differ and the cards there. ``rows``:
    ``[(grid, component, case, difference in sigma)]``, largest first."""

    def __init__(self, message: str, rows=()):
        self.rows = list(rows)
        super().__init__(message)


class DesignError(BlackboxError, ValueError):
    """A test design that cannot be made as asked (bad budgets, unknown criterion, candidates
    that carry no information); says what was given."""


__all__ = ["DesignError", "BlackboxError", "StudyError", "IdentificationError", "JointModelError", "ComparisonError",
           "DiagnosisError", "EditedDeckError", "SolverError", "DeckFormatError", "ModelError", "UnstableStructureError",
           "UnknownDofError", "SolverRunError", "SolverTimeoutError", "FactorizationError",
           "RegistryError", "UnknownPluginError", "PluginLoadError", "PluginConflictError", "OptionError"]
