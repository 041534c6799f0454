"""``joint_softening``: a declared joint is softer in the load cases of larger amplitude (a
connection that cracks, slips or yields progressively: the secant stiffness of a reinforced
concrete base falling as the drift grows).

One parameter ``s`` per joint (simple model): in load case ``c`` each spring ``k`` acts as
``k / (1 - s + s a_c)``: the joint's compliance grows linearly with the amplitude ``a_c`` (in
``[0, 1]``, below), from ``(1 - s) / k`` at none to ``1 / k`` at the largest measured. The joint's
``k`` is then its stiffness at the largest amplitude, which stays finite however strong the
softening. It is the form ``k_0 / (1 + b a_c)`` with ``b = s / (1 - s)`` and the stiffness at
zero amplitude ``k_0 = k / (1 - s)``. Nested at ``s = 0`` (the declared, linear joint; one-sided:
softening), bounded above by ``1 - 1e-6``: ``s -> 1`` is a compliance proportional to the
amplitude, a force that no longer grows with the deformation (the joint yields), the physical
end of the range, not an arbitrary box: at ``s = 1`` the joint's force is the same at every
amplitude (``k / a_c`` times a deformation proportional to ``a_c``: an elastic-perfectly-plastic
joint read at its secant), so a refit that ends there stands and reads "the joint has yielded
over the measured range", ``k`` its secant stiffness at the largest amplitude
(:meth:`JointSoftening.rejection`; the stiffness at zero amplitude, ``k / (1 - s)``, is then
only bounded below). The default rule of the other kinds (a parameter held at a bound other than
its nested value is refused) would refuse the one reading a yielded joint has.

The covariate ``a_c`` is the case's *amplitude*: its largest measured displacement magnitude
over its translation rows (its rotation rows when the study measures no translation), divided by
the largest over all measured cases (fitted and hold-out), so that ``a_c`` lies in ``[0, 1]``.
It is read from the
measurements, not from the model, so it does not depend on the parameters and the Jacobian is
exact. Why the measured displacement, not the load: in a cyclic test the force levels off at
yield (the RC column of ``fixtures/measured/rc_column`` reaches 160-195 kN at every amplitude from
20 to 78 mm), so the load cannot tell the cycles apart while the deformation can; engineers read
stiffness degradation against drift or ductility for that reason. The measured value carries its
noise into ``a_c`` (errors in variables): negligible when sigma is a small fraction of the
amplitudes (0.1 mm against 20-78 mm there), a slight attenuation of ``s`` when not.

A load case without measurements (none of the study's, or a load the report proposes) has
``a_c = 0``: the joint at zero amplitude. Only offered when the measured amplitudes differ between
cases (with one amplitude the factor is a change of ``k`` and says nothing new).

It is a defect of the structure (a nonlinear joint), not of the data.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.effects.base import JointCaseEffect
from blackbox.diagnosis.effects.registry import register
from blackbox.joints import SimpleJoint

__all__ = ["JointSoftening", "case_amplitudes"]

S_MAX = 1.0 - 1.0e-6        # the yield limit: a case of zero amplitude is then 1e6 times stiffer
                            # than at the largest, rigid against the structure, still finite


def case_amplitudes(obs) -> tuple[tuple[tuple[str, float], ...], str, float] | None:
    """``(((case, a_c), ...), kind, a_ref)`` of measured rows ``obs``
    (:class:`blackbox.identification.Observations`): each measured case's largest displacement
    magnitude of ``kind`` (``"translation"``, or ``"rotation"`` when no translation is measured)
    over ``a_ref``, the largest over every case; ``None`` when nothing of that kind moved or all
    amplitudes are equal."""
    if obs is None or not len(obs.values):
        return None
    comp = np.array([c for _, c in obs.dofs], dtype=int)
    kind = "translation" if np.any(comp <= 3) else "rotation"
    rows = comp <= 3 if kind == "translation" else comp >= 4
    amp: dict[int, float] = {}
    for c, v in zip(np.asarray(obs.case_index)[rows].tolist(), np.abs(np.asarray(obs.values)[rows]).tolist()):
        amp[c] = max(amp.get(c, 0.0), v)
    a_ref = max(amp.values(), default=0.0)
    if not a_ref > 0.0 or len({round(v / a_ref, 12) for v in amp.values()}) < 2:
        return None
    labels = obs.case_labels
    return tuple((str(labels[c]), v / a_ref) for c, v in amp.items()), kind, float(a_ref)


@register
@dataclass(frozen=True, eq=False)
class JointSoftening(JointCaseEffect):
    """``amplitude``: ``(case label, a_c)`` of every measured case; ``a_kind``, ``a_ref``: what
    was measured and its largest magnitude (``a_c = 1`` there)."""
    kind = "joint_softening"
    summary = ("a declared joint is softer in cases of larger amplitude: its springs k / (1 - s + s a), a "
               "the case's largest measured displacement over the largest of all cases")

    amplitude: tuple[tuple[str, float], ...] = ()
    a_kind: str = "translation"
    a_ref: float = 1.0

    @classmethod
    def candidates(cls, ctx, split) -> list["JointSoftening"]:
        amp = case_amplitudes(ctx.measured)
        if amp is None:
            return []
        a, kind, ref = amp
        return [cls((j.name,), (f"soft_{j.name}",), amplitude=a, a_kind=kind, a_ref=ref)
                for j in ctx.joints if isinstance(j, SimpleJoint)]

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(1)

    @property
    def bounds(self):
        return np.zeros(1), np.full(1, S_MAX)

    @property
    def one_sided(self) -> np.ndarray:
        return np.ones(1, bool)

    @functools.cached_property
    def _by_case(self) -> dict[str, float]:
        return dict(self.amplitude)

    @functools.cached_property
    def _seen(self) -> dict:
        return {}

    def covariate(self, cases) -> np.ndarray:
        """``a_c`` of the cases labelled ``cases`` (0 for a case without measurements); the
        model asks for the same labels at every evaluation, so each list is looked up once."""
        if cases is None:
            raise ValueError("joint_softening needs the labels of the load cases")
        key = tuple(cases)
        a = self._seen.get(key)
        if a is None:
            amp = self._by_case
            a = self._seen[key] = np.array([amp.get(str(c), 0.0) for c in key])
        return a

    def case_factors(self, rel, x_effect, cases=None):
        a = self.covariate(cases)
        s = float(np.asarray(x_effect)[0])
        return np.broadcast_to(1.0 / (1.0 - s + s * a), np.shape(rel)).copy()

    def case_factor_derivatives(self, rel, x_effect, cases=None):
        a = self.covariate(cases)
        s = float(np.asarray(x_effect)[0])
        return np.broadcast_to((1.0 - a) / (1.0 - s + s * a) ** 2, np.shape(rel)).copy()[None]

    def rejection(self, x_effect):
        """``None``: both ends of ``[0, S_MAX]`` are physical (nested at 0; at ``S_MAX`` the
        yield limit, module docstring), so no refit in the box is refused for where it ends."""
        return None

    def refit_starts(self, x2, step, lo, hi, first):
        out = super().refit_starts(x2, step, lo, hi, first)
        for s in (0.5, 0.9, 0.99):          # zero amplitude 2x, 10x, 100x stiffer than the largest
            xs = x2.copy()
            xs[first:] = s
            out.append(xs)
        return out

    def details_json(self) -> dict:
        return {"amplitude": f"largest measured {self.a_kind} of the case / {self.a_ref:.6g}",
                "amplitude_reference": self.a_ref}
