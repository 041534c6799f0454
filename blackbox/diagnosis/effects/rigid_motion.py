"""``rigid_motion``: in one load case the whole specimen moved as a rigid body.

On a static rig the transducers are referenced to the floor or a frame; when in one case a
support base slides, a bolted foot settles or the reference frame itself is knocked, every
reading of that case carries one and the same rigid-body motion on top of the structure's
response: a translation ``t`` and a small rotation ``w`` of the whole specimen. At grid ``x``
a translation reading along the unit direction ``e`` (its component in the grid's CD system)
gets ``e . (t + w x (x - c))``, a rotation reading ``e . w``; ``c`` is the centre of the measured
grids. Exact and linear, no run: six offsets of the case's readings, each with its own weight.

Parameters: ``t1 t2 t3`` (basic directions, length) and ``r1 r2 r3``, the rotation times ``L``,
the largest distance of a measured grid from ``c`` (so that all six are lengths: the motion a
rotation gives at the farthest sensor). Where the case's readings cannot see a motion (grids
in a line see no rotation about it; one grid read in translation only sees no rotation), those
parameters are left out: the candidate keeps the largest set of the six whose weighted columns
are independent (pivoted QR, a column counted when its pivot is above 1e-6 of the first), so
its LR test has as many degrees of freedom as the readings can tell.

Nested at 0, unbounded. Candidates: every fitted case whose readings can see at least one
motion. It is a defect of the data (the rig, not the structure): a support that is flexible
moves the structure in every case, in proportion to its reaction, and is the structural effect
``support_flexibility``; a motion confined to one case is the rig. Against ``bad_case`` (a free
offset per reading) it costs six parameters at most, so it wins where the case's misfit is
rigid; against a structural effect it must explain one case well enough to beat an effect that
explains every case with fewer parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from blackbox.diagnosis.effects.base import Effect, FreeOffsets
from blackbox.diagnosis.effects.registry import register

__all__ = ["RigidMotion", "rigid_weights"]

VISIBLE = 1e-6          # a motion counts as seen when its pivot is above this share of the first


def rigid_weights(grids: np.ndarray, comps: np.ndarray, geometry: dict, centre: np.ndarray,
                  length: float) -> np.ndarray:
    """``(n, 6)``: the reading of each row (``grids``, ``comps``) per unit ``t1 t2 t3 r1 r2 r3``
    (module docstring); ``geometry``: grid -> ``(xyz, frame)``, ``frame`` the rows' unit
    directions of components 1-3 (and 4-6) in basic."""
    grids, comps = np.asarray(grids, int), np.asarray(comps, int)
    out = np.zeros((len(grids), 6))
    if not len(grids):
        return out
    xyz = np.array([geometry[int(g)][0] for g in grids.tolist()], float)
    frames = np.array([geometry[int(g)][1] for g in grids.tolist()], float)      # (n, 3, 3)
    e = frames[np.arange(len(grids)), (comps - 1) % 3]                            # each reading's direction
    trans = comps <= 3
    out[trans, :3] = e[trans]
    out[trans, 3:] = np.cross(xyz[trans] - centre, e[trans]) / length     # e . (w x r) = w . (r x e)
    out[~trans, 3:] = e[~trans] / length
    return out


@register
@dataclass(frozen=True, eq=False)
class RigidMotion(FreeOffsets, Effect):
    """``case``: the load case; ``motions``: which of ``t1 t2 t3 r1 r2 r3`` (0-5) it fits;
    ``geometry``: grid -> ``(xyz, frame)`` of the measured grids (:func:`rigid_weights`), one
    dict shared by the study's candidates; ``centre``, ``length``: the rotation's centre and
    scale."""
    kind = "rigid_motion"
    of_data = True
    summary = ("in one load case the whole specimen moved as a rigid body (a support base slid, the "
               "reference frame was knocked): every reading of the case carries one rigid translation and rotation")

    case: str = ""
    motions: tuple[int, ...] = ()
    geometry: dict = field(default_factory=dict)
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    length: float = 1.0

    @classmethod
    def candidates(cls, ctx, split) -> list["RigidMotion"]:
        obs = ctx.fit_obs
        grids = sorted({int(g) for g, _ in obs.dofs})
        if not grids:
            return []
        frames = ctx.deck.displacement_frames(grids)
        xyz = {g: np.asarray(ctx.deck.grids[g].xyz, float) for g in grids}
        centre = np.mean([xyz[g] for g in grids], axis=0)
        length = max(float(np.linalg.norm(xyz[g] - centre)) for g in grids) or 1.0
        geometry = {g: (tuple(xyz[g]), tuple(map(tuple, f))) for g, f in zip(grids, frames)}
        g_all = np.array([d[0] for d in obs.dofs], int)
        c_all = np.array([d[1] for d in obs.dofs], int)
        ci = np.asarray(obs.case_index, int)
        sig = np.asarray(obs.sigma, float)
        out = []
        names = ("t1", "t2", "t3", "r1", "r2", "r3")
        for k, case in enumerate(obs.case_labels):
            rows = ci == k
            if not rows.any():
                continue
            W = rigid_weights(g_all[rows], c_all[rows], geometry, centre, length) / sig[rows, None]
            _, R, piv = linalg.qr(W, mode="economic", pivoting=True)
            d = np.abs(np.diag(R))
            seen = sorted(int(p) for p, v in zip(piv, d) if v > VISIBLE * d[0])
            if not seen:
                continue
            out.append(cls((case,), tuple(f"{names[m]}_{case}" for m in seen), case=case, motions=tuple(seen),
                           geometry=geometry, centre=tuple(centre),
                           length=length))
        return out

    def offset_rows(self, om):
        """Weights, not masks: ``x_q`` times the column adds to every row of the case."""
        idx = [i for i, lab in enumerate(om.labels) if lab == self.case]
        rows = np.isin(om.case, idx)
        rows &= np.isin(om.grid, list(self.geometry))
        W = np.zeros((len(om.y), 6))
        if rows.any():
            W[rows] = rigid_weights(om.grid[rows], om.comp[rows], self.geometry, np.asarray(self.centre),
                                    self.length)
        return [(q, W[:, m]) for q, m in enumerate(self.motions)]

    def findings(self, fit) -> dict:
        x = fit.x[self.in_fit(fit)[1]]
        v = np.zeros(6)
        v[list(self.motions)] = x
        return {"translation": [float(a) for a in v[:3]], "rotation_rad": [float(a) / self.length for a in v[3:]],
                "about": [float(a) for a in self.centre]}

    def label(self) -> str:
        return f"{self.kind} @ case {self.case}"
