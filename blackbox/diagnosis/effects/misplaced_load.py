"""``misplaced_load``: the load a case applies at a grid went into the structure at a neighbouring
grid (an actuator on the next node along a member, a weight hung at the wrong joint).

A fitted case, a grid ``g`` it loads and a neighbour ``h`` (joined to ``g`` by one bar or rod,
not held in all six components). A share ``t`` (bounded to ``[0, 2]``): the structure felt
``(1 - t) f`` at ``g`` and ``t f`` at ``h``, ``f`` the case's whole load at ``g`` (force and
moment, the same physical vectors: ``h``'s components from ``g``'s through both grids'
displacement systems). ``t = 0`` is the load as declared (nested, one-sided), ``t = 1`` the
whole load at ``h``. Linear in ``t`` and exact: the structure's response follows from the split
run's unit-load columns at both grids (:meth:`MisplacedLoad.split_columns`, in the split run's
one batch), no run of its own. A refit that ends below ``t = 1/2`` is no misplacement (the
load mostly where declared), one above 3/2 more than a misplacement: rejected, with the
reason (:class:`~blackbox.diagnosis.effects.base.Share`). A component held by a support takes
its load into the support and is left out.

Candidates: every grid a fitted case loads, with each of its neighbours (those of the hold-out
cases: what the hold-out check tries a case it does not predict as). ``where`` is the
declared grid; the case and the grid the load went in at (``moved_to``) are in the details. A
data defect: the structure is as declared, the load was not where the log says.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.decks import constrained_grids
from blackbox.diagnosis.effects.base import Effect, Share
from blackbox.diagnosis.effects.load_tilt import ChangesLoads, case_loads
from blackbox.diagnosis.effects.misplaced_sensor import neighbours
from blackbox.diagnosis.effects.registry import register

__all__ = ["MisplacedLoad"]


def _free(held: dict, g: int) -> tuple[int, ...]:
    """The components 1-6 of ``g`` not held by a support."""
    return tuple(c for c in range(1, 7) if str(c) not in held.get(g, ""))


@register
@dataclass(frozen=True, eq=False)
class MisplacedLoad(Share, ChangesLoads, Effect):
    """``case``: the case; ``moved_to``: the neighbour ``h``; ``at_g``/``at_h``: the free
    components of each grid the load acts on and their values (the whole load ``f`` at ``g`` in
    ``g``'s system, the same load in ``h``'s)."""
    kind = "misplaced_load"
    summary = "the load of one case at a grid went in at a neighbouring grid (the data, not the structure)"
    of_data = True

    case: str = ""
    moved_to: int = 0
    at_g: tuple = ()            # ((component, value), ...) at where[0]
    at_h: tuple = ()            # ((component, value), ...) at moved_to

    @property
    def size(self) -> float:
        return float(np.linalg.norm([v for _, v in self.at_g]))

    @classmethod
    def _places(cls, ctx, held_cases: bool = False) -> list[tuple[str, int, int, np.ndarray]]:
        """``(case, g, h, f)`` of every candidate (``held_cases``: of the hold-out cases)."""
        nb = neighbours(ctx.deck)
        held = constrained_grids(ctx.deck)
        return [(case, g, h, f) for case, g, f in case_loads(ctx, held_cases) for h in nb.get(g, ())
                if h in ctx.deck.grids and held.get(h) != "123456"]

    @classmethod
    def _listed(cls, ctx, held_cases: bool = False) -> list["MisplacedLoad"]:
        """Every candidate, before the column budget (:func:`~blackbox.diagnosis.effects.load_tilt.within_budget`)."""
        places = cls._places(ctx, held_cases)
        if not places:
            return []
        held = constrained_grids(ctx.deck)
        ids = sorted({x for _, g, h, _ in places for x in (g, h)})
        frames = dict(zip(ids, ctx.deck.displacement_frames(ids)))
        out = []
        for case, g, h, f in places:
            T = frames[h] @ frames[g].T             # g's components -> h's (rows: h's directions)
            fh = np.concatenate([T @ f[:3], T @ f[3:]])
            at_g = tuple((c, float(f[c - 1])) for c in _free(held, g) if f[c - 1] != 0.0)
            at_h = tuple((c, float(fh[c - 1])) for c in _free(held, h) if abs(fh[c - 1]) > 1e-12 * np.abs(fh).max())
            if at_g or at_h:
                out.append(cls((g,), (f"t_{case}_{g}_to_{h}",), case=case, moved_to=h, at_g=at_g, at_h=at_h))
        return out

    @property
    def key(self) -> tuple:
        return (self.kind, self.case, self.grid, self.moved_to)

    @property
    def load_dofs(self):
        return tuple((self.grid, c) for c, _ in self.at_g) + tuple((self.moved_to, c) for c, _ in self.at_h)

    def _per_unit(self, cases) -> np.ndarray:
        out = np.zeros((len(self.at_g) + len(self.at_h), len(cases)))
        out[:, list(cases).index(self.case)] = [-v for _, v in self.at_g] + [v for _, v in self.at_h]
        return out

    def load_change(self, x_effect, cases):
        return float(np.asarray(x_effect)[0]) * self._per_unit(cases)

    def load_change_derivatives(self, x_effect, cases):
        return self._per_unit(cases)[None]

    not_low = "the load mostly where declared, not misplaced"
    summary_noun = "a misplacement"

    def share_read(self, t: float) -> str:
        return f"{t:.3g} of the load went in at grid {self.moved_to}"

    def details_json(self) -> dict:
        return {"case": self.case, "moved_to": self.moved_to}

    def findings(self, fit) -> dict:
        return {"pattern": "moved",
                "pattern_detail": f"the load at grid {self.grid} in case {self.case} went into the structure at grid "
                                  f"{self.moved_to}, the next grid along a member (an actuator on the wrong node?)"}

    def label(self) -> str:
        return f"{self.kind} @ {self.grid} case {self.case} at {self.moved_to}"

    def marker_points(self, xyz, deck):
        return [xyz[g] for g in (self.grid, self.moved_to) if g in xyz]
