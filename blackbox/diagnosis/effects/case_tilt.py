"""``case_tilt``: every load of one case went into the structure turned, each its own way
(actuators each mounted askew, a loading frame set up turned): one hypothesis for the case,
where ``load_tilt`` (one force or moment turned) would need one per vector and leave the case
set aside (``bad_case``) or misread.

The members are the case's :class:`~blackbox.diagnosis.effects.load_tilt.LoadTilt` candidates
(two or more: a force or a moment at a grid), each with its two angles; the model, the split
run's unit-load columns and the bounds are theirs. Candidates: every fitted case with two or
more loaded vectors. In a hold-out case the hold-out check already tries all of its loads turned
together (``blackbox.diagnosis.holdout``), so the family offers no hold-out candidate. When every
load turned by more than :data:`~blackbox.diagnosis.effects.load_tilt.REVERSED_DEG` the report
reads the case as loaded the other way (pattern ``reversed``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.load_tilt import REVERSED_DEG, ChangesLoads, LoadTilt
from blackbox.diagnosis.effects.registry import register

__all__ = ["CaseTilt"]


@register
@dataclass(frozen=True, eq=False)
class CaseTilt(ChangesLoads, Effect):
    """Every load of one fitted case went in turned, each its own way (actuators each mounted
    askew; a loading frame set up turned): the case's forces and moments (two or more) are the
    ``members``, each a :class:`LoadTilt` with its two angles. ``where``: the case's loaded
    grids; the parameters are the members' in turn, so one case's tilts are one hypothesis.
    A case with one load vector has none (that is :class:`LoadTilt`)."""
    kind = "case_tilt"
    summary = "the loads of one case went in turned off their declared directions (the data, not the structure)"
    of_data = True

    case: str = ""
    members: tuple = ()

    @property
    def size(self) -> float:
        return max(m.size for m in self.members)

    @classmethod
    def _listed(cls, ctx, held_cases: bool = False) -> list["CaseTilt"]:
        per: dict[str, list[LoadTilt]] = {}
        for e in LoadTilt._listed(ctx, held_cases):
            per.setdefault(e.case, []).append(e)
        return [cls(tuple(dict.fromkeys(m.grid for m in ms)), tuple(n for m in ms for n in m.names),
                    case=case, members=tuple(ms))
                for case, ms in per.items() if len(ms) >= 2]

    @classmethod
    def holdout_candidates(cls, ctx, split) -> list:
        """None: the hold-out check tries a case's loads turned together from the single tilts."""
        return []

    @property
    def key(self) -> tuple:
        return (self.kind, self.case)

    @property
    def nominal(self) -> np.ndarray:
        return np.concatenate([m.nominal for m in self.members])

    @property
    def bounds(self):
        lo, hi = zip(*(m.bounds for m in self.members))
        return np.concatenate(lo), np.concatenate(hi)

    @property
    def load_dofs(self):
        return tuple(d for m in self.members for d in m.load_dofs)

    def load_change(self, x_effect, cases):
        return np.vstack([m.load_change(x_effect[2 * i:2 * i + 2], cases) for i, m in enumerate(self.members)])

    def load_change_derivatives(self, x_effect, cases):
        rows = [len(m.free) for m in self.members]
        out = np.zeros((len(x_effect), sum(rows), len(cases)))
        at = 0
        for i, m in enumerate(self.members):
            out[2 * i:2 * i + 2, at:at + rows[i]] = m.load_change_derivatives(x_effect[2 * i:2 * i + 2], cases)
            at += rows[i]
        return out

    def details_json(self) -> dict:
        return {"case": self.case,
                "vectors": [{"grid": m.grid, **m.details_json()} for m in self.members]}

    def findings(self, fit) -> dict:
        e, sl = self.in_fit(fit)
        x = fit.x[sl]
        turns = []
        for i, m in enumerate(e.members):
            deg, d0, d1 = m.turned(x[2 * i:2 * i + 2])
            turns.append({"grid": m.grid, "vector": "force" if m.first == 1 else "moment", "angle_deg": deg,
                          "declared_direction": [float(a) for a in d0], "turned_direction": [float(a) for a in d1]})
        each = ", ".join(f"the {t['vector']} at {t['grid']} {t['angle_deg']:.3g}" for t in turns)
        if all(t["angle_deg"] > REVERSED_DEG for t in turns):
            return {"pattern": "reversed", "angle_deg": max(t["angle_deg"] for t in turns), "turns": turns,
                    "pattern_detail": f"the {len(turns)} loads of case {self.case} went in the other way, turned "
                                      f"(degrees): {each} (the case loaded reversed, push for pull?)"}
        return {"pattern": "turned", "angle_deg": max(t["angle_deg"] for t in turns), "turns": turns,
                "pattern_detail": f"the {len(turns)} loads of case {self.case} went in turned (degrees): {each} "
                                  f"(loads mounted askew?)"}

    def label(self) -> str:
        return f"{self.kind} case {self.case} ({len(self.members)} loads)"

    def marker_points(self, xyz, deck):
        return [xyz[g] for g in self.where if g in xyz]
