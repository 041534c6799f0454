"""``undeclared_joint``: a grid where members meet rigidly in the study is really a flexible joint.

Cut: the grid is split into one grid per member (the first member keeps the original grid), the
branches are tied in translation by an RBE2 (CM=123) as the study's joints are, and their
rotations are bridged by springs ``K0`` (the smaller of the two members' own rotational stiffness
at the grid). Released, as the data support (:func:`~blackbox.diagnosis.effects.connection.branch_ladder`):
"equal" (``k_G``: one factor on that stiffness about every global axis), "per-axis" (``kx_G, ky_G,
kz_G``: equal springs between every pair of branches about each axis) or "per-branch" (``kx_G_eE``
...: per axis, a spring from each member ``E``'s end to the joint's centre; three or more members).
Beside it, on the same cut, each member's end hinged ("hinge", ``kh_G_eE``, then "hinge-per-axis",
``khy_G_eE``, ``khz_G_eE``: springs about the member's own bending axes, y and z, between its end and
the joint's centre; :func:`~blackbox.diagnosis.effects.connection.hinge_ladder`): a pin, a shear
connection or a bolted end plate where the model has a rigid connection, which springs about the
basic axes cannot release alone when the member is at a skew to them (track ``hinge-e<EID>``;
reported with ``member`` and pattern ``hinged``). The first member keeps the grid's rotations,
and with them the moments applied and the rotations read there, so its hinge is a candidate only
at a grid with neither (forces and translations, tied to every branch, are the joint's).
Candidates: grids of >= 2 members that are not a declared joint's, constrained, in an RBE2, on a
spring or on an element the reader does not model (a shell, a solid); beyond ``max_joint_candidates``
those nearest the declared fit's residual concentration
(:meth:`~blackbox.diagnosis.effects.base.CandidateContext.nearest_residual`; without a declared
fit, those nearest the measured grids), and the diagnosis says how many it left out. Each candidate
grid costs ``3 (n - 1)`` right-hand sides of the split run (``n`` members), so the cap bounds that
run on a large model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blackbox.diagnosis.decks import constrained_grids, member_axes, members_at, rbe2_grids, unsplittable_grids
from blackbox.diagnosis.effects.base import CandidateLimit
from blackbox.diagnosis.effects.connection import GridConnection, branch_ladder, hinge_ladder
from blackbox.diagnosis.effects.registry import register
from solver_adapters.protocol import Deck, Rbe2

__all__ = ["UndeclaredJoint", "joint_candidate_grids"]


def joint_candidate_grids(deck: Deck, declared_grids: set[int]) -> list[int]:
    """Grids where >= 2 members meet that could be an undeclared flexible joint: not a declared
    joint's grid, not constrained, not in an RBE2, no scalar spring, and no element the reader
    does not model (:func:`unsplittable_grids`)."""
    at = members_at(deck)
    fixed = set(constrained_grids(deck))
    sprung = {g for s in deck.springs.values() for g in (s.g1, s.g2) if g}
    skip = declared_grids | fixed | rbe2_grids(deck) | sprung | set(unsplittable_grids(deck))
    return [g for g in sorted(at) if len(at[g]) >= 2 and g not in skip]


def _turned_at(ctx) -> set[int]:
    """The grids a load case puts a moment on or a reading measures a rotation of (components
    4-6; fitted or hold-out cases)."""
    out = set()
    if ctx.loads is not None:
        out |= {int(g) for g, c in ctx.loads.dofs if int(c) >= 4}
    for obs in (ctx.measured, ctx.fit_obs):
        if obs is not None:
            out |= {int(g) for g, c in obs.dofs if int(c) >= 4}
    return out


@register
@dataclass(frozen=True, eq=False)
class UndeclaredJoint(GridConnection):
    kind = "undeclared_joint"
    summary = "a grid where members meet is a flexible joint (rotation springs between its members)"

    @classmethod
    def cut(cls, editor, ctx) -> list["UndeclaredJoint"]:
        declared = {g for j in ctx.joints for g in j.grids}
        grids = joint_candidate_grids(ctx.deck, declared)
        if len(grids) > ctx.max_joint_candidates:
            grids = ctx.nearest_residual({g: ctx.deck.grids[g].xyz for g in grids}, ctx.max_joint_candidates)
            ctx.note_limit(CandidateLimit(
                cls.kind, len(grids), len(joint_candidate_grids(ctx.deck, declared)),
                "the grids nearest the declared fit's residual" if ctx.residual_rms is not None
                else "the grids nearest the measured grids (no declared fit)", "max_joint_candidates"))
        at = editor.members_at
        d = editor.deck
        turned = _turned_at(ctx)
        out = []
        for g in grids:
            eids = at[g]
            branches = [g]
            for eid in eids[1:]:
                ng = editor.new_grid(g)
                b = d.cbars[eid]
                d.cbars[eid] = replace(b, ga=ng if b.ga == g else b.ga, gb=ng if b.gb == g else b.gb)
                branches.append(ng)
            eid = editor.new_eid()
            d.rbe2s[eid] = Rbe2(eid, g, "123", tuple(branches[1:]))
            editor.split_grids[g] = tuple(branches)
            idx, k_ref = [], []
            for c in (4, 5, 6):
                ks = []
                for i in range(1, len(eids)):
                    k0 = editor.bridge(g, c, [eids[i], eids[0]])
                    idx.append(editor.connect(k0, (branches[i], c), (g, c)))
                    ks.append(k0)
                k_ref.append(float(np.mean(ks)))
            ladder = branch_ladder(len(eids), np.array(k_ref), (f"kx_{g}", f"ky_{g}", f"kz_{g}"), f"k_{g}",
                                   tuple(f"e{e}" for e in eids))
            out.append(cls.on_ladder((g,), idx, ladder))
            # one member's end hinged (or connected less rigidly than modelled) about its own
            # bending axes: the springs above are per basic axis, which a member at a skew to
            # them cannot release alone, so each member end is a track of its own on the same cut
            frame = editor.original.displacement_frames([g])[0]
            for b, e in enumerate(eids):
                axes = member_axes(editor.original, e)
                if axes is None or (b == 0 and g in turned):
                    # the first member keeps the grid's rotations, and with them the moments
                    # applied there and the rotations read there: its end hinged would leave
                    # them on its side of the hinge, where the real joint's are on the others'
                    # (the translations, tied to every branch, stay the joint's)
                    continue
                hinge = hinge_ladder(len(eids), b, axes @ frame.T, np.array(k_ref),
                                     (f"kh_{g}_e{e}", f"khy_{g}_e{e}", f"khz_{g}_e{e}"))
                out.append(cls.on_ladder((g,), idx, hinge, track=f"hinge-e{e}"))
        return out

    @property
    def hinged_member(self) -> int | None:
        """The member whose end this candidate hinges (a ``hinge-e<EID>`` track), else ``None``."""
        return int(self.track[len("hinge-e"):]) if self.track.startswith("hinge-e") else None

    def details_json(self) -> dict:
        eid = self.hinged_member
        return {**super().details_json(), **({"member": eid} if eid is not None else {})}

    def findings(self, fit) -> dict:
        out = super().findings(fit)
        eid = self.hinged_member
        if eid is not None:
            g = self.where[0]
            out.update({"pattern": "hinged",
                        "pattern_detail": f"member {eid}'s end at grid {g} turns against the joint about its own "
                                          f"bending axes (y and z of the member): a hinge, or a connection less "
                                          f"rigid than the model's"})
        return out

    def label(self) -> str:
        eid = self.hinged_member
        return super().label() + (f" member {eid}" if eid is not None else "")
