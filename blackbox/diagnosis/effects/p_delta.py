"""``p_delta``: the geometric stiffness of a declared permanent load (P-Delta) that the linear
model leaves out.

The study declares the load the structure carries throughout the test (``study.toml``
``[[preloads]]``: a column's axial load, the dead load on a floor); it is no load case: the
readings are taken from the preloaded state, as a rig zeroes its sensors after applying it. The
members' axial forces under it come from the black box: one run of the split deck under the
permanent load, its rigid state conditioned like the study's cases, evaluated in the declared
model at the declared fit's joint stiffness (:func:`axial_forces`); each member's end forces are
its ``K_e`` (the solver's own element) times its end displacements, and its axial force ``N``
(tension positive) their component along the member's axis at end b. The forces are held at
that solution: a first-order analysis, exact when the structure is statically determinate for
the load (a cantilever column) and otherwise as good as the declared joints.

Each member with an axial force adds the consistent Euler-Bernoulli geometric stiffness of a
beam (:func:`geometric_stiffness_local`: Przemieniecki 1968, McGuire, Gallagher & Ziemian 2000
eq. 9.19, bending in both planes; the axial and torsional terms, ``N / EA`` of the element's own,
are left out), in the member's axes read from ``K_e`` (:func:`member_axis`; the transverse
terms are the same in every plane through the axis, so no orientation vector is needed) and
turned into its grids' components in the split deck. Their sum ``K_G`` enters as a linear
stiffness term ``dK = theta K_G``: nested at ``theta = 0`` (no P-Delta), ``theta = 1`` the
declared load acting with its full geometric effect; bounded to ``[-10, 10]`` (two-sided: the
data may say the structure is stiffer than the declared load would leave it). Scored by
reciprocity like a member factor (no run); its refit needs unit-load columns at every DOF
``K_G`` touches.

Checked against closed forms (``tests/test_response_effects.py``): a cantilever's lateral
stiffness under axial compression ``P`` from the stability functions,
``k = P kappa / (tan(kappa L) - kappa L)`` with ``kappa = sqrt(P / EI)`` (Timoshenko & Gere 1961,
Sec. 1.11), and, for a column turning rigidly on its base spring, the first-order reduction
``P / L``. It is a defect of the structure's model, not of the data.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from blackbox.diagnosis.decks import in_member_frames, member_frames
from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.member_stiffness import stiffness_columns
from blackbox.diagnosis.effects.registry import register
from solver_adapters.protocol import DofLabel, LoadMatrix

__all__ = ["PDelta", "Preload", "geometric_stiffness_local", "member_axis", "member_geometric_stiffness",
           "axial_forces"]

THETA_BOUND = 10.0
AXIAL_RTOL = 1e-9           # members whose axial force is below this of the largest carry none
                            # (the rounding of K_e u in a member the permanent load does not reach)


@dataclass(frozen=True, eq=False)
class Preload:
    """The declared permanent load (one load case, ``loads``) and, once solved, each member's
    axial force under it (``axial``: member -> N, tension positive; ``None`` before the run)."""
    loads: LoadMatrix
    axial: dict[int, float] | None = None
    end_displacements: dict[int, np.ndarray] = field(default_factory=dict)

    def entries(self) -> list[list]:
        """``[[grid, component, value], ...]`` of the permanent load."""
        V = self.loads.values.toarray()[:, 0]
        return [[int(g), int(c), float(v)] for (g, c), v in zip(self.loads.dofs, V) if v != 0.0]


def geometric_stiffness_local(N: float, L: float) -> np.ndarray:
    """The consistent geometric stiffness (12 x 12, element axes, DOFs ``u v w th_x th_y th_z``
    at end a then end b) of an Euler-Bernoulli beam of length ``L`` under axial force ``N``
    (tension positive): ``N / (30 L)`` times the cubic-interpolation matrix in each bending plane
    (``v, th_z`` with ``th_z = v'``; ``w, th_y`` with ``th_y = -w'``)."""
    c = N / (30.0 * L)
    bend = c * np.array([[36.0, 3.0 * L, -36.0, 3.0 * L],
                         [3.0 * L, 4.0 * L * L, -3.0 * L, -L * L],
                         [-36.0, -3.0 * L, 36.0, -3.0 * L],
                         [3.0 * L, -L * L, -3.0 * L, 4.0 * L * L]])
    K = np.zeros((12, 12))
    K[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = bend                 # v, th_z
    flip = np.diag([1.0, -1.0, 1.0, -1.0])                          # th_y = -w'
    K[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = flip @ bend @ flip    # w, th_y
    return K


def member_axis(K_e: np.ndarray) -> np.ndarray:
    """The vector from end a to end b of a member, read from its ``K_e`` (basic axes, DOFs
    ``a1..a6, b1..b6``): ``K_e = T^T K_bb T`` with ``T = [-Gamma, I]``, ``Gamma = -K_bb^-1 K_ba``
    whose upper right block is ``-[r x]`` (how :func:`blackbox.diagnosis.runs.element_stiffness`
    builds it)."""
    gamma = -np.linalg.solve(K_e[6:, 6:], K_e[6:, :6])
    S = -gamma[:3, 3:]
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def member_geometric_stiffness(K_e: np.ndarray, N: float) -> np.ndarray:
    """The member's geometric stiffness under ``N`` in basic axes (DOFs ``a1..a6, b1..b6``): the
    local matrix turned by ``R = [e_x; e_y; e_z]``, ``e_x`` along :func:`member_axis`, ``e_y``,
    ``e_z`` any two directions completing it (the matrix is the same for every such pair)."""
    r = member_axis(K_e)
    L = float(np.linalg.norm(r))
    ex = r / L
    helper = np.eye(3)[int(np.argmin(np.abs(ex)))]
    ey = np.cross(ex, helper)
    ey /= np.linalg.norm(ey)
    R = np.vstack([ex, ey, np.cross(ex, ey)])
    T = np.kron(np.eye(4), R)
    return T.T @ geometric_stiffness_local(N, L) @ T


def axial_forces(base, member_dofs: dict[int, tuple[DofLabel, ...]], K_e: dict[int, np.ndarray], deck,
                 preload: LoadMatrix, boundary, K_deck, joints, k, log: list) -> Preload:
    """The members' axial forces under the permanent load ``preload`` in the declared model
    (the joints ``joints`` at ``k``) on the split structure ``base``: one run of the split deck
    (recorded in ``log``), conditioned on its rigid state, the declared model's joint
    stiffness added (:class:`blackbox.diagnosis.model.AugmentedModel`); each member's end
    displacements (its split-deck DOFs ``member_dofs``, in its grids' components) turned into
    basic, ``K_e`` times them, the end-b force along the axis. The split run must report every
    member's end DOFs (:meth:`PDelta.split_rows`)."""
    from blackbox.diagnosis.model import AugmentedModel, ModelSpec
    from blackbox.diagnosis.runs import solve
    from blackbox.diagnosis.separation import unit_load_view

    V = solve(base.adapter, preload, base.rows, "permanent load (p_delta)", base.deck, log)
    view = unit_load_view(base, [])
    view.n_cases, view.cases = 1, tuple(preload.cases)
    if base.m:
        view.lam = base.Q @ base.P(V)
        view.U_rigid = V - base._Z @ view.lam
    else:
        view.lam, view.U_rigid = np.zeros((0, 1)), V
    eids = sorted(e for e in member_dofs if e in K_e and e in deck.cbars)   # bars: a rod has no bending
    rows = list(dict.fromkeys(d for e in eids for d in member_dofs[e]))
    U = AugmentedModel(view, ModelSpec(tuple(joints)), boundary, K_deck, rows).state(np.asarray(k, float)).U_O[:, 0]
    at = {d: i for i, d in enumerate(rows)}
    axial, ends = {}, {}
    for e in eids:
        u_cd = U[[at[d] for d in member_dofs[e]]]
        u = member_frames(deck, e).T @ u_cd if (deck.grids[deck.cbars[e].ga].cd or deck.grids[deck.cbars[e].gb].cd) \
            else u_cd
        r = member_axis(K_e[e])
        axial[e] = float((K_e[e] @ u)[6:9] @ (r / np.linalg.norm(r)))
        ends[e] = u_cd
    return Preload(preload, axial, ends)


@register
@dataclass(frozen=True, eq=False)
class PDelta(Effect):
    """``dofs``: the split deck's DOFs ``K_G`` acts on; ``K_G`` the members' geometric stiffness
    under the permanent load, summed; ``members``: how many carry an axial force;
    ``largest_compression``: the largest compressive force (positive); ``preloads``: the load;
    ``axial``: ``(member, N)`` of every member it reaches."""
    kind = "p_delta"
    summary = ("the declared permanent load's geometric stiffness (P-Delta) is missing: theta K_G, "
               "theta = 1 the load as declared")

    dofs: tuple[DofLabel, ...] = ()
    K_G: np.ndarray | None = None
    members: int = 0
    largest_compression: float = 0.0
    preloads: tuple = ()
    axial: tuple[tuple[int, float], ...] = ()

    @classmethod
    def split_rows(cls, ctx, split) -> tuple[DofLabel, ...]:
        """Every member's end DOFs when a permanent load is declared: its axial forces are read
        there (the members it reaches are known only after the run)."""
        if ctx.preload is None:
            return ()
        return tuple(d for e in sorted(split.member_dofs) if e in ctx.K_e and e in ctx.deck.cbars
                     for d in split.member_dofs[e])

    @classmethod
    def candidates(cls, ctx, split) -> list["PDelta"]:
        pre = ctx.preload
        if pre is None or not pre.axial:
            return []
        top = max(abs(v) for v in pre.axial.values())
        loaded = [e for e, n in pre.axial.items() if top > 0 and abs(n) > AXIAL_RTOL * top]
        if not loaded:
            return []
        dofs = list(dict.fromkeys(d for e in loaded for d in split.member_dofs[e]))
        at = {d: i for i, d in enumerate(dofs)}
        K = np.zeros((len(dofs), len(dofs)))
        for e in loaded:
            ii = [at[d] for d in split.member_dofs[e]]
            K[np.ix_(ii, ii)] += in_member_frames(ctx.deck, e, member_geometric_stiffness(ctx.K_e[e], pre.axial[e]))
        keep = np.flatnonzero(np.any(K != 0.0, axis=1))           # the axial and torsion DOFs drop out
        K = K[np.ix_(keep, keep)]
        where = tuple(dict.fromkeys(g for g, _, _ in pre.entries()))
        return [cls(where, ("theta",), dofs=tuple(dofs[i] for i in keep), K_G=0.5 * (K + K.T),
                    members=len(loaded), largest_compression=float(max(0.0, -min(pre.axial.values()))),
                    preloads=tuple(tuple(x) for x in pre.entries()),
                    axial=tuple((e, float(pre.axial[e])) for e in sorted(loaded)))]

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(1)

    @property
    def bounds(self):
        return np.full(1, -THETA_BOUND), np.full(1, THETA_BOUND)

    @property
    def stiffness_dofs(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def stiffness_terms(self):
        return [(0, self.K_G)]

    def refit_columns(self) -> tuple[DofLabel, ...]:
        return self.dofs

    @classmethod
    def batch_columns(cls, model, st, x, om, effects: Sequence["PDelta"]):
        return stiffness_columns(model, st, x, om, [(e.dofs, e.K_G) for e in effects])

    def refit_starts(self, x2, step, lo, hi, first):
        out = super().refit_starts(x2, step, lo, hi, first)
        xs = x2.copy()
        xs[first:] = 1.0                    # the declared load acting as declared
        out.append(xs)
        return out

    def details_json(self) -> dict:
        return {"preloads": [list(p) for p in self.preloads], "members": self.members,
                "largest_compression": self.largest_compression}

    def label(self) -> str:
        return f"p_delta of the permanent load at {', '.join(map(str, self.where))}"
