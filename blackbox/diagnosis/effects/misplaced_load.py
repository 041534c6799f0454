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

A case that loads several grids may have had more than one of them misplaced (actuators each on
the wrong node, a loading frame set up one bay off). An accepted misplacement is refined
through its richer variant ``loads`` (:class:`MisplacedLoads`, :meth:`MisplacedLoad.richer`):
one more load of the same case at one of its neighbours, each with its own share, kept only
when the data support it on the search's tests, and climbed again from there. One load at a
time, so the variants tried grow with the case's loads and their neighbours, not with their
product; the first climb's are counted in the kind's multiplicity
(:attr:`MisplacedLoad.variant_tests`).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np

from blackbox.diagnosis.decks import constrained_grids
from blackbox.diagnosis.effects.base import Effect, Share
from blackbox.diagnosis.effects.load_tilt import ChangesLoads, case_loads
from blackbox.diagnosis.effects.misplaced_sensor import neighbours
from blackbox.diagnosis.effects.registry import register

__all__ = ["MisplacedLoad", "MisplacedLoads"]


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
    others: tuple = field(default=(), repr=False)   # the same case's other candidate moves:
                                                    # ((g, h, at_g, at_h), ...), the richer variants

    @classmethod
    def candidates(cls, ctx, split) -> list["MisplacedLoad"]:
        kept = super().candidates(ctx, split)
        per: dict[str, list] = {}
        for e in kept:
            per.setdefault(e.case, []).append(e)
        return [dataclasses.replace(e, others=tuple((o.grid, o.moved_to, o.at_g, o.at_h) for o in per[e.case]
                                                    if o.grid != e.grid)) for e in kept]

    def applicable(self, spec) -> bool:
        # a load went in at one place: not again while a misplacement of it is in the model
        return not any(e.kind == self.kind and getattr(e, "case", None) == self.case and self.grid in e.where
                       for e in spec.effects)

    @property
    def variant_tests(self) -> int:
        # the first climb's tests: each of the case's other loads at each of its neighbours (a
        # later climb tests what is left of the same moves, from the model the last one kept)
        return len(self.others)

    def richer(self, x_effect):
        return MisplacedLoads(self.where, self.names, case=self.case, members=(self,),
                              others=self.others).richer(x_effect)

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


@dataclass(frozen=True, eq=False)
class MisplacedLoads(ChangesLoads, Effect):
    """Several loads of one fitted case each went in at a neighbouring grid: the ``members``
    (:class:`MisplacedLoad`, one per declared grid), each with its own share ``t`` (the
    parameters, in the members' order). ``others``: the case's remaining candidate moves (grids
    not among the members), each a richer variant with one member more. The variant ``loads``
    of ``misplaced_load`` (module docstring): never a candidate of its own."""
    kind = "misplaced_load"
    summary = MisplacedLoad.summary
    of_data = True

    variant: str = "loads"
    case: str = ""
    members: tuple = ()
    others: tuple = field(default=(), repr=False)

    @property
    def key(self) -> tuple:
        return (self.kind, self.case, tuple((m.grid, m.moved_to) for m in self.members))

    @property
    def nominal(self) -> np.ndarray:
        return np.zeros(self.n_params)

    @property
    def bounds(self):
        return np.zeros(self.n_params), np.full(self.n_params, 2.0)

    @property
    def one_sided(self) -> np.ndarray:
        return np.ones(self.n_params, bool)

    def refit_starts(self, x2, step, lo, hi, first):
        whole = x2.copy()
        whole[first:] = 1.0
        return super().refit_starts(x2, step, lo, hi, first) + [whole]

    def rejection(self, x_effect) -> str | None:
        for m, t in zip(self.members, np.asarray(x_effect, float)):
            why = m.rejection(np.array([t]))
            if why is not None:
                return f"the load at grid {m.grid}: {why}"
        return None

    def applicable(self, spec) -> bool:
        return True

    @functools.cached_property
    def _rows(self) -> tuple[tuple, list]:
        """The load DOFs (each once: two members may load one grid) and each member's rows in them."""
        dofs = tuple(dict.fromkeys(d for m in self.members for d in m.load_dofs))
        at = {d: i for i, d in enumerate(dofs)}
        return dofs, [np.array([at[d] for d in m.load_dofs], int) for m in self.members]

    @property
    def load_dofs(self):
        return self._rows[0]

    def load_change_derivatives(self, x_effect, cases):
        dofs, rows = self._rows
        out = np.zeros((len(self.members), len(dofs), len(cases)))
        for q, (m, r) in enumerate(zip(self.members, rows)):
            np.add.at(out[q], r, m._per_unit(cases))
        return out

    def load_change(self, x_effect, cases):
        return np.tensordot(np.asarray(x_effect, float), self.load_change_derivatives(x_effect, cases), axes=1)

    def richer(self, x_effect):
        out = []
        x = np.asarray(x_effect, float)
        for g, h, at_g, at_h in self.others:
            m = MisplacedLoad((g,), (f"t_{self.case}_{g}_to_{h}",), case=self.case, moved_to=h, at_g=at_g, at_h=at_h)
            members = self.members + (m,)
            out.append((MisplacedLoads(tuple(k.grid for k in members), tuple(n for k in members for n in k.names),
                                       case=self.case, members=members,
                                       others=tuple(o for o in self.others if o[0] != g)),
                        np.concatenate([x, [0.0]])))
        return out

    def details_json(self) -> dict:
        return {"variant": self.variant, "case": self.case, "moved_to": [m.moved_to for m in self.members]}

    def findings(self, fit) -> dict:
        each = ", ".join(f"{m.grid} at {m.moved_to}" for m in self.members)
        return {"pattern": "moved",
                "pattern_detail": f"the loads of case {self.case} went into the structure at neighbouring grids, each "
                                  f"the next grid along a member: {each} (actuators on the wrong nodes, a loading "
                                  f"frame set up one bay off?)"}

    def label(self) -> str:
        return (f"{self.kind} @ {', '.join(str(m.grid) for m in self.members)} case {self.case} at "
                f"{', '.join(str(m.moved_to) for m in self.members)}")

    def marker_points(self, xyz, deck):
        return [xyz[g] for m in self.members for g in (m.grid, m.moved_to) if g in xyz]
