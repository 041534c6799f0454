"""``load_tilt``: one load of one case went into the structure turned off its declared direction
(an actuator or a load cell mounted askew, a cable pulling at an angle).

One loaded vector of one fitted case: the force (components 1-3) or the moment (4-6) that the
case applies at a grid, ``v`` in the grid's displacement system. Two tilt angles ``t = (t_a,
t_b)`` (radians) about two axes ``e_a``, ``e_b`` perpendicular to ``v`` (a turn about ``v``
itself changes nothing): the structure felt ``R(w) v``, ``w = t_a e_a + t_b e_b``, ``R`` the
rotation by ``|w|`` about ``w`` -- the same magnitude, turned by ``|w|``. Exactly, not to first
order::

    R(w) v - v = (cos|w| - 1) v + (sin|w| / |w|) (w x v)          (w perpendicular to v)

The structure's response follows by linearity from the split run's unit-load columns at the
grid's three components (:meth:`LoadTilt.split_columns`, loaded in the split run's own batch),
so the refit needs no run. ``t = 0`` is the load as declared (nested, two-sided), each
angle bounded to +-pi. A component held by a support takes its load into the support: it is
left out of the change. A load's size is ``load_scale``'s; a tilt keeps it.

Candidates: every force and every moment of every fitted case, at a grid (scalar points have no
direction); those of the hold-out cases are what the hold-out check tries a case it does not
predict as (:meth:`LoadTilt.holdout_candidates`). ``where`` is the grid; the case, the vector (``force`` or ``moment``) and the two
axes (in basic) are in the details, and the report gives the angle and the turned direction;
beyond :data:`REVERSED_DEG` it reads the load as applied the other way (pattern ``reversed``).
A data defect: the structure is as declared, the load was not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.decks import constrained_grids
from blackbox.diagnosis.effects.base import CandidateLimit, Effect
from blackbox.diagnosis.effects.registry import register

__all__ = ["LOAD_DOF_COLUMNS", "REVERSED_DEG", "ChangesLoads", "LoadTilt", "case_loads", "tilt", "tilt_derivatives", "within_budget"]


# a load turned by more than this (degrees) acts more against its declared direction than across
# it: reported as reversed (``pattern`` "reversed"), not as mounted askew
REVERSED_DEG = 135.0


def _sinc_terms(theta: float) -> tuple[float, float, float]:
    """``(sin t / t, cos t - 1, (t cos t - sin t) / t^3)`` at ``t = theta``, by series near 0."""
    if theta < 1e-4:
        t2 = theta * theta
        return 1.0 - t2 / 6.0, -t2 / 2.0, -1.0 / 3.0 + t2 / 30.0
    return (np.sin(theta) / theta, np.cos(theta) - 1.0,
            (theta * np.cos(theta) - np.sin(theta)) / theta ** 3)


def tilt(v: np.ndarray, axes: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``R(w) v - v`` for ``w = axes.T @ t`` perpendicular to ``v`` (module docstring)."""
    w = np.asarray(axes, float).T @ np.asarray(t, float)
    s, c, _ = _sinc_terms(float(np.linalg.norm(w)))
    return c * v + s * np.cross(w, v)


