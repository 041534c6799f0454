"""``misplaced_sensor``: the channels of a grid were really read at a neighbouring grid (a
gauge mounted on the next node along a member, a target glued to the wrong joint).

A grid ``g``, a neighbour ``h`` (joined to ``g`` by one bar or rod) and the channels measured at
``g`` (all of them: the sensor block; or one). A fraction ``t`` (bounded to ``[0, 2]``): each channel reads
``(1 - t) u_g + t u_h``, ``u_h`` taken along ``g``'s own direction for that component (the
sensor measures a physical direction; ``h`` may have another displacement system); ``t = 0`` is
the declared placement (nested, one-sided), ``t = 1`` the neighbour. Linear in ``t``, exact, no
solver run beyond reporting ``h``'s motion in the split run (:meth:`split_rows`). A refit that
ends below ``t = 1/2`` or above 3/2 is no misplacement: rejected, with the reason. Candidates: every fitted
grid with each of its neighbours that moves (not one held in all six components: a channel read
there reads nothing, a dead channel), once for its block of channels and once per channel when
it has several, scored in one sparse batch.

``where`` is the grid; ``read_at`` (the neighbour) and ``components`` in the details. A data defect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from blackbox.diagnosis.decks import constrained_grids
from blackbox.diagnosis.effects.base import Effect, ReadsAnother
from blackbox.diagnosis.effects.registry import register

__all__ = ["MisplacedSensor", "neighbours"]


def neighbours(deck) -> dict[int, list[int]]:
    """Grid -> the grids joined to it by one CBAR or rod, ascending."""
    out: dict[int, set] = {}
    for b in list(deck.cbars.values()) + list(deck.rods.values()):
        out.setdefault(b.ga, set()).add(b.gb)
        out.setdefault(b.gb, set()).add(b.ga)
    return {g: sorted(v) for g, v in out.items()}


@register
@dataclass(frozen=True, eq=False)
class MisplacedSensor(ReadsAnother, Effect):
    """``read_at``: the neighbour grid; ``components``: the channels of ``where[0]`` it moves;
    ``weights[k]``: for channel ``components[k]``, the three weights of ``h``'s components of the
    same kind (translations or rotations) that give ``h``'s motion along ``g``'s direction."""
    kind = "misplaced_sensor"
    summary = "a grid's channels were read at a neighbouring grid (the data, not the structure)"
    of_data = True

    read_at: int = 0
    components: tuple[int, ...] = ()
    weights: tuple = ()

    @property
    def grid(self) -> int:
        return int(self.where[0])

    @classmethod
    def _pairs(cls, ctx) -> list[tuple[int, int, tuple[int, ...]]]:
        measured: dict[int, list[int]] = {}
        for g, c in dict.fromkeys(ctx.fit_obs.dofs):
            measured.setdefault(int(g), []).append(int(c))
        nb = neighbours(ctx.deck)
        # a neighbour held in every component never moves: a channel reading it reads nothing,
        # which is a dead channel (bad_channel), not a placement the data could confirm
        held = {g for g, c in constrained_grids(ctx.deck).items() if c == "123456"}
        return [(g, h, tuple(sorted(cs))) for g, cs in sorted(measured.items()) for h in nb.get(g, ())
                if h in ctx.deck.grids and h not in held]

    @classmethod
    def split_rows(cls, ctx, split):
        return tuple(dict.fromkeys((h, c) for _, h, _ in cls._pairs(ctx) for c in range(1, 7)))

    @classmethod
    def candidates(cls, ctx, split) -> list["MisplacedSensor"]:
        deck = ctx.deck
        out = []
        for g, h, comps in cls._pairs(ctx):
            Rg, Rh = deck.displacement_frames([g, h])
            W = Rg @ Rh.T                       # row k: g's direction k in h's components
            sets = [comps] + ([(c,) for c in comps] if len(comps) > 1 else [])
            for cs in sets:
                w = tuple(tuple(float(v) for v in W[(c - 1) % 3]) for c in cs)
                tag = "all" if cs == comps and len(comps) > 1 else "_".join(map(str, cs))
                out.append(cls((g,), (f"t_{g}_at_{h}_{tag}",), read_at=h, components=cs, weights=w))
        return out

    @property
    def source_dofs(self):
        return tuple((self.read_at, c) for c in range(1, 7))

    @property
    def key(self) -> tuple:
        return (self.kind, tuple(self.where), self.read_at, self.components)

    def _terms(self, c: int, w, o_index, n: int):
        first = 1 if c <= 3 else 4
        return [(np.full(n, o_index[(self.read_at, first + j)]), float(w[j])) for j in range(3)
                if w[j] != 0.0]

    def mix_rows(self, om, o_index):
        out = []
        for c, w in zip(self.components, self.weights):
            rows = np.flatnonzero(om.rows_of(self.grid, c))
            if rows.size:
                out.append((0, rows, self._terms(c, w, o_index, rows.size)))
        return out

    not_low = "mostly their own grid, not misplaced"
    summary_noun = "a misplacement"

    def share_read(self, t: float) -> str:
        return f"the channels read {t:.3g} of grid {self.read_at}"

    def details_json(self) -> dict:
        return {"read_at": self.read_at, "components": list(self.components)}

    def label(self) -> str:
        return f"{self.kind} @ {self.grid} read at {self.read_at} components {''.join(map(str, self.components))}"

    def marker_points(self, xyz, deck):
        return [xyz[g] for g in (self.grid, self.read_at) if g in xyz]
