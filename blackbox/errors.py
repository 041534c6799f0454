"""Every error class the tool raises, in one place (solver errors come from the protocol)."""

from solver_adapters.protocol import (DeckFormatError, ModelError, SolverError, SolverRunError,
                                      SolverTimeoutError, UnknownDofError, UnstableStructureError)


class StudyError(Exception):
    """A study folder that cannot be used: says file, line, column and what was given."""

    def __init__(self, message: str, *, file: str | None = None, line: int | None = None,
                 column: str | None = None):
        self.file, self.line, self.column = file, line, column
        where = ""
        if file:
            where = str(file) + (f":{line}" if line is not None else "")
            if column:
                where += f" column '{column}'"
        super().__init__(f"{where}: {message}" if where else message)


class IdentificationError(Exception):
    """The estimation cannot proceed (too few observations, non-finite residuals...)."""


__all__ = ["StudyError", "IdentificationError", "DeckFormatError", "ModelError", "SolverError",
           "SolverRunError", "SolverTimeoutError", "UnknownDofError", "UnstableStructureError"]
