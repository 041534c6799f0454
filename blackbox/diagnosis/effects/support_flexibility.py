"""``support_flexibility``: a clamped (or partly constrained) grid is really elastic.

Cut: the grid's SPC components (SPC1 sets and GRID PS) are removed and each is replaced by a
grounded spring ``K0`` (the sum of the members' own stiffness at the grid in that component).
Released, as the data support (:func:`~blackbox.diagnosis.effects.connection.grounded_ladder`):
"equal" (``ks_G_T``, ``ks_G_R``: one factor on that stiffness for the translations and one for
the rotations) or "per-axis" (``ks_G_C``: one spring per constrained component). Grids in an RBE2 or with
no member have no candidate.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blackbox.diagnosis.decks import constrained_grids, rbe2_grids
from blackbox.diagnosis.effects.connection import GridConnection, grounded_ladder
from blackbox.diagnosis.effects.registry import register
from solver_adapters.protocol import Spc1

__all__ = ["SupportFlexibility"]


@register
@dataclass(frozen=True, eq=False)
class SupportFlexibility(GridConnection):
    kind = "support_flexibility"
    summary = "a constrained grid is elastic (grounded springs instead of its SPC components)"

    @classmethod
    def cut(cls, editor, ctx) -> list["SupportFlexibility"]:
        deck, d = editor.original, editor.deck
        at = editor.members_at
        in_rbe2 = rbe2_grids(deck)
        out = []
        for g, comps in sorted(constrained_grids(deck).items()):
            if g in in_rbe2 or g not in at:
                continue
            new_spc = []
            for s in d.spc1s:
                if g in s.grids:
                    rest = tuple(x for x in s.grids if x != g)
                    if rest:
                        new_spc.append(replace(s, grids=rest))
                    left = "".join(c for c in s.components if c not in comps)
                    if left:
                        new_spc.append(Spc1(s.sid, left, (g,)))
                else:
                    new_spc.append(s)
            d.spc1s = new_spc
            if d.grids[g].ps:
                d.grids[g] = replace(d.grids[g], ps="")
            idx, ks = [], []
            for c in comps:
                k0 = editor.bridge(g, int(c), at[g], "sum")
                idx.append(editor.connect(k0, (g, int(c))))
                ks.append(k0)
            out.append(cls.on_ladder((g,), idx, grounded_ladder(comps, np.array(ks), f"ks_{g}")))
        return out
