"""The one interface between the method (``blackbox``) and any finite-element code.

A solver adapter receives load vectors over DOF labels and returns displacements at the DOF
labels the caller asks for. No stiffness matrix and no element data cross this interface: the
method layers of ``blackbox`` import this module and nothing else from ``solver_adapters``
(enforced by the import-linter contract in ``pyproject.toml``).

Vocabulary
----------
DOF label
    ``(grid, component)`` with component 1-3 translations and 4-6 rotations, global axes.
Batch
    Many load cases solved in one call: one factorization, many right-hand sides. The
    black-box condensation of Chapter 3 relies on this: ``n_B + L`` right-hand sides in one run.

The parsed-deck data model (:mod:`solver_adapters.deck`: plain dataclasses of grids, bars,
springs, constraints; no solver code) is re-exported here too: diagnosis edits a deck (cuts a
support, splits a joint) and hands the edited deck to the same adapter, which stays a black box.

Errors are typed and all derive from :class:`SolverError` (defined in
:mod:`solver_adapters.errors`, re-exported here): a solver's crash, garbage output, timeout or
singular stiffness is always a :class:`SolverError` subclass, whatever adapter saw it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, Sequence, runtime_checkable

import numpy as np
import scipy.sparse as sp

# every error class lives in solver_adapters.errors; re-exported here because this is the one
# module of solver_adapters that blackbox's method layers may import
from solver_adapters.deck import (Bush, CBar, Coord, Deck, Grid, Mat1, PBar, PBush, Pelas, Prod,  # noqa: F401
                                  Rbe2, Rbe3, Rod, Spc1, SpcAdd, Spring, Unmodelled)
from solver_adapters.errors import (COMPONENT_NAMES, located, AdapterNotFound, CheckFailure, FeatureRefused,  # noqa: F401
                                    ConsentError, CorruptEntry, DeckFormatError, EquationError, FactorizationError,
                                    InsecureFileError, ModelError, OptionError, PluginConflictError,
                                    PluginLoadError, RegistryError, SolverError, SolverRunError,
                                    SolverTimeoutError, TableFormatError, UnauthenticEntry,
                                    UnknownDofError, UnknownPluginError, UnsafeCacheFolder, UnsafeEntry,
                                    UnstableStructureError, UnsupportedFeatureError)

DofLabel = tuple[int, int]
"""``(grid id, component 1..6)``."""


# --------------------------------------------------------------------------------------------
# data crossing the interface
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LoadMatrix:
    """A batch of load cases: ``values[i, j]`` is the load on ``dofs[i]`` in case ``cases[j]``.

    ``values`` is a SciPy sparse matrix (CSC) of shape ``(len(dofs), len(cases))``.
    """

    dofs: tuple[DofLabel, ...]
    values: sp.csc_matrix
    cases: tuple[str, ...]

    def __post_init__(self) -> None:
        vals = sp.csc_matrix(self.values, dtype=float)
        object.__setattr__(self, "values", vals)
        object.__setattr__(self, "dofs", tuple((int(g), int(c)) for g, c in self.dofs))
        object.__setattr__(self, "cases", tuple(str(c) for c in self.cases))
        if vals.shape != (len(self.dofs), len(self.cases)):
            raise ValueError(f"load values have shape {vals.shape}, expected "
                             f"({len(self.dofs)}, {len(self.cases)}) = (dofs, cases)")
        if len(set(self.dofs)) != len(self.dofs):
            raise ValueError("LoadMatrix dofs must be unique")
        if vals.nnz and not np.all(np.isfinite(vals.data)):
            raise ValueError("LoadMatrix contains non-finite values")
        bad = [d for d in self.dofs if not 1 <= d[1] <= 6]
        if bad:
            raise UnknownDofError(bad, "load DOF (component must be 1..6)")

    @property
    def n_cases(self) -> int:
        return len(self.cases)

    @classmethod
    def unit(cls, dofs: Sequence[DofLabel], prefix: str = "unit") -> "LoadMatrix":
        """One case per DOF with a unit load there (columns of the flexibility, Fig. 3.2)."""
        dofs = tuple(dofs)
        return cls(dofs, sp.identity(len(dofs), format="csc"),
                   tuple(f"{prefix}:{g}:{c}" for g, c in dofs))

    @classmethod
    def from_dense(cls, dofs: Sequence[DofLabel], values: np.ndarray, cases: Sequence[str]) -> "LoadMatrix":
        return cls(tuple(dofs), sp.csc_matrix(np.asarray(values, dtype=float)), tuple(cases))

    def hstack(self, other: "LoadMatrix") -> "LoadMatrix":
        """Both batches side by side over the union of their DOF labels."""
        dofs = list(self.dofs)
        index = {d: i for i, d in enumerate(dofs)}
        for d in other.dofs:
            if d not in index:
                index[d] = len(dofs)
                dofs.append(d)
        a = _reindex_rows(self.values, [index[d] for d in self.dofs], len(dofs))
        b = _reindex_rows(other.values, [index[d] for d in other.dofs], len(dofs))
        return LoadMatrix(tuple(dofs), sp.hstack([a, b], format="csc"), self.cases + other.cases)

    def select(self, columns: Sequence[int]) -> "LoadMatrix":
        cols = list(columns)
        return LoadMatrix(self.dofs, self.values[:, cols], tuple(self.cases[j] for j in cols))


def _reindex_rows(m: sp.spmatrix, rows: list[int], n_rows: int) -> sp.csc_matrix:
    coo = sp.coo_matrix(m)
    r = np.asarray(rows, dtype=int)[coo.row] if coo.nnz else coo.row
    return sp.csc_matrix((coo.data, (r, coo.col)), shape=(n_rows, m.shape[1]))


@dataclass(frozen=True)
class Displacements:
    """Displacements at the requested DOF labels: ``values[i, j]`` at ``dofs[i]`` in case ``cases[j]``."""

    dofs: tuple[DofLabel, ...]
    values: np.ndarray
    cases: tuple[str, ...]

    def __post_init__(self) -> None:
        vals = np.asarray(self.values, dtype=float)
        object.__setattr__(self, "values", vals)
        if vals.shape != (len(self.dofs), len(self.cases)):
            raise ValueError(f"displacement values have shape {vals.shape}, expected "
                             f"({len(self.dofs)}, {len(self.cases)})")

    def rows(self, dofs: Sequence[DofLabel]) -> np.ndarray:
        """Values at ``dofs`` (in that order), all cases."""
        index = {d: i for i, d in enumerate(self.dofs)}
        missing = [d for d in dofs if tuple(d) not in index]
        if missing:
            raise UnknownDofError(missing, "reported DOF")
        return self.values[[index[tuple(d)] for d in dofs], :]


@dataclass(frozen=True)
class ScalarSpring:
    """A scalar spring of stiffness ``k`` between two DOF labels, or to ground when ``b`` is None.

    This is the one structural modification that crosses the interface: it is how a joint model
    is put *into the full model* for the finite-difference comparisons of Section 3.2 (a CELAS2
    card for a NASTRAN-type code). Negative values are allowed (an exact spring network for a
    coupled joint matrix needs some).
    """

    a: DofLabel
    b: DofLabel | None
    k: float


@dataclass
class SolverStats:
    """Counters an adapter keeps over its lifetime (the benchmark reads them)."""

    runs: int = 0
    right_hand_sides: int = 0
    factorizations: int = 0
    wall_s: float = 0.0
    peak_rss_bytes: int = 0
    history: list[dict] = field(default_factory=list)

    def snapshot(self) -> dict:
        return {"runs": self.runs, "right_hand_sides": self.right_hand_sides,
                "factorizations": self.factorizations, "wall_s": self.wall_s,
                "peak_rss_bytes": self.peak_rss_bytes}


@runtime_checkable
class SolverAdapter(Protocol):
    """What the method needs from a finite-element code: linear static solves, batched.

    ``solve`` must cost about one factorization however many columns ``loads`` has. Loads on a
    constrained DOF are carried by the support (no displacement); a requested constrained DOF
    reports 0.0. Unknown labels raise :class:`UnknownDofError`; any failure of the code raises a
    :class:`SolverError` subclass and never returns partial results.
    """

    name: str
    stats: SolverStats

    def dofs(self) -> tuple[DofLabel, ...]:
        """Every DOF label the adapter can load and report (all grid components)."""
        ...

    def grid_xyz(self) -> dict[int, tuple[float, float, float]]:
        """Basic-system coordinates of every grid (geometry for joints, reports and plots)."""
        ...

    def solve(self, loads: LoadMatrix, report: Sequence[DofLabel]) -> Displacements:
        """Displacements at ``report`` for every case (column) of ``loads``: one solver run."""
        ...

    def with_springs(self, springs: Sequence[ScalarSpring]) -> "SolverAdapter":
        """A new adapter for the same structure with ``springs`` added (the deck edited)."""
        ...
