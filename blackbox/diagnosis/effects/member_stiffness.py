"""``member_stiffness``: a member is stiffer or softer than the deck says (a factor on its ``K_e``).

``dK = (alpha - 1) K_e`` on the member's 12 end DOFs in the split deck, ``K_e`` the solver's own
element from the element deck's run. Its score at ``alpha = 1`` needs only rows of the
flexibility at the member's DOFs under the unit loads at ``B`` and ``O`` (reciprocity), which the
split run reports (:meth:`MemberStiffness.batch_columns`: every member scored without a run); its
refit needs the member's own columns, one batched run for every short-listed member of a round.
Candidates: every member.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.registry import register
from solver_adapters.protocol import DofLabel

__all__ = ["MemberStiffness"]


@register
@dataclass(frozen=True, eq=False)
class MemberStiffness(Effect):
    """``dofs``: the member's 12 end DOFs in the split deck; ``K_e`` its stiffness over them."""
    kind = "member_stiffness"
    summary = "a member's stiffness differs from the deck's (a factor on its element matrix)"

    dofs: tuple[DofLabel, ...] = ()
    K_e: np.ndarray | None = None

    @property
    def eid(self) -> int:
        return int(self.where[0])

    @classmethod
    def candidates(cls, ctx, split) -> list["MemberStiffness"]:
        return [cls((eid,), (f"alpha_{eid}",), dofs=split.member_dofs[eid], K_e=ctx.K_e[eid])
                for eid in sorted(ctx.K_e)]

    @property
    def bounds(self):
        return np.full(self.n_params, 0.02), np.full(self.n_params, 50.0)

    @property
    def stiffness_dofs(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def stiffness_terms(self):
        return [(0, self.K_e)]

    def refit_columns(self) -> tuple[DofLabel, ...]:
        return self.dofs

    @classmethod
    def batch_columns(cls, model, st, x, om, effects):
        """``d prediction / d alpha_e`` at ``alpha_e = 1`` for members NOT in ``model``, by
        reciprocity: ``u_E`` and ``G_ES``, ``G_OE`` are rows of the split run at the member's
        DOFs, so no column of the member's own is needed."""
        nS, m = model.nS, model.m
        IDK = np.eye(m) - st.D * model.K0[None, :]
        cond = model.cond
        out = np.zeros((len(om.y), len(effects)))
        for q, e in enumerate(effects):
            E = list(e.dofs)
            G_ES = cond.G(E, model.S) if nS else np.zeros((len(E), 0))
            Z_E = cond.Z(E)
            u_E = cond.u0(E) - G_ES @ (st.dK @ st.u_S) - Z_E @ st.f
            F = e.K_e @ u_E                                           # (12, L)
            rhs = np.vstack([G_ES.T @ F, IDK @ (Z_E.T @ F)])
            dz = -st.Ainv @ rhs
            du_S, df = dz[:nS], dz[nS:]
            G_OE = cond.G(model.o_dofs, E)
            dU = -model.Gos @ (st.dK @ du_S) - G_OE @ F - model.Zo @ df
            out[:, q] = om.pick(dU)
        return out * model.multiplier(x, om)[:, None]

    def marker_points(self, xyz, deck):
        b = deck.cbars[self.eid]
        return [(xyz[b.ga] + xyz[b.gb]) / 2]
