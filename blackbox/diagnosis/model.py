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

*Input side.* An effect that changes the study's loads (a load turned off its declared
direction, a load at the neighbouring grid) adds ``dF(x)`` at its DOFs ``L``: by linearity the
right-hand sides become ``u~0 + G~[:, L] dF`` and ``P_a u~0 + Z~[L]^T dF`` (the split run's
unit-load columns at ``L``), and ``d/dx_q`` enters like a stiffness parameter's with
``-[G~_SL; (I - D K0) Z~_L^T] dF_q`` as its right-hand side, plus ``G~_OL dF_q`` at the
observed DOFs.

*Output side.* A factor on some measured rows (a load scale on its cases, a sensor gain on its
grid) multiplies the prediction there (linearity): exact, no run. An offset on some rows (a
sensor's zero offset on one channel) is added after the factors: ``f = mult * U + offset``.

``K_deck`` is the declared model's (:meth:`blackbox.declared.DeclaredModel.K_deck`): the deck's
own springs minus the rigid-pair penalty, so a rigid pair stays rigid in every model here.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from blackbox.condensation import JointAssembly
from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.split import SplitBase
from blackbox.errors import IdentificationError
from blackbox.identification import Observations
from blackbox.joints import ComplexJoint, JointModel, SimpleJoint
from solver_adapters.protocol import DofLabel

__all__ = ["ModelSpec", "ObsMap", "State", "AugmentedModel", "RIGID_RATIO"]

RIGID_RATIO = 1e8           # a joint spring this many times stiffer than the structure is rigid


MANY_GROUPS = 8             # beyond this many groups of cases, derivatives are applied case by case at once


def per_case(stack: np.ndarray, index: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``stack[index[c]] @ R[:, c]`` for every case ``c``: ``(a, L)`` from a stack ``(g, a, b)``
    of per-group matrices, the group ``index`` of each case and ``R`` ``(b, L)``; in chunks of
    cases of ~32 MB of gathered matrices."""
    out = np.empty((stack.shape[1], R.shape[1]))
    step = max(1, int(4e6 // max(stack.shape[1] * stack.shape[2], 1)))
    for s in range(0, R.shape[1], step):
        sl = slice(s, s + step)
        out[:, sl] = np.einsum("lij,jl->il", stack[index[sl]], R[:, sl])
    return out


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
    labels: tuple[str, ...] = ()        # the case labels ``case`` indexes

    @classmethod
    def of(cls, obs: Observations, o_index: dict) -> "ObsMap":
        refs = obs.ref_dofs or (None,) * len(obs)
        return cls(np.array([o_index[d] for d in obs.dofs], dtype=int),
                   np.array([-1 if r is None else o_index[r] for r in refs], dtype=int),
                   np.asarray(obs.case_index, int), np.array([d[0] for d in obs.dofs], dtype=int),
                   np.asarray(obs.values, float), np.asarray(obs.sigma, float),
                   np.array([d[1] for d in obs.dofs], dtype=int), tuple(obs.case_labels))

    def subset(self, rows: np.ndarray) -> "ObsMap":
        """The rows ``rows`` (indices or a mask) alone."""
        return ObsMap(self.row[rows], self.ref[rows], self.case[rows], self.grid[rows], self.y[rows],
                      self.sigma[rows], None if self.comp is None else self.comp[rows], self.labels)

    @functools.cached_property
    def _channels(self) -> dict:
        out: dict = {}
        for i, (g, c) in enumerate(zip(self.grid.tolist(), self.comp.tolist())):
            out.setdefault((g, c), []).append(i)
        return {k: np.array(v, int) for k, v in out.items()}

    def rows_of(self, grid: int, comp: int, case: str | None = None) -> np.ndarray:
        """Mask of the rows of channel ``(grid, comp)`` (in case ``case`` only, when given)."""
        m = np.zeros(len(self.y), bool)
        m[self._channels.get((int(grid), int(comp)), np.zeros(0, int))] = True
        if case is not None:
            idx = [i for i, lab in enumerate(self.labels) if lab == case]
            m &= np.isin(self.case, idx)
        return m

    @functools.cached_property
    def _has_ref(self) -> np.ndarray | None:
        """The rows read against a reference DOF (None: no row is)."""
        has = self.ref >= 0
        return has if has.any() else None

    @functools.cached_property
    def _flats(self) -> dict:
        return {}

    def _flat(self, n_cases: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Flat indices into a C-ordered ``U`` of ``n_cases`` columns: the rows, their references."""
        got = self._flats.get(n_cases)
        if got is None:
            flat = self.row * n_cases + self.case
            ref = None if self._has_ref is None else np.maximum(self.ref, 0) * n_cases + self.case
            got = self._flats[n_cases] = (flat, ref)
        return got

    def source(self, U: np.ndarray, rows: np.ndarray, terms: list, cases: np.ndarray | None = None) -> np.ndarray:
        """What the rows ``rows`` read from another source (an output mix, :meth:`Effect.mix_rows`):
        ``sum(w * U[idx, case])`` over ``terms = [(idx, w)]``, less the rows' reference DOFs, in
        the rows' own cases or in ``cases`` (U's column per row: another case's readings)."""
        case = self.case[rows] if cases is None else cases
        src = sum(w * U[idx, case] for idx, w in terms)
        ref = self.ref[rows]
        has = ref >= 0
        if has.any():
            src = src - np.where(has, U[np.maximum(ref, 0), case], 0.0)
        return src

    def pick(self, U: np.ndarray) -> np.ndarray:
        """``U`` (observed DOFs x cases) at the rows, less the reference DOF's where a row has one
        (the same values as ``U[row, case]``, read through flat indices: this runs per residual)."""
        flat, ref = self._flat(U.shape[1])
        u = U if U.flags.c_contiguous else np.ascontiguousarray(U)
        f = u.take(flat)
        if ref is not None:
            f = f - np.where(self._has_ref, u.take(ref), 0.0)
        return f


@dataclass
class State:
    """The block system solved at one parameter point. ``groups``: with case-dependent joint
    stiffness (:meth:`Effect.case_factors`), the cases solved together -- ``(cols, dK, Ainv,
    phi)``, ``phi`` the joint parameters' factors in those cases -- else ``None`` (every case
    with ``dK`` and ``Ainv``)."""
    dK: np.ndarray
    D: np.ndarray
    Ainv: np.ndarray
    u_S: np.ndarray
    f: np.ndarray
    delta: np.ndarray
    U_O: np.ndarray
    groups: list | None = None
    stacked: tuple | None = None        # with groups: (dK, Ainv, phi) stacked over the groups,
                                        # and each case's group -- what many groups are applied by

    def each(self):
        """``(cols, dK, Ainv, phi)`` of every group of cases (``cols`` a slice or index array;
        ``phi`` ``None`` when every factor is 1)."""
        if self.groups is None:
            return [(slice(None), self.dK, self.Ainv, None)]
        return self.groups


class AugmentedModel:
    """Predictions and exact Jacobians of a :class:`ModelSpec` (module docstring, block system)."""

    def __init__(self, base: SplitBase, spec: ModelSpec, boundary: Sequence[DofLabel],
                 K_deck: np.ndarray | None, o_dofs: Sequence[DofLabel]):
        self.base, self.spec = base, spec
        self.o_dofs = tuple(o_dofs)
        self._o_index = {d: i for i, d in enumerate(self.o_dofs)}
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
        # effects that change the study's loads (a load turned off its declared direction):
        # the split structure's response to unit loads at their DOFs L, at S and O, and the cut
        # pairs' relative motion under them (``P_a G~[:, L] = Z~[L]^T`` by symmetry)
        L = list(dict.fromkeys(d for e in spec.effects for d in e.load_dofs))
        self.L = tuple(L)
        self._loads = []            # (parameter slice, effect, indices of its load DOFs in L)
        if L:
            lidx = {d: i for i, d in enumerate(L)}
            self.Gsl = cond.G(S, L) if nS else np.zeros((0, len(L)))
            self.Gol = cond.G(self.o_dofs, L)
            self.Zl = cond.Z(L)
            for e, sl in zip(spec.effects, spec.effect_slices()):
                if e.load_dofs:
                    self._loads.append((sl, e, np.array([lidx[d] for d in e.load_dofs], dtype=int)))
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
        # effects that make a joint's stiffness depend on the case: (effect, its slice, the
        # joint's parameter slice, each spring's relative-rotation vector over S)
        self._case = []
        jsl = dict(zip((j.name for j in spec.joints), spec.joint_slices()))
        for e, sl in zip(spec.effects, spec.effect_slices()):
            name = e.case_joint
            if name is None:
                continue
            js = jsl[name]
            E = np.zeros((js.stop - js.start, nS))
            for q, i in enumerate(range(js.start, js.stop)):
                d = np.diag(self._jD[i])
                a = int(np.flatnonzero(d > 0)[0])
                E[q] = self._jD[i][:, a] / np.sqrt(d[a])       # +1 at the lower branch's DOF
            self._case.append((e, sl, js, E))

    def rigid_limits(self) -> np.ndarray:
        """Upper limits on the parameters beyond which a spring is rigid to rounding: a joint
        spring ``k_i`` (unit stiffness matrix ``dK_i``) stops at ``RIGID_RATIO / tr(G_SS dK_i)``,
        ``RIGID_RATIO`` times the stiffness the structure offers along it (``inf`` for the other
        parameters). The joint is then rigid to ``1 / RIGID_RATIO`` of the relative rotation,
        and the force through it (``dK u_S``, a difference of nearly equal rotations times ``k``)
        still keeps about ``16 - log10(RIGID_RATIO)`` digits; a spring far beyond (a misfit model's
        flat valley, 1e13-1e20) makes chi2 rounding noise of several units, which a refit would
        follow instead of the valley. A complex joint's diagonal entries of ``K_C`` get the same
        limit (its unit matrix ``B E_ii B^T``); :func:`~blackbox.diagnosis.fit.fit_model` uses it
        to recognise a rigid mode, never as a bound (a bound on one entry would cut ``K_C``'s
        positive definiteness)."""
        out = np.full(self.p, np.inf)
        if self._jD is None:
            return out
        for j, sl in zip(self.spec.joints, self.spec.joint_slices()):
            if isinstance(j, SimpleJoint):
                params = range(sl.start, sl.stop)
            elif isinstance(j, ComplexJoint):
                iu = np.triu_indices(j.m)
                params = sl.start + np.flatnonzero(iu[0] == iu[1])
            else:
                continue
            for i in params:
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
        Ainv = self._inverse(dK, D, IDK)
        us0, dt0, uo0 = self.loaded(x)
        b = np.vstack([us0, IDK @ dt0])
        z = Ainv @ b
        if not np.all(np.isfinite(z)):
            raise np.linalg.LinAlgError("singular augmented system")
        groups = stacked = None
        if self._case:
            z, groups, stacked = self._case_solve(x, dK, D, IDK, b, z, Ainv)
        u_S, f = z[:nS], z[nS:]
        if groups is None:
            dKu = dK @ u_S
        elif len(groups) > MANY_GROUPS:
            dKu = per_case(stacked[0], stacked[3], u_S)
        else:
            dKu = np.zeros_like(u_S)
            for cols, dKg, _, _ in groups:
                dKu[:, cols] = dKg @ u_S[:, cols]
        delta = dt0 - self.Zs.T @ dKu - self.St @ f
        U_O = uo0 - self.Gos @ dKu - self.Zo @ f
        return State(dK, D, Ainv, u_S, f, delta, U_O, groups, stacked)

    def load_change(self, x: np.ndarray) -> np.ndarray | None:
        """``(len(L), cases)``: the change of the study's loads at the DOFs ``L`` that the load
        effects make at ``x`` (``None`` without one)."""
        if not self._loads:
            return None
        dF = np.zeros((len(self.L), self.base.n_cases))
        for sl, e, li in self._loads:
            dF[li] += e.load_change(x[sl], self.base.cases)
        return dF

    def loaded(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(u0_S, delta0, u0_O)``: the split structure's response to the study's loads as the
        load effects change them at ``x`` (linear in the loads: the unit-load columns at ``L``)."""
        dF = self.load_change(x)
        if dF is None:
            return self.us0, self.dt0, self.uo0
        return self.us0 + self.Gsl @ dF, self.dt0 + self.Zl.T @ dF, self.uo0 + self.Gol @ dF

    def _inverse(self, dK: np.ndarray, D: np.ndarray, IDK: np.ndarray) -> np.ndarray:
        nS, m = self.nS, self.m
        A = np.zeros((nS + m, nS + m))
        A[:nS, :nS] = np.eye(nS) + self.Gss @ dK
        A[:nS, nS:] = self.Zs
        A[nS:, :nS] = IDK @ self.Zs.T @ dK
        A[nS:, nS:] = D + IDK @ self.St
        return np.linalg.inv(A)             # small (n_S + m): inverted once, applied many times

    def condition(self, x: np.ndarray) -> float:
        """The 2-norm condition number of the augmented system solved at ``x``: how much it
        amplifies the split run's rounding (large where a declared spring is many decades
        stiffer than the structure around it, e.g. a fit that wants a joint rigid)."""
        st = self.state(x)
        with np.errstate(all="ignore"):
            c = float(np.linalg.cond(st.Ainv))
        return c if np.isfinite(c) else float("inf")

    def _inverses(self, dKs: np.ndarray, D: np.ndarray, IDK: np.ndarray) -> np.ndarray:
        """:meth:`_inverse` of each stiffness change of the stack ``dKs`` ``(g, n_S, n_S)``."""
        nS, m = self.nS, self.m
        A = np.zeros((len(dKs), nS + m, nS + m))
        A[:, :nS, :nS] = np.eye(nS) + np.einsum("ij,gjk->gik", self.Gss, dKs)
        A[:, :nS, nS:] = self.Zs
        A[:, nS:, :nS] = np.einsum("ij,gjk->gik", IDK @ self.Zs.T, dKs)
        A[:, nS:, nS:] = D + IDK @ self.St
        return np.linalg.inv(A)

    CASE_ITERATIONS = 20

    def case_factors(self, x: np.ndarray, u_S: np.ndarray) -> np.ndarray:
        """``(joint params, cases)``: each joint parameter's stiffness factor in each case, from
        the case-dependent effects at the joint solution ``u_S`` (1 elsewhere; the product of
        the factors of several effects on one joint)."""
        phi = np.ones((self.spec.joint_params, u_S.shape[1]))
        for e, sl, js, E in self._case:
            phi[js] *= e.case_factors(E @ u_S, x[sl], self.base.cases)
        return phi

    def _case_solve(self, x, dK, D, IDK, b, z, Ainv0):
        """The cases solved with their own joint stiffness (factors ``phi`` from the case-dependent
        effects at the current solution), repeated until ``phi`` settles: a gap's side depends on
        the sign of the relative rotation it causes. Cases with equal factors share one inverse."""
        nS = self.nS
        jp = self.spec.joint_params
        xj = x[:jp]
        phi = self.case_factors(x, z[:nS])
        for _ in range(self.CASE_ITERATIONS):
            if jp == 1:                     # one joint parameter: a plain (faster) unique
                _, first, inv = np.unique(np.round(phi[0], 12), return_index=True, return_inverse=True)
            else:
                _, first, inv = np.unique(np.round(phi.T, 12), axis=0, return_index=True, return_inverse=True)
            inv = np.asarray(inv).reshape(-1)
            keys = phi.T[first]             # each group's factors as computed, not as rounded to group
            # every group's joint stiffness and inverse at once (stacked), the unit group's exact
            dKs = dK[None] + np.einsum("gi,ijk->gjk", (keys - 1.0) * xj, self._jD)
            As = self._inverses(dKs, D, IDK)
            ones = np.all(keys == 1.0, axis=1)
            As[ones] = Ainv0
            z = per_case(As, inv, b)
            if not np.all(np.isfinite(z)):
                raise np.linalg.LinAlgError("singular augmented system")
            new = self.case_factors(x, z[:nS])
            if np.array_equal(np.round(new, 12), np.round(phi, 12)):
                break
            phi = new
        # each group's cases, once the factors settled (slices of one sort: np.split into one
        # piece per case, as an amplitude-dependent joint has, costs more than the solve)
        order = np.argsort(inv, kind="stable")
        ends = np.searchsorted(inv[order], np.arange(1, len(keys) + 1))
        starts = np.concatenate([[0], ends[:-1]])
        groups = [(order[a:e], dKs[g], As[g], keys[g]) for g, (a, e) in enumerate(zip(starts, ends))]
        return z, groups, (dKs, As, keys, inv)

    def _output_mixes(self, om: ObsMap) -> list[tuple]:
        """``(parameter index, rows, terms, cases)`` of every output mix (:meth:`Effect.mix_rows`;
        ``cases`` None: the rows' own)."""
        if not any(type(e).mix_rows is not Effect.mix_rows for e in self._outputs):
            return []
        sl = dict(zip(self.spec.effects, self.spec.effect_slices()))
        o_index = self._o_index
        return [(sl[e].start + m[0], m[1], m[2], m[3] if len(m) > 3 else None)
                for e in self._outputs for m in e.mix_rows(om, o_index)]

    def pick(self, U: np.ndarray, x: np.ndarray, om: ObsMap) -> np.ndarray:
        """``U`` (observed DOFs x cases) at the rows of ``om``, with the output mixes applied
        (a channel that reads, in part ``x_q``, another DOF's motion or another case's: two
        channels swapped, a sensor on the neighbouring grid, two cases' readings exchanged):
        ``f_rows += x_q (source - f_rows)``. Linear in ``U``."""
        f = om.pick(U)
        mixes = self._output_mixes(om)
        if not mixes:
            return f
        out = f.copy()
        for i, rows, terms, cases in mixes:
            out[rows] += x[i] * (om.source(U, rows, terms, cases) - f[rows])
        return out

    def _mix_columns(self, U: np.ndarray, om: ObsMap) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """``d pick / d x_q`` of every mixing parameter: ``(q, rows, source - own)``."""
        f = om.pick(U)
        return [(i, rows, om.source(U, rows, terms, cases) - f[rows])
                for i, rows, terms, cases in self._output_mixes(om)]

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
            if rows.dtype.kind == "f":          # weights over every row (a rigid motion)
                add += x[i] * rows
            else:
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
        return self.multiplier(x, om) * self.pick(st.U_O, x, om) + self.offset(x, om)

    def structural_derivatives(self, x: np.ndarray, st: State, which: np.ndarray) -> np.ndarray:
        """``dU_O/dx_i`` for the structural parameters ``which``: ``(len(which), n_O, L)``. With
        case-dependent joint stiffness, per group of cases, the factors held fixed (a gap's side
        is piecewise constant in the parameters)."""
        nS, m, L = self.nS, self.m, self.base.n_cases
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
        load_B = {}                 # a load parameter's change of the loads at L, per unit
        for sl, e, li in self._loads:
            if any(sl.start <= i < sl.stop for i in which):
                dB = e.load_change_derivatives(x[sl], self.base.cases)
                for q in range(e.n_params):
                    B = np.zeros((len(self.L), L))
                    B[li] = dB[q]
                    load_B[sl.start + q] = B
        case_of = {}
        for e, sl, js, E in self._case:
            for q, i in enumerate(range(sl.start, sl.stop)):
                case_of[i] = (e, sl, js, E, q)
        jp = self.spec.joint_params
        out = np.zeros((len(which), len(self.o_dofs), L))
        if not len(which):
            return out

        def direction(i, u, phi, labels):
            """``dK/dx_i u`` over the cases of ``u`` (``None`` for a compliance parameter)."""
            if i < jp:
                return (self._jD[i] @ u) * (1.0 if phi is None else phi[i])
            if i in stiff:
                dKq = np.zeros((nS, nS))
                for idx, K_q in stiff[i]:
                    dKq[np.ix_(idx, idx)] += K_q
                return dKq @ u
            if i in case_of:
                e, sl, js, E, q = case_of[i]
                dphi = e.case_factor_derivatives(E @ u, x[sl], labels)[q]      # (joint params, cases)
                for e2, sl2, js2, E2 in self._case:     # times the other effects' factors there
                    if e2 is not e and js2 == js:
                        dphi = dphi * e2.case_factors(E2 @ u, x[sl2], labels)
                v = np.zeros_like(u)
                for k, ij in enumerate(range(js.start, js.stop)):
                    if np.any(dphi[k]):
                        v += (self._jD[ij] @ u) * (dphi[k] * x[ij])
                return v
            return None

        def rhs_of(i, v, cols):
            if i in load_B:             # the loads change, the structure does not
                B = load_B[i][:, cols]
                return -np.vstack([self.Gsl @ B, IDK @ (self.Zl.T @ B)])
            if v is not None:
                return np.vstack([self.Gss @ v, IDK @ (self.Zs.T @ v)])
            return np.vstack([np.zeros((nS, force[:, cols].shape[1])), basis[i] @ force[:, cols]])

        if st.groups is not None and len(st.groups) > MANY_GROUPS:
            # many groups (an amplitude-dependent joint: one per case): every case's inverse
            # applied at once instead of group by group
            dKs, As, keys, index = st.stacked
            phi = keys[index].T
            u, allc = st.u_S, np.arange(L)
            for q, i in enumerate(which):
                v = direction(i, u, phi, self.base.cases)
                dz = -per_case(As, index, rhs_of(i, v, allc))
                w = per_case(dKs, index, dz[:nS])
                if v is not None:
                    w = w + v
                out[q] = -self.Gos @ w - self.Zo @ dz[nS:]
                if i in load_B:
                    out[q] += self.Gol @ load_B[i]
            return out
        for cols, dKg, Ainv, phi in st.each():
            u = st.u_S[:, cols]
            labels = [self.base.cases[c] for c in np.arange(L)[cols]]
            vs = [direction(i, u, phi, labels) for i in which]
            rhs = [rhs_of(i, v, cols) for i, v in zip(which, vs)]
            n = u.shape[1]
            dz = -(Ainv @ np.hstack(rhs)).reshape(nS + m, len(rhs), n).transpose(1, 0, 2)
            for q, v in enumerate(vs):
                du_S, df = dz[q, :nS], dz[q, nS:]
                w = dKg @ du_S
                if v is not None:
                    w = w + v
                out[q][:, cols] = -self.Gos @ w - self.Zo @ df
                if which[q] in load_B:
                    out[q][:, cols] += self.Gol @ load_B[which[q]][:, cols]
        return out

    def jacobian(self, x: np.ndarray, om: ObsMap, st: State | None = None) -> np.ndarray:
        """``d prediction / dx`` at the rows of ``om``: ``(n_obs, n_params)``, natural coordinates."""
        return self.jacobians(x, (om,), st)[0]

    def jacobians(self, x: np.ndarray, oms, st: State | None = None) -> list[np.ndarray]:
        """:meth:`jacobian` at each row set of ``oms``, the structural derivatives solved once."""
        x = np.asarray(x, float)
        st = self.state(x) if st is None else st
        structural = self._structural
        dU = self.structural_derivatives(x, st, structural) if structural.size else None
        return [self._jacobian_rows(x, om, st, dU) for om in oms]

    def _jacobian_rows(self, x: np.ndarray, om: ObsMap, st: State, dU) -> np.ndarray:
        mult = self.multiplier(x, om)
        base = self.pick(st.U_O, x, om)
        J = np.zeros((len(om.y), self.p))
        if dU is not None:
            for q, i in enumerate(self._structural):
                J[:, i] = mult * self.pick(dU[q], x, om)
        factors = self._output_factors(om)
        for k, (i, rows) in enumerate(factors):
            other = np.ones(len(om.y))          # the other factors' product (x_i may cross 0)
            for k2, (i2, rows2) in enumerate(factors):
                if k2 != k:
                    other[rows2] *= x[i2]
            J[rows, i] += other[rows] * base[rows]
        for i, rows, col in self._mix_columns(st.U_O, om):
            J[rows, i] += mult[rows] * col
        for i, rows in self._output_offsets(om):
            if rows.dtype.kind == "f":
                J[:, i] = rows
            else:
                J[rows, i] = 1.0
        return J
