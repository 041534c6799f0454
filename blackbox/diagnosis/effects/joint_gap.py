"""``joint_gap``: a declared joint has play -- its springs are stiffer in one sense of the load
than in the other (a bolted joint whose plates bear on one side and slip on the other, a
contact that opens).

One factor ``r`` per joint (simple model): in each load case each spring ``k`` (branches ``i <
j``, one axis) acts as ``k`` when its relative rotation (branch ``i`` minus branch ``j`` about
its axis) is ``>= 0`` and as ``r k`` when it is ``< 0``. Nested at ``r = 1`` (the declared,
linear joint), bounded to ``[0.05, 20]`` (either side may be the softer). The side depends on
the solution, so the augmented model solves each case with its own joint stiffness and repeats
until the sides settle (:meth:`blackbox.diagnosis.model.AugmentedModel._case_solve`); no solver
run. The Jacobian holds the sides fixed (the response is piecewise smooth in the parameters).

The same definition simulates it (``benchmarks/blind``: the truth solved per case, iterating the
sides). It is a defect of the structure (play is physics), not of the data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import JointCaseEffect
from blackbox.diagnosis.effects.registry import register
from blackbox.joints import SimpleJoint

__all__ = ["JointGap"]


@register
@dataclass(frozen=True, eq=False)
class JointGap(JointCaseEffect):
    kind = "joint_gap"
    summary = "a declared joint has play: its springs are softer for one sense of the load (a factor r)"

    @classmethod
    def candidates(cls, ctx, split) -> list["JointGap"]:
        return [cls((j.name,), (f"r_{j.name}",)) for j in ctx.joints if isinstance(j, SimpleJoint)]

    @property
    def bounds(self):
        return np.full(1, 0.05), np.full(1, 20.0)

    def case_factors(self, rel, x_effect, cases=None):
        return np.where(np.asarray(rel) < 0.0, float(np.asarray(x_effect)[0]), 1.0)

    def case_factor_derivatives(self, rel, x_effect, cases=None):
        return (np.asarray(rel) < 0.0).astype(float)[None]

    def refit_starts(self, x2, step, lo, hi, first):
        out = super().refit_starts(x2, step, lo, hi, first)
        for r in (0.3, 3.0):                # one start on each side of the nested point
            xs = x2.copy()
            xs[first:] = r
            out.append(xs)
        return out

    def details_json(self) -> dict:
        return {}

    def marker_points(self, xyz, deck):
        return []
