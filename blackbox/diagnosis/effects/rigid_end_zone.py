"""``rigid_end_zone``: the members at a joint are rigid over a length ``e`` from its centre.

A frame model draws its members to the joint's centre; a joint whose core is stiffer than the
members (a welded node, a cast node, thick walls with diaphragms) has no flexible beam there, and
no positive joint spring can make the model stiffer than rigid. Structural engineers give each
member a *rigid end zone* at the joint: the member is rigid from the joint's centre over a length
``e`` (about half the depth of the members it joins) and flexible over the rest, ``L - e``.

*The member with a zone, from its own element.* A prismatic member's cantilever flexibility
(clamped at one end, loaded at the other, length ``l``) is a polynomial in ``l`` whatever the
element axes (:func:`beam_polynomial`)::

    F_uu = l S - l^3/3 X D X      F_ut = -l^2/2 X D      F_tu = l^2/2 D X      F_tt = l D

with ``D`` the bending and torsion compliance per unit length (``1/EI``, ``1/GJ`` in the
element axes), ``S`` the axial and shear compliance per unit length (``1/EA``, ``1/(kGA)``:
Timoshenko; 0 shear compliance: Euler-Bernoulli) and ``X = [ex x]`` the member's direction. Both
are read from the member's black-box ``K_e`` (the element run,
:func:`blackbox.diagnosis.runs.element_stiffness`): its cantilever flexibility at full length
gives ``D = F_tt / L`` and ``S``, and its ``F_tu`` must be ``L^2/2 D X`` (a member where it is not
-- offsets, pin flags, a tapered element -- is no prismatic beam, and a joint with such a member
has no candidate). With the zone at end A (the clamped end of the cantilever view), the member is
the cantilever of the flexible part, clamped through the rigid zone::

    K(e) = T^T F(L - e)^-1 T,       T = [-Gamma, I]

with the same rigid-body map ``T`` as ``K_e`` (the zone moves with end A). This is what NASTRAN's
CBAR with an offset ``WA = e ex`` is (``tests/test_rigid_end_zone.py`` checks it against the
reference solver's own element to round-off). The change ``dK(e) = T^T (F(L-e)^-1 - F(L)^-1) T``
is exactly 0 at ``e = 0``, and ``d dK / de = T^T F^-1 F'(L-e) F^-1 T`` (``F' = dF/dl``). ``K_e``
is in basic axes; both matrices are then turned into the components of the member's grids (their
CD systems, :func:`blackbox.diagnosis.decks.member_frames`), as the split deck has them. A member
with pin flags or offsets on its card has no zone, whatever its ``K_e``.

*Parameters.* ``e`` in metres, from the joint's centre (the declared joint's grid, or the grid where
the members meet), nested at 0 (one-sided: a zone cannot be shorter than nothing) and bounded by
half the shortest member at the joint. Variants: "common" (``e_J``: one length for every member
at the joint) and, with two or more members, "per-member" (``e_J_eE``: one length per member,
nested at all equal); the data choose (:func:`blackbox.diagnosis.search.refine`). It enters the
augmented model through the nonlinear stiffness hook
(:meth:`~blackbox.diagnosis.effects.base.Effect.stiffness_matrix`); its score at ``e = 0`` needs
only rows of the split run at the members' DOFs (reciprocity, :meth:`RigidEndZone.batch_columns`,
as ``member_stiffness``).

Candidates: every declared joint (its branch members, ``where`` = its name) and every grid where
members meet that could be an undeclared joint
(:func:`~blackbox.diagnosis.effects.undeclared_joint.joint_candidate_grids`; ``where`` = the
grid); beyond ``max_joint_candidates`` grids, those nearest the declared fit's residual. Two zones
on one member (the joints at both its ends) are not combined: once one is in the model, a zone
at the member's other end is not offered.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blackbox.diagnosis.decks import member_frames, members_at
from blackbox.diagnosis.effects.base import CandidateLimit, Effect, kept_parameters
from blackbox.diagnosis.effects.registry import register
from blackbox.diagnosis.effects.undeclared_joint import joint_candidate_grids
from solver_adapters.protocol import DofLabel

__all__ = ["RigidEndZone", "ZoneMember", "beam_polynomial", "zone_stiffness", "PRISMATIC_RTOL", "E_MAX_FRACTION"]

PRISMATIC_RTOL = 1e-4       # F_tu of K_e against the prismatic beam's L^2/2 D X (scaled by the
                            # diagonal): above this the member is no prismatic beam (a sideways
                            # offset of 0.1 % of L gives 2e-2); a K_e from 7-digit flexibilities
                            # is off ~1e-6
E_MAX_FRACTION = 0.5        # a zone reaches at most half the shortest member at the joint
AT_BOUND = 1e-9             # a per-member length (m) below this after a refit: that member has no zone
START_FRACTION = 0.2        # a third refit start: every zone at 0.2 x its upper bound


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def _unskew(S: np.ndarray) -> np.ndarray:
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


@dataclass(frozen=True, eq=False)
class Prismatic:
    """A prismatic member's cantilever polynomial (module docstring): its length ``L``, direction
    ``X = [ex x]`` (from its zone end), compliances per unit length ``D`` (bending, torsion) and
    ``S`` (axial, shear), and ``T`` the rigid-body map (6 x 12, DOFs zone end first)."""
    L: float
    X: np.ndarray
    D: np.ndarray
    S: np.ndarray
    T: np.ndarray

    def flexibility(self, l: float) -> np.ndarray:
        """``F(l)``: the tip flexibility (6 x 6) of the cantilever of length ``l``."""
        X, D, S = self.X, self.D, self.S
        F = np.empty((6, 6))
        F[:3, :3] = l * S - l ** 3 / 3.0 * X @ D @ X
        F[:3, 3:] = -l ** 2 / 2.0 * X @ D
        F[3:, :3] = l ** 2 / 2.0 * D @ X
        F[3:, 3:] = l * D
        return 0.5 * (F + F.T)

    def flexibility_rate(self, l: float) -> np.ndarray:
        """``dF/dl`` at ``l``."""
        X, D, S = self.X, self.D, self.S
        F = np.empty((6, 6))
        F[:3, :3] = S - l ** 2 * X @ D @ X
        F[:3, 3:] = -l * X @ D
        F[3:, :3] = l * D @ X
        F[3:, 3:] = D
        return 0.5 * (F + F.T)


def beam_polynomial(K_e: np.ndarray, zone_end: int = 0) -> tuple[Prismatic | None, str]:
    """The cantilever polynomial of the member whose black-box stiffness is ``K_e`` (12 x 12,
    global axes, DOFs ``a1..a6, b1..b6``) seen from ``zone_end`` (0: a, 1: b), or ``None`` and
    why not (no prismatic beam: its ``F_tu`` is not ``L^2/2 D X`` to ``PRISMATIC_RTOL``)."""
    K = np.asarray(K_e, float)
    if zone_end:
        p = np.r_[6:12, 0:6]
        K = K[np.ix_(p, p)]
    K_bb, K_ba = K[6:, 6:], K[6:, :6]
    try:
        gamma = -np.linalg.solve(K_bb, K_ba)
        F = np.linalg.inv(K_bb)
    except np.linalg.LinAlgError:
        return None, "its cantilever stiffness is singular"
    F = 0.5 * (F + F.T)
    r = _unskew(-gamma[:3, 3:])
    L = float(np.linalg.norm(r))
    if not L > 0.0:
        return None, "its ends coincide"
    X = _skew(r / L)
    D = F[3:, 3:] / L
    S = (F[:3, :3] + L ** 3 / 3.0 * X @ D @ X) / L
    d = np.sqrt(np.abs(np.diag(F)))
    ref = L ** 2 / 2.0 * D @ X
    dev = float(np.max(np.abs(F[3:, :3] - ref) / np.outer(d[3:], d[:3])))
    if not dev <= PRISMATIC_RTOL:
        return None, f"it is no prismatic beam (its flexibility departs from one by {dev:.2g})"
    T = np.hstack([-gamma, np.eye(6)])
    return Prismatic(L, X, 0.5 * (D + D.T), 0.5 * (S + S.T), T), ""


def zone_stiffness(K_e: np.ndarray, e: float, zone_end: int = 0) -> np.ndarray:
    """The member of stiffness ``K_e`` with a rigid zone of length ``e`` at ``zone_end``: its
    12 x 12 stiffness (same DOFs as ``K_e``), ``K_e + dK(e)`` (module docstring)."""
    pm, why = beam_polynomial(K_e, zone_end)
    if pm is None:
        raise ValueError(f"no rigid zone for this member: {why}")
    return np.asarray(K_e, float) + ZoneMember.of(pm, tuple(range(12)), zone_end).change(e)


@dataclass(frozen=True, eq=False)
class ZoneMember:
    """One member at the joint: its element id, its 12 DOFs in the split deck (the CBAR's end a
    first), which end is at the joint (0: a, 1: b), its cantilever polynomial from there (basic
    axes, as ``K_e``) and ``frame``: the rotation from basic to its grids' displacement components
    (:func:`blackbox.diagnosis.decks.member_frames`; ``None``: basic)."""
    eid: int
    dofs: tuple[DofLabel, ...]
    zone_end: int
    poly: Prismatic
    frame: np.ndarray | None = None

    @classmethod
    def of(cls, poly: Prismatic, dofs, zone_end: int, eid: int = 0) -> "ZoneMember":
        return cls(eid, tuple(dofs), zone_end, poly)

    def _unpermute(self, M: np.ndarray) -> np.ndarray:
        """From the zone end first (basic) to the split deck's DOFs: the CBAR's end a first, in
        its grids' displacement components."""
        if self.zone_end:
            p = np.r_[6:12, 0:6]
            out = np.empty_like(M)
            out[np.ix_(p, p)] = M
            M = out
        return M if self.frame is None else self.frame @ M @ self.frame.T

    def change(self, e: float) -> np.ndarray:
        """``dK(e) = T^T (F(L-e)^-1 - F(L)^-1) T`` over the member's 12 DOFs."""
        pm = self.poly
        dKbb = np.linalg.inv(pm.flexibility(pm.L - e)) - np.linalg.inv(pm.flexibility(pm.L))
        M = pm.T.T @ dKbb @ pm.T
        return self._unpermute(0.5 * (M + M.T))

    def rate(self, e: float) -> np.ndarray:
        """``d dK / de`` at ``e``: ``T^T F^-1 F'(L-e) F^-1 T``."""
        pm = self.poly
        Kbb = np.linalg.inv(pm.flexibility(pm.L - e))
        M = pm.T.T @ (Kbb @ pm.flexibility_rate(pm.L - e) @ Kbb) @ pm.T
        return self._unpermute(0.5 * (M + M.T))


