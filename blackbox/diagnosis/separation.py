"""Which measurement would separate two explanations the data hardly tell apart.

When the search adds one effect and another candidate fits almost as well (a member factor
against the joint at its end; :data:`blackbox.diagnosis.document.AMBIGUOUS`), the report says
what to measure next, from the two fitted models themselves (no solver run):

* **a sensor**: every DOF the split run reports (measured or not: member ends, neighbours of
  sensors, the joints' boundary), under the study's load cases; the separation is the RMS over
  the cases of the two models' difference, in units of the noise of the measured channels of
  the same kind (the median sigma of the translations, or of the rotations);
* **a load case**: a load at each DOF the split run has a unit-load column for (the joints'
  boundary and the measured DOFs), of the study's own size for that kind (the median load
  magnitude of its forces, or of its moments), read by the sensors the study has; the
  separation is the whitened norm of the two models' difference there.

Only the structural responses are compared (the models' displacements before any factor,
offset or mix on measured rows): a data defect (a sensor's gain, a swapped channel) is
separated from the structure by a second, independent sensor at the grid, which the report says
in words.
"""

from __future__ import annotations

import copy
from typing import Sequence

import numpy as np

from blackbox.diagnosis.fit import Fit
from blackbox.diagnosis.model import AugmentedModel, ObsMap
from blackbox.diagnosis.split import SplitBase
from solver_adapters.protocol import DofLabel

__all__ = ["separating_measurements", "unit_load_view"]


def unit_load_view(base: SplitBase, dofs: Sequence[DofLabel]) -> SplitBase | None:
    """The split base with unit loads at ``dofs`` (which must have unit-load columns) as its load
    cases instead of the study's: the rigid state of those columns, and their pair responses for
    the released cuts. ``None`` for a detached base (it no longer has the split run's columns)."""
    if base.G_split is None:
        return None
    cols = [base.col_of[d] for d in dofs]
    view = copy.copy(base)
    view.n_cases = len(cols)
    view.cases = tuple(f"unit:{g}:{c}" for g, c in dofs)
    view.U_rigid = base.G_rigid[:, cols]
    view.lam = base.Q @ base.P(base.G_split[:, cols]) if base.m else np.zeros((0, len(cols)))
    return view


def _kind_sigma(om: ObsMap) -> tuple[float, float]:
    trans = om.sigma[om.comp <= 3] if om.comp is not None else om.sigma
    rot = om.sigma[om.comp >= 4] if om.comp is not None else np.zeros(0)
    t = float(np.median(trans)) if trans.size else float(np.median(om.sigma))
    r = float(np.median(rot)) if rot.size else t
    return t, r


def separating_measurements(base: SplitBase, fit_a: Fit, fit_b: Fit, boundary, K_deck, om: ObsMap,
                            load_magnitudes: tuple[float, float] | None = None, top: int = 3) -> dict:
    """``{"sensors": [...], "loads": [...]}`` (module docstring), best first: each sensor
    ``{"grid", "component", "measured", "separation_sigma"}``, each load ``{"grid", "component",
    "value", "separation_sigma"}`` (``value``: the load's size, from ``load_magnitudes`` =
    (force, moment), else 1 and the separation per unit load)."""
    sig_t, sig_r = _kind_sigma(om)
    rows = list(base.rows)
    measured = {(int(g), int(c)) for g, c in zip(om.grid, om.comp)} if om.comp is not None else set()
    out: dict = {"sensors": [], "loads": []}
    try:
        Ua = AugmentedModel(base, fit_a.spec, boundary, K_deck, rows).state(fit_a.x).U_O
        Ub = AugmentedModel(base, fit_b.spec, boundary, K_deck, rows).state(fit_b.x).U_O
    except Exception:                       # a model that cannot be evaluated at every row: no advice
        return out
    sig = np.array([sig_t if c <= 3 else sig_r for _, c in rows])
    sep = np.sqrt(np.mean(((Ua - Ub) / sig[:, None]) ** 2, axis=1))
    for i in np.argsort(-sep)[:top]:
        g, c = rows[i]
        out["sensors"].append({"grid": int(g), "component": int(c), "measured": (int(g), int(c)) in measured,
                               "separation_sigma": float(sep[i])})
    # loads: unit loads at the split run's unit-load columns, read by the study's sensors
    dofs = list(base.col_of)
    view = unit_load_view(base, dofs)
    if view is None or om.comp is None:
        return out
    chan = list(dict.fromkeys((int(g), int(c)) for g, c in zip(om.grid, om.comp)))
    try:
        Va = AugmentedModel(view, fit_a.spec, boundary, K_deck, chan).state(fit_a.x).U_O
        Vb = AugmentedModel(view, fit_b.spec, boundary, K_deck, chan).state(fit_b.x).U_O
    except Exception:
        return out
    csig = np.array([sig_t if c <= 3 else sig_r for _, c in chan])
    F, M = load_magnitudes if load_magnitudes is not None else (1.0, 1.0)
    size = np.array([F if c <= 3 else M for _, c in dofs])
    lsep = np.linalg.norm((Va - Vb) / csig[:, None], axis=0) * size
    for j in np.argsort(-lsep)[:top]:
        g, c = dofs[j]
        out["loads"].append({"grid": int(g), "component": int(c), "value": float(size[j]),
                             "separation_sigma": float(lsep[j])})
    return out
