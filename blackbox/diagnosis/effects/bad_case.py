"""``bad_case``: the readings of one load case follow no model; they are set aside.

A case can go wrong as a whole in ways a load-cell factor does not describe: its file written in
millimetres where the others are in metres, its readings exchanged with a hold-out case's (two
fitted cases exchanged are ``case_swap``, one parameter for both), the load applied at another
point or not at all. This effect gives every channel read in the case a free
offset (``c_<case>_G_C``), which is what setting the case's readings aside means; its LR
statistic is the part of the case's misfit the model cannot absorb. Exact, no run. Candidates:
every fitted case when at least three are fitted (one set aside leaves two).

It costs one parameter per channel, so a load scale of the case (one parameter) wins where it
explains, and any effect that explains several cases wins as well. Once added it takes the place
of what it subsumes in its case (its outliers, its own load scale: :meth:`subsumes`). The report
says what the readings look like (:meth:`BadCase.findings`): ``zero`` (noise about zero: no load
reached the structure), ``scale`` (the model's response times a factor beyond a load cell's
error: other units, a factor 1000 is millimetres for metres), ``exchanged`` (another case set
aside in the same fit reads as this case's response and this case as its: the two cases'
readings exchanged) or ``other`` (none of these: a load applied elsewhere, or another case's
readings).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.bad_channel import _fits
from blackbox.diagnosis.effects.base import Effect, SetAsideEffect
from blackbox.diagnosis.effects.registry import register

__all__ = ["BadCase", "case_pattern"]


def case_pattern(y: np.ndarray, u: np.ndarray, s: np.ndarray) -> dict:
    """What a case's readings ``y`` (standard deviations ``s``) show against the model's
    predictions ``u`` (module docstring): ``{"pattern": name, "pattern_detail": sentence}``."""
    y, u, s = (np.asarray(a, float) for a in (y, u, s))
    n = len(y)
    w = 1.0 / s ** 2
    if _fits(float(np.sum(w * y ** 2)), n) and not _fits(float(np.sum(w * u ** 2)), n):
        return {"pattern": "zero", "pattern_detail": "the readings are noise about zero where the model predicts a "
                                                     "response: no load reached the structure"}
    uu = float(np.sum(w * u ** 2))
    if uu > 0:
        g = float(np.sum(w * u * y) / uu)
        # readings in other units carry their noise in those units too
        if _fits(float(np.sum(w * (y - g * u) ** 2)) / max(g * g, 1.0), n - 1):
            hint = ""
            for k, why in ((1000.0, "millimetres read as metres"), (1e-3, "metres read as millimetres"),
                           (25.4, "millimetres read as inches"), (1 / 25.4, "inches read as millimetres"),
                           (-1.0, "the load applied in the opposite direction")):
                if abs(g / k - 1.0) < 0.02:
                    hint = f" ({why}?)"
            return {"pattern": "scale", "pattern_detail": f"the readings are {g:.4g} times the model's response to "
                                                          f"the case's load{hint}"}
    return {"pattern": "other", "pattern_detail": "the readings are no multiple of the model's response to the "
                                                  "case's load: a load applied elsewhere, or another case's readings"}


@register
@dataclass(frozen=True, eq=False)
class BadCase(SetAsideEffect):
    """``case``: the load case set aside; ``channels``: the ``(grid, component)`` read in it
    (one parameter each, ``readings`` in the same order)."""
    kind = "bad_case"
    of_data = True
    summary = "the readings of one load case follow no model (other units, exchanged files, a load elsewhere): set aside"

    case: str = ""
    channels: tuple[tuple[int, int], ...] = ()

    @classmethod
    def candidates(cls, ctx, split) -> list["BadCase"]:
        per = cls.grouped_readings(ctx.fit_obs, lambda g, c, k: k, lambda g, c, k: (g, c))
        if len(per) < 3:
            return []
        out = []
        for case in (c for c in ctx.cases if c in per):
            chans = list(per[case])
            out.append(cls((case,), tuple(f"c_{case}_{g}_{c}" for g, c in chans), case=case, channels=tuple(chans),
                           readings=tuple(per[case][ch][0] for ch in chans),
                           sigmas=tuple(per[case][ch][1] for ch in chans)))
        return out

    def offset_rows(self, om):
        return [(q, om.rows_of(g, c, self.case)) for q, (g, c) in enumerate(self.channels)]

    def subsumes(self, other: Effect) -> bool:
        if other.kind == "outlier":
            return getattr(other, "case", None) == self.case
        if other.kind in ("load_tilt", "case_tilt", "misplaced_load"):
            return getattr(other, "case", None) == self.case
        return other.kind == "load_scale" and tuple(other.where) == (self.case,)

    def findings(self, fit) -> dict:
        y, u, s = self.model_readings(fit)
        found = case_pattern(y, u, s)
        if found["pattern"] == "other":
            found = self._exchanged(fit, y, u, s) or found
        return found

    def _exchanged(self, fit, y, u, s) -> dict | None:
        """Another case set aside in ``fit`` whose model response these readings are while its
        readings are this case's response: the two cases' readings exchanged (the exchange is
        ``case_swap``; it gives way to two set-aside cases when the exchanged readings scatter
        beyond their declared sigma, a sigma that stayed with the case's label while its
        readings moved). Each reading is judged with the larger of the two cases' sigmas at its
        channel, as either may be its noise."""
        mine = {ch: i for i, ch in enumerate(self.channels)}
        for e in fit.spec.effects:
            if e is self or not isinstance(e, BadCase) or set(e.channels) != set(mine):
                continue
            yo, uo, so = e.model_readings(fit)
            order = np.array([mine[ch] for ch in e.channels])
            y2, u2, s2 = np.empty_like(yo), np.empty_like(uo), np.empty_like(so)
            y2[order], u2[order], s2[order] = yo, uo, so
            sm = np.maximum(s, s2)
            n = len(y)
            if _fits(float(np.sum(((y - u2) / sm) ** 2)), n) and _fits(float(np.sum(((y2 - u) / sm) ** 2)), n):
                return {"pattern": "exchanged",
                        "pattern_detail": f"the readings are the model's response to case {e.case}'s load, and "
                                          f"case {e.case}'s readings (set aside too) are this case's: the readings "
                                          f"of cases {self.case} and {e.case} exchanged"}
        return None

    def label(self) -> str:
        return f"{self.kind} @ case {self.case}"
