"""The split structure: one batched run of the split deck, conditioned on its rigid state.

The split deck (:mod:`blackbox.diagnosis.decks`) is the study's deck with every connection a
candidate could make flexible cut, the two sides of each cut ("pair" ``i``: DOF ``a_i`` and DOF
``b_i`` or ground) joined by a moderate scalar spring ``K0_i`` (the order of the members' own
stiffness there). One batched run with unit *pair* loads (+1 at ``a_i``, -1 at ``b_i``), unit
loads at the joint boundary ``B`` and the measured DOFs ``O`` and the study's load cases gives the
split structure's flexibility ``G'`` and load response ``U0'``.

*Rigid state = the declared model, exactly.* With ``P`` the pair-difference operator,
``Z = G' P^T``, ``S = P Z`` (SPD) and ``Y = Z S^-1``::

    G_rigid = G' - Y P G'        U_rigid = U0' - Y lam,  lam = S^-1 P U0'

(conditioning on ``P u = 0``). Releasing the pairs ``a`` only (the others stay rigid), with
``Q = S^-1``: ``G~ = G_rigid + Y_a Q_aa^-1 Y_a^T``, ``Z~ = Y_a Q_aa^-1``, ``S~ = Q_aa^-1``,
``u~0 = U_rigid + Y_a Q_aa^-1 lam_a``: the structure with the ``a`` pairs on their ``K0`` springs
(:class:`Conditioned`, what :class:`blackbox.diagnosis.model.AugmentedModel` builds on).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from blackbox.diagnosis.runs import RunRecord, solve
from blackbox.errors import IdentificationError
from solver_adapters.protocol import DofLabel, LoadMatrix, SolverAdapter

__all__ = ["Pair", "SplitBase", "Conditioned"]


@dataclass(frozen=True)
class Pair:
    """A cut connection: DOF ``a`` and DOF ``b`` (``None``: ground), joined by ``k0`` in the split deck."""
    a: DofLabel
    b: DofLabel | None
    k0: float


def _pair_loads(pairs: Sequence[Pair]) -> LoadMatrix:
    dofs = list(dict.fromkeys([p.a for p in pairs] + [p.b for p in pairs if p.b is not None]))
    index = {d: i for i, d in enumerate(dofs)}
    rows, cols, vals = [], [], []
    for j, p in enumerate(pairs):
        rows.append(index[p.a]); cols.append(j); vals.append(1.0)
        if p.b is not None:
            rows.append(index[p.b]); cols.append(j); vals.append(-1.0)
    M = sp.csc_matrix((vals, (rows, cols)), shape=(len(dofs), len(pairs)))
    return LoadMatrix(tuple(dofs), M, tuple(f"pair:{j}" for j in range(len(pairs))))


class Conditioned:
    """The split structure with the pairs ``a`` on their K0 springs and every other pair rigid."""

    def __init__(self, base: "SplitBase", a: np.ndarray):
        self.base, self.a = base, a
        if a.size:
            Q_aa = base.Q[np.ix_(a, a)]
            self.St = np.linalg.inv(0.5 * (Q_aa + Q_aa.T))          # P_a G~ P_a^T = Q_aa^-1
            self.St = 0.5 * (self.St + self.St.T)
            self._lam = base.lam[a]
            self.dt0 = self.St @ self._lam
        else:
            self.St = np.zeros((0, 0))
            self.dt0 = np.zeros((0, base.n_cases))

    def _Ya(self, rows: Sequence[DofLabel]) -> np.ndarray:
        return self.base.Y[np.ix_(self.base.row_index(rows), self.a)]

    def Z(self, rows: Sequence[DofLabel]) -> np.ndarray:
        """``G~ P_a^T`` at ``rows``."""
        return self._Ya(rows) @ self.St if self.a.size else np.zeros((len(rows), 0))

    def u0(self, rows: Sequence[DofLabel]) -> np.ndarray:
        U = self.base.U_rigid[self.base.row_index(rows)]
        return U + self._Ya(rows) @ self.dt0 if self.a.size else U

    def G(self, rows: Sequence[DofLabel], cols: Sequence[DofLabel]) -> np.ndarray:
        """``G~[rows, cols]``: by columns when loaded, else by symmetry from loaded rows."""
        b = self.base
        if not all(c in b.col_of for c in cols):
            if all(r in b.col_of for r in rows):
                return self.G(cols, rows).T
            missing = [c for c in cols if c not in b.col_of][:6]
            raise IdentificationError(f"flexibility columns {missing} were not loaded in the split run")
        Gr = b.G_rigid[np.ix_(b.row_index(rows), [b.col_of[c] for c in cols])]
        if self.a.size:
            Gr = Gr + self._Ya(rows) @ self.St @ self._Ya(cols).T
        return Gr


class SplitBase:
    """One batched run of the split deck, conditioned on the rigid state (module docstring).

    ``unit_dofs``: DOFs loaded one by one (joint boundary, measured DOFs); ``report``: every DOF
    whose displacement may be needed (pairs, boundary, measured, member ends). More unit-load
    columns can be added later with :meth:`ensure_columns` (one batched run).
    """

    def __init__(self, adapter: SolverAdapter, loads: LoadMatrix, pairs: Sequence[Pair],
                 unit_dofs: Sequence[DofLabel], report: Sequence[DofLabel], log: list[RunRecord],
                 deck: str = "split"):
        self.adapter, self.pairs, self.log, self.deck = adapter, tuple(pairs), log, deck
        self.cases = loads.cases
        self.n_cases = loads.n_cases
        pair_dofs = [p.a for p in pairs] + [p.b for p in pairs if p.b is not None]
        self.rows = tuple(dict.fromkeys(list(report) + pair_dofs + list(unit_dofs)))
        self._row = {d: i for i, d in enumerate(self.rows)}
        unit_dofs = tuple(dict.fromkeys(unit_dofs))
        m = len(pairs)
        batch = loads
        if m:
            batch = _pair_loads(pairs).hstack(batch)
        if unit_dofs:
            batch = LoadMatrix.unit(unit_dofs).hstack(batch)
        V = solve(adapter, batch, self.rows, "split structure: unit, pair and study loads", deck, log)
        nU = len(unit_dofs)
        self.G_split = V[:, :nU]                      # G'[R, unit columns]
        Zfull = V[:, nU:nU + m]                       # G' P^T
        self.U0 = V[:, nU + m:]
        self.col_of = {d: j for j, d in enumerate(unit_dofs)}
        self.m = m
        ia = np.array([self._row[p.a] for p in pairs], dtype=int)
        ib = np.array([self._row[p.b] if p.b is not None else -1 for p in pairs], dtype=int)
        self._ia, self._ib = ia, ib
        if m:
            S = self.P(Zfull)
            self.symmetry_error = float(np.max(np.abs(S - S.T)) / max(np.max(np.abs(S)), 1e-300))
            S = 0.5 * (S + S.T)
            self._cho = sla.cho_factor(S)
            self.Q = sla.cho_solve(self._cho, np.eye(m))
            self.Q = 0.5 * (self.Q + self.Q.T)
            self.Y = Zfull @ self.Q
            self.lam = self.Q @ self.P(self.U0)
            self.U_rigid = self.U0 - Zfull @ self.lam
            self.G_rigid = self.G_split - self.Y @ self.P(self.G_split)
            w = np.linalg.eigvalsh(S)                # S is SPD: cond = largest / smallest eigenvalue
            self.condition = float(w[-1] / w[0])
        else:
            self.symmetry_error, self.condition = 0.0, 1.0
            self.Q = np.zeros((0, 0))
            self.Y = np.zeros((len(self.rows), 0))
            self.lam = np.zeros((0, self.n_cases))
            self.U_rigid = self.U0
            self.G_rigid = self.G_split
        self._Z = Zfull

    def P(self, M: np.ndarray) -> np.ndarray:
        """Pair differences of the rows of ``M`` (rows indexed like :attr:`rows`)."""
        out = M[self._ia].copy()
        g = self._ib >= 0
        out[g] -= M[self._ib[g]]
        return out

    def row_index(self, dofs: Sequence[DofLabel]) -> np.ndarray:
        try:
            return np.array([self._row[tuple(d)] for d in dofs], dtype=int)
        except KeyError as exc:
            raise IdentificationError(f"DOF {exc.args[0]} was not reported by the split run") from None

    def has_rows(self, dofs: Sequence[DofLabel]) -> bool:
        return all(tuple(d) in self._row for d in dofs)

    def ensure_columns(self, dofs: Sequence[DofLabel], purpose: str) -> int:
        """Unit-load columns at ``dofs`` not loaded yet: one batched run. Returns the number added."""
        new = [d for d in dict.fromkeys(tuple(x) for x in dofs) if d not in self.col_of]
        if not new:
            return 0
        if self.adapter is None:
            raise IdentificationError(f"{purpose}: a detached split base cannot run the split deck")
        V = solve(self.adapter, LoadMatrix.unit(new), self.rows, purpose, self.deck, self.log)
        start = self.G_split.shape[1]
        self.G_split = np.hstack([self.G_split, V])
        self.G_rigid = np.hstack([self.G_rigid, V - self.Y @ self.P(V) if self.m else V])
        for j, d in enumerate(new):
            self.col_of[d] = start + j
        return len(new)

    def conditioned(self, a: Sequence[int]) -> Conditioned:
        return Conditioned(self, np.asarray(list(a), dtype=int))

    def detached_nbytes(self) -> int:
        """The size of :meth:`detached`'s arrays (what a task on another process receives)."""
        return sum(int(getattr(self, k).nbytes) for k in ("G_rigid", "Y", "Q", "lam", "U_rigid"))

    def detached(self) -> "SplitBase":
        """A copy with what models evaluate on it (the rigid state, ``Q``, ``Y``, the rows and
        columns; the arrays shared, not copied) and without the adapter, the run log and the
        split run's raw answer: what a task on another process needs, a fraction of the size.
        :meth:`ensure_columns` on it is an error."""
        twin = object.__new__(SplitBase)
        twin.__dict__.update(self.__dict__)
        twin.adapter, twin.log = None, []
        twin.G_split = twin._Z = twin.U0 = twin._cho = None
        return twin
