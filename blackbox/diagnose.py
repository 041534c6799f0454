"""Diagnosis of a declared model (issue 6): find what it lacks, add it, report before and after.

The loop: fit the declared model; test the standardized residuals against the declared noise
(chi-square band, structure per case / grid / component); score a library of candidate effects
(a few extra parameters each, nested in the declared model at a known value) against the
residual; refit the best few; add the best one if it is significant after a Bonferroni
correction over every candidate scored, improves BIC and does not spoil the prediction of
hold-out cases; repeat until nothing is significant.

Everything happens in condensed spaces of batched solver runs; the solver stays a black box:

**Element run** (:func:`element_stiffness`). A deck with every member alone, clamped at end a,
unit loads at end b: ``F_bb`` (6 x 6) per member, ``K_e = T^T F_bb^-1 T`` with ``T = [-Gamma, I]``
(``Gamma``: rigid-body transfer a -> b). The solver's own element, whatever its beam theory.

**Split run** (:class:`SplitBase`). An edited deck in which every connection a candidate could
make flexible -- a support component, a declared joint's RBE2 translation tie, the rotations of
the members meeting at a grid -- is cut, and the two sides of each cut ("pair" ``i``: DOF ``a_i``
and DOF ``b_i`` or ground) are joined by a moderate scalar spring ``K0_i`` (the order of the
members' own stiffness there). One batched run with unit *pair* loads (+1 at ``a_i``, -1 at
``b_i``), unit loads at the joint boundary ``B`` and the measured DOFs ``O`` and the study's load
cases gives the split structure's flexibility ``G'`` and load response ``U0'``.

*Rigid state = the declared model, exactly.* With ``P`` the pair-difference operator,
``Z = G' P^T``, ``S = P Z`` (SPD) and ``Y = Z S^-1``::

    G_rigid = G' - Y P G'        U_rigid = U0' - Y lam,  lam = S^-1 P U0'

(conditioning on ``P u = 0``). Releasing the pairs ``a`` only (the others stay rigid), with
``Q = S^-1``: ``G~ = G_rigid + Y_a Q_aa^-1 Y_a^T``, ``Z~ = Y_a Q_aa^-1``, ``S~ = Q_aa^-1``,
``u~0 = U_rigid + Y_a Q_aa^-1 lam_a``: the structure with the ``a`` pairs on their ``K0`` springs.

*Compliance form.* A released connection has compliance ``D(theta) = sum theta_i D_i`` (``D = 0``
is rigid, the declared state, exactly and well conditioned). Replacing the ``K0`` springs by
``D^-1`` adds a parallel connection of compliance ``(I - D K0)^-1 D`` carrying forces ``f``;
together with the stiffness-form part ``dK = K_J(k) - K_deck + sum (alpha_e - 1) K_e`` on the
DOFs ``S`` (joint boundary plus the ends of members whose stiffness is a parameter)::

    [ I + G~_SS dK              Z~_S           ] [u_S]   [ u~0_S              ]
    [ (I - D K0) Z~_S^T dK      D + (I - D K0) S~] [ f ] = [ (I - D K0) P u~0    ]
    u_O = u~0_O - G~_OS dK u_S - Z~_O f

and by implicit differentiation (``A z = b``): ``dz/dk = -A^-1 [G~_SS dK' u_S; (I - D K0) Z~_S^T dK' u_S]``,
``dz/dtheta_i = -A^-1 [0; D_i (f + K0 delta)]`` with ``delta = P u`` the relative motion of the
pairs (``f + K0 delta`` is the whole force through the connection).

**Output side.** A load scale ``s`` multiplies every response of its cases (linearity); a sensor
gain ``g`` every measurement of its grid. Exact, no run.

**Member stiffness.** ``dK = (alpha - 1) K_e`` on the member's 12 end DOFs. Its score at
``alpha = 1`` needs only rows of the flexibility at the member's DOFs under the unit loads at
``B`` and ``O`` (reciprocity), which the split run reports; its refit needs the member's own
columns, one batched run for every short-listed member of a round.

**Statistics.** Whitened residuals ``r``, Jacobians ``J`` at the current optimum (declared sigma,
Gaussian likelihood; BIC as in ``identify``). Score (Lagrange multiplier) test of a candidate
with Jacobian ``J_c``: ``S = h^T M^+ h`` with ``M = (Pi J_c)^T Pi J_c``, ``h = (Pi J_c)^T Pi r`` and
``Pi`` the projector out of the span of the current model's *free* parameters' columns (a spring
held at its bound 0 leaves its direction to a candidate that can go beyond it, as the complex
model can); for compliances, one-sided, ``S`` is the largest decrease of the linearised chi2 over
the cone ``theta >= 0`` and ``chi2(df)`` a conservative reference; ``df = rank M``. Everything
through Gram matrices of a few columns (a LAPACK SVD of the tall Jacobian costs 100x more with a
threaded BLAS). The ``refit_top`` best by ``p`` are refitted (Levenberg-Marquardt with bounds,
two or three starts: the nested point, the score step, a moderate compliance); connection
parameters that end at 0 are dropped (that part stays rigid). A candidate is *accepted* when its
likelihood-ratio p-value times the number of candidates scored (Bonferroni) is below ``alpha``,
BIC improves, and the hold-out chi2 does not grow by more than its number of parameters (the
effect must improve prediction, not only the fit); the accepted one with the lowest BIC is added.
The loop stops when no candidate is accepted: a candidate that is significant after the
correction is still added when the overall reduced chi2 is already inside its 99 % band (the
band is a weak omnibus test; a localised effect is found by the targeted score first), and with
no effect present the Bonferroni level bounds the chance of a false addition per round by
``alpha``.

**Cost.** Runs: one condensation of the study's deck (the declared fit), one element run, one
split run, plus one split run per round in which a member is short-listed. Right-hand sides:
``6 x members`` (element run) and ``n_B + n_O + pairs + L`` (split run). The loop itself needs no
solver: the car fixture (115 members, 459 cut pairs, 234 candidates) diagnoses in ~2 s.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy import optimize, stats

from blackbox.condensation import JointAssembly
from blackbox.errors import IdentificationError
from blackbox.identification import Observations
from blackbox.joints import ComplexJoint, JointModel, SimpleJoint, simple_to_complex_params
from solver_adapters.protocol import DofLabel, LoadMatrix, SolverAdapter

__all__ = ["EFFECTS", "RunRecord", "element_stiffness", "Pair", "SplitBase", "Effect", "ModelSpec",
           "AugmentedModel", "Fit", "fit_model", "CandidateScore", "score_candidates",
           "residual_structure", "Step", "Diagnosis", "diagnose", "chi2_band", "default_holdout"]

EFFECTS = ("joint_coupling", "joint_translation", "undeclared_joint", "support_flexibility",
           "load_scale", "sensor_gain", "member_stiffness")
CONNECTION_KINDS = ("joint_translation", "undeclared_joint", "support_flexibility")
_THETA_MAX = 1e4            # a compliance parameter: connection >= 1e-4 K0 (a free cut is a mechanism)
_AT_BOUND = 1e-7            # theta below this after a refit: the connection is rigid (parameter dropped)
_GRAM_RTOL = 1e-12          # Gram eigenvalues below this x the largest (column-scaled): rank loss
_SCORE_RTOL = 1e-8          # a candidate direction whose part outside the model's span is below
                            # 1e-4 of its own size (eigenvalue 1e-8) adds nothing (rounding)
_BAD_RESIDUAL = 1e6         # whitened residual returned for a singular trial point (rejected by TRF)


# --------------------------------------------------------------------------------------------
# solver runs
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunRecord:
    """One batched solver run: what for, on which deck, how many right-hand sides, how long."""
    purpose: str
    deck: str
    right_hand_sides: int
    wall_s: float


def _run(adapter: SolverAdapter, loads: LoadMatrix, report: Sequence[DofLabel], purpose: str,
         deck: str, log: list[RunRecord]) -> np.ndarray:
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
    V = _run(adapter, LoadMatrix.unit(dofs), dofs, "element stiffness", deck, log)
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


# --------------------------------------------------------------------------------------------
# the split structure and its rigid state
# --------------------------------------------------------------------------------------------
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


class _Conditioned:
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
        V = _run(adapter, batch, self.rows, "split structure: unit, pair and study loads", deck, log)
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
            self.condition = float(np.linalg.cond(S))
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
        V = _run(self.adapter, LoadMatrix.unit(new), self.rows, purpose, self.deck, self.log)
        start = self.G_split.shape[1]
        self.G_split = np.hstack([self.G_split, V])
        self.G_rigid = np.hstack([self.G_rigid, V - self.Y @ self.P(V) if self.m else V])
        for j, d in enumerate(new):
            self.col_of[d] = start + j
        return len(new)

    def conditioned(self, a: Sequence[int]) -> _Conditioned:
        return _Conditioned(self, np.asarray(list(a), dtype=int))


# --------------------------------------------------------------------------------------------
# effects and model specifications
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Effect:
    """A candidate effect: a few parameters nested in the declared model at ``nominal``.

    By ``kind``: connections (``joint_translation``, ``undeclared_joint``, ``support_flexibility``)
    use ``pairs`` (indices into :attr:`SplitBase.pairs`) and ``basis`` (``(p, m, m)`` compliance per
    unit parameter, pair coordinates); ``k_ref[i] / theta_i`` is parameter ``i``'s stiffness.
    ``member_stiffness``: ``dofs`` (12, split deck) and ``K_e``. ``load_scale``: ``cases``
    (indices of the condensed cases). ``sensor_gain``: ``grid``. ``joint_coupling``: ``joint``
    (its parameters are the joint's complex-model ones).
    """
    kind: str
    where: tuple
    names: tuple[str, ...] = ()
    pairs: tuple[int, ...] = ()
    basis: np.ndarray | None = None
    k_ref: np.ndarray | None = None
    dofs: tuple[DofLabel, ...] = ()
    K_e: np.ndarray | None = None
    cases: tuple[int, ...] = ()
    grid: int | None = None
    joint: str | None = None

    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where))

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def nominal(self) -> np.ndarray:
        return np.full(self.n_params, 0.0 if self.kind in CONNECTION_KINDS else 1.0)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n_params
        if self.kind in CONNECTION_KINDS:
            return np.zeros(n), np.full(n, _THETA_MAX)
        if self.kind == "member_stiffness":
            return np.full(n, 0.02), np.full(n, 50.0)
        return np.full(n, 0.2), np.full(n, 5.0)

    @property
    def one_sided(self) -> np.ndarray:
        return np.full(self.n_params, self.kind in CONNECTION_KINDS)

    def label(self) -> str:
        return f"{self.kind} @ {', '.join(map(str, self.where))}"

    def keep(self, mask: np.ndarray) -> "Effect":
        """The effect with only the parameters in ``mask`` (connections whose compliance went to 0)."""
        mask = np.asarray(mask, bool)
        return replace(self, names=tuple(n for n, k in zip(self.names, mask) if k),
                       basis=None if self.basis is None else self.basis[mask],
                       k_ref=None if self.k_ref is None else self.k_ref[mask])


@dataclass(frozen=True, eq=False)
class ModelSpec:
    """Joint models (declared or coupled) plus the effects added so far; parameter order:
    the joints' parameters, then each effect's."""
    joints: tuple[JointModel, ...]
    effects: tuple[Effect, ...] = ()

    @property
    def joint_params(self) -> int:
        return sum(j.n_params for j in self.joints)

    @property
    def n_params(self) -> int:
        return self.joint_params + sum(e.n_params for e in self.effects)

    @property
    def names(self) -> tuple[str, ...]:
        return (tuple(f"{j.name}.{n}" for j in self.joints for n in j.param_names)
                + tuple(n for e in self.effects for n in e.names))

    def effect_slices(self) -> list[slice]:
        out, i = [], self.joint_params
        for e in self.effects:
            out.append(slice(i, i + e.n_params))
            i += e.n_params
        return out

    def joint_slices(self) -> list[slice]:
        out, i = [], 0
        for j in self.joints:
            out.append(slice(i, i + j.n_params))
            i += j.n_params
        return out

    def has(self, effect: Effect) -> bool:
        return any(e.key == effect.key for e in self.effects)

    def add(self, effect: Effect, x: np.ndarray) -> tuple["ModelSpec", np.ndarray]:
        """The specification with ``effect`` added and ``x`` extended at the nested point."""
        if effect.kind == "joint_coupling":
            joints, parts = [], []
            for j, sl in zip(self.joints, self.joint_slices()):
                if j.name == effect.joint and isinstance(j, SimpleJoint):
                    cj = ComplexJoint(j.name, j.grids)
                    joints.append(cj)
                    parts.append(simple_to_complex_params(j, x[sl]))
                else:
                    joints.append(j)
                    parts.append(x[sl])
            return (ModelSpec(tuple(joints), self.effects + (effect,)),
                    np.concatenate(parts + [x[self.joint_params:]]))
        return ModelSpec(self.joints, self.effects + (effect,)), np.concatenate([x, effect.nominal])

    def replace_effect(self, i: int, effect: Effect) -> "ModelSpec":
        eff = list(self.effects)
        eff[i] = effect
        return ModelSpec(self.joints, tuple(eff))

    def transforms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(one_sided, lower, upper)``: simple-model springs ``>= 0``, complex-model entries free
        (``K_C`` positive definiteness is checked on the result), effects within
        :attr:`Effect.bounds`; ``one_sided``: parameters whose nested value is a bound."""
        one = np.zeros(self.n_params, bool)
        lo = np.full(self.n_params, -np.inf)
        hi = np.full(self.n_params, np.inf)
        for j, sl in zip(self.joints, self.joint_slices()):
            if isinstance(j, SimpleJoint):
                lo[sl] = 0.0
        for e, sl in zip(self.effects, self.effect_slices()):
            lo[sl], hi[sl] = e.bounds
            one[sl] = e.one_sided
        return one, lo, hi


# --------------------------------------------------------------------------------------------
# observations located in the model
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _ObsMap:
    row: np.ndarray         # index into the model's observed DOFs
    ref: np.ndarray         # index of the reference DOF or -1
    case: np.ndarray
    grid: np.ndarray
    y: np.ndarray
    sigma: np.ndarray

    @classmethod
    def of(cls, obs: Observations, o_index: dict) -> "_ObsMap":
        refs = obs.ref_dofs or (None,) * len(obs)
        return cls(np.array([o_index[d] for d in obs.dofs], dtype=int),
                   np.array([-1 if r is None else o_index[r] for r in refs], dtype=int),
                   np.asarray(obs.case_index, int), np.array([d[0] for d in obs.dofs], dtype=int),
                   np.asarray(obs.values, float), np.asarray(obs.sigma, float))

    def pick(self, U: np.ndarray) -> np.ndarray:
        f = U[self.row, self.case]
        has = self.ref >= 0
        if has.any():
            f = f - np.where(has, U[np.maximum(self.ref, 0), self.case], 0.0)
        return f


# --------------------------------------------------------------------------------------------
# the augmented model
# --------------------------------------------------------------------------------------------
@dataclass
class _State:
    dK: np.ndarray
    D: np.ndarray
    Ainv: np.ndarray
    u_S: np.ndarray
    f: np.ndarray
    delta: np.ndarray
    U_O: np.ndarray


class AugmentedModel:
    """Predictions and exact Jacobians of a :class:`ModelSpec` (module docstring, block system)."""

    def __init__(self, base: SplitBase, spec: ModelSpec, boundary: Sequence[DofLabel],
                 K_deck: np.ndarray | None, o_dofs: Sequence[DofLabel]):
        self.base, self.spec = base, spec
        self.o_dofs = tuple(o_dofs)
        members = [e for e in spec.effects if e.kind == "member_stiffness"]
        S = list(dict.fromkeys(list(boundary) + [d for e in members for d in e.dofs]))
        self.S = tuple(S)
        sidx = {d: i for i, d in enumerate(S)}
        nS = len(S)
        self.assembly = JointAssembly(spec.joints, S) if spec.joints else None
        self.K_deck = np.zeros((nS, nS))
        if K_deck is not None:
            bi = np.array([sidx[d] for d in boundary])
            self.K_deck[np.ix_(bi, bi)] = K_deck
        conn = [e for e in spec.effects if e.kind in CONNECTION_KINDS]
        a = [i for e in conn for i in e.pairs]
        if len(set(a)) != len(a):
            raise IdentificationError("two connection effects share a cut pair")
        self.a = np.array(a, dtype=int)
        cond = base.conditioned(self.a)
        self.Gss = cond.G(S, S) if nS else np.zeros((0, 0))
        self.Gos = cond.G(self.o_dofs, S) if nS else np.zeros((len(self.o_dofs), 0))
        self.Zs, self.Zo = cond.Z(S), cond.Z(self.o_dofs)
        self.St, self.dt0 = cond.St, cond.dt0
        self.us0, self.uo0 = cond.u0(S), cond.u0(self.o_dofs)
        self.K0 = np.array([base.pairs[i].k0 for i in a])
        self.cond = cond
        self.nS, self.m = nS, len(a)
        # parameter bookkeeping: structural (joints, members, compliances), then output side
        p = spec.n_params
        self.kind = np.array(["joint"] * spec.joint_params + [e.kind for e in spec.effects for _ in e.names])
        self._member = []           # (param index, S indices, K_e)
        self._basis = []            # (param index, m x m matrix)
        self._scale = []            # (param index, case mask)
        self._gain = []             # (param index, grid)
        off = 0
        for e, sl in zip(spec.effects, spec.effect_slices()):
            if e.kind == "member_stiffness":
                self._member.append((sl.start, np.array([sidx[d] for d in e.dofs]), e.K_e))
            elif e.kind in CONNECTION_KINDS:
                me = len(e.pairs)
                for q in range(e.n_params):
                    Dm = np.zeros((self.m, self.m))
                    Dm[off:off + me, off:off + me] = e.basis[q]
                    self._basis.append((sl.start + q, Dm))
                off += me
            elif e.kind == "load_scale":
                mask = np.zeros(base.n_cases, bool)
                mask[list(e.cases)] = True
                self._scale.append((sl.start, mask))
            elif e.kind == "sensor_gain":
                self._gain.append((sl.start, e.grid))
        self.p = p
        self._jD = self.assembly.derivatives(np.ones(spec.joint_params)) if self.assembly else None

    # ---- the block system ---------------------------------------------------------------------
    def state(self, x: np.ndarray) -> _State:
        x = np.asarray(x, float)
        spec = self.spec
        dK = -self.K_deck.copy()
        if self.assembly is not None:
            dK += self.assembly.matrix(x[:spec.joint_params])
        for i, idx, K_e in self._member:
            dK[np.ix_(idx, idx)] += (x[i] - 1.0) * K_e
        D = np.zeros((self.m, self.m))
        for i, Dm in self._basis:
            D += x[i] * Dm
        nS, m = self.nS, self.m
        IDK = np.eye(m) - D * self.K0[None, :]                      # I - D K0
        A = np.zeros((nS + m, nS + m))
        A[:nS, :nS] = np.eye(nS) + self.Gss @ dK
        A[:nS, nS:] = self.Zs
        A[nS:, :nS] = IDK @ self.Zs.T @ dK
        A[nS:, nS:] = D + IDK @ self.St
        b = np.vstack([self.us0, IDK @ self.dt0])
        Ainv = np.linalg.inv(A)             # small (n_S + m): inverted once, applied many times
        z = Ainv @ b
        if not np.all(np.isfinite(z)):
            raise np.linalg.LinAlgError("singular augmented system")
        u_S, f = z[:nS], z[nS:]
        delta = self.dt0 - self.Zs.T @ (dK @ u_S) - self.St @ f
        U_O = self.uo0 - self.Gos @ (dK @ u_S) - self.Zo @ f
        return _State(dK, D, Ainv, u_S, f, delta, U_O)

    def _multiplier(self, x: np.ndarray, om: _ObsMap) -> np.ndarray:
        mult = np.ones(len(om.y))
        for i, mask in self._scale:
            mult[mask[om.case]] *= x[i]
        for i, g in self._gain:
            mult[om.grid == g] *= x[i]
        return mult

    def predict(self, x: np.ndarray, om: _ObsMap, st: _State | None = None) -> np.ndarray:
        st = self.state(x) if st is None else st
        return self._multiplier(x, om) * om.pick(st.U_O)

    def structural_derivatives(self, x: np.ndarray, st: _State, which: np.ndarray) -> np.ndarray:
        """``dU_O/dx_i`` for the structural parameters ``which``: ``(len(which), n_O, L)``."""
        nS, m, L = self.nS, self.m, self.base.n_cases
        rhs, dKs = [], []
        IDK = np.eye(m) - st.D * self.K0[None, :]
        force = st.f + self.K0[:, None] * st.delta                 # whole force through the pairs
        basis = dict(self._basis)
        members = {i: (idx, K_e) for i, idx, K_e in self._member}
        for i in which:
            if self.kind[i] == "joint":
                dKq = self._jD[i]
            elif i in members:
                idx, K_e = members[i]
                dKq = np.zeros((nS, nS))
                dKq[np.ix_(idx, idx)] = K_e
            else:
                dKq = None
            if dKq is not None:
                v = dKq @ st.u_S
                rhs.append(np.vstack([self.Gss @ v, IDK @ (self.Zs.T @ v)]))
            else:
                rhs.append(np.vstack([np.zeros((nS, L)), basis[i] @ force]))
            dKs.append(dKq)
        if not rhs:
            return np.zeros((0, len(self.o_dofs), L))
        dz = -(st.Ainv @ np.hstack(rhs)).reshape(nS + m, len(rhs), L).transpose(1, 0, 2)
        out = np.empty((len(rhs), len(self.o_dofs), L))
        for q, dKq in enumerate(dKs):
            du_S, df = dz[q, :nS], dz[q, nS:]
            w = st.dK @ du_S
            if dKq is not None:
                w = w + dKq @ st.u_S
            out[q] = -self.Gos @ w - self.Zo @ df
        return out

    def jacobian(self, x: np.ndarray, om: _ObsMap, st: _State | None = None) -> np.ndarray:
        """``d prediction / dx`` at the rows of ``om``: ``(n_obs, n_params)``, natural coordinates."""
        x = np.asarray(x, float)
        st = self.state(x) if st is None else st
        mult = self._multiplier(x, om)
        base = om.pick(st.U_O)
        J = np.zeros((len(om.y), self.p))
        structural = np.array([i for i in range(self.p) if self.kind[i] not in ("load_scale", "sensor_gain")], int)
        if structural.size:
            dU = self.structural_derivatives(x, st, structural)
            for q, i in enumerate(structural):
                J[:, i] = mult * om.pick(dU[q])
        for i, mask in self._scale:
            sel = mask[om.case]
            J[sel, i] = mult[sel] / x[i] * base[sel]
        for i, g in self._gain:
            sel = om.grid == g
            J[sel, i] = mult[sel] / x[i] * base[sel]
        return J

    def member_score_columns(self, st: _State, members: Sequence[Effect], om: _ObsMap) -> np.ndarray:
        """``d prediction / d alpha_e`` at ``alpha_e = 1`` for members NOT in the model, by
        reciprocity (rows of the split run at the member DOFs; no column of their own needed)."""
        nS, m = self.nS, self.m
        IDK = np.eye(m) - st.D * self.K0[None, :]
        cond = self.cond
        out = np.zeros((len(om.y), len(members)))
        for q, e in enumerate(members):
            E = list(e.dofs)
            G_ES = cond.G(E, self.S) if nS else np.zeros((len(E), 0))
            Z_E = cond.Z(E)
            u_E = cond.u0(E) - G_ES @ (st.dK @ st.u_S) - Z_E @ st.f
            F = e.K_e @ u_E                                           # (12, L)
            rhs = np.vstack([G_ES.T @ F, IDK @ (Z_E.T @ F)])
            dz = -st.Ainv @ rhs
            du_S, df = dz[:nS], dz[nS:]
            G_OE = cond.G(self.o_dofs, E)
            dU = -self.Gos @ (st.dK @ du_S) - G_OE @ F - self.Zo @ df
            out[:, q] = om.pick(dU)
        return out


# --------------------------------------------------------------------------------------------
# fitting
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Fit:
    """One weighted least-squares fit of a specification (Gaussian likelihood, declared sigma)."""
    spec: ModelSpec
    x: np.ndarray
    std: np.ndarray
    n_obs: int
    n_params: int
    chi2: float
    reduced_chi2: float
    rms_residual: float
    bic: float
    residuals: np.ndarray               # whitened, fit rows
    predicted: np.ndarray
    holdout_rms: float | None
    holdout_chi2: float | None
    holdout_n: int
    converged: bool
    message: str
    J: np.ndarray                       # whitened Jacobian at x (natural coordinates)


def _stats(y, sigma, f, p):
    r = (y - f) / sigma
    chi2 = float(r @ r)
    n = len(y)
    dof = n - p
    bic = chi2 + float(np.sum(np.log(2.0 * np.pi * sigma ** 2))) + p * math.log(n)
    return r, chi2, (chi2 / dof if dof > 0 else float("nan")), float(np.sqrt(np.mean((y - f) ** 2))), bic


def fit_model(model: AugmentedModel, om: _ObsMap, hold: _ObsMap | None, x0: np.ndarray,
              max_iterations: int = 200) -> Fit:
    """Weighted least squares from ``x0``: Levenberg-Marquardt (Marquardt scaling) with box
    bounds by an active set -- simple-model springs ``>= 0``, compliances ``>= 0``, factors in
    their ranges -- in natural coordinates (every joint model is linear in its parameters, and a
    spring that the data want at 0 or at infinity gets there, which log k makes crawl). Singular
    trial points (a mechanism) are rejected."""
    spec = model.spec
    _, lo, hi = spec.transforms()
    x = np.clip(np.asarray(x0, float), lo, hi)

    def residual(x):
        try:
            st = model.state(x)
            f = model.predict(x, om, st)
        except (np.linalg.LinAlgError, ValueError):
            return None, None
        return ((om.y - f) / om.sigma, st) if np.all(np.isfinite(f)) else (None, None)

    def jac(x, st):
        return model.jacobian(x, om, st) / om.sigma[:, None]

    r, st = residual(x)
    if r is None:
        raise IdentificationError("the model is singular at the start of a refit")
    F = float(r @ r)
    converged, msg, lam = model.p == 0, "no parameters" if model.p == 0 else "", 0.0
    it = 0
    J = jac(x, st) if model.p else None
    while not converged and it < max_iterations:
        it += 1
        g = J.T @ r                                    # -1/2 gradient of chi2 (r = (y - f) / sigma)
        N = J.T @ J
        free = ~(((x <= lo) & (g < 0)) | ((x >= hi) & (g > 0)))
        accepted = False
        while True:
            d = np.zeros_like(x)
            d[free] = _solve_normal(N[np.ix_(free, free)], g[free], lam)
            x_new = np.clip(x + d, lo, hi)
            r_new, st_new = residual(x_new)
            F_new = float(r_new @ r_new) if r_new is not None else np.inf
            if F_new < F:
                accepted = True
                break
            lam = 1e-4 if lam == 0.0 else 10.0 * lam
            if lam > 1e12:
                break
        if not accepted:
            converged, msg = True, "no damped step decreases chi2 (at the minimum to rounding)"
            break
        dec = F - F_new
        x, r, st, F = x_new, r_new, st_new, F_new
        J = jac(x, st)
        lam = 0.0 if lam < 1e-3 else lam / 10.0
        if dec <= 1e-13 * max(F, 1e-300):
            converged, msg = True, "relative decrease of chi2 below 1e-13"
    if not converged:
        msg = "maximum number of iterations reached"
    f = model.predict(x, om, st)
    Jn = jac(x, st) if model.p else np.zeros((len(om.y), 0))
    r, chi2, red, rms, bic = _stats(om.y, om.sigma, f, model.p)
    std = _std(Jn)
    h_rms = h_chi2 = None
    hn = 0
    if hold is not None and len(hold.y):
        fh = model.predict(x, hold, st)
        h_rms = float(np.sqrt(np.mean((hold.y - fh) ** 2)))
        h_chi2 = float(np.sum(((hold.y - fh) / hold.sigma) ** 2))
        hn = len(hold.y)
    return Fit(spec, x, std, len(om.y), model.p, chi2, red, rms, bic, r, f, h_rms, h_chi2, hn,
               bool(converged), msg, Jn)


def _solve_normal(N: np.ndarray, g: np.ndarray, lam: float) -> np.ndarray:
    """``argmin |J d - r|^2 + lam |diag(N)^1/2 d|^2`` from ``N = J^T J``, ``g = J^T r``: Marquardt
    scaling, symmetric eigendecomposition, directions below 1e-13 of the largest eigenvalue left
    out (minimum norm). Normal equations of a few columns: microseconds, where a LAPACK SVD of the
    tall Jacobian costs milliseconds to seconds with a threaded BLAS."""
    if N.size == 0:
        return np.zeros(0)
    dg_ = np.sqrt(np.diag(N))
    dg_ = np.where(dg_ > 0, dg_, 1.0)
    w, V = np.linalg.eigh(N / np.outer(dg_, dg_) + lam * np.eye(len(g)))
    keep = w > 1e-13 * max(float(w[-1]), 1e-300)
    return (V[:, keep] @ ((V[:, keep].T @ (g / dg_)) / w[keep])) / dg_


def _std(J: np.ndarray) -> np.ndarray:
    """Square roots of ``diag (J^T J)^+`` (column-scaled Gram matrix); inf where not identifiable
    (a component in the numerical null space: eigenvalues below ``_GRAM_RTOL`` of the largest)."""
    if J.shape[1] == 0:
        return np.zeros(0)
    s = np.linalg.norm(J, axis=0)
    s = np.where(s > 0, s, 1.0)
    w, V = np.linalg.eigh((J.T @ J) / np.outer(s, s))
    keep = w > _GRAM_RTOL * max(float(w[-1]), 1e-300)
    var = np.sum(V[:, keep] ** 2 / w[keep], axis=1) / s ** 2
    bad = np.linalg.norm(V[:, ~keep], axis=1) > 1e-6 if np.any(~keep) else np.zeros(J.shape[1], bool)
    return np.where(bad, np.inf, np.sqrt(var))


# --------------------------------------------------------------------------------------------
# scores
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CandidateScore:
    """The score test of one candidate at the current optimum, and its refit if it was made."""
    effect: Effect
    score: float
    df: int
    p_value: float
    log10_p: float
    p_adjusted: float
    step_estimate: np.ndarray           # one Gauss-Newton step from the nested point
    delta_bic: float                    # refit, else the score approximation -S + df log n
    delta_bic_method: str
    refit: Fit | None = None
    lr: float | None = None
    lr_p_value: float | None = None
    lr_p_adjusted: float | None = None
    holdout_delta_chi2: float | None = None
    accepted: bool = False
    reason: str = ""


class _Projector:
    """Projection out of the span of the current model's whitened Jacobian ``J0``, through its
    (column-scaled) Gram matrix: ``Pi r = r - J0 N0^+ J0^T r``."""

    def __init__(self, J0: np.ndarray, r: np.ndarray):
        self.J0, self.r = J0, r
        p = J0.shape[1]
        if p:
            s = np.linalg.norm(J0, axis=0)
            self.s = np.where(s > 0, s, 1.0)
            w, V = np.linalg.eigh((J0.T @ J0) / np.outer(self.s, self.s))
            keep = w > _GRAM_RTOL * max(float(w[-1]), 1e-300)
            self.Ninv = (V[:, keep] / w[keep]) @ V[:, keep].T
            self.b0 = (J0.T @ r) / self.s
        self.p = p

    def reduced(self, Jc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(M, h)`` = ``((Pi Jc)^T Pi Jc, (Pi Jc)^T Pi r)``."""
        M = Jc.T @ Jc
        h = Jc.T @ self.r
        if self.p:
            C = (self.J0.T @ Jc) / self.s[:, None]
            M = M - C.T @ self.Ninv @ C
            h = h - C.T @ self.Ninv @ self.b0
        return 0.5 * (M + M.T), h


def score_test(proj: _Projector, Jc: np.ndarray, one_sided: np.ndarray):
    """``(S, df, step)``: the score statistic of the extra whitened columns ``Jc`` given the
    current fit (``proj``): ``S = h^T M^+ h`` with ``M, h`` the projected Gram matrix and
    right-hand side, or, when some parameters are one-sided (compliances ``>= 0``), the largest
    decrease of chi2 of the linearised problem over the feasible cone. ``df``: the rank of ``M``
    (eigenvalues above ``_SCORE_RTOL`` of the columns' own scale); ``step``: the maximiser (one
    Gauss-Newton step from the nested point)."""
    M, h = proj.reduced(Jc)
    pc = Jc.shape[1]
    step = np.zeros(pc)
    scale = np.sqrt(np.maximum(np.sum(Jc ** 2, axis=0), 1e-300))
    Ms, hs = M / np.outer(scale, scale), h / scale
    w, V = np.linalg.eigh(Ms)
    keep = w > _SCORE_RTOL
    df = int(np.sum(keep))
    if not df:
        return 0.0, 0, step
    Vk, wk = V[:, keep], w[keep]
    full = float(np.sum((Vk.T @ hs) ** 2 / wk))
    th = Vk @ ((Vk.T @ hs) / wk)
    if np.any(one_sided) and np.any(th[one_sided] < 0):
        R = np.sqrt(wk)[:, None] * Vk.T                      # M = R^T R on its range
        b = (Vk.T @ hs) / np.sqrt(wk)
        lb = np.where(one_sided, 0.0, -np.inf)
        th = optimize.lsq_linear(R, b, bounds=(lb, np.full(pc, np.inf)), method="bvls").x
        full = float(b @ b - np.sum((R @ th - b) ** 2))
    step = th / scale
    return max(full, 0.0), df, step


def score_candidates(model: AugmentedModel, fit: Fit, om: _ObsMap, candidates: Sequence[Effect],
                     boundary, K_deck, o_dofs) -> list[tuple[Effect, float, int, np.ndarray]]:
    """Score every candidate at the current optimum: ``[(effect, S, df, step)]``. Members not in
    the model are scored by reciprocity (no run); the others through their augmented model."""
    # at a bounded optimum the residual is orthogonal only to the free parameters' columns: a
    # parameter held at its bound (a spring at 0) does not remove its direction from a candidate
    # that can go beyond it (the complex model's K_C is not sign-restricted)
    _, lo, hi = fit.spec.transforms()
    g = fit.J.T @ fit.residuals
    held = ((fit.x <= lo) & (g < 0)) | ((fit.x >= hi) & (g > 0))
    proj = _Projector(fit.J[:, ~held], fit.residuals)
    st = model.state(fit.x)
    out = []
    members = [c for c in candidates if c.kind == "member_stiffness"]
    if members:
        cols = model.member_score_columns(st, members, om)
        mult = model._multiplier(fit.x, om)
        Jm = cols * (mult / om.sigma)[:, None]
        for q, e in enumerate(members):
            S, df, step = score_test(proj, Jm[:, q:q + 1], np.zeros(1, bool))
            out.append((e, S, df, step))
    for e in candidates:
        if e.kind == "member_stiffness":
            continue
        spec2, x2 = fit.spec.add(e, fit.x)
        try:
            m2 = AugmentedModel(model.base, spec2, boundary, K_deck, o_dofs)
            J2 = m2.jacobian(x2, om) / om.sigma[:, None]
        except (np.linalg.LinAlgError, IdentificationError):
            out.append((e, 0.0, 0, np.zeros(e.n_params)))
            continue
        if e.kind == "joint_coupling":
            sl = next(sl for j, sl in zip(spec2.joints, spec2.joint_slices()) if j.name == e.joint)
            cols = np.arange(sl.start, sl.stop)
            one = np.zeros(cols.size, bool)
        else:
            cols = np.arange(fit.spec.n_params, spec2.n_params)
            one = e.one_sided
        S, df, step = score_test(proj, J2[:, cols], one)
        out.append((e, S, df, step))
    return out


# --------------------------------------------------------------------------------------------
# residual structure
# --------------------------------------------------------------------------------------------
def chi2_band(dof: int, level: float = 0.99) -> tuple[float, float]:
    """The central ``level`` band of ``chi2(dof) / dof``."""
    if dof <= 0:
        return float("nan"), float("nan")
    a = (1.0 - level) / 2.0
    return float(stats.chi2.ppf(a, dof) / dof), float(stats.chi2.ppf(1.0 - a, dof) / dof)


def residual_structure(obs: Observations, r: np.ndarray, xyz: dict | None = None, top: int = 10) -> dict:
    """Whitened residuals grouped per case, per grid and per component: ``chi2/n`` and the
    upper-tail p-value of each group against ``chi2(n)`` (the declared noise), plus every
    measured grid's RMS and coordinates (the spatial map)."""
    def groups(keys):
        out = {}
        for k in dict.fromkeys(keys):
            sel = np.array([kk == k for kk in keys])
            c2 = float(np.sum(r[sel] ** 2))
            n = int(sel.sum())
            out[k] = {"n": n, "chi2_per_n": c2 / n, "rms": math.sqrt(c2 / n),
                      "p_value": float(stats.chi2.sf(c2, n))}
        return out
    labels = obs.case_labels
    per_case = groups([labels[c] if labels else str(c) for c in obs.case_index])
    per_grid = groups([int(d[0]) for d in obs.dofs])
    per_comp = groups([int(d[1]) for d in obs.dofs])
    worst = sorted(per_grid.items(), key=lambda kv: kv[1]["p_value"])[:top]
    grid_map = [{"grid": g, "rms": v["rms"], "n": v["n"],
                 "xyz": list(xyz[g]) if xyz and g in xyz else None} for g, v in per_grid.items()]
    return {"per_case": per_case, "per_component": {str(k): v for k, v in per_comp.items()},
            "per_grid": {str(k): v for k, v in per_grid.items()},
            "worst_grids": [{"grid": g, **v} for g, v in worst], "grid_map": grid_map}


def default_holdout(case_labels: Sequence[str], every: int = 5) -> list[str]:
    """A deterministic hold-out when the study declares none: every ``every``-th measured case
    (the 5th, 10th, ...), none when there are fewer than ``every`` cases."""
    cases = list(case_labels)
    return [c for i, c in enumerate(cases) if i % every == every - 1] if len(cases) >= every else []


# --------------------------------------------------------------------------------------------
# the loop
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Step:
    """One round: the fit it started from, every candidate's score (best first), the refits,
    the effect added (or None) and the fit after."""
    before: Fit
    scores: tuple[CandidateScore, ...]
    added: CandidateScore | None
    after: Fit
    structure_before: dict
    structure_after: dict
    runs: int


@dataclass(frozen=True, eq=False)
class Diagnosis:
    declared: Fit
    final: Fit
    steps: tuple[Step, ...]
    n_candidates: dict
    alpha: float
    band: tuple[float, float]
    holdout_cases: tuple[str, ...]
    nesting_error: float | None
    runs: tuple[RunRecord, ...]
    wall_s: float
    stop_reason: str
    warnings: tuple[str, ...] = ()

    @property
    def added(self) -> list[CandidateScore]:
        return [s.added for s in self.steps if s.added is not None]


def _refit_candidate(base, fit: Fit, e: Effect, om, hold, boundary, K_deck, o_dofs, step) -> tuple[Fit, Effect]:
    """Refit the current model plus ``e`` (two starts: the nested point and the score step);
    connection parameters that end at 0 are dropped (the connection stays rigid there)."""
    spec2, x2 = fit.spec.add(e, fit.x)
    m2 = AugmentedModel(base, spec2, boundary, K_deck, o_dofs)
    lo_i = fit.spec.n_params if e.kind != "joint_coupling" else None
    starts = [x2]
    if lo_i is not None and e.n_params and np.all(np.isfinite(step)):
        xs = x2.copy()
        _, lo, hi = spec2.transforms()
        xs[lo_i:] = np.clip(x2[lo_i:] + step, lo[lo_i:], hi[lo_i:])
        if e.kind in CONNECTION_KINDS:
            xs[lo_i:] = np.maximum(xs[lo_i:], 1e-3)
        starts.append(xs)
    if e.kind in CONNECTION_KINDS:
        xs = x2.copy()
        xs[lo_i:] = 0.1
        starts.append(xs)
    best = None
    for xs in starts:
        try:
            f = fit_model(m2, om, hold, xs)
        except (np.linalg.LinAlgError, IdentificationError):
            continue
        if best is None or f.chi2 < best.chi2:
            best = f
    if best is None:
        raise IdentificationError(f"refit of {e.label()} failed")
    if e.kind in CONNECTION_KINDS:
        th = best.x[lo_i:]
        keep = th > _AT_BOUND
        if not np.any(keep):
            keep[np.argmax(th)] = True
        if not np.all(keep):
            e2 = e.keep(keep)
            spec3 = ModelSpec(spec2.joints, spec2.effects[:-1] + (e2,))
            x3 = np.concatenate([best.x[:lo_i], th[keep]])
            m3 = AugmentedModel(base, spec3, boundary, K_deck, o_dofs)
            best = fit_model(m3, om, hold, x3)
            e = e2
    return best, e


def diagnose(base: SplitBase, boundary: Sequence[DofLabel], K_deck: np.ndarray | None,
             joints: Sequence[JointModel], k_start: np.ndarray, obs_fit: Observations,
             obs_hold: Observations | None, candidates: Sequence[Effect], *, alpha: float = 0.01,
             refit_top: int = 6, max_steps: int = 5, band_level: float = 0.99,
             declared_prediction: np.ndarray | None = None, xyz: dict | None = None,
             progress=None) -> Diagnosis:
    """The loop of the module docstring. ``k_start``: the declared joints' estimate (e.g. from
    :func:`blackbox.identification.identify`); ``declared_prediction``: that estimate's fit-row
    predictions on the original deck, to measure how exactly the split deck nests the declared
    model (``nesting_error``, in sigma)."""
    t0 = time.perf_counter()
    boundary = tuple(boundary)
    o_dofs = tuple(dict.fromkeys(list(obs_fit.dofs) + [r for r in obs_fit.ref_dofs if r is not None]
                                 + (list(obs_hold.dofs) + [r for r in obs_hold.ref_dofs if r is not None]
                                    if obs_hold is not None else [])))
    o_index = {d: i for i, d in enumerate(o_dofs)}
    om = _ObsMap.of(obs_fit, o_index)
    hold = _ObsMap.of(obs_hold, o_index) if obs_hold is not None and len(obs_hold) else None
    warnings: list[str] = []

    spec = ModelSpec(tuple(joints))
    model = AugmentedModel(base, spec, boundary, K_deck, o_dofs)
    x0 = np.asarray(k_start, float)
    nest = None
    if declared_prediction is not None:
        nest = float(np.max(np.abs(model.predict(x0, om) - declared_prediction) / om.sigma))
        if nest > 1e-3:
            warnings.append(f"the split deck reproduces the declared model only to {nest:.2g} sigma "
                            "(rigid-state nesting); scores may be inaccurate")
    fit = fit_model(model, om, hold, x0)
    declared = fit
    steps: list[Step] = []
    counts: dict = {}
    for e in candidates:
        counts[e.kind] = counts.get(e.kind, 0) + 1
    stop = "max_steps reached"
    for it in range(max_steps):
        runs0 = len(base.log)
        pool = [e for e in candidates if not fit.spec.has(e) and _applicable(e, fit.spec)]
        if not pool:
            stop = "no candidate left"
            break
        M = len(pool)
        raw = score_candidates(model, fit, om, pool, boundary, K_deck, o_dofs)
        n = fit.n_obs
        scored = []
        for e, S, df, step in raw:
            p = float(stats.chi2.sf(S, df)) if df else 1.0
            lp = _log10_sf(S, df)
            scored.append(CandidateScore(e, S, df, p, lp, min(1.0, M * p), step,
                                         (-S + df * math.log(n)) if df else 0.0, "score approximation"))
        scored.sort(key=lambda c: (c.log10_p, -c.score))
        short = [c for c in scored[:refit_top] if c.df > 0]
        need = [d for c in short if c.effect.kind == "member_stiffness" for d in c.effect.dofs]
        if need:
            base.ensure_columns(need, f"member columns for refits (round {it + 1})")
        refits = []
        for c in short:
            try:
                f2, e2 = _refit_candidate(base, fit, c.effect, om, hold, boundary, K_deck, o_dofs, c.step_estimate)
            except IdentificationError as exc:
                refits.append(replace(c, reason=f"refit failed: {exc}"))
                continue
            dp = f2.n_params - fit.n_params
            lr = max(fit.chi2 - f2.chi2, 0.0)
            lr_p = float(stats.chi2.sf(lr, dp)) if dp > 0 else 1.0
            lr_adj = min(1.0, M * lr_p)
            dbic = f2.bic - fit.bic
            dh = (f2.holdout_chi2 - fit.holdout_chi2) if (hold is not None and fit.holdout_chi2 is not None) else None
            reasons = []
            if not lr_adj < alpha:
                reasons.append(f"not significant (LR p x {M} = {lr_adj:.3g} >= {alpha:g})")
            if not dbic < 0:
                reasons.append(f"BIC does not improve ({dbic:+.4g})")
            if dh is not None and dh > max(dp, 1):
                reasons.append(f"hold-out prediction worse (chi2 {dh:+.4g})")
            refits.append(replace(c, effect=e2, refit=f2, lr=lr, lr_p_value=lr_p, lr_p_adjusted=lr_adj,
                                  delta_bic=dbic, delta_bic_method="refit", holdout_delta_chi2=dh,
                                  accepted=not reasons, reason="; ".join(reasons) or "accepted"))
        ok = [c for c in refits if c.accepted]
        best = min(ok, key=lambda c: c.delta_bic) if ok else None
        if best is not None:
            refits = [replace(c, reason="significant, but another candidate improves BIC more")
                      if (c.accepted and c is not best) else c for c in refits]
            best = next(c for c in refits if c.effect is best.effect)
        by_key = {c.effect.key: c for c in refits}
        ranked = [by_key.get(c.effect.key, c) for c in scored]
        sb = residual_structure(obs_fit, fit.residuals, xyz)
        if best is None:
            steps.append(Step(fit, tuple(ranked), None, fit, sb, sb, len(base.log) - runs0))
            stop = "no candidate is significant after the Bonferroni correction and improves BIC"
            break
        new = best.refit
        steps.append(Step(fit, tuple(ranked), best, new, sb, residual_structure(obs_fit, new.residuals, xyz),
                          len(base.log) - runs0))
        if progress is not None:
            progress(steps[-1])
        fit = new
        model = AugmentedModel(base, fit.spec, boundary, K_deck, o_dofs)
    lo, hi = chi2_band(fit.n_obs - fit.n_params, band_level)
    if not (lo <= fit.reduced_chi2 <= hi):
        warnings.append(f"the final reduced chi2 {fit.reduced_chi2:.4g} is outside the {band_level:.0%} "
                        f"band [{lo:.4g}, {hi:.4g}] of the declared noise")
    for j, sl in zip(fit.spec.joints, fit.spec.joint_slices()):
        if isinstance(j, ComplexJoint) and not j.is_admissible(fit.x[sl]):
            warnings.append(f"joint {j.name}: the fitted K_C is not positive semi-definite")
    return Diagnosis(declared, fit, tuple(steps), counts, alpha, (lo, hi),
                     tuple(obs_hold.case_labels[c] for c in obs_hold.cases) if obs_hold is not None else (),
                     nest, tuple(base.log), time.perf_counter() - t0, stop, tuple(warnings))


def _log10_sf(S: float, df: int) -> float:
    """``log10 chi2.sf(S, df)``, finite however large ``S`` (the leading term of the asymptotic
    tail, ``sf ~ pdf(S) * 2`` for ``S >> df``, where scipy's ``logsf`` underflows to -inf)."""
    if not df:
        return 0.0
    v = float(stats.chi2.logsf(S, df))
    if not math.isfinite(v):
        v = float(stats.chi2.logpdf(S, df)) + math.log(2.0)
    return v / math.log(10.0)


def _applicable(e: Effect, spec: ModelSpec) -> bool:
    if e.kind == "joint_coupling":
        return any(j.name == e.joint and isinstance(j, SimpleJoint) for j in spec.joints)
    return True


# --------------------------------------------------------------------------------------------
# parameters of an added effect, for reports
# --------------------------------------------------------------------------------------------
def effect_parameters(fit: Fit, effect: Effect) -> list[dict]:
    """``[{name, value, std, ...}]`` of an added effect in the fit: connection compliances as
    stiffnesses ``k = k_ref / theta`` (delta-method std), the rest as fitted; joint coupling: the
    joint's complex-model parameters."""
    spec = fit.spec
    if effect.kind == "joint_coupling":
        sl = next(sl for j, sl in zip(spec.joints, spec.joint_slices()) if j.name == effect.joint)
        j = next(j for j in spec.joints if j.name == effect.joint)
        return [{"name": n, "value": float(v), "std": _f(s)} for n, v, s in
                zip(j.param_names, fit.x[sl], fit.std[sl])]
    i = next(i for i, e in enumerate(spec.effects) if e.key == effect.key)
    e = spec.effects[i]
    sl = spec.effect_slices()[i]
    out = []
    for q, name in enumerate(e.names):
        v, s = float(fit.x[sl][q]), float(fit.std[sl][q])
        if e.kind in CONNECTION_KINDS:
            k = e.k_ref[q] / v if v > 0 else float("inf")
            ks = e.k_ref[q] * s / v ** 2 if v > 0 else float("inf")
            out.append({"name": name, "value": _f(k), "std": _f(ks), "compliance": _f(v / e.k_ref[q]),
                        "compliance_std": _f(s / e.k_ref[q]), "k0": float(e.k_ref[q])})
        else:
            out.append({"name": name, "value": v, "std": _f(s)})
    return out


def _f(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None
