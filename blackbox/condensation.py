"""Black-box static condensation (Sections 3.3-3.5, eq. 10-18).

One batched adapter call with ``n_B + L`` right-hand sides gives everything:

* unit loads at the boundary DOFs B (Fig. 3.2) -> the condensed flexibility ``G_BB = K_R^-1``
  (eq. 15) and, by superposition, ``G_OB``: the response at any other observed DOF O
  (measurements away from the joint, recovery of the whole field) to those unit loads;
* the actual loads (Fig. 3.3) -> ``U_B0``, ``U_O0``: the response of the super-element alone.
  The reduced loads of eq. 14 are ``F_R = K_R U_B0``.

The joint matrices ``K_J`` are then added in the condensed space (eq. 22). Following the
flexibility form (docs/mystran.md: a 7-digit flexibility should not be inverted), with
``dK = K_J(k) - K_deck`` (``K_deck``: joint springs already in the deck, ``deck_stiffness``):

    (K_R + dK) U_B = F_R   <=>   (I + G_BB dK) U_B = U_B0                   (eq. 22, 30)
    U_O = U_O0 - G_OB dK U_B                                                 (superposition)
    (I + G_BB dK) U_B' = -G_BB K_J' U_B                                      (eq. 18)
    U_O' = -G_OB (K_J' U_B + dK U_B')

No solver run is needed after the first one: that is the point of the method.

**Reference springs** (a joint that is the structure's only support). The unit loads need
``K_R`` to be invertible: the structure with its joints released must stand on its own. A
column whose base is a joint (footing grid clamped, column base grid tied to it in translation)
does not: released, the column turns freely about its base. Then ``condense(..., springs=K_ref)``
runs the solver on the deck with scalar springs ``K_ref`` added across the joints
(``SolverAdapter.with_springs``); it returns ``G~ = (K_R + K_ref)^-1`` and ``U~_B0 = G~ F_R``, and
records the springs (:attr:`Condensed.added_springs`). The springs are then carried exactly as
springs the deck already had, ``K_deck = K_ref``::

    (K_R + K_J) U_B = F_R  <=>  (K_R + K_ref + (K_J - K_ref)) U_B = F_R
                           <=>  (I + G~ (K_J - K_ref)) U_B = U~_B0
    U_O = U~_O0 - G~_OB (K_J - K_ref) U_B

which is exact whatever ``K_ref`` is, provided ``K_R + K_ref`` is invertible (the solver could
run) -- ``K_R`` alone may be singular; ``K_R + K_J`` must not be (a joint of zero stiffness
leaves the mechanism, and the condensed system says so by becoming singular). In floating point,
the flexibility ``G~`` carries the solver's relative precision; ``K_ref`` of the order of the
joint's own stiffness (the study's ``initial``) keeps ``I + G~ (K_J - K_ref)`` as well conditioned
as ``K_J / K_ref``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from solver_adapters.protocol import Displacements, DofLabel, LoadMatrix, ScalarSpring, SolverAdapter


class JointLike(Protocol):
    """What condensation needs from a joint model (see ``blackbox.joints``)."""
    name: str
    dofs: tuple[DofLabel, ...]
    n_params: int
    param_names: tuple[str, ...]

    def matrix(self, k: np.ndarray) -> np.ndarray: ...
    def derivatives(self, k: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Condensed:
    """What the one batched solver run returned (frozen: the identification only reads it)."""
    boundary: tuple[DofLabel, ...]          # B
    observed: tuple[DofLabel, ...]          # O (disjoint from B)
    cases: tuple[str, ...]
    G_BB: np.ndarray                        # K_R^-1, (n_B, n_B), symmetrized
    G_OB: np.ndarray                        # (n_O, n_B)
    U_B0: np.ndarray                        # (n_B, L)
    U_O0: np.ndarray                        # (n_O, L)
    symmetry_error: float                   # max |G_BB - G_BB^T| / max |G_BB| (Maxwell-Betti check)
    solver_runs: int
    right_hand_sides: int
    wall_s: float
    added_springs: tuple[ScalarSpring, ...] = ()
    """Springs the condensation added to the solver's deck (reference springs, module docstring):
    ``G_BB`` and ``U_B0`` are those of the deck with them; :meth:`added_stiffness` gives their
    matrix for ``K_deck``."""

    def added_stiffness(self) -> np.ndarray | None:
        """The added springs' stiffness over ``boundary`` (``None`` without any). A spring must
        join two boundary DOFs (or one and the ground): only then is it exactly accounted for."""
        if not self.added_springs:
            return None
        index = {d: i for i, d in enumerate(self.boundary)}
        K = np.zeros((len(self.boundary), len(self.boundary)))
        for s in self.added_springs:
            ends = [s.a] + ([s.b] if s.b is not None else [])
            missing = [e for e in ends if (int(e[0]), int(e[1])) not in index]
            if missing:
                raise ValueError(f"added spring between {s.a} and {s.b}: DOF(s) {missing} are not boundary "
                                 f"DOFs of the condensation, so the spring cannot be accounted for")
            a = index[(int(s.a[0]), int(s.a[1]))]
            K[a, a] += s.k
            if s.b is not None:
                b = index[(int(s.b[0]), int(s.b[1]))]
                K[b, b] += s.k
                K[a, b] -= s.k
                K[b, a] -= s.k
        return K

    @property
    def K_R(self) -> np.ndarray:
        """Condensed stiffness (eq. 13), by inversion of the flexibility; for reports and eq. 25."""
        return np.linalg.inv(self.G_BB)

    @property
    def F_R(self) -> np.ndarray:
        """Reduced loads (eq. 14) ``F_R = K_R U_B0``."""
        return np.linalg.solve(self.G_BB, self.U_B0)


def condense(adapter: SolverAdapter, loads: LoadMatrix, boundary: Sequence[DofLabel],
             observed: Sequence[DofLabel] = (), springs: Sequence[ScalarSpring] = ()) -> Condensed:
    """Run the adapter once with unit loads at ``boundary`` and the actual ``loads`` (Sec. 3.4);
    with ``springs``, on the deck with those springs added (reference springs, module docstring)."""
    boundary = tuple(dict.fromkeys((int(g), int(c)) for g, c in boundary))
    bset = set(boundary)
    observed = tuple(d for d in dict.fromkeys((int(g), int(c)) for g, c in observed) if d not in bset)
    springs = tuple(springs)
    solver = adapter.with_springs(springs) if springs else adapter
    batch = LoadMatrix.unit(boundary).hstack(loads)
    runs0, rhs0 = solver.stats.runs, solver.stats.right_hand_sides
    t0 = time.perf_counter()
    out: Displacements = solver.solve(batch, boundary + observed)
    wall = time.perf_counter() - t0
    nB = len(boundary)
    V = out.values
    G = V[:nB, :nB]
    scale = np.max(np.abs(G)) or 1.0
    sym_err = float(np.max(np.abs(G - G.T)) / scale)
    return Condensed(boundary=boundary, observed=observed, cases=loads.cases,
                     G_BB=0.5 * (G + G.T), G_OB=V[nB:, :nB], U_B0=V[:nB, nB:], U_O0=V[nB:, nB:],
                     symmetry_error=sym_err, solver_runs=solver.stats.runs - runs0,
                     right_hand_sides=solver.stats.right_hand_sides - rhs0, wall_s=wall,
                     added_springs=springs)


class JointAssembly:
    """Several joints on one boundary: scatter each ``K_J`` into the ``n_B x n_B`` space.

    The parameter vector is the concatenation of the joints' parameters, in joint order.
    """

    def __init__(self, joints: Sequence[JointLike], boundary: Sequence[DofLabel]):
        self.joints = tuple(joints)
        index = {d: i for i, d in enumerate(boundary)}
        missing = [d for j in self.joints for d in j.dofs if d not in index]
        if missing:
            raise ValueError(f"joint DOFs {missing[:6]} are not boundary DOFs")
        self.n_B = len(boundary)
        self._idx = [np.array([index[d] for d in j.dofs]) for j in self.joints]
        self.slices = []
        start = 0
        for j in self.joints:
            self.slices.append(slice(start, start + j.n_params))
            start += j.n_params
        self.n_params = start
        self.param_names = tuple(n for j in self.joints for n in j.param_names)
        self.param_joint = tuple(j.name for j in self.joints for _ in j.param_names)

    def matrix(self, k: np.ndarray) -> np.ndarray:
        K = np.zeros((self.n_B, self.n_B))
        for j, idx, sl in zip(self.joints, self._idx, self.slices):
            K[np.ix_(idx, idx)] += j.matrix(np.asarray(k, float)[sl])
        return K

    def derivatives(self, k: np.ndarray) -> np.ndarray:
        D = np.zeros((self.n_params, self.n_B, self.n_B))
        for j, idx, sl in zip(self.joints, self._idx, self.slices):
            D[sl][:, idx[:, None], idx[None, :]] = j.derivatives(np.asarray(k, float)[sl])
        return D


@dataclass(frozen=True)
class Response:
    """Predicted response with the joints added: at B and at O, every case."""
    U_B: np.ndarray
    U_O: np.ndarray


class CondensedModel:
    """The structure condensed to B plus joint models: predictions and eq. 18 sensitivities."""

    def __init__(self, condensed: Condensed, joints: Sequence[JointLike],
                 K_deck: np.ndarray | None = None):
        self.c = condensed
        self.assembly = JointAssembly(joints, condensed.boundary)
        nB = len(condensed.boundary)
        self.K_deck = np.zeros((nB, nB)) if K_deck is None else np.asarray(K_deck, float)
        self._row = {d: ("B", i) for i, d in enumerate(condensed.boundary)}
        self._row.update({d: ("O", i) for i, d in enumerate(condensed.observed)})

    @property
    def n_params(self) -> int:
        return self.assembly.n_params

    def _A(self, dK: np.ndarray) -> np.ndarray:
        return np.eye(dK.shape[0]) + self.c.G_BB @ dK

    def response(self, k: np.ndarray) -> Response:
        """Eq. 22/30 in flexibility form."""
        dK = self.assembly.matrix(k) - self.K_deck
        U_B = np.linalg.solve(self._A(dK), self.c.U_B0)
        U_O = self.c.U_O0 - self.c.G_OB @ (dK @ U_B)
        return Response(U_B, U_O)

    def sensitivities(self, k: np.ndarray, response: Response | None = None,
                      D: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Direct method in the condensed space (eq. 18): ``(dU_B/dk, dU_O/dk)``,
        shapes ``(n_params, n_B, L)`` and ``(n_params, n_O, L)``. No solver run.

        ``D`` overrides the exact ``dK_J/dk`` (the semi-analytic scheme of Section 3.2.4)."""
        r = self.response(k) if response is None else response
        dK = self.assembly.matrix(k) - self.K_deck
        D = self.assembly.derivatives(k) if D is None else D
        A = self._A(dK)
        rhs = -np.einsum("ij,pjk,kl->pil", self.c.G_BB, D, r.U_B)       # -G_BB K_J' U_B
        dU_B = np.linalg.solve(A[None], rhs)
        dU_O = -np.einsum("oj,pjl->pol", self.c.G_OB, np.einsum("pij,jl->pil", D, r.U_B)
                          + np.einsum("ij,pjl->pil", dK, dU_B))
        return dU_B, dU_O

    # -- selection of measured quantities -------------------------------------------------------
    def locate(self, dofs: Sequence[DofLabel]) -> list[tuple[str, int]]:
        """Where each DOF label lives: ``("B", i)`` or ``("O", i)``; KeyError names the label."""
        out = []
        for d in dofs:
            key = (int(d[0]), int(d[1]))
            if key not in self._row:
                raise KeyError(f"DOF {key} was neither a boundary nor an observed DOF of the condensation")
            out.append(self._row[key])
        return out

    def pick(self, r: Response, dofs: Sequence[DofLabel]) -> np.ndarray:
        """Rows of the response at ``dofs``, shape ``(len(dofs), L)``."""
        return np.stack([(r.U_B if s == "B" else r.U_O)[i] for s, i in self.locate(dofs)]) \
            if len(dofs) else np.zeros((0, len(self.c.cases)))

    def pick_sensitivities(self, sens: tuple[np.ndarray, np.ndarray], dofs: Sequence[DofLabel]) -> np.ndarray:
        """``(n_params, len(dofs), L)`` rows of the sensitivities at ``dofs``."""
        dB, dO = sens
        return np.stack([(dB if s == "B" else dO)[:, i] for s, i in self.locate(dofs)], axis=1)
