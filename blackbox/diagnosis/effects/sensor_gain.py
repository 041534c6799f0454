"""``sensor_gain``: the sensors of one grid read a scaled displacement.

A factor ``g`` on every measurement of its grid (exact, no run). Candidates: every fitted grid.
"""

from __future__ import annotations

from dataclasses import dataclass

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.registry import register

__all__ = ["SensorGain"]


@register
@dataclass(frozen=True, eq=False)
class SensorGain(Effect):
    kind = "sensor_gain"
    of_data = True
    summary = "the sensors of a grid have a gain (a factor on its measurements)"

    @property
    def grid(self) -> int:
        return int(self.where[0])

    @classmethod
    def candidates(cls, ctx, split) -> list["SensorGain"]:
        return [cls((g,), (f"g_{g}",)) for g in dict.fromkeys(d[0] for d in ctx.fit_obs.dofs)]

    @property
    def acts_on_output(self) -> bool:
        return True

    def output_rows(self, om):
        return [(0, om.grid == self.grid)]

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []
