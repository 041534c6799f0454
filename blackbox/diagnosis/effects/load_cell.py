"""``load_cell``: the load at one grid is off by one factor in every case that loads it (the load
cell of the actuator there reads wrong, a weight's mass mislabelled).

A grid that a fitted case loads. One factor ``s`` (nominal 1, bounded to ``[0.2, 5]`` as a load
scale): the structure felt ``s f_c`` at the grid in every case ``c`` (fitted and hold-out alike:
the same actuator loads them all), ``f_c`` the case's whole declared load there (force and
moment), the other loads of each case as declared. Linear in ``s`` and exact, from the split
run's unit-load columns at the grid (:meth:`LoadCell.split_columns`), no run of its own. A
component held by a support takes its load into the support and is left out.

Where a grid's loads come from one case that loads nothing else, this is that case's
``load_scale``; where several cases load the grid, or a case loads several grids, it is one
parameter where a scale per case would need one per case and get the other loads of each case
wrong. The hold-out cases that load the grid are predicted with the factor, so they check it.

Candidates: every grid a fitted case loads (scalar points left out, as the other load effects
leave them) but a grid whose every case loads nothing else: there the factor is a load scale of
those cases (``load_scale``), one hypothesis that keeps the one name. ``where`` is the grid; the cases that load it are in the
details. A data defect: the structure is as declared, the load was not what the log says.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.decks import constrained_grids
from blackbox.diagnosis.effects.base import Effect
from blackbox.diagnosis.effects.load_tilt import ChangesLoads
from blackbox.diagnosis.effects.registry import register

__all__ = ["LoadCell"]


@register
@dataclass(frozen=True, eq=False)
class LoadCell(ChangesLoads, Effect):
    """``comps``: the grid's free components loaded in some case; ``loads``: ``((case, values at
    comps), ...)`` of every case that loads the grid, in the study's case order."""
    kind = "load_cell"
    summary = ("the load at one grid is off by one factor in every case that loads it (a load cell's "
               "calibration; the data, not the structure)")
    of_data = True

    comps: tuple = ()
    loads: tuple = ()

    @property
    def size(self) -> float:
        return float(max(np.linalg.norm(v) for _, v in self.loads))

    @property
    def case(self) -> str:
        """The first case that loads the grid (what the column budget orders grids by)."""
        return self.loads[0][0]

    @property
    def cases(self) -> tuple[str, ...]:
        return tuple(c for c, _ in self.loads)

    @classmethod
    def _listed(cls, ctx, held_cases: bool = False) -> list["LoadCell"]:
        if held_cases or ctx.loads is None:
            return []               # a hold-out case's load alone: the hold-out check's load factor
        fitted = {ctx.fit_obs.case_labels[int(i)] for i in np.unique(ctx.fit_obs.case_index)}
        held = constrained_grids(ctx.deck)
        V = ctx.loads.values.tocsr()
        per: dict[int, dict[int, int]] = {}
        for i, (g, c) in enumerate(ctx.loads.dofs):
            if g not in ctx.deck.grids or str(c) in held.get(g, "") or not V[i].nnz:
                continue
            per.setdefault(int(g), {})[int(c)] = i
        grids_of: dict[str, set] = {}           # case -> every grid it loads (held components too)
        for i, j in zip(*V.nonzero()):
            grids_of.setdefault(ctx.loads.cases[j], set()).add(int(ctx.loads.dofs[i][0]))
        out = []
        for g, rows in sorted(per.items()):
            comps = tuple(sorted(rows))
            block = V[[rows[c] for c in comps]].toarray()            # (comps, cases)
            loads = tuple((case, tuple(float(v) for v in block[:, j])) for j, case in enumerate(ctx.loads.cases)
                          if np.any(block[:, j]))
            if not any(case in fitted for case, _ in loads):
                continue
            if all(grids_of[case] == {g} for case, _ in loads):
                continue                        # a load scale of its cases (module docstring)
            out.append(cls((g,), (f"s_load_{g}",), comps=comps, loads=loads))
        return out

    @classmethod
    def holdout_candidates(cls, ctx, split) -> list:
        return []

    @property
    def load_dofs(self):
        return tuple((self.grid, c) for c in self.comps)

    def _per_unit(self, cases) -> np.ndarray:
        out = np.zeros((len(self.comps), len(cases)))
        at = {c: j for j, c in enumerate(cases)}
        for case, v in self.loads:
            if case in at:
                out[:, at[case]] = v
        return out

    def load_change(self, x_effect, cases):
        return (float(np.asarray(x_effect)[0]) - 1.0) * self._per_unit(cases)

    def load_change_derivatives(self, x_effect, cases):
        return self._per_unit(cases)[None]

    def details_json(self) -> dict:
        return {"cases": list(self.cases)}

    def findings(self, fit) -> dict:
        e, sl = self.in_fit(fit)
        s = float(fit.x[sl][0])
        n = len(self.loads)
        which = ", ".join(self.cases[:6]) + (" ..." if n > 6 else "")
        return {"pattern": "scale", "factor": s,
                "pattern_detail": f"the load at grid {self.grid} is {s:.3g} times the logged one in every case that "
                                  f"loads it ({n} case{'s' if n > 1 else ''}: {which}; its load cell's calibration?)"}

    def label(self) -> str:
        return f"{self.kind} @ {self.grid}"

    def marker_points(self, xyz, deck):
        return [xyz[self.grid]] if self.grid in xyz else []
