"""``load_scale``: the structure felt scaled loads (all cases, a group of cases, or one case), Sec. 5.3.1.

A factor ``s`` on every response of its cases (linearity: exact, no run). Candidates: one factor
for all cases (``s_all``); when ``loads.csv`` names groups (the set-up a case was run in: a test
day, a rig, a load cell) and there are at least two, one factor per group with a fitted case
(``s_group_G``, a miscalibrated load cell of one set-up); with more than one fitted case, one
per fitted case (``s_L``). ``where`` lists the cases scaled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.registry import register

__all__ = ["LoadScale"]


@register
@dataclass(frozen=True, eq=False)
class LoadScale(Effect):
    """``cases``: indices of the scaled cases among the study's load cases; ``group``: the
    ``loads.csv`` group they form (a group candidate), else ``None``."""
    kind = "load_scale"
    summary = "the loads of some cases were scaled (a factor on their responses)"

    cases: tuple[int, ...] = ()
    group: str | None = None

    def details_json(self) -> dict:
        return {} if self.group is None else {"group": self.group}

    def label(self) -> str:
        return f"{self.kind} @ group {self.group}" if self.group is not None else super().label()

    @classmethod
    def candidates(cls, ctx, split) -> list["LoadScale"]:
        cases = list(ctx.cases)
        fitted = [ctx.fit_obs.case_labels[c] for c in ctx.fit_obs.cases]
        out = [cls(tuple(cases), ("s_all",), cases=tuple(range(len(cases))))]
        groups = ctx.groups or {}
        names = list(dict.fromkeys(groups[c] for c in cases if c in groups))
        if len(names) > 1:
            for g in names:
                members = [c for c in cases if groups.get(c) == g]
                if len(members) > 1 and any(c in fitted for c in members):
                    out.append(cls(tuple(members), (f"s_group_{g}",), cases=tuple(cases.index(c) for c in members),
                                   group=g))
        if len(fitted) > 1:
            out += [cls((c,), (f"s_{c}",), cases=(cases.index(c),)) for c in fitted]
        return out

    @property
    def acts_on_output(self) -> bool:
        return True

    def output_rows(self, om):
        return [(0, np.isin(om.case, self.cases))]
