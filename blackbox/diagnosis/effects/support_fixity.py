"""``support_fixity``: a support restrains a component the model leaves free (a pin that is not one).

A frame model takes a column base as a pin (translations held, rotations free) or a bearing as a
roller (one translation free); the real base plate, grouted anchor bolts or a seized bearing
restrain that component partly or wholly. ``support_flexibility`` only softens what the model
holds; this family stiffens what it leaves free: a grounded spring on each free component ``c``
of a supported grid,

    k_c = k_ref_c r / (1 - r)

with ``r`` the *fixity factor* of the semi-rigid connection literature (0: the model's pin,
1: clamped) and ``k_ref_c`` the sum of the members' own diagonal stiffness at the grid in that
component (what the members resist there themselves; at ``r = 1/2`` the base restrains as much
as the members do). ``r`` is nested at 0 (one-sided: a support cannot pull a free component the
other way) and bounded by ``R_MAX``: a fixity of 0.99 restrains 99 times what the members do,
which the readings cannot tell from a clamp, and a refit that ends there says "clamped" -- a
plausible value, never rejected as beyond one (:meth:`SupportFixity.rejection`).

Candidates, per supported grid (SPC1 sets and GRID PS) with a free component that its members
stiffen (a pin flag or a rod leaves none: no spring could act there), not in an RBE2:

* "rotations": one factor on every free rotation (a base plate fixes the rotations together),
  richer "per-axis" (one factor per free rotation, nested at all equal);
* "component-c": one free component alone (a base restrained in one plane, a roller that does
  not roll), for every free translation and, when several rotations are free, each of them.

It enters the augmented model through the nonlinear stiffness hook (``dK(r)`` on the grid's
free components, exactly 0 at ``r = 0``); its score at ``r = 0`` (``d dK / dr = k_ref``) needs
only rows of the split run at the grid, by reciprocity, as ``member_stiffness``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blackbox.diagnosis.decks import constrained_grids, in_member_frames, members_at, rbe2_grids
from blackbox.diagnosis.effects.base import Effect, kept_parameters
from blackbox.diagnosis.effects.member_stiffness import stiffness_columns
from blackbox.diagnosis.effects.registry import register
from solver_adapters.protocol import DofLabel

__all__ = ["SupportFixity", "R_MAX", "free_stiffness"]

R_MAX = 0.99                # the largest fixity factor: k = 99 k_ref, a clamp to the readings
LIVE = 1e-6                 # a component whose members' stiffness is below this x the largest
                            # of its kind at the grid has none (a pin flag: rounding only)
AT_ZERO = 1e-6              # a per-axis factor below this after a refit: that component stays free
STARTS = (0.5, 0.9)         # refit starts beyond the nested point and the score step: a clamp
                            # (r near 1) is far along a curved path from r = 0


def free_stiffness(deck, K_e: dict[int, np.ndarray]) -> dict[int, dict[int, float]]:
    """Supported grid -> {free component: ``k_ref``}: the components its SPCs leave free that its
    members stiffen (the sum of their own diagonal stiffness there, in the grid's CD system)."""
    at = members_at(deck)
    in_rbe2 = rbe2_grids(deck)
    out: dict[int, dict[int, float]] = {}
    for g, held in sorted(constrained_grids(deck).items()):
        if g in in_rbe2 or g not in at or any(e not in K_e for e in at[g]):
            continue
        diag = np.zeros(6)
        for eid in at[g]:
            b = deck.cbars[eid]
            K = in_member_frames(deck, eid, K_e[eid])
            diag += np.diag(K)[0:6] if b.ga == g else np.diag(K)[6:12]
        free = {}
        for c in range(1, 7):
            group = slice(0, 3) if c <= 3 else slice(3, 6)
            if str(c) not in held and diag[c - 1] > LIVE * np.max(diag[group]):
                free[c] = float(diag[c - 1])
        if free:
            out[g] = free
    return out


@register
@dataclass(frozen=True, eq=False)
class SupportFixity(Effect):
    """``dofs``: the grid's free components restrained (``(g, c)``), ``k_ref`` their members'
    stiffness (same order)."""
    kind = "support_fixity"
    summary = ("a support restrains a component the model leaves free (a grounded spring, fixity factor "
               "0 = the model's pin, 1 = clamped)")
    of_data = False

    dofs: tuple[DofLabel, ...] = ()
    k_ref: tuple[float, ...] = ()

    @property
    def grid(self) -> int:
        return int(self.where[0])

    # ---- listing ------------------------------------------------------------------------------
    @classmethod
    def split_rows(cls, ctx, split) -> tuple[DofLabel, ...]:
        """The free components of every supported grid: the score reads the split run there."""
        return tuple((g, c) for g, free in free_stiffness(ctx.deck, ctx.K_e).items() for c in free)

    @classmethod
    def candidates(cls, ctx, split) -> list["SupportFixity"]:
        out = []
        for g, free in free_stiffness(ctx.deck, ctx.K_e).items():
            rot = [c for c in free if c >= 4]
            if rot:
                out.append(cls((g,), (f"r_{g}_R",), "rotations", dofs=tuple((g, c) for c in rot),
                               k_ref=tuple(free[c] for c in rot)))
            for c in free:
                if c <= 3 or len(rot) > 1:
                    out.append(cls((g,), (f"r_{g}_{c}",), f"component-{c}", dofs=((g, c),), k_ref=(free[c],)))
        return out

    @property
    def key(self) -> tuple:
        # "rotations" and each component are distinct hypotheses at one grid; "per-axis" refines
        # "rotations" in place (same key)
        return (self.kind, tuple(self.where), "rotations" if self.variant == "per-axis" else self.variant)

    def applicable(self, spec) -> bool:
        """Not on a component another fixity at the grid already restrains."""
        mine = set(self.dofs)
        return not any(isinstance(e, SupportFixity) and e.key != self.key and mine & set(e.dofs)
                       for e in spec.effects)

    # ---- parameters ---------------------------------------------------------------------------
    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(self.n_params)

    @property
    def bounds(self):
        return np.zeros(self.n_params), np.full(self.n_params, R_MAX)

    @property
    def one_sided(self) -> np.ndarray:
        return np.ones(self.n_params, bool)

    def _factors(self, x_effect) -> np.ndarray:
        """Each restrained component's fixity factor."""
        x = np.asarray(x_effect, float)
        return np.full(len(self.dofs), x[0]) if self.n_params == 1 else x

    # ---- the augmented model ------------------------------------------------------------------
    @property
    def stiffness_dofs(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def stiffness_matrix(self, x_effect) -> np.ndarray:
        r = self._factors(x_effect)
        return np.diag(np.array(self.k_ref) * r / (1.0 - r))

    def stiffness_derivatives(self, x_effect) -> np.ndarray:
        r = self._factors(x_effect)
        rate = np.array(self.k_ref) / (1.0 - r) ** 2
        if self.n_params == 1:
            return np.diag(rate)[None]
        out = np.zeros((self.n_params, len(self.dofs), len(self.dofs)))
        for q in range(self.n_params):
            out[q, q, q] = rate[q]
        return out

    # ---- scoring and refits -------------------------------------------------------------------
    def refit_columns(self) -> tuple[DofLabel, ...]:
        return self.dofs

    def refit_starts(self, x2, step, lo, hi, first):
        starts = super().refit_starts(x2, step, lo, hi, first)
        for r in STARTS:
            xs = x2.copy()
            xs[first:] = r
            starts.append(xs)
        return starts

    @classmethod
    def batch_columns(cls, model, st, x, om, effects):
        """``d prediction / d r`` at ``r = 0`` for fixities NOT in ``model``: ``dK/dr = k_ref`` on
        the grid's components, by reciprocity (rows of the split run, no column of their own)."""
        if any(e.n_params != 1 for e in effects):
            return None
        return stiffness_columns(model, st, x, om, [(e.dofs, np.diag(e.k_ref)) for e in effects])

    def rejection(self, x_effect) -> str | None:
        """A fixity at ``R_MAX`` is a clamp, a plausible support: never rejected for its bound."""
        return None

    # ---- variants -----------------------------------------------------------------------------
    @property
    def variant_tests(self) -> int:
        return 1 if self.variant == "rotations" and len(self.dofs) >= 2 else 0

    def richer(self, x_effect):
        """"rotations" -> "per-axis", every rotation's factor at the common one."""
        if self.variant != "rotations" or len(self.dofs) < 2:
            return []
        names = tuple(f"r_{self.grid}_{c}" for _, c in self.dofs)
        return [(replace(self, names=names, variant="per-axis"),
                 np.full(len(self.dofs), float(np.asarray(x_effect)[0])))]

    def trimmed(self, x_effect) -> "SupportFixity | None":
        """Per axis: the components whose factor ended at 0 stay free (at least one is kept)."""
        if self.variant != "per-axis":
            return None
        keep = kept_parameters(x_effect, AT_ZERO)
        if keep is None:
            return None
        return replace(self, names=tuple(n for n, k in zip(self.names, keep) if k),
                       dofs=tuple(d for d, k in zip(self.dofs, keep) if k),
                       k_ref=tuple(v for v, k in zip(self.k_ref, keep) if k))

    # ---- reports ------------------------------------------------------------------------------
    def details_json(self) -> dict:
        return {**super().details_json(), "components": [int(c) for _, c in self.dofs],
                "k_ref": [float(k) for k in self.k_ref]}

    def findings(self, fit) -> dict:
        """The grounded spring each component gets, ``k_ref r / (1 - r)`` (N/m or N m/rad)."""
        e, sl = self.in_fit(fit)
        r = e._factors(fit.x[sl])
        k = np.array(e.k_ref) * r / (1.0 - r)
        return {"spring_stiffness": {str(c): float(v) for (_, c), v in zip(e.dofs, k)}}

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []
