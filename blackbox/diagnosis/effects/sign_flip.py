"""``sign_flip``: one measurement channel reads with the wrong sign in every case (a gauge
mounted the other way round, a cable polarity, a sign convention of the logger).

A factor ``gamma`` on the channel's predictions, nested at ``gamma = 1`` and bounded to
``[-3, 3]``: linear, so the refit finds ``gamma ~ -1`` from a start there as readily as from 1,
and the interval says how sure the sign is. Only a refit that ends at ``gamma < 0`` describes a
sign flip (a positive factor on one channel is a gain: that refit is rejected, with the reason).
Exact, no run. Candidates: every fitted channel, scored in one sparse batch (the column is the
channel's own prediction).

``where`` is the grid, the component is in the details (and the key). A data defect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect, OnChannel
from blackbox.diagnosis.effects.registry import register

__all__ = ["SignFlip"]


@register
@dataclass(frozen=True, eq=False)
class SignFlip(OnChannel, Effect):
    kind = "sign_flip"
    summary = "a measurement channel reads with the wrong sign (the data, not the structure)"
    of_data = True

    component: int = 0

    @classmethod
    def candidates(cls, ctx, split) -> list["SignFlip"]:
        return [cls((int(g),), (f"sign_{g}_{c}",), component=int(c)) for g, c in dict.fromkeys(ctx.fit_obs.dofs)]

    @property
    def bounds(self):
        return np.full(1, -3.0), np.full(1, 3.0)

    @property
    def acts_on_output(self) -> bool:
        return True

    def output_rows(self, om):
        return [(0, om.rows_of(self.grid, self.component))]

    @classmethod
    def sparse_columns(cls, model, st, x, om, effects):
        f = model.multiplier(x, om) * model.pick(st.U_O, x, om)
        out = []
        for e in effects:
            rows = np.flatnonzero(om.rows_of(e.grid, e.component))
            out.append((rows, f[rows]))
        return out

    def refit_starts(self, x2, step, lo, hi, first):
        flipped = x2.copy()
        flipped[first:] = -1.0
        return super().refit_starts(x2, step, lo, hi, first) + [flipped]

    def rejection(self, x_effect: np.ndarray) -> str | None:
        g = float(np.asarray(x_effect)[0])
        if g >= 0.0:
            return f"the channel's best factor is {g:+.3g}: a gain, not a sign flip"
        if g > -0.5:
            return (f"the channel's best factor is {g:+.3g}: nearer a channel that reads nothing than one "
                    "that reads with the wrong sign")
        return super().rejection(x_effect)
