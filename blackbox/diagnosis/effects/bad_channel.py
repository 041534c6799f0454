"""``bad_channel``: one measurement channel follows no model over the test; its readings are set aside.

Real transducers fail in ways no one-parameter defect describes: a zero that drifts over the
test (temperature), one that jumps when the sensor is knocked, noise well above the declared
sigma (a loose mount, a bad cable), a transducer that reads nothing. Each would otherwise be
piled up as an offset plus a string of outliers at one channel. This effect gives the channel
a free offset in every fitted case it is read in (``u_G_C_<case>``), which is what setting its
readings aside means: with them the channel no longer pulls the fit, and its LR statistic is the
part of the channel's misfit that the model cannot absorb (``df``: its fitted cases, less what
the model's own parameters share). Exact, no run. Candidates: every channel read in at least
two fitted cases. Its hold-out readings are set aside too: the hold-out check of the addition
compares both fits on the other hold-out rows (:meth:`BadChannel.set_aside_rows`).

It costs one parameter per case, so where an offset, a gain, a sign or a swap of the channel
explains the readings, that one-parameter defect wins on BIC, and a structural effect that
explains several channels wins as well. Once added it takes the place of what it subsumes at
its channel (an offset, a sign flip, its outliers: :meth:`subsumes`).

The report says what the set-aside readings look like (:meth:`BadChannel.findings`, in the
cases' order in ``loads.csv``, taken as the order they were run in): ``dead`` (the readings are
noise about zero where the model predicts a response), ``drift`` (what the channel reads beyond
the model grows linearly over the cases), ``step`` (it jumps once, at a named case), ``gain``
(the readings are the model's times a factor beyond any plausible sensor gain: other units),
``offset`` (a constant), or ``scatter`` (none of those: noise about ``F`` times the declared
sigma). Each pattern is the first of that list whose remaining chi2 lies within the 99 % band
of its degrees of freedom.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from blackbox.diagnosis.effects.base import Effect, OnChannel, SetAsideEffect
from blackbox.diagnosis.effects.registry import register

__all__ = ["BadChannel", "channel_pattern"]

PATTERN_LEVEL = 0.01        # a pattern describes the readings when its remaining chi2 is below the 99 % point


def _fits(rem: float, dof: int) -> bool:
    return dof <= 0 or float(stats.chi2.sf(rem, dof)) > PATTERN_LEVEL


def channel_pattern(y: np.ndarray, u: np.ndarray, s: np.ndarray, cases: list[str]) -> dict:
    """What readings ``y`` (standard deviations ``s``) show against the model's predictions
    ``u`` at the same rows, in the order of ``cases`` (module docstring): ``{"pattern": name,
    "pattern_detail": sentence}``."""
    y, u, s = (np.asarray(a, float) for a in (y, u, s))
    n = len(y)
    w = 1.0 / s ** 2
    d = y - u
    if n >= 2 and _fits(float(np.sum(w * y ** 2)), n) and not _fits(float(np.sum(w * u ** 2)), n):
        return {"pattern": "dead", "pattern_detail": "the channel reads noise about zero where the model predicts "
                                                     "a response: a transducer that reads nothing"}
    c = float(np.sum(w * d) / np.sum(w))
    rem0 = float(np.sum(w * (d - c) ** 2))
    if _fits(rem0, n - 1):
        return {"pattern": "offset", "pattern_detail": f"a constant {c:.4g} beyond the model in every case"}
    t = np.arange(n, dtype=float)
    if n >= 3:
        A = np.column_stack([np.ones(n), t]) * np.sqrt(w)[:, None]
        coef, *_ = np.linalg.lstsq(A, d * np.sqrt(w), rcond=None)
        rem1 = float(np.sum((A @ coef - d * np.sqrt(w)) ** 2))
        if _fits(rem1, n - 2):
            return {"pattern": "drift", "pattern_detail": f"what the channel reads beyond the model drifts by "
                                                          f"{coef[1]:.4g} per case over the test ({cases[0]} to "
                                                          f"{cases[-1]}): a zero that moved during the test"}
        best = None
        for k in range(1, n):
            a, b = slice(0, k), slice(k, n)
            ma = float(np.sum(w[a] * d[a]) / np.sum(w[a]))
            mb = float(np.sum(w[b] * d[b]) / np.sum(w[b]))
            rem = float(np.sum(w[a] * (d[a] - ma) ** 2) + np.sum(w[b] * (d[b] - mb) ** 2))
            if best is None or rem < best[0]:
                best = (rem, k, mb - ma)
        if best is not None and _fits(best[0], n - 2):
            return {"pattern": "step", "pattern_detail": f"the channel's zero jumps by {best[2]:.4g} from case "
                                                         f"{cases[best[1]]} on: a sensor moved during the test"}
    uu = float(np.sum(w * u ** 2))
    if uu > 0:
        g = float(np.sum(w * u * y) / uu)
        # readings in other units carry their noise in those units too
        if _fits(float(np.sum(w * (y - g * u) ** 2)) / max(g * g, 1.0), n - 1):
            return {"pattern": "gain", "pattern_detail": f"the readings are {g:.4g} times the model's: other units "
                                                         "or a wrong calibration factor"}
    f = float(np.sqrt(rem0 / max(n - 1, 1)))
    return {"pattern": "scatter", "pattern_detail": f"no pattern: the readings scatter about {f:.3g} times the "
                                                    "declared sigma (a loose mount, a bad cable, a sigma too small)"}


@register
@dataclass(frozen=True, eq=False)
class BadChannel(OnChannel, SetAsideEffect):
    """``component`` of grid ``where[0]``; ``cases``: the fitted cases it is read in (one
    parameter each, ``readings`` in the same order)."""
    kind = "bad_channel"
    of_data = True
    summary = "one channel follows no model over the test (a drift, a jump, noise, a dead transducer): set aside"

    component: int = 0
    cases: tuple[str, ...] = ()

    @classmethod
    def candidates(cls, ctx, split) -> list["BadChannel"]:
        order = {c: i for i, c in enumerate(ctx.cases)}
        per = cls.grouped_readings(ctx.fit_obs, lambda g, c, k: (g, c), lambda g, c, k: k)
        out = []
        for (g, c), by_case in per.items():
            if len(by_case) < 2:
                continue
            cases = sorted(by_case, key=lambda k: order.get(k, len(order)))
            out.append(cls((g,), tuple(f"u_{g}_{c}_{k}" for k in cases), component=c, cases=tuple(cases),
                           readings=tuple(by_case[k][0] for k in cases),
                           sigmas=tuple(by_case[k][1] for k in cases)))
        return out

    def offset_rows(self, om):
        return [(q, om.rows_of(self.grid, self.component, k)) for q, k in enumerate(self.cases)]

    def set_aside_rows(self, om):
        return om.rows_of(self.grid, self.component)

    def subsumes(self, other: Effect) -> bool:
        same = getattr(other, "component", None) == self.component and tuple(other.where)[:1] == (self.grid,)
        return same and other.kind in ("sensor_offset", "sign_flip", "outlier")

    def findings(self, fit) -> dict:
        y, u, s = self.model_readings(fit)
        return channel_pattern(y, u, s, list(self.cases))
