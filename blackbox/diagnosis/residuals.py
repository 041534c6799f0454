"""Where the residual concentrates: whitened residuals grouped per case, grid and component, the
hotspots of the chi-square excess, and the default hold-out cases of a diagnosis."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy import stats

from blackbox.identification import Observations

__all__ = ["residual_structure", "hotspots"]


def residual_structure(obs: Observations, r: np.ndarray, xyz: dict | None = None, top: int = 10) -> dict:
    """Whitened residuals grouped per case, per grid and per component: ``chi2/n`` and the
    upper-tail p-value of each group against ``chi2(n)`` (the declared noise), plus every
    measured grid's RMS and coordinates (the spatial map)."""
    def groups(keys):
        out = {}
        for k in dict.fromkeys(keys):
            sel = np.array([kk == k for kk in keys])
            c2 = float(np.sum(r[sel] ** 2))
            n = int(sel.sum())
            out[k] = {"n": n, "chi2_per_n": c2 / n, "rms": math.sqrt(c2 / n),
                      "p_value": float(stats.chi2.sf(c2, n))}
        return out
    labels = obs.case_labels
    per_case = groups([labels[c] if labels else str(c) for c in obs.case_index])
    per_grid = groups([int(d[0]) for d in obs.dofs])
    per_comp = groups([int(d[1]) for d in obs.dofs])
    worst = sorted(per_grid.items(), key=lambda kv: kv[1]["p_value"])[:top]
    grid_map = [{"grid": g, "rms": v["rms"], "n": v["n"],
                 "xyz": list(xyz[g]) if xyz and g in xyz else None} for g, v in per_grid.items()]
    return {"per_case": per_case, "per_component": {str(k): v for k, v in per_comp.items()},
            "per_grid": {str(k): v for k, v in per_grid.items()},
            "worst_grids": [{"grid": g, **v} for g, v in worst], "grid_map": grid_map}


def hotspots(obs: Observations, r: np.ndarray, top: int = 10) -> dict[str, list[dict]]:
    """Where the chi-square excess of whitened residuals ``r`` sits: per grid, case and component
    the group's excess ``sum(z^2 - 1)`` over its rows, clipped at 0, as a share of the sum of the
    clipped excesses of all groups of that kind (the noise alone gives excesses near 0 spread
    over every group; a misfit concentrated at a few grids gives them most of the share).
    Returns ``{"grids": [{"grid", "share", "n", "excess"}], "cases": [{"case", ...}],
    "components": [{"component", ...}]}``, largest share first, the ``top`` largest positive
    shares of each kind."""
    labels = obs.case_labels
    z2m1 = np.asarray(r, float) ** 2 - 1.0

    def shares(keys, name):
        acc: dict = {}
        cnt: dict = {}
        for k, v in zip(keys, z2m1):
            acc[k] = acc.get(k, 0.0) + float(v)
            cnt[k] = cnt.get(k, 0) + 1
        pos = {k: max(v, 0.0) for k, v in acc.items()}
        total = sum(pos.values())
        if total <= 0.0:
            return []
        best = sorted((k for k in pos if pos[k] > 0.0), key=lambda k: -pos[k])[:top]
        return [{name: k, "share": pos[k] / total, "n": cnt[k], "excess": acc[k]} for k in best]

    return {"grids": shares([int(d[0]) for d in obs.dofs], "grid"),
            "cases": shares([labels[c] if labels else str(c) for c in obs.case_index], "case"),
            "components": shares([int(d[1]) for d in obs.dofs], "component")}