@register
@dataclass(frozen=True, eq=False)
class RigidEndZone(Effect):
    """``members``: the members at the joint with a zone; ``dofs``: the union of their DOFs in
    the split deck (the order of :attr:`stiffness_dofs`); ``e_max``: the upper bound of each
    length (m); ``grid``: the joint's centre grid."""
    kind = "rigid_end_zone"
    summary = ("the members at a joint are rigid over a length e from its centre (a joint stiffer than the "
               "beams drawn through it)")

    members: tuple[ZoneMember, ...] = ()
    dofs: tuple[DofLabel, ...] = ()
    e_max: float = 0.0
    grid: int = 0               # the joint's centre (a declared joint's first grid)

    # ---- listing ------------------------------------------------------------------------------
    @classmethod
    def _places(cls, ctx) -> list[tuple[tuple, int, list[tuple[int, int]]]]:
        """``[(where, centre grid, [(eid, zone end)])]``: the declared joints (their branch
        members) and the candidate grids (their members), in that order; grids capped by
        ``max_joint_candidates``."""
        deck = ctx.deck
        at = members_at(deck)
        out = []
        for j in ctx.joints:
            mem = []
            for g in j.grids:
                for eid in at.get(g, ()):
                    b = deck.cbars[eid]
                    mem.append((eid, 0 if b.ga == g else 1))
            out.append(((j.name,), int(j.grids[0]), mem))
        declared = {g for j in ctx.joints for g in j.grids}
        grids = joint_candidate_grids(deck, declared)
        if len(grids) > ctx.max_joint_candidates:
            chosen = ctx.nearest_residual({g: deck.grids[g].xyz for g in grids}, ctx.max_joint_candidates)
            ctx.note_limit(CandidateLimit(
                cls.kind, len(chosen), len(grids),
                "the grids nearest the declared fit's residual" if ctx.residual_rms is not None
                else "the grids nearest the measured grids (no declared fit)", "max_joint_candidates"))
            grids = chosen
        for g in grids:
            out.append(((g,), g, [(eid, 0 if deck.cbars[eid].ga == g else 1) for eid in at[g]]))
        return out

    @classmethod
    def split_rows(cls, ctx, split) -> tuple[DofLabel, ...]:
        """Every considered member's DOFs: the score reads the split run's rows there."""
        return tuple(d for _, _, mem in cls._places(ctx) for eid, _ in mem for d in split.member_dofs[eid])

    @classmethod
    def candidates(cls, ctx, split) -> list["RigidEndZone"]:
        out = []
        for where, grid, mem in cls._places(ctx):
            if len(mem) < 2 or any(eid not in ctx.K_e for eid, _ in mem):
                continue
            zm = []
            for eid, end in mem:
                b = ctx.deck.cbars[eid]
                if b.pa or b.pb or b.wa is not None or b.wb is not None:
                    break           # pin flags or offsets: no prismatic beam between its grids
                poly, _ = beam_polynomial(ctx.K_e[eid], end)
                if poly is None:
                    break
                g = ctx.deck.grids
                frame = member_frames(ctx.deck, eid) if (g[b.ga].cd or g[b.gb].cd) else None
                zm.append(ZoneMember(eid, split.member_dofs[eid], end, poly, frame))
            else:
                tag = where[0]
                dofs = tuple(dict.fromkeys(d for m in zm for d in m.dofs))
                e_max = E_MAX_FRACTION * min(m.poly.L for m in zm)
                out.append(cls(where, (f"e_{tag}",), "common", members=tuple(zm), dofs=dofs, e_max=e_max,
                               grid=grid))
        return out

    def applicable(self, spec) -> bool:
        """Not on a member that already has a zone at its other end (two zones are not combined)."""
        mine = {m.eid for m in self.members}
        return not any(isinstance(e, RigidEndZone) and e.key != self.key and mine & {m.eid for m in e.members}
                       for e in spec.effects)

    # ---- parameters ---------------------------------------------------------------------------
    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(self.n_params)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(self.n_params), np.full(self.n_params, self.e_max)

    @property
    def one_sided(self) -> np.ndarray:
        return np.ones(self.n_params, bool)

    def _lengths(self, x_effect) -> np.ndarray:
        """Each member's zone length from the parameters."""
        x = np.asarray(x_effect, float)
        return np.full(len(self.members), x[0]) if self.variant == "common" else x

    # ---- the augmented model ------------------------------------------------------------------
    @property
    def stiffness_dofs(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def _index(self, m: ZoneMember) -> np.ndarray:
        at = {d: i for i, d in enumerate(self.dofs)}
        return np.array([at[d] for d in m.dofs])

    def stiffness_matrix(self, x_effect) -> np.ndarray:
        n = len(self.dofs)
        out = np.zeros((n, n))
        for m, e in zip(self.members, self._lengths(x_effect)):
            i = self._index(m)
            out[np.ix_(i, i)] += m.change(float(e))
        return out

    def stiffness_derivatives(self, x_effect) -> np.ndarray:
        n = len(self.dofs)
        out = np.zeros((self.n_params, n, n))
        for q, (m, e) in enumerate(zip(self.members, self._lengths(x_effect))):
            i = self._index(m)
            out[0 if self.variant == "common" else q][np.ix_(i, i)] += m.rate(float(e))
        return out

    # ---- scoring and refits -------------------------------------------------------------------
    def refit_columns(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def refit_starts(self, x2, step, lo, hi, first):
        starts = super().refit_starts(x2, step, lo, hi, first)
        xs = x2.copy()
        xs[first:] = START_FRACTION * self.e_max
        return starts + [xs]

    @classmethod
    def batch_columns(cls, model, st, x, om, effects):
        """``d prediction / d e`` at ``e = 0`` for zones NOT in ``model``, by reciprocity (as
        :meth:`blackbox.diagnosis.effects.member_stiffness.MemberStiffness.batch_columns`, with
        ``dK/de`` at 0 over the members' DOFs): rows of the split run, no column of their own."""
        if any(e.variant != "common" for e in effects):
            return None
        nS, m = model.nS, model.m
        IDK = np.eye(m) - st.D * model.K0[None, :]
        cond = model.cond
        out = np.zeros((len(om.y), len(effects)))
        # observed DOFs without unit-load columns (read only by a mix not yet added) stay 0, as
        # in member_stiffness
        loaded = [i for i, d in enumerate(model.o_dofs) if d in cond.base.col_of]
        o_loaded = [model.o_dofs[i] for i in loaded]
        groups = st.each()
        for q, e in enumerate(effects):
            E = list(e.dofs)
            G_ES = cond.G(E, model.S) if nS else np.zeros((len(E), 0))
            Z_E = cond.Z(E)
            G_OE = np.zeros((len(model.o_dofs), len(E)))
            G_OE[loaded] = cond.G(o_loaded, E)
            u0E = cond.u0(E)
            dKe = e.stiffness_derivatives(e.nominal)[0]
            dU = np.zeros_like(st.U_O)
            for cols, dK, Ainv, _ in groups:         # cases with their own joint stiffness (a gap)
                u_E = u0E[:, cols] - G_ES @ (dK @ st.u_S[:, cols]) - Z_E @ st.f[:, cols]
                F = dKe @ u_E
                rhs = np.vstack([G_ES.T @ F, IDK @ (Z_E.T @ F)])
                dz = -Ainv @ rhs
                du_S, df = dz[:nS], dz[nS:]
                dU[:, cols] = -model.Gos @ (dK @ du_S) - G_OE @ F - model.Zo @ df
            out[:, q] = model.pick(dU, x, om)
        return out * model.multiplier(x, om)[:, None]

    # ---- variants -----------------------------------------------------------------------------
    @property
    def variant_tests(self) -> int:
        return 1 if self.variant == "common" and len(self.members) >= 2 else 0

    def richer(self, x_effect):
        """"common" -> "per-member", every member's length at the common one."""
        if self.variant != "common" or len(self.members) < 2:
            return []
        tag = self.where[0]
        names = tuple(f"e_{tag}_e{m.eid}" for m in self.members)
        return [(replace(self, names=names, variant="per-member"),
                 np.full(len(self.members), float(np.asarray(x_effect)[0])))]

    def trimmed(self, x_effect) -> "RigidEndZone | None":
        """Per member: the members whose length ended at 0 have no zone (at least one stays)."""
        if self.variant != "per-member":
            return None
        keep = kept_parameters(x_effect, AT_BOUND)
        if keep is None:
            return None
        members = tuple(m for m, k in zip(self.members, keep) if k)
        return replace(self, names=tuple(n for n, k in zip(self.names, keep) if k), members=members,
                       dofs=tuple(dict.fromkeys(d for m in members for d in m.dofs)))

    # ---- reports ------------------------------------------------------------------------------
    def details_json(self) -> dict:
        return {**super().details_json(), "members": [m.eid for m in self.members],
                "member_lengths": [m.poly.L for m in self.members]}

    def parameters(self, fit) -> list[dict]:
        """The lengths, in metres from the joint's centre."""
        return [{**p, "unit": "m"} for p in super().parameters(fit)]

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []
