"""``case_swap``: the readings of two load cases were exchanged (two files saved under each
other's names, two runs logged in the wrong order).

Two fitted cases ``A < B`` (in the study's case order) read at the same channels. A mixing
fraction ``s`` (bounded to ``[0, 2]``): every reading of case ``A`` is ``(1 - s) u_A + s u_B``
and every reading of ``B`` is ``(1 - s) u_B + s u_A``, ``u`` the model's response to each case's
load at the channel; ``s = 0`` is the cases as logged (nested, one-sided), ``s = 1`` the whole
exchange, and the interval says how sure it is. Linear in ``s``, exact, no run. A refit that
ends below ``s = 1/2`` is no exchange (each case mostly reads its own load), one above 3/2 more
than an exchange: rejected, with the reason. Candidates: every pair of fitted cases measured at
the same channels, scored in one sparse batch (the column is ``u_B - u_A`` on ``A``'s rows and
``u_A - u_B`` on ``B``'s).

One parameter explains both cases, where setting each aside (``bad_case``) costs one per channel
and each case's misfit judged alone leaves the other case in the fit: the exchange is found as
one hypothesis, and the structure is then fitted to both cases' readings where they belong. A
load scale of ``A`` or ``B`` in the same model still scales the rows of its case as logged (a
load cell's error stays with the case whose file it is).

``where`` is the two case labels. A data defect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect, ReadsAnother
from blackbox.diagnosis.effects.registry import register

__all__ = ["CaseSwap"]


@register
@dataclass(frozen=True, eq=False)
class CaseSwap(ReadsAnother, Effect):
    kind = "case_swap"
    summary = "the readings of two load cases were exchanged (the data, not the structure)"
    of_data = True

    @classmethod
    def candidates(cls, ctx, split) -> list["CaseSwap"]:
        obs = ctx.fit_obs
        labels = obs.case_labels
        channels: dict[str, set] = {}
        for (g, c), ci in zip(obs.dofs, obs.case_index):
            channels.setdefault(labels[int(ci)], set()).add((int(g), int(c)))
        fitted = [c for c in ctx.cases if c in channels]
        return [cls((a, b), (f"swap_{a}_{b}",)) for i, a in enumerate(fitted) for b in fitted[i + 1:]
                if channels[a] == channels[b]]

    def mix_rows(self, om, o_index):
        labels = list(om.labels)
        a, b = (str(w) for w in self.where)
        if a not in labels or b not in labels:
            return []
        ia, ib = labels.index(a), labels.index(b)
        out = []
        for own, other in ((ia, ib), (ib, ia)):
            rows = np.flatnonzero(om.case == own)
            if rows.size:
                out.append((0, rows, [(om.row[rows], 1.0)], np.full(rows.size, other)))
        return out

    not_low = "each case mostly reads its own load, not an exchange"
    summary_noun = "an exchange"

    def share_read(self, t: float) -> str:
        return f"the cases mix by {t:.3g}"

    def findings(self, fit) -> dict:
        a, b = self.where
        return {"pattern": "exchanged",
                "pattern_detail": f"the readings of cases {a} and {b} are each other's (two files saved under "
                                  f"each other's names, two runs logged in the wrong order?)"}

    def label(self) -> str:
        return f"{self.kind} @ cases {self.where[0]}, {self.where[1]}"
