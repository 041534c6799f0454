"""The declared model plus effects, on the split structure: predictions and exact Jacobians.

A :class:`ModelSpec` is the joints (declared, or coupled) and the effects added so far; an
:class:`AugmentedModel` evaluates it on a :class:`~blackbox.diagnosis.split.SplitBase`. Each
effect enters through the hooks of :class:`~blackbox.diagnosis.effects.Effect`:

*Compliance form* (released cuts). A released connection has compliance ``D(theta) = sum theta_i D_i``.
Replacing the ``K0`` springs by ``D^-1`` adds a parallel connection of compliance
``(I - D K0)^-1 D`` carrying forces ``f``; together with the stiffness-form part
``dK = K_J(k) - K_deck + sum (x_q - nominal_q) K_q + sum dK_e(x_e)`` on the DOFs ``S`` (joint
boundary plus the DOFs of stiffness terms, e.g. a member's ends; ``dK_e``: an effect's nonlinear
stiffness change, :meth:`~blackbox.diagnosis.effects.Effect.stiffness_matrix`, whose derivative
``d dK_e / dx_q`` takes the place of ``K_q`` below)::

    [ I + G~_SS dK              Z~_S           ] [u_S]   [ u~0_S              ]
    [ (I - D K0) Z~_S^T dK      D + (I - D K0) S~] [ f ] = [ (I - D K0) P u~0    ]
    u_O = u~0_O - G~_OS dK u_S - Z~_O f

and by implicit differentiation (``A z = b``): ``dz/dk = -A^-1 [G~_SS dK' u_S; (I - D K0) Z~_S^T dK' u_S]``,
``dz/dtheta_i = -A^-1 [0; D_i (f + K0 delta)]`` with ``delta = P u`` the relative motion of the
pairs (``f + K0 delta`` is the whole force through the connection).

*Output side.* A factor on some measured rows (a load scale on its cases, a sensor gain on its
grid) multiplies the prediction there (linearity): exact, no run. An offset on some rows (a
sensor's zero offset on one channel) is added after the factors: ``f = mult * U + offset``.

``K_deck`` is the declared model's (:meth:`blackbox.declared.DeclaredModel.K_deck`): the deck's
own springs minus the rigid-pair penalty, so a rigid pair stays rigid in every model here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from blackbox.condensation import JointAssembly
from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.split import SplitBase
from blackbox.errors import IdentificationError
from blackbox.identification import Observations
from blackbox.joints import JointModel, SimpleJoint
from solver_adapters.protocol import DofLabel

__all__ = ["ModelSpec", "ObsMap", "State", "AugmentedModel", "RIGID_RATIO"]

RIGID_RATIO = 1e8           # a joint spring this many times stiffer than the structure is rigid


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
        joints, xj = effect.joint_models(self, x)
        return (ModelSpec(tuple(joints), self.effects + (effect,)),
                np.concatenate([xj, x[self.joint_params:], effect.nominal]))

    def replace_effect(self, i: int, effect: Effect) -> "ModelSpec":
        eff = list(self.effects)
        eff[i] = effect
        return ModelSpec(self.joints, tuple(eff))

    def transforms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(one_sided, lower, upper)``: simple-model springs ``>= 0``, complex-model entries free
        (``K_C`` positive definiteness is checked on the result), effects within their bounds;
        ``one_sided``: parameters whose nested value is a bound."""
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


@dataclass(frozen=True, eq=False)
class ObsMap:
    """Observation rows located in a model's observed DOFs."""
    row: np.ndarray         # index into the model's observed DOFs
    ref: np.ndarray         # index of the reference DOF or -1
    case: np.ndarray
    grid: np.ndarray
    y: np.ndarray
    sigma: np.ndarray
    comp: np.ndarray | None = None      # the measured component of each row

    @classmethod
    def of(cls, obs: Observations, o_index: dict) -> "ObsMap":
        refs = obs.ref_dofs or (None,) * len(obs)
        return cls(np.array([o_index[d] for d in obs.dofs], dtype=int),
                   np.array([-1 if r is None else o_index[r] for r in refs], dtype=int),
                   np.asarray(obs.case_index, int), np.array([d[0] for d in obs.dofs], dtype=int),
                   np.asarray(obs.values, float), np.asarray(obs.sigma, float),
                   np.array([d[1] for d in obs.dofs], dtype=int))

    def pick(self, U: np.ndarray) -> np.ndarray:
        f = U[self.row, self.case]
        has = self.ref >= 0
        if has.any():
            f = f - np.where(has, U[np.maximum(self.ref, 0), self.case], 0.0)
        return f


@dataclass
class State:
    """The block system solved at one parameter point."""
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
        S = list(dict.fromkeys(list(boundary) + [d for e in spec.effects for d in e.stiffness_dofs]))
        self.S = tuple(S)
        sidx = {d: i for i, d in enumerate(S)}
        nS = len(S)
        self.assembly = JointAssembly(spec.joints, S) if spec.joints else None
        self.K_deck = np.zeros((nS, nS))
        if K_deck is not None:
            bi = np.array([sidx[d] for d in boundary])
            self.K_deck[np.ix_(bi, bi)] = K_deck
        a = [i for e in spec.effects for i in e.cut_pairs]
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
        # parameter bookkeeping: joints, stiffness terms, compliances (structural), output factors
        self.p = spec.n_params
        self._stiff = []            # (param index, S indices, K_q, nominal)
        self._nonlinear = []        # (parameter slice, S indices, effect): dK += effect.stiffness_matrix(x[slice])
        self._basis = []            # (param index, m x m matrix)
        self._outputs = []          # (param index, effect, q)
        output = np.zeros(self.p, bool)
        off = 0
        for e, sl in zip(spec.effects, spec.effect_slices()):
            if e.stiffness_dofs:
                idx = np.array([sidx[d] for d in e.stiffness_dofs])
                nom = e.nominal
                self._stiff += [(sl.start + q, idx, K_q, nom[q]) for q, K_q in e.stiffness_terms()]
                if e.stiffness_matrix(nom) is not None:
                    self._nonlinear.append((sl, idx, e))
            me = len(e.cut_pairs)
            if me:
                for q in range(e.n_params):
                    Dm = np.zeros((self.m, self.m))
                    Dm[off:off + me, off:off + me] = e.compliance_basis[q]
                    self._basis.append((sl.start + q, Dm))
                off += me
            if e.acts_on_output:
                output[sl] = True
                self._outputs.append(e)
        self._structural = np.flatnonzero(~output)
        self._jD = self.assembly.derivatives(np.ones(spec.joint_params)) if self.assembly else None

    def rigid_limits(self) -> np.ndarray:
        """Upper limits on the parameters beyond which a spring is rigid to rounding: a joint
        spring ``k_i`` (unit stiffness matrix ``dK_i``) stops at ``RIGID_RATIO / tr(G_SS dK_i)``,
        ``RIGID_RATIO`` times the stiffness the structure offers along it (``inf`` for the other
        parameters). The joint is then rigid to ``1 / RIGID_RATIO`` of the relative rotation,
        and the force through it (``dK u_S``, a difference of nearly equal rotations times ``k``)
        still keeps about ``16 - log10(RIGID_RATIO)`` digits; a spring far beyond (a misfit model's
        flat valley, 1e13-1e20) makes chi2 rounding noise of several units, which a refit would
        follow instead of the valley."""
        out = np.full(self.p, np.inf)
        if self._jD is None:
            return out
        for j, sl in zip(self.spec.joints, self.spec.joint_slices()):
            if not isinstance(j, SimpleJoint):
                continue
            for i in range(sl.start, sl.stop):
                flex = float(np.trace(self.Gss @ self._jD[i]))
                if flex > 0.0:
                    out[i] = RIGID_RATIO / flex
        return out

    # ---- the block system ---------------------------------------------------------------------
    def state(self, x: np.ndarray) -> State:
        x = np.asarray(x, float)
        spec = self.spec
        dK = -self.K_deck.copy()
        if self.assembly is not None:
            dK += self.assembly.matrix(x[:spec.joint_params])
        for i, idx, K_q, nom in self._stiff:
            dK[np.ix_(idx, idx)] += (x[i] - nom) * K_q
        for sl, idx, e in self._nonlinear:
            dK[np.ix_(idx, idx)] += e.stiffness_matrix(x[sl])
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
        return State(dK, D, Ainv, u_S, f, delta, U_O)

    def _output_factors(self, om: ObsMap) -> list[tuple[int, np.ndarray]]:
        sl = dict(zip(self.spec.effects, self.spec.effect_slices()))
        return [(sl[e].start + q, rows) for e in self._outputs for q, rows in e.output_rows(om)]

    def _output_offsets(self, om: ObsMap) -> list[tuple[int, np.ndarray]]:
        sl = dict(zip(self.spec.effects, self.spec.effect_slices()))
        return [(sl[e].start + q, rows) for e in self._outputs for q, rows in e.offset_rows(om)]

    def offset(self, x: np.ndarray, om: ObsMap) -> np.ndarray:
        """The output offsets' sum at each row of ``om``."""
        add = np.zeros(len(om.y))
        for i, rows in self._output_offsets(om):
            add[rows] += x[i]
        return add

    def multiplier(self, x: np.ndarray, om: ObsMap) -> np.ndarray:
        """The output factors' product at each row of ``om``."""
        mult = np.ones(len(om.y))
        for i, rows in self._output_factors(om):
            mult[rows] *= x[i]
        return mult

    def predict(self, x: np.ndarray, om: ObsMap, st: State | None = None) -> np.ndarray:
        st = self.state(x) if st is None else st
        return self.multiplier(x, om) * om.pick(st.U_O) + self.offset(x, om)

    def structural_derivatives(self, x: np.ndarray, st: State, which: np.ndarray) -> np.ndarray:
        """``dU_O/dx_i`` for the structural parameters ``which``: ``(len(which), n_O, L)``."""
        nS, m, L = self.nS, self.m, self.base.n_cases
        rhs, dKs = [], []
        IDK = np.eye(m) - st.D * self.K0[None, :]
        force = st.f + self.K0[:, None] * st.delta                 # whole force through the pairs
        basis = dict(self._basis)
        stiff = {}
        for i, idx, K_q, _ in self._stiff:
            stiff.setdefault(i, []).append((idx, K_q))
        for sl, idx, e in self._nonlinear:
            if any(sl.start <= i < sl.stop for i in which):
                for q, K_q in enumerate(e.stiffness_derivatives(x[sl])):
                    stiff.setdefault(sl.start + q, []).append((idx, K_q))
        jp = self.spec.joint_params
        for i in which:
            if i < jp:
                dKq = self._jD[i]
            elif i in stiff:
                dKq = np.zeros((nS, nS))
                for idx, K_q in stiff[i]:
                    dKq[np.ix_(idx, idx)] += K_q
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

    def jacobian(self, x: np.ndarray, om: ObsMap, st: State | None = None) -> np.ndarray:
        """``d prediction / dx`` at the rows of ``om``: ``(n_obs, n_params)``, natural coordinates."""
        x = np.asarray(x, float)
        st = self.state(x) if st is None else st
        mult = self.multiplier(x, om)
        base = om.pick(st.U_O)
        J = np.zeros((len(om.y), self.p))
        structural = self._structural
        if structural.size:
            dU = self.structural_derivatives(x, st, structural)
            for q, i in enumerate(structural):
                J[:, i] = mult * om.pick(dU[q])
        for i, rows in self._output_factors(om):
            J[rows, i] = mult[rows] / x[i] * base[rows]
        for i, rows in self._output_offsets(om):
            J[rows, i] = 1.0
        return J
