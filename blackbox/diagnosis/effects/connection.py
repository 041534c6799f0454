"""What the three connection families share: a cut of the split deck released as a compliance.

A released connection has compliance ``D(theta) = sum_i theta_i D_i`` over its cut pairs (``D = 0``
is rigid: the declared state, exactly and well conditioned). ``D_i`` is :attr:`Connection.basis`
``[i]``; ``k_ref[i] / theta_i`` is parameter ``i``'s stiffness (reported as such). The compliance
form of :class:`blackbox.diagnosis.model.AugmentedModel` takes it; the parameters are one-sided
(``theta >= 0``), bounded by ``THETA_MAX`` (a free cut is a mechanism), and a parameter that a
refit leaves at 0 is dropped (that part of the connection stays rigid); one at ``THETA_MAX`` is
reported as released (a hinge, a slot, a support that does not hold).

*Variants.* A connection carries a ladder of nested parameterisations of the same cut
(:class:`Rung`: simplest first), each with the matrix that maps the previous rung's parameters to
its own nested point; a candidate starts at the first rung and :meth:`Connection.richer` offers the
higher ones. The helpers build the usual ladders: :func:`branch_ladder` for springs between the
branches of a joint per axis ("equal": one factor on the members' own stiffness along every axis;
"per-axis": one per axis; "per-branch": per axis, one spring from each branch to the joint's
centre) and :func:`grounded_ladder` for grounded springs ("equal": one factor for the
translations and one for the rotations; "per-axis": one per component).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from blackbox.diagnosis.effects.base import Effect, finite_or_none, kept_parameters

if TYPE_CHECKING:
    from blackbox.diagnosis.fit import Fit
    from solver_adapters.protocol import Deck

__all__ = ["Connection", "Rung", "THETA_MAX", "AT_BOUND", "complete_graph_basis", "branch_ladder",
           "branch_axis_basis", "hinge_ladder", "grounded_ladder"]

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


def star_basis(n: int, k_ref: np.ndarray) -> np.ndarray:
    """Compliance per unit parameter of one spring per axis from each of ``n`` branches to a
    common centre (coordinates and ordering as :func:`complete_graph_basis`): branch 1's spring
    moves every relative coordinate of its axis alike (``1 1^T``), branch ``i >= 2``'s only its
    own (``e_i e_i^T``); ``3 n`` parameters, axis-major. Equal compliances ``c`` on one axis give
    ``c (I + 1 1^T)``: the complete graph of equal springs ``1 / (n c)`` (the star-mesh identity),
    so this variant nests :func:`complete_graph_basis` at ``c = theta / n``."""
    return np.stack([branch_axis_basis(n, i, np.eye(3)[p]) / k_ref[p] for p in range(3) for i in range(n)])


@dataclass(frozen=True)
class Rung:
    """One parameterisation of a cut: its ``variant`` name, parameter ``names``, compliance
    ``basis`` ``(p, m, m)``, ``k_ref`` (p) and ``embed`` ``(p, p_prev)``: the previous rung's
    parameters -> this rung's nested point (``None`` for the first rung)."""
    variant: str
    names: tuple[str, ...]
    basis: np.ndarray
    k_ref: np.ndarray
    embed: np.ndarray | None = None


def branch_ladder(n: int, k_ref: np.ndarray, axis_names: tuple[str, str, str], equal_name: str,
                  branch_tags: tuple[str, ...]) -> tuple[Rung, ...]:
    """The ladder of springs between ``n`` branches along three axes: "equal" (one parameter,
    stiffness ``k_ref_p / theta`` along every axis ``p``; reported at the geometric mean of
    ``k_ref``), "per-axis" (``theta_p``: equal springs between every pair of branches along axis
    ``p``, :func:`complete_graph_basis`), "per-branch" (with ``n >= 3``: per axis, one spring from
    each branch to the centre, :func:`star_basis`; names ``<axis name>_<branch tag>``)."""
    k_ref = np.asarray(k_ref, float)
    per_axis = complete_graph_basis(n, k_ref)
    rungs = [Rung("equal", (equal_name,), per_axis.sum(axis=0)[None],
                  np.array([float(np.exp(np.mean(np.log(k_ref))))])),
             Rung("per-axis", tuple(axis_names), per_axis, k_ref, np.ones((3, 1)))]
    if n >= 3:
        embed = np.zeros((3 * n, 3))
        for p in range(3):
            embed[p * n:(p + 1) * n, p] = 1.0 / n
        rungs.append(Rung("per-branch", tuple(f"{a}_{t}" for a in axis_names for t in branch_tags),
                          star_basis(n, k_ref), np.repeat(k_ref, n), embed))
    return tuple(rungs)


def branch_axis_basis(n: int, branch: int, e: np.ndarray) -> np.ndarray:
    """``(3 m, 3 m)``: the compliance of a unit spring about the unit axis ``e`` (in the cut's
    three rotation components) between branch ``branch`` (0-based, of ``n``) and the joint's
    centre, in the coordinates and ordering of :func:`complete_graph_basis`: ``e e^T`` on the
    branch's own block for ``branch >= 1``, on every pair of blocks for the first branch (whose
    turn moves every relative coordinate alike). About the basic axes it gives
    :func:`star_basis`'s terms."""
    m = n - 1
    ee = np.outer(e, e)
    out = np.zeros((3 * m, 3 * m))
    rows = [list(range(p * m, (p + 1) * m)) if branch == 0 else [p * m + branch - 1] for p in range(3)]
    for p in range(3):
        for q in range(3):
            out[np.ix_(rows[p], rows[q])] = ee[p, q]
    return out


def hinge_ladder(n: int, branch: int, axes: np.ndarray, k_ref: np.ndarray, names: tuple[str, str, str]
                 ) -> tuple[Rung, ...]:
    """The ladder of one branch's end turning against the joint about its own bending axes (a
    member end hinged, or connected less rigidly than modelled): ``axes`` its element axes x,
    y, z as rows in the cut's rotation components, ``k_ref`` the cut's reference stiffness per
    component. "hinge" (``names[0]``: one compliance about both bending axes, y and z) and
    "hinge-per-axis" (``names[1:]``: about y and about z apart). About each axis ``a`` the
    reference is the cut's, ``1 / sum_p a_p^2 / k_ref_p``; the hinge's is the geometric mean of
    its two. The twist about the member's own axis stays rigid (a pin releases bending)."""
    k_ref = np.asarray(k_ref, float)
    k_ax = np.array([1.0 / float(np.sum(a * a / k_ref)) for a in axes[1:]])
    per = np.stack([branch_axis_basis(n, branch, a) / k for a, k in zip(axes[1:], k_ax)])
    return (Rung("hinge", (names[0],), per.sum(axis=0)[None], np.array([float(np.sqrt(k_ax[0] * k_ax[1]))])),
            Rung("hinge-per-axis", tuple(names[1:]), per, k_ax, np.ones((2, 1))))


def grounded_ladder(comps: str, k_ref: np.ndarray, name: str) -> tuple[Rung, ...]:
    """The ladder of grounded springs on the components ``comps`` (one cut pair each, in that
    order): "equal" (one factor on the translations' ``k_ref`` and one on the rotations', names
    ``<name>_T``, ``<name>_R``; reported at each group's geometric mean) and "per-axis" (one per
    component, ``<name>_<c>``); only "per-axis" when no group has two components."""
    k_ref = np.asarray(k_ref, float)
    m = len(comps)
    per = np.zeros((m, m, m))
    for q in range(m):
        per[q, q, q] = 1.0 / k_ref[q]
    per_axis = Rung("per-axis", tuple(f"{name}_{c}" for c in comps), per, k_ref)
    groups = [(tag, [q for q, c in enumerate(comps) if c in cs]) for tag, cs in (("T", "123"), ("R", "456"))]
    groups = [(tag, qs) for tag, qs in groups if qs]
    if len(groups) == m:
        return (per_axis,)
    basis = np.stack([per[qs].sum(axis=0) for _, qs in groups])
    kg = np.array([float(np.exp(np.mean(np.log(k_ref[qs])))) for _, qs in groups])
    embed = np.zeros((m, len(groups)))
    for j, (_, qs) in enumerate(groups):
        embed[qs, j] = 1.0
    return (Rung("equal", tuple(f"{name}_{tag}" for tag, _ in groups), basis, kg),
            Rung(per_axis.variant, per_axis.names, per, k_ref, embed))


