"""``joint_unloading``: a declared joint answers differently when the load is taken off than when
it is put on (hysteresis: a cracked or yielding connection unloads along another line than it
loaded).

Only for a *sequential* study (``study.toml`` ``[measurements] sequential = true``: the cases of
``loads.csv``, in the file's order, are the steps of one test in time order); never guessed from
case labels. A step is *unloading* when its load magnitude is smaller than the previous step's
(the first step follows the unloaded structure: loading). The magnitude is the norm of the
case's load vector, forces and moments each divided by the study's typical force and moment (the
median magnitude of its nonzero entries of that kind), so that mixed loads compare in one
number. A step that reverses the load through zero to a larger magnitude is loading.

One factor ``r`` per joint (simple model): in each unloading step each spring ``k`` acts as
``r k``; in the loading steps as ``k``. Nested at ``r = 1`` (the declared joint, as stiff both
ways), bounded to ``[0.05, 20]`` (either may be the softer). The steps are known from the loads,
so the Jacobian is exact. Only offered when the record has both loading and unloading steps.

Read with care on a model that is linear in each step: the model's response passes through the
origin, so ``r`` is the ratio of *secant* stiffnesses (force over displacement from the unloaded
state), not of the tangent stiffness of the unloading branch. A branch that unloads steeply but
towards a residual displacement at zero force has a small secant stiffness: ``r < 1`` there,
however stiff its tangent. It is a defect of the structure, not of the data.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import JointCaseEffect
from blackbox.diagnosis.effects.registry import register
from blackbox.joints import SimpleJoint

__all__ = ["JointUnloading", "load_magnitude", "unloading_steps"]


def load_magnitude(loads) -> np.ndarray:
    """Each case's load magnitude: the norm of its load vector, forces and moments each over the
    study's median nonzero magnitude of that kind (:class:`solver_adapters.protocol.LoadMatrix`)."""
    V = loads.values.tocsr()
    comps = np.array([c for _, c in loads.dofs], dtype=int)
    out = np.zeros(loads.n_cases)
    for kind in (comps <= 3, comps >= 4):
        if not kind.any():
            continue
        part = V[np.flatnonzero(kind)]
        vals = np.abs(part.data)
        vals = vals[vals > 0]
        if not vals.size:
            continue
        scaled = part.multiply(1.0 / float(np.median(vals)))
        out += np.asarray(scaled.multiply(scaled).sum(axis=0)).reshape(-1)
    return np.sqrt(out)


def unloading_steps(loads) -> tuple[str, ...]:
    """The labels of the cases whose load magnitude is smaller than the previous case's, in a
    sequential study (module docstring)."""
    mag = load_magnitude(loads)
    prev = np.concatenate([[0.0], mag[:-1]])
    return tuple(c for c, m, p in zip(loads.cases, mag, prev) if m < p)


@register
@dataclass(frozen=True, eq=False)
class JointUnloading(JointCaseEffect):
    """``unloading``: the labels of the unloading steps; ``steps``: how many steps there are."""
    kind = "joint_unloading"
    summary = ("a declared joint is softer or stiffer while the load is being taken off (a sequential "
               "test's steps whose load magnitude falls): its springs r k in those steps")

    unloading: tuple[str, ...] = ()
    steps: int = 0

    @classmethod
    def candidates(cls, ctx, split) -> list["JointUnloading"]:
        if not ctx.sequential or ctx.loads is None:
            return []
        down = unloading_steps(ctx.loads)
        if not down or len(down) == ctx.loads.n_cases:
            return []
        return [cls((j.name,), (f"r_unload_{j.name}",), unloading=down, steps=ctx.loads.n_cases)
                for j in ctx.joints if isinstance(j, SimpleJoint)]

    @property
    def bounds(self):
        return np.full(1, 0.05), np.full(1, 20.0)

    @functools.cached_property
    def _down(self) -> frozenset[str]:
        return frozenset(self.unloading)

    def indicator(self, cases) -> np.ndarray:
        """1 for the unloading steps among ``cases`` (labels), 0 for the others (a case not in
        the study, such as a load the report proposes, is applied to the unloaded structure);
        each list of labels is looked up once."""
        if cases is None:
            raise ValueError("joint_unloading needs the labels of the load cases")
        key = tuple(cases)
        d = self._seen.get(key)
        if d is None:
            down = self._down
            d = self._seen[key] = np.array([str(c) in down for c in key], dtype=float)
        return d

    @functools.cached_property
    def _seen(self) -> dict:
        return {}

    def case_factors(self, rel, x_effect, cases=None):
        d = self.indicator(cases)
        r = float(np.asarray(x_effect)[0])
        return np.broadcast_to(1.0 + d * (r - 1.0), np.shape(rel)).copy()

    def case_factor_derivatives(self, rel, x_effect, cases=None):
        return np.broadcast_to(self.indicator(cases), np.shape(rel)).copy()[None]

    def refit_starts(self, x2, step, lo, hi, first):
        out = super().refit_starts(x2, step, lo, hi, first)
        for r in (0.3, 3.0):                # one start on each side of the nested point
            xs = x2.copy()
            xs[first:] = r
            out.append(xs)
        return out

    def details_json(self) -> dict:
        return {"unloading_steps": len(self.unloading), "steps": self.steps}