def tilt_derivatives(v: np.ndarray, axes: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``d tilt / d t_k`` as rows ``(len(t), 3)``: with ``theta = |w|``, ``d theta / d t_k =
    t_k / theta`` (the axes are orthonormal), ``d (cos theta - 1) = -theta sinc`` and ``d sinc =
    theta q``, ``q = (theta cos theta - sin theta) / theta^3``."""
    axes = np.asarray(axes, float)
    t = np.asarray(t, float)
    w = axes.T @ t
    s, _, q = _sinc_terms(float(np.linalg.norm(w)))
    wv = np.cross(w, v)
    return np.array([-t[k] * s * v + t[k] * q * wv + s * np.cross(axes[k], v) for k in range(len(t))])


def case_loads(ctx, held: bool = False) -> list[tuple[str, int, np.ndarray]]:
    """``(case, grid, load)`` of every grid a fitted case (``held``: a measured case not fitted,
    a hold-out case) loads, its six components in the grid's displacement system, in the cases'
    and the grids' order (scalar points, which have no direction and no neighbour, left out)."""
    loads = ctx.loads
    if loads is None:
        return []
    fitted = set(ctx.fit_obs.case_labels[int(i)] for i in np.unique(ctx.fit_obs.case_index))
    if held:
        m = ctx.measured
        if m is None:
            return []
        want = set(m.case_labels[int(i)] for i in np.unique(m.case_index)) - fitted
    else:
        want = fitted
    grids = ctx.deck.grids
    V = loads.values.tocsc()
    out = []
    for j, case in enumerate(loads.cases):
        if case not in want:
            continue
        col = V[:, j].toarray().ravel()
        per: dict[int, np.ndarray] = {}
        for i in np.flatnonzero(col):
            g, c = loads.dofs[i]
            if g in grids:
                per.setdefault(g, np.zeros(6))[c - 1] = col[i]
        out += [(case, g, f) for g, f in sorted(per.items())]
    return out


LOAD_DOF_COLUMNS = 1.0e7
"""What each load family (``load_tilt``, ``misplaced_load``) may add to the split run, in model
DOFs x unit-load columns: every loaded grid of a study of a few thousand DOFs, 100 columns at
1e5 DOFs (about 15 s through MYSTRAN), 10 at 1e6."""


def within_budget(ctx, kind: str, cands: list, n_dofs: int) -> list:
    """``cands`` whose unit-load columns (:attr:`~Effect.load_dofs`) fit in
    :data:`LOAD_DOF_COLUMNS` / ``n_dofs``: grids taken whole, those loaded in the most cases
    first (then by the largest load there; the same choice wherever it is made, from the
    deck and the loads alone). Beyond it the limit is noted in ``ctx`` (reported)."""
    budget = int(LOAD_DOF_COLUMNS // max(n_dofs, 1))
    cols = {d for e in cands for d in e.load_dofs}
    if len(cols) <= budget:
        return cands
    per: dict[int, list] = {}
    for e in cands:
        per.setdefault(e.grid, []).append(e)
    order = sorted(per, key=lambda g: (-len({e.case for e in per[g]}), -max(e.size for e in per[g]), g))
    kept, have = [], set()
    for g in order:
        new = {d for e in per[g] for d in e.load_dofs} - have
        if len(have) + len(new) > budget:
            continue
        have |= new
        kept += per[g]
    kept_ids = {id(e) for e in kept}
    ctx.note_limit(CandidateLimit(kind, len(kept), len(cands),
                                  f"the grids loaded in the most cases whose unit-load columns fit in "
                                  f"{LOAD_DOF_COLUMNS:.0e} model DOFs x columns", ""))
    return [e for e in cands if id(e) in kept_ids]


def perpendicular_axes(v: np.ndarray) -> np.ndarray:
    """Two orthonormal axes perpendicular to ``v`` (rows, in ``v``'s coordinates): the
    coordinate axis least along ``v`` made perpendicular to it, and ``v`` cross that."""
    n = v / np.linalg.norm(v)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    a = a - (a @ n) * n
    a /= np.linalg.norm(a)
    return np.array([a, np.cross(n, a)])


class ChangesLoads:
    """What a family whose effects change the study's loads at a grid (``where[0]``) shares on
    top of :class:`Effect`: its candidates of the fitted cases and of the hold-out cases, each
    kept within its column budget (:func:`within_budget`), whose :attr:`~Effect.load_dofs` the
    split run loads one by one and a refit needs. Mixed into a dataclass that lists every
    candidate, before the budget (``_listed(ctx, held_cases)``), and says each one's ``size``
    (the load at its grid, which orders the grids kept)."""

    @property
    def grid(self) -> int:
        return int(self.where[0])

    @classmethod
    def candidates(cls, ctx, split) -> list:
        return within_budget(ctx, cls.kind, cls._listed(ctx), 6 * len(ctx.deck.grids))

    @classmethod
    def holdout_candidates(cls, ctx, split) -> list:
        return within_budget(ctx, f"{cls.kind} (hold-out cases)", cls._listed(ctx, True), 6 * len(ctx.deck.grids))

    @classmethod
    def split_columns(cls, ctx, split) -> tuple:
        return tuple(dict.fromkeys(d for e in cls.candidates(ctx, split) + cls.holdout_candidates(ctx, split)
                                   for d in e.load_dofs))

    def refit_columns(self):
        return self.load_dofs


@register
@dataclass(frozen=True, eq=False)
class LoadTilt(ChangesLoads, Effect):
    """``case``: the case whose load is turned; ``first``: 1 for the force, 4 for the moment at
    ``where[0]``; ``v``: the declared vector (the grid's displacement system); ``axes``: the two
    tilt axes in that system; ``frame``: its unit vectors in basic (rows); ``free``: the
    components the load can move (those not held by a support)."""
    kind = "load_tilt"
    summary = "one load of one case went in turned off its declared direction (the data, not the structure)"
    of_data = True

    case: str = ""
    first: int = 1
    v: tuple = ()
    axes: tuple = ()
    frame: tuple = ()
    free: tuple[int, ...] = ()

    @property
    def size(self) -> float:
        return float(np.linalg.norm(self.v))

    @classmethod
    def _loaded(cls, ctx, held: bool = False) -> list[tuple[str, int, int, np.ndarray]]:
        """``(case, grid, first component, vector)`` of every force and moment of a fitted case
        (``held``: of a hold-out case)."""
        return [(case, g, first, f[first - 1:first + 2]) for case, g, f in case_loads(ctx, held)
                for first in (1, 4) if np.any(f[first - 1:first + 2])]

    @classmethod
    def _listed(cls, ctx, held_cases: bool = False) -> list["LoadTilt"]:
        """Every candidate, before the column budget (:func:`within_budget`)."""
        held = constrained_grids(ctx.deck)
        loaded = cls._loaded(ctx, held_cases)
        if not loaded:
            return []
        frames = dict(zip(sorted({g for _, g, _, _ in loaded}),
                          ctx.deck.displacement_frames(sorted({g for _, g, _, _ in loaded}))))
        out = []
        for case, g, first, vec in loaded:
            free = tuple(k for k in range(3) if str(first + k) not in held.get(g, ""))
            if not free:
                continue
            what = "F" if first == 1 else "M"
            ax = perpendicular_axes(vec)
            out.append(cls((g,), (f"tilt_{case}_{g}_{what}_a", f"tilt_{case}_{g}_{what}_b"), case=case, first=first,
                           v=tuple(float(a) for a in vec), axes=tuple(tuple(float(a) for a in r) for r in ax),
                           frame=tuple(tuple(float(a) for a in r) for r in frames[g]), free=free))
        return out

    @property
    def key(self) -> tuple:
        return (self.kind, self.case, self.grid, self.first)

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(2)

    @property
    def bounds(self):
        return np.full(2, -np.pi), np.full(2, np.pi)

    @property
    def load_dofs(self):
        return tuple((self.grid, self.first + k) for k in self.free)

    def _column(self, cases) -> int:
        return list(cases).index(self.case)

    def load_change(self, x_effect, cases):
        out = np.zeros((len(self.free), len(cases)))
        out[:, self._column(cases)] = tilt(np.array(self.v), np.array(self.axes), x_effect)[list(self.free)]
        return out

    def load_change_derivatives(self, x_effect, cases):
        out = np.zeros((2, len(self.free), len(cases)))
        out[:, :, self._column(cases)] = tilt_derivatives(np.array(self.v), np.array(self.axes), x_effect)[:, list(self.free)]
        return out

    def turned(self, t: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """``(angle in degrees, declared direction, turned direction)``, the directions in basic."""
        v = np.array(self.v)
        R = np.array(self.frame)
        w = np.array(self.axes).T @ np.asarray(t, float)
        d0 = R.T @ v / np.linalg.norm(v)
        d1 = R.T @ (v + tilt(v, np.array(self.axes), t)) / np.linalg.norm(v)
        return float(np.degrees(np.linalg.norm(w))), d0, d1

    def details_json(self) -> dict:
        R = np.array(self.frame)
        return {"case": self.case, "vector": "force" if self.first == 1 else "moment",
                "axes": [[float(a) for a in R.T @ np.array(r)] for r in self.axes]}

    def findings(self, fit) -> dict:
        e, sl = self.in_fit(fit)
        deg, d0, d1 = e.turned(fit.x[sl])
        what = "force" if self.first == 1 else "moment"

        def fmt(d):
            return "(" + ", ".join(f"{a:.3f}" for a in d) + ")"
        if deg > REVERSED_DEG:
            why = "the load applied the other way, push for pull?"
        else:
            why = "a load mounted askew?"
        return {"pattern": "reversed" if deg > REVERSED_DEG else "turned", "angle_deg": deg,
                "declared_direction": [float(a) for a in d0], "turned_direction": [float(a) for a in d1],
                "pattern_detail": f"the {what} at grid {self.grid} in case {self.case} went in turned {deg:.3g} degrees, "
                                  f"along {fmt(d1)} instead of {fmt(d0)} in basic ({why})"}

    def label(self) -> str:
        return f"{self.kind} @ {self.grid} case {self.case} ({'force' if self.first == 1 else 'moment'})"

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []
