"""Batched solver runs of a diagnosis, and each member's stiffness from the element deck's run.

Every run goes through :func:`solve`, which keeps a :class:`RunRecord` (what for, which deck, how
many right-hand sides, how long) and rejects non-finite answers. :func:`element_stiffness` turns
one run of the element deck (every member alone, clamped at end a) into the members' 12 x 12
stiffness matrices: the solver's own element, whatever its beam theory (six load cases however
many members: :func:`element_flexibility`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp

from blackbox.errors import IdentificationError
from solver_adapters.protocol import DofLabel, LoadMatrix, SolverAdapter

__all__ = ["RunRecord", "solve", "element_flexibility", "element_stiffness"]


@dataclass(frozen=True)
class RunRecord:
    """One batched solver run: what for, on which deck, how many right-hand sides, how long."""
    purpose: str
    deck: str
    right_hand_sides: int
    wall_s: float

    def to_json(self) -> dict:
        return {"purpose": self.purpose, "deck": self.deck, "right_hand_sides": self.right_hand_sides,
                "wall_s": self.wall_s}


def solve(adapter: SolverAdapter, loads: LoadMatrix, report: Sequence[DofLabel], purpose: str,
          deck: str, log: list[RunRecord]) -> np.ndarray:
    """``adapter.solve(loads, report)`` as an array ``(len(report), n_cases)``, recorded in ``log``."""
    t0 = time.perf_counter()
    out = adapter.solve(loads, tuple(report))
    log.append(RunRecord(purpose, deck, loads.n_cases, time.perf_counter() - t0))
    if not np.all(np.isfinite(out.values)):
        raise IdentificationError(f"adapter {adapter.name!r} returned non-finite displacements ({purpose})")
    return out.values


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def element_flexibility(adapter: SolverAdapter, members: dict[int, tuple[int, int]],
                        log: list[RunRecord], deck: str = "elements") -> dict[int, np.ndarray]:
    """Every member's tip flexibility ``F_bb`` (6 x 6: displacement at ``grid_b`` per unit load
    there, global axes) from ONE run of six load cases.

    ``members[eid] = (grid_a, grid_b)`` in the adapter's element deck, where every member has its
    own two grids, is clamped at ``grid_a`` and nothing else connects it
    (:func:`blackbox.diagnosis.decks.element_deck`): the members are separate structures in one
    deck. Case ``c`` (1..6) therefore puts a unit load on component ``c`` at ``grid_b`` of EVERY
    member at once, and member ``i``'s column ``c`` of ``F_bb`` is the response at its own
    ``grid_b``: six right-hand sides and a ``6 m x 6`` answer for ``m`` members, the same
    numbers as one unit load per DOF (``6 m`` cases, a dense ``6 m x 6 m`` answer whose
    off-diagonal blocks are zero)."""
    ends = [gb for _, gb in members.values()]
    dofs = [(gb, c) for gb in ends for c in range(1, 7)]
    rows = np.arange(len(dofs))
    loads = LoadMatrix(tuple(dofs), sp.csc_matrix((np.ones(len(dofs)), (rows, rows % 6)), shape=(len(dofs), 6)),
                       tuple(f"tip:{c}" for c in range(1, 7)))
    V = solve(adapter, loads, dofs, "element stiffness", deck, log)
    return {eid: V[6 * i:6 * i + 6, :] for i, eid in enumerate(members)}


def element_stiffness(adapter: SolverAdapter, members: dict[int, tuple[int, int]],
                      log: list[RunRecord], deck: str = "elements",
                      tips: dict[int, np.ndarray] | None = None) -> tuple[dict[int, np.ndarray], float]:
    """``K_e`` (12 x 12, global axes, DOFs ``a1..a6, b1..b6``) of every member from ONE run.

    ``members[eid] = (grid_a, grid_b)`` in the adapter's element deck, where each member is alone
    and clamped at ``grid_a``. Unit loads at ``grid_b`` give ``F_bb`` (:func:`element_flexibility`:
    six load cases for all members); the member's stiffness with its six rigid-body modes is
    ``T^T F_bb^-1 T``, ``T = [-Gamma, I]``, ``Gamma = [[I, -[r x]], [0, I]]`` (``r = x_b - x_a``).
    ``tips[eid]``: grounded springs (6 components) that hold end b of a member pinned at an end
    (:func:`blackbox.diagnosis.decks.element_deck`); the run then gives ``(K_bb + diag(k))^-1``,
    and ``diag(k)`` is subtracted. Returns the matrices and the largest relative asymmetry of ``F_bb`` (Maxwell-Betti check of
    the run).
    """
    flex = element_flexibility(adapter, members, log, deck)
    xyz = adapter.grid_xyz()
    out, asym = {}, 0.0
    for eid, (ga, gb) in members.items():
        F = flex[eid]
        asym = max(asym, float(np.max(np.abs(F - F.T)) / max(np.max(np.abs(F)), 1e-300)))
        K_bb = np.linalg.inv(0.5 * (F + F.T))
        if tips and eid in tips:
            K_bb = K_bb - np.diag(tips[eid])
        r = np.subtract(xyz[gb], xyz[ga])
        gamma = np.eye(6)
        gamma[:3, 3:] = -_skew(r)
        T = np.hstack([-gamma, np.eye(6)])
        K = T.T @ K_bb @ T
        out[eid] = 0.5 * (K + K.T)
    return out, asym
