"""Batched solver runs of a diagnosis, and each member's stiffness from the element deck's run.

Every run goes through :func:`solve`, which keeps a :class:`RunRecord` (what for, which deck, how
many right-hand sides, how long) and rejects non-finite answers. :func:`element_stiffness` turns
one run of the element deck (every member alone, clamped at end a) into the members' 12 x 12
stiffness matrices: the solver's own element, whatever its beam theory.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from blackbox.errors import IdentificationError
from solver_adapters.protocol import DofLabel, LoadMatrix, SolverAdapter

__all__ = ["RunRecord", "solve", "element_stiffness"]


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


def element_stiffness(adapter: SolverAdapter, members: dict[int, tuple[int, int]],
                      log: list[RunRecord], deck: str = "elements") -> tuple[dict[int, np.ndarray], float]:
    """``K_e`` (12 x 12, global axes, DOFs ``a1..a6, b1..b6``) of every member from ONE run.

    ``members[eid] = (grid_a, grid_b)`` in the adapter's element deck, where each member is alone
    and clamped at ``grid_a``. Unit loads at ``grid_b`` give ``F_bb``; the member's stiffness with
    its six rigid-body modes is ``T^T F_bb^-1 T``, ``T = [-Gamma, I]``, ``Gamma = [[I, -[r x]], [0, I]]``
    (``r = x_b - x_a``). Returns the matrices and the largest relative asymmetry of ``F_bb``
    (Maxwell-Betti check of the run).
    """
    dofs = [(gb, c) for _, gb in members.values() for c in range(1, 7)]
    V = solve(adapter, LoadMatrix.unit(dofs), dofs, "element stiffness", deck, log)
    xyz = adapter.grid_xyz()
    out, asym = {}, 0.0
    for i, (eid, (ga, gb)) in enumerate(members.items()):
        F = V[6 * i:6 * i + 6, 6 * i:6 * i + 6]
        asym = max(asym, float(np.max(np.abs(F - F.T)) / max(np.max(np.abs(F)), 1e-300)))
        K_bb = np.linalg.inv(0.5 * (F + F.T))
        r = np.subtract(xyz[gb], xyz[ga])
        gamma = np.eye(6)
        gamma[:3, 3:] = -_skew(r)
        T = np.hstack([-gamma, np.eye(6)])
        K = T.T @ K_bb @ T
        out[eid] = 0.5 * (K + K.T)
    return out, asym
