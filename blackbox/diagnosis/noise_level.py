"""Whether a misfit no effect explains looks like noise larger than declared.

On a real rig the declared standard deviations are often a guess (a transducer's data-sheet
figure, a repeatability test on a quiet day), and a guess too small makes every model misfit.
The diagnosis then ends above its noise band with nothing supported, and "the model lacks
something" is not the only reading: the readings may scatter ``c`` times their declared sigma.

When the final fit is above its band, the whitened residuals ``z`` (``chi2 / (n - p) = c^2``)
are tested against noise of ``c`` times the declared sigma, at ``alpha`` split equally among
three tests:

* **even**: each group of readings (per grid, per case, per component, per quarter of the
  declared sigmas: a floor or a proportional part misjudged alone shows there, and per quarter
  of the predicted response in units of its sigma: a model error grows with the response, at
  the largest loads most, where noise of any declared form is the same in those units) has
  ``chi2_g / c^2`` within the two-sided ``chi2(nu_g)`` bounds, ``nu_g`` the group's readings less
  their leverages (what the fit takes from each reading: a reading that pins a parameter keeps
  little residual), Bonferroni over all groups of the five groupings. A model error
  concentrates where the model is wrong (its hotspots), and grows with the response; noise
  spreads as its sigmas say;
* **no gross reading**: the largest ``|z| / c`` within the two-sided Bonferroni normal bound;
* **the hold-out cases** (when there are any): predicted at noise ``c`` times declared by the
  hold-out check (:mod:`blackbox.diagnosis.holdout`), which is data the fit never saw.

When all pass, the diagnosis says so, with ``c``: "the misfit looks like noise ``c`` times the
declared sigma". It is a reading of the evidence, not a verdict: the verdict stays "unexplained"
(the misfit is above the declared band), because a model error spread evenly over the whole
test looks the same; the sentence names both. What it rules out is any effect the search has,
and any misfit concentrated at a grid, a case or a component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

__all__ = ["NoiseLevel", "noise_level", "leverages", "GROUPINGS"]

GROUPINGS = ("grid", "case", "component", "sigma quarter", "response quarter")


@dataclass(frozen=True)
class NoiseLevel:
    """The result of :func:`noise_level`. ``factor``: ``c``, the residual scatter over the
    declared sigma; ``uneven``: the groups beyond their bounds (``grouping, key, chi2 / c^2,
    n``); ``largest_z``: the largest ``|z| / c`` and its bound; ``holdout``: whether the
    hold-out cases are predicted at that noise (``None``: no hold-out cases)."""
    factor: float
    n: int
    dof: float
    uneven: tuple[tuple[str, str, float, int], ...]
    largest_z: float
    z_bound: float
    holdout: bool | None = None
    alpha: float = 0.01

    @property
    def noise_like(self) -> bool:
        return not self.uneven and self.largest_z <= self.z_bound and self.holdout is not False

    def sentence(self) -> str:
        c = f"{self.factor:.3g}"
        if self.noise_like:
            held = "" if self.holdout is None else ", and the hold-out cases are predicted at that noise"
            return (f"the misfit looks like noise {c} times the declared sigma: it is spread evenly over the "
                    "grids, cases, components, sigmas and sizes of the response, no reading is gross at that "
                    f"noise{held}; either the declared sigma understates the noise by about {c} (then the model "
                    "fits), or the model lacks something spread evenly over the whole test")
        why = []
        if self.uneven:
            g, k, q, n = max(self.uneven, key=lambda u: abs(u[2] / max(u[3], 1) - 1.0))
            why.append(f"it is uneven ({len(self.uneven)} group(s) beyond their bounds at that noise, "
                       f"most of all {g} {k}: chi2 {q:.4g} over {n} readings)")
        if self.largest_z > self.z_bound:
            why.append(f"a reading is gross even at that noise (|z| {self.largest_z:.3g} beyond {self.z_bound:.3g})")
        if self.holdout is False:
            why.append("the hold-out cases are not predicted even at that noise")
        return (f"the misfit is not noise {c} times the declared sigma: " + "; ".join(why))

    def to_json(self) -> dict:
        return {"factor": self.factor, "noise_like": self.noise_like, "n": self.n, "dof": self.dof,
                "uneven": [{"grouping": g, "group": k, "chi2_scaled": q, "n": n} for g, k, q, n in self.uneven],
                "largest_z_scaled": self.largest_z, "z_bound": self.z_bound, "holdout_predicted": self.holdout,
                "alpha": self.alpha, "sentence": self.sentence()}


def _quarters(v: np.ndarray) -> np.ndarray:
    """Each value's quarter of the values ``v`` (0..3; equal values kept together)."""
    ranks = np.argsort(np.argsort(v, kind="stable"), kind="stable")
    q = np.minimum(4 * ranks // max(len(v), 1), 3)
    # equal values go to the quarter of the first of them
    first: dict = {}
    for s, k in sorted(zip(v.tolist(), q.tolist())):
        first.setdefault(s, k)
    return np.array([first[s] for s in v.tolist()], int)


def leverages(J: np.ndarray, rtol: float = 1e-10) -> np.ndarray:
    """The diagonal of the hat matrix of the whitened Jacobian ``J`` (rows: readings, columns:
    the free parameters): the squared row norms of its left singular vectors over its numerical
    rank, the columns scaled to unit norm first."""
    J = np.asarray(J, float)
    if J.size == 0:
        return np.zeros(J.shape[0])
    norms = np.linalg.norm(J, axis=0)
    U, s, _ = np.linalg.svd(J / np.where(norms > 0, norms, 1.0), full_matrices=False)
    rank = int(np.sum(s > rtol * (s[0] if s.size else 0.0)))
    return np.sum(U[:, :rank] ** 2, axis=1)


def noise_level(z: np.ndarray, h: np.ndarray, grid: np.ndarray, case: np.ndarray, comp: np.ndarray,
                sigma: np.ndarray, predicted: np.ndarray | None = None, alpha: float = 0.01,
                holdout=None) -> NoiseLevel:
    """The tests of the module docstring on the whitened residuals ``z`` of a fit, ``h`` their
    leverages (:func:`leverages`); ``grid``, ``case``, ``comp``, ``sigma``, ``predicted``: each
    row's grid, case, component, declared sigma and the fit's prediction (``None``: no response
    grouping). ``holdout``: a callable ``factor -> bool`` (are the hold-out cases predicted at
    noise ``factor`` times declared), or ``None``."""
    z = np.asarray(z, float)
    free = 1.0 - np.clip(np.asarray(h, float), 0.0, 1.0)
    n = len(z)
    dof = max(float(free.sum()), 1.0)
    c2 = float(z @ z) / dof
    c = math.sqrt(max(c2, 0.0))
    keys = {"grid": np.asarray(grid), "case": np.asarray(case), "component": np.asarray(comp),
            "sigma quarter": _quarters(np.asarray(sigma, float)),
            "response quarter": (np.zeros(n, int) if predicted is None else
                                 _quarters(np.abs(np.asarray(predicted, float)) / np.asarray(sigma, float)))}
    groups = [(name, k, keys[name] == k) for name in GROUPINGS for k in np.unique(keys[name])]
    a = alpha / (3 if holdout is not None else 2)
    a_group = a / max(len(groups), 1)
    uneven = []
    for name, k, sel in groups:
        m = int(sel.sum())
        nu = max(float(free[sel].sum()), 1e-3)
        q = float(z[sel] @ z[sel]) / c2 if c2 > 0 else 0.0
        if q < stats.chi2.ppf(a_group / 2, nu) or q > stats.chi2.isf(a_group / 2, nu):
            uneven.append((name, str(k), q, m))
    largest = float(np.max(np.abs(z))) / c if n and c > 0 else 0.0
    bound = float(-special.ndtri(a / (2 * n))) if n else math.inf
    held = None if holdout is None else bool(holdout(c))
    return NoiseLevel(c, n, float(dof), tuple(uneven), largest, bound, held, alpha)
