"""``outlier``: one reading is wrong by a gross amount (a misread dial, a bumped gauge).

An offset ``b`` added to the prediction of one measured row (one case, grid and component), so
its residual no longer counts: the diagnosis's equivalent of deleting the reading, sized with an
interval. Exact, no run. Nested at ``b = 0``; unbounded. Candidates: every fitted row, scored
in one sparse batch (an indicator column; its score is the row's projected residual squared
over ``1 - leverage``, the externally studentized residual of regression diagnostics). With one
candidate per reading, the kind's Bonferroni share (:func:`blackbox.diagnosis.search.multipliers`)
asks for ~5 sigma on a study of a few thousand rows; a reading that is merely large is noise.

``where`` is the grid; the case and component are in the details (and the key). A data defect:
reported as the data, not the structure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.registry import register

__all__ = ["Outlier"]


@register
@dataclass(frozen=True, eq=False)
class Outlier(Effect):
    """``case`` (label) and ``component`` of the reading at grid ``where[0]``."""
    kind = "outlier"
    summary = "one reading is off by a gross amount (the data, not the structure)"
    of_data = True

    case: str = ""
    component: int = 0

    @property
    def grid(self) -> int:
        return int(self.where[0])

    @classmethod
    def candidates(cls, ctx, split) -> list["Outlier"]:
        obs = ctx.fit_obs
        labels = obs.case_labels
        out, seen = [], set()
        for (g, c), ci in zip(obs.dofs, obs.case_index):
            key = (int(g), int(c), labels[int(ci)])
            if key in seen:
                continue
            seen.add(key)
            out.append(cls((int(g),), (f"b_{g}_{c}_{key[2]}",), case=key[2], component=int(c)))
        return out

    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where), self.case, self.component)

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(1)

    @property
    def bounds(self):
        return np.full(1, -np.inf), np.full(1, np.inf)

    @property
    def acts_on_output(self) -> bool:
        return True

    def offset_rows(self, om):
        return [(0, om.rows_of(self.grid, self.component, self.case))]

    @classmethod
    def sparse_columns(cls, model, st, x, om, effects):
        index = {}
        for i, (g, c, k) in enumerate(zip(om.grid, om.comp, om.case)):
            index.setdefault((int(g), int(c), om.labels[int(k)]), []).append(i)
        return [(np.array(index.get((e.grid, e.component, e.case), []), int),
                 np.ones(len(index.get((e.grid, e.component, e.case), []))))
                for e in effects]

    def details_json(self) -> dict:
        return {"case": self.case, "component": self.component}

    def label(self) -> str:
        return f"{self.kind} @ {self.grid} component {self.component} case {self.case}"

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []
