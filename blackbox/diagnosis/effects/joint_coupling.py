"""``joint_coupling``: a declared simple-model joint is really coupled (the complex model, Ch. 2).

No cut and no parameter of its own: adding it replaces the joint's simple model by the complex
model at the equivalent parameters (:func:`blackbox.joints.simple_to_complex_params`, exact), so
the score test uses the complex model's columns and the refit estimates its ``K_C``. Candidates:
every declared joint that is a simple model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import Effect, finite_or_none
from blackbox.diagnosis.effects.registry import register
from blackbox.joints import ComplexJoint, SimpleJoint, simple_to_complex_params

__all__ = ["JointCoupling"]


@register
@dataclass(frozen=True, eq=False)
class JointCoupling(Effect):
    kind = "joint_coupling"
    summary = "a declared simple-model joint is coupled: its complex model instead"

    @property
    def joint(self) -> str:
        return self.where[0]

    @classmethod
    def of(cls, joint: str) -> "JointCoupling":
        return cls((joint,))

    @classmethod
    def candidates(cls, ctx, split) -> list["JointCoupling"]:
        return [cls.of(j.name) for j in ctx.joints if j.model_name == "simple"]

    def applicable(self, spec) -> bool:
        """A simple-model joint without a gap (a gap is defined on the simple model's springs)."""
        return (any(j.name == self.joint and isinstance(j, SimpleJoint) for j in spec.joints)
                and not any(e.case_joint == self.joint for e in spec.effects))

    def joint_models(self, spec, x):
        joints, parts = [], []
        for j, sl in zip(spec.joints, spec.joint_slices()):
            if j.name == self.joint and isinstance(j, SimpleJoint):
                joints.append(ComplexJoint(j.name, j.grids))
                parts.append(simple_to_complex_params(j, x[sl]))
            else:
                joints.append(j)
                parts.append(x[sl])
        return tuple(joints), (np.concatenate(parts) if parts else np.zeros(0))

    def _slice(self, spec) -> slice:
        return next(sl for j, sl in zip(spec.joints, spec.joint_slices()) if j.name == self.joint)

    def scored_columns(self, before, after):
        sl = self._slice(after)
        return np.arange(sl.start, sl.stop), np.zeros(sl.stop - sl.start, bool)

    def refit_starts(self, x2, step, lo, hi, first):
        return [x2]                   # the step is in the joint's columns: the nested point only

    def parameters(self, fit) -> list[dict]:
        """The joint's complex-model parameters."""
        sl = self._slice(fit.spec)
        j = next(j for j in fit.spec.joints if j.name == self.joint)
        return [{"name": n, "value": float(v), "std": finite_or_none(s)}
                for n, v, s in zip(j.param_names, fit.x[sl], fit.std[sl])]
