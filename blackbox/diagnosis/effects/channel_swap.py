"""``channel_swap``: two measurement channels were exchanged in every case (two cables plugged
into each other's logger inputs, two gauges' labels swapped).

Two channels of the same component at two grids ``a < b``. A mixing fraction ``s`` (bounded to ``[0, 2]``):
channel ``a`` reads ``(1 - s) u_a + s u_b`` and ``b`` reads ``(1 - s) u_b + s u_a``; ``s = 0`` is
the declared wiring (nested, one-sided), ``s = 1`` the full swap, and the interval says how sure
it is. Linear in ``s``, exact, no run. A refit that ends below ``s = 1/2`` is no swap (the
channels mostly read their own grid), one above 3/2 more than a swap: rejected, with the reason. Candidates: every pair of
fitted channels of one component at two grids, scored in one sparse batch (the column is
``u_b - u_a`` on ``a``'s rows and ``u_a - u_b`` on ``b``'s).

``where`` is the two grids, the component in the details (and the key). A data defect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect, ReadsAnother
from blackbox.diagnosis.effects.registry import register

__all__ = ["ChannelSwap"]


@register
@dataclass(frozen=True, eq=False)
class ChannelSwap(ReadsAnother, Effect):
    kind = "channel_swap"
    summary = "two measurement channels were exchanged (the data, not the structure)"
    of_data = True

    component: int = 0

    @classmethod
    def candidates(cls, ctx, split) -> list["ChannelSwap"]:
        by_comp: dict[int, list[int]] = {}
        for g, c in dict.fromkeys(ctx.fit_obs.dofs):
            by_comp.setdefault(int(c), []).append(int(g))
        out = []
        for c, grids in sorted(by_comp.items()):
            grids = sorted(set(grids))
            for i, a in enumerate(grids):
                for b in grids[i + 1:]:
                    out.append(cls((a, b), (f"swap_{a}_{b}_{c}",), component=c))
        return out

    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where), self.component)

    def mix_rows(self, om, o_index):
        a, b = (int(w) for w in self.where)
        c = self.component
        out = []
        for own, other in ((a, b), (b, a)):
            rows = np.flatnonzero(om.rows_of(own, c))
            if rows.size and (other, c) in o_index:
                out.append((0, rows, [(np.full(rows.size, o_index[(other, c)]), 1.0)]))
        return out

    not_low = "mostly their own grids, not a swap"
    summary_noun = "a swap"

    def share_read(self, t: float) -> str:
        return f"the channels mix by {t:.3g}"

    def details_json(self) -> dict:
        return {"component": self.component}

    def label(self) -> str:
        return f"{self.kind} @ {self.where[0]}, {self.where[1]} component {self.component}"

    def marker_points(self, xyz, deck):
        return [xyz[int(g)] for g in self.where if int(g) in xyz]
