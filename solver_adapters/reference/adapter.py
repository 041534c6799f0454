"""The in-process reference solver as a :class:`~solver_adapters.protocol.SolverAdapter`."""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Sequence

import numpy as np
import scipy.sparse as sp

from solver_adapters.deck import Deck
from solver_adapters.protocol import (Displacements, DofLabel, LoadMatrix, ModelError, ScalarSpring,
                                      SolverStats, UnknownDofError, UnstableStructureError)
from solver_adapters.reference.model import BACKENDS, Assembled, Factorization, assemble


def lost_loads_warning(loads: LoadMatrix, removed: Sequence[DofLabel]) -> list[DofLabel]:
    """Warn (``RuntimeWarning``) about the loaded components that AUTOSPC constrained and return
    them. NASTRAN does the same thing with such a load: the component is held by an automatic
    SPC, so the load goes into its constraint force and moves nothing (it is lost); the
    solution is that of the other loads. MYSTRAN too (docs/mystran.md)."""
    gone = set(map(tuple, removed))
    vals = loads.values.tocoo()
    loaded = np.unique(vals.row[vals.data != 0.0])
    hit = [tuple(loads.dofs[i]) for i in loaded.tolist() if tuple(loads.dofs[i]) in gone]
    if hit:
        warnings.warn(f"load on {len(hit)} component(s) that AUTOSPC constrained (no stiffness there), "
                      f"first {hit[:10]}: as in NASTRAN, such a load is taken by the automatic constraint "
                      f"and lost; the displacements are those of the other loads (PARAM,AUTOSPC,NO makes "
                      f"the component a mechanism error instead)", RuntimeWarning, stacklevel=3)
    return hit