@dataclass(frozen=True, eq=False)
class Connection(Effect):
    """A released cut: ``pairs`` (indices into the split run's pairs), ``basis`` ``(p, m, m)``,
    ``k_ref`` (p) the stiffness that parameter value 1 stands for; ``ladder`` the variants of the
    cut (module docstring), the current one named by ``variant``."""
    pairs: tuple[int, ...] = ()
    basis: np.ndarray | None = None
    k_ref: np.ndarray | None = None
    ladder: tuple[Rung, ...] = ()
    track: str = ""
    """Which of several candidates on the same cut this is (the joint's "axis-x" beside its
    "equal"): part of the key, so each is scored, refitted and reported on its own."""

    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where)) + ((self.track,) if self.track else ())

    @classmethod
    def on_ladder(cls, where: tuple, pairs, ladder: tuple[Rung, ...], level: int = 0, **kw) -> "Connection":
        """The candidate at rung ``level`` of ``ladder``."""
        r = ladder[level]
        return cls(tuple(where), r.names, r.variant, pairs=tuple(pairs), basis=r.basis, k_ref=r.k_ref,
                   ladder=tuple(ladder), **kw)

    @property
    def variant_tests(self) -> int:
        """Every pair of rungs at or above the current one (each may be refitted against another)."""
        n = len(self.ladder) - [r.variant for r in self.ladder].index(self.variant) if self.ladder else 1
        return n * (n - 1) // 2

    def richer(self, x_effect: np.ndarray) -> list[tuple["Connection", np.ndarray]]:
        """Every higher rung with its nested start: the current parameters by name (a dropped
        one at 0, rigid) carried up through the rungs' ``embed`` maps."""
        levels = [r.variant for r in self.ladder]
        if self.variant not in levels:
            return []
        j = levels.index(self.variant)
        val = dict(zip(self.names, np.asarray(x_effect, float)))
        x = np.array([val.get(n, 0.0) for n in self.ladder[j].names])
        out = []
        for r in self.ladder[j + 1:]:
            x = r.embed @ x
            out.append((replace(self, names=r.names, variant=r.variant, basis=r.basis, k_ref=r.k_ref), x.copy()))
        return out

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

    def rejection(self, x_effect: np.ndarray) -> str | None:
        """``None``: both ends of ``[0, THETA_MAX]`` are physical. At 0 the part stays rigid (the
        nested state); at ``THETA_MAX`` it is released, no more than 1e-4 of the members' own
        stiffness: a hinge where the model has a rigid connection, a slotted hole, a support that
        does not hold that component -- defects real frames have, reported as ``released``
        (:meth:`findings`), as a member factor at its lower bound is reported ``missing``."""
        return None

    def findings(self, fit: "Fit") -> dict:
        """``released``: the parameters at ``THETA_MAX`` (that part of the connection carries
        nothing the readings can tell from nothing)."""
        e, sl = self.in_fit(fit)
        free = [n for n, v in zip(e.names, fit.x[sl]) if v >= THETA_MAX * (1.0 - 1e-9)]
        return {"released": free} if free else {}

    def trimmed(self, x_effect: np.ndarray) -> "Connection | None":
        keep = kept_parameters(x_effect, AT_BOUND)
        if keep is None:
            return None
        return replace(self, names=tuple(n for n, k in zip(self.names, keep) if k),
                       basis=None if self.basis is None else self.basis[keep],
                       k_ref=None if self.k_ref is None else self.k_ref[keep])

    def parameters(self, fit: "Fit") -> list[dict]:
        """Compliances as stiffnesses ``k = k_ref / theta`` (delta-method std), with the compliance."""
        e, sl = self.in_fit(fit)
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
