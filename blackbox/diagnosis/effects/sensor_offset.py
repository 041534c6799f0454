"""``sensor_offset``: one measurement channel (a grid's component) reads a constant zero offset.

An offset ``o`` added to every measurement of the channel, in every case (a sensor not zeroed
before loading). Exact, no run: the prediction there is ``mult * U + o``, so its Jacobian
column is 1 on the channel's rows. Nested at ``o = 0``; unbounded. Candidates: every fitted
channel. ``where`` is the grid (the contract's grid ids), the component is part of the key and
of the parameter name ``o_G_C``.

Scored in one batch (the columns are indicator vectors: no augmented model per candidate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect, OnChannel
from blackbox.diagnosis.effects.registry import register

__all__ = ["SensorOffset"]


@register
@dataclass(frozen=True, eq=False)
class SensorOffset(OnChannel, Effect):
    """``component``: the channel's component at grid ``where[0]``."""
    kind = "sensor_offset"
    of_data = True
    summary = "a measurement channel reads a constant offset (a sensor not zeroed)"

    component: int = 0

    @classmethod
    def candidates(cls, ctx, split) -> list["SensorOffset"]:
        return [cls((g,), (f"o_{g}_{c}",), component=int(c)) for g, c in dict.fromkeys(ctx.fit_obs.dofs)]

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(1)

    @property
    def bounds(self):
        return np.full(1, -np.inf), np.full(1, np.inf)

    @property
    def acts_on_output(self) -> bool:
        return True

    def _rows(self, om) -> np.ndarray:
        return (om.grid == self.grid) & (om.comp == self.component)

    def offset_rows(self, om):
        return [(0, self._rows(om))]

    @classmethod
    def batch_columns(cls, model, st, x, om, effects):
        return np.column_stack([e._rows(om).astype(float) for e in effects]) if effects else None