class ReferenceAdapter:
    """Reads a NASTRAN bulk-data deck and solves it in-process (see ``model.py``).

    Assembly and factorization happen on the first ``solve`` and are reused for every batch, so
    a call with many right-hand sides costs one factorization plus cheap triangular solves.

    ``backend``: ``"auto"`` (default: SuperLU below ``model.AUTO_PARDISO_MIN_DOFS`` free DOFs,
    MKL PARDISO above when pypardiso is installed), ``"superlu"`` or ``"pardiso"``; see
    ``docs/scale.md`` for the measured difference. ``timings`` holds the wall time of each
    assembly phase and of the factorization (seconds) once they have run.
    """

    name = "reference"
    version = "1"

    def __init__(self, deck: Deck | str | Path, *, backend: str = "auto",
                 extra_springs: Sequence[ScalarSpring] = (), parsed: Deck | None = None):
        """``deck``: a parsed :class:`Deck` or a deck path. ``parsed``: the already parsed deck of
        that path (the caller read it), so that it is not parsed twice; ``deck_path`` is kept
        for whoever needs the files (the run cache hashes them)."""
        if backend not in BACKENDS:
            raise ModelError(f"unknown factorization backend {backend!r}; "
                             f"use one of {', '.join(BACKENDS)}")
        if not isinstance(deck, Deck):
            self.deck_path: Path | None = Path(deck)
            if parsed is None:
                from solver_adapters.bdf import read_deck
                parsed = read_deck(deck)
            deck = parsed
        else:
            self.deck_path = None
        if deck.unmodelled:
            # a deck read for an external solver (shells, solids kept apart): this solver would
            # leave them out and solve another structure; the reader's own message instead
            from solver_adapters.bdf import unmodelled_error
            raise unmodelled_error(deck)
        self.deck = deck
        self.backend = backend
        self.extra_springs = tuple(extra_springs)
        self.stats = SolverStats()
        self.timings: dict[str, float] = {}
        self._model: Assembled | None = None
        self._fact: Factorization | None = None
        self._labels = tuple((int(g), c) for g in sorted(deck.grids) for c in range(1, 7))
        self._label_set = frozenset(self._labels)
        for s in self.extra_springs:
            self._check_known([s.a] + ([s.b] if s.b else []), "spring DOF")

    # -- protocol -----------------------------------------------------------------------------
    def dofs(self) -> tuple[DofLabel, ...]:
        return self._labels

    def grid_xyz(self) -> dict[int, tuple[float, float, float]]:
        return {g.id: tuple(g.xyz) for g in self.deck.grids.values()}

    def solve(self, loads: LoadMatrix, report: Sequence[DofLabel]) -> Displacements:
        report = tuple((int(g), int(c)) for g, c in report)
        self._check_known(loads.dofs, "load DOF")
        self._check_known(report, "reported DOF")
        t0 = time.perf_counter()
        fact = self.factorization()
        m = self.model
        if m.autospc and loads.dofs:
            lost_loads_warning(loads, m.autospc)
        F_g = sp.csr_matrix((m.T.shape[0], loads.n_cases))
        if loads.dofs:
            gi = m.g_index(loads.dofs)
            coo = sp.coo_matrix(loads.values)
            F_g = sp.csr_matrix((coo.data, (gi[coo.row], coo.col)), shape=(m.T.shape[0], loads.n_cases))
        F_f = (m.T.T @ F_g).toarray(order="F")      # column-major: no copy in the solvers
        U_f = fact.solve(F_f) if loads.n_cases else np.zeros((m.T.shape[1], 0))
        U_f = U_f.reshape(m.T.shape[1], loads.n_cases)
        values = np.asarray(m.T[m.g_index(report), :] @ U_f if report else np.zeros((0, loads.n_cases)))
        if not np.all(np.isfinite(values)):   # never hand non-finite numbers to the method
            bad = sorted({report[i] for i in np.flatnonzero(~np.all(np.isfinite(values), axis=1))})
            raise UnstableStructureError("the reference solver produced non-finite displacements: the "
                                         "stiffness is too ill-conditioned for these loads (or the loads "
                                         "overflow)", bad)
        wall = time.perf_counter() - t0
        self.stats.runs += 1
        self.stats.right_hand_sides += loads.n_cases
        self.stats.wall_s += wall
        self.stats.history.append({"right_hand_sides": loads.n_cases, "wall_s": wall})
        return Displacements(report, values, loads.cases)

    def with_springs(self, springs: Sequence[ScalarSpring]) -> "ReferenceAdapter":
        return ReferenceAdapter(self.deck, backend=self.backend,
                                extra_springs=self.extra_springs + tuple(springs))

    # -- outside the protocol (benchmark's "standard condensation" only) ------------------------
    @property
    def model(self) -> Assembled:
        if self._model is None:
            self._model = assemble(self.deck, self.extra_springs, timings=self.timings)
        return self._model

    def factorization(self) -> Factorization:
        if self._fact is None:
            t0 = time.perf_counter()
            self._fact = Factorization(self.model, self.backend)
            self.stats.factorizations += 1
            self.stats.wall_s += time.perf_counter() - t0
            self.timings["factor_s"] = self._fact.factor_s
        return self._fact

    @property
    def autospc_dofs(self) -> list[DofLabel]:
        """The components AUTOSPC constrained (grid, component), after assembly. AUTOSPC is
        NASTRAN's SOL 101 default and runs unless the deck says PARAM,AUTOSPC,NO (then this is
        empty and a component without stiffness is a mechanism error naming it)."""
        return list(self.model.autospc)

    @property
    def backend_used(self) -> str | None:
        """The backend that factorized (``"superlu"``/``"pardiso"``), None before the first solve."""
        return self._fact.backend if self._fact is not None else None

    def stiffness(self) -> tuple[sp.csc_matrix, list[DofLabel], sp.csr_matrix]:
        """``(K_ff, f_labels, T)`` with ``u_g = T u_f``: the assembled matrices, for the
        benchmark's standard-condensation comparison. Not part of the protocol."""
        m = self.model
        return m.K_ff, m.f_labels, m.T

    # -- helpers -------------------------------------------------------------------------------
    def _check_known(self, dofs, what: str) -> None:
        unknown = [d for d in dofs if tuple(d) not in self._label_set]
        if unknown:
            raise UnknownDofError(unknown, what)
