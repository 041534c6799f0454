"""What the three connection families share: a cut of the split deck released as a compliance.

A released connection has compliance ``D(theta) = sum_i theta_i D_i`` over its cut pairs (``D = 0``
is rigid: the declared state, exactly and well conditioned). ``D_i`` is :attr:`Connection.basis`
``[i]``; ``k_ref[i] / theta_i`` is parameter ``i``'s stiffness (reported as such). The compliance
form of :class:`blackbox.diagnosis.model.AugmentedModel` takes it; the parameters are one-sided
(``theta >= 0``), bounded by ``THETA_MAX`` (a free cut is a mechanism), and a parameter that a
refit leaves at 0 is dropped (that part of the connection stays rigid).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from blackbox.diagnosis.effects.base import Effect, finite_or_none

if TYPE_CHECKING:
    from blackbox.diagnosis.fit import Fit
    from solver_adapters.deck import Deck

__all__ = ["Connection", "THETA_MAX", "AT_BOUND", "complete_graph_basis"]

THETA_MAX = 1e4             # a compliance parameter: connection >= 1e-4 K0 (a free cut is a mechanism)
AT_BOUND = 1e-7             # theta below this after a refit: the connection is rigid (parameter dropped)
START_MIN = 1e-3            # a score-step start keeps every compliance at least this (off the bound)
START_MODERATE = 0.1        # third start: every compliance at 1/10 of K0's


def complete_graph_basis(n: int, k_ref: np.ndarray) -> np.ndarray:
    """Compliance per unit parameter of equal springs between every pair of ``n`` branches, per
    axis, in coordinates 'branch i relative to branch 1' (i = 2..n), pairs ordered axis-major:
    ``D_p = (I + 1 1^T) / (n k_ref_p)`` (the inverse of the reduced Laplacian ``n I - 1 1^T``)."""
    m = n - 1
    block = (np.eye(m) + np.ones((m, m))) / n
    out = np.zeros((3, 3 * m, 3 * m))
    for p in range(3):
        out[p, p * m:(p + 1) * m, p * m:(p + 1) * m] = block / k_ref[p]
    return out


@dataclass(frozen=True, eq=False)
class Connection(Effect):
    """A released cut: ``pairs`` (indices into the split run's pairs), ``basis`` ``(p, m, m)``,
    ``k_ref`` (p) the stiffness that parameter value 1 stands for."""
    pairs: tuple[int, ...] = ()
    basis: np.ndarray | None = None
    k_ref: np.ndarray | None = None

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(self.n_params)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(self.n_params), np.full(self.n_params, THETA_MAX)

    @property
    def one_sided(self) -> np.ndarray:
        return np.ones(self.n_params, bool)

    @property
    def cut_pairs(self) -> tuple[int, ...]:
        return self.pairs

    @property
    def compliance_basis(self) -> np.ndarray | None:
        return self.basis

    def refit_starts(self, x2, step, lo, hi, first):
        starts = super().refit_starts(x2, step, lo, hi, first)
        if len(starts) > 1:
            starts[1][first:] = np.maximum(starts[1][first:], START_MIN)
        xs = x2.copy()
        xs[first:] = START_MODERATE
        return starts + [xs]

    def trimmed(self, x_effect: np.ndarray) -> "Connection | None":
        keep = np.asarray(x_effect) > AT_BOUND
        if not np.any(keep):
            keep[np.argmax(x_effect)] = True
        if np.all(keep):
            return None
        return replace(self, names=tuple(n for n, k in zip(self.names, keep) if k),
                       basis=None if self.basis is None else self.basis[keep],
                       k_ref=None if self.k_ref is None else self.k_ref[keep])

    def parameters(self, fit: "Fit") -> list[dict]:
        """Compliances as stiffnesses ``k = k_ref / theta`` (delta-method std), with the compliance."""
        i = next(i for i, e in enumerate(fit.spec.effects) if e.key == self.key)
        e = fit.spec.effects[i]
        sl = fit.spec.effect_slices()[i]
        out = []
        for q, name in enumerate(e.names):
            v, s = float(fit.x[sl][q]), float(fit.std[sl][q])
            k = e.k_ref[q] / v if v > 0 else float("inf")
            ks = e.k_ref[q] * s / v ** 2 if v > 0 else float("inf")
            out.append({"name": name, "value": finite_or_none(k), "std": finite_or_none(ks),
                        "compliance": finite_or_none(v / e.k_ref[q]),
                        "compliance_std": finite_or_none(s / e.k_ref[q]), "k0": float(e.k_ref[q])})
        return out


class GridConnection(Connection):
    """A connection at one grid (``where = (grid,)``), marked there on residual maps."""

    def marker_points(self, xyz: dict[int, np.ndarray], deck: "Deck") -> list[np.ndarray]:
        return [xyz[int(w)] for w in self.where if int(w) in xyz]
