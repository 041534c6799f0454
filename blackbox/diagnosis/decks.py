"""The edited decks a diagnosis runs through the study's adapter (the solver stays a black box).

* the **element deck** (:func:`element_deck`): every member alone, clamped at end a; one run gives
  each member's ``K_e`` (:func:`blackbox.diagnosis.runs.element_stiffness`);
* the **split deck** (:func:`split_deck`): the study's deck with every connection a candidate could
  make flexible cut and bridged by scalar springs ``K0`` (CELAS2). Each connection family cuts its
  own connections through a :class:`SplitEditor` (``Effect.cut``): the undeclared joints split a
  grid into one grid per member, the declared joints lose their RBE2 translation tie, the supports
  their SPC components. ``K0`` is the order of the members' own stiffness at the cut, so the cut is
  as stiff as the structure there and the rigid state is recovered well conditioned
  (:mod:`blackbox.diagnosis.split`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from blackbox.diagnosis.split import Pair
from solver_adapters.protocol import CBar, Deck, Grid, Spc1, Spring
from solver_adapters.protocol import DofLabel

if TYPE_CHECKING:
    from blackbox.diagnosis.effects.base import CandidateContext, Effect

__all__ = ["members_at", "constrained_grids", "unsplittable_grids", "unmodelled_notes", "element_deck",
           "SplitEditor", "SplitDeck", "split_deck"]


def members_at(deck: Deck) -> dict[int, list[int]]:
    """Grid -> EIDs of the CBARs ending there (ascending)."""
    out: dict[int, list[int]] = {}
    for b in sorted(deck.cbars.values(), key=lambda b: b.eid):
        out.setdefault(b.ga, []).append(b.eid)
        out.setdefault(b.gb, []).append(b.eid)
    return out


def constrained_grids(deck: Deck) -> dict[int, str]:
    """Grid -> its constrained components (every SPC1 set and GRID PS)."""
    out: dict[int, set] = {}
    for s in deck.spc1s:
        for g in s.grids:
            out.setdefault(g, set()).update(s.components)
    for g in deck.grids.values():
        if g.ps:
            out.setdefault(g.id, set()).update(g.ps)
    return {g: "".join(sorted(c)) for g, c in out.items()}


def rbe2_grids(deck: Deck) -> set[int]:
    """Every grid of every RBE2 (independent and dependent)."""
    return {g for r in deck.rbe2s.values() for g in (r.gn, *r.gm)}


def unsplittable_grids(deck: Deck) -> dict[int, list[str]]:
    """Grids where >= 2 bars meet that also carry a card the reader does not model (a shell, a
    solid, kept for an external solver), with those cards. The undeclared-joint cut splits a
    grid into one grid per bar; such an element is no bar and would stay on the first bar's grid
    only, rigidly joined to that bar and flexibly to the others: a connection the structure does
    not have. So these grids are not undeclared-joint candidates (:func:`unmodelled_notes`)."""
    if not deck.unmodelled:
        return {}
    at = members_at(deck)
    # grids no cut touches anyway (constrained, in an RBE2, on a spring) are left out
    sprung = {g for s in deck.springs.values() for g in (s.g1, s.g2) if g}
    other = set(constrained_grids(deck)) | rbe2_grids(deck) | sprung
    return {g: cards for g, cards in sorted(deck.unmodelled_grids().items())
            if len(at.get(g, ())) >= 2 and g not in other}


def unmodelled_notes(deck: Deck) -> list[str]:
    """What the diagnosis leaves aside on a deck with cards the reader does not model (shells,
    solids, solved by an external adapter), one sentence each, for ``diagnosis.json`` ``notes``."""
    if not deck.unmodelled:
        return []
    kinds = ", ".join(f"{n} x{k}" for n, (k, _) in deck.unmodelled_counts().items())
    notes = [f"the deck holds cards the diagnosis does not edit ({kinds}): they stay in every edited "
             f"deck as they are; member_stiffness candidates are the CBAR members only"]
    skipped = unsplittable_grids(deck)
    if skipped:
        cards = sorted({c.split()[0] for cs in skipped.values() for c in cs})
        grids = list(skipped)
        notes.append(f"undeclared_joint: {len(grids)} grid(s) where bars meet {'/'.join(cards)} elements are "
                     f"not candidates ({', '.join(map(str, grids[:20]))}{' ...' if len(grids) > 20 else ''}): "
                     f"the cut splits the bars there but not the {'/'.join(cards)}, which would stay rigidly "
                     f"joined to one bar and flexibly to the others")
    return notes


def element_deck(deck: Deck) -> tuple[Deck, dict[int, tuple[int, int]]]:
    """Every CBAR alone (same EID, PID, orientation; G0 turned into a vector), end a clamped.
    Returns the deck and ``{eid: (grid_a, grid_b)}`` in it. Each member has its own two grids and
    nothing else is in the deck (no spring, rigid element or shared grid), so the members are
    separate structures: one load case can load every member at once
    (:func:`blackbox.diagnosis.runs.element_flexibility`)."""
    e = Deck(pbars=dict(deck.pbars), mat1s=dict(deck.mat1s))
    members = {}
    for i, eid in enumerate(sorted(deck.cbars)):
        b = deck.cbars[eid]
        ga, gb = 2 * i + 1, 2 * i + 2
        e.grids[ga] = Grid(ga, deck.grids[b.ga].xyz)
        e.grids[gb] = Grid(gb, deck.grids[b.gb].xyz)
        x = b.x if b.g0 is None else tuple(np.subtract(deck.grids[b.g0].xyz, deck.grids[b.ga].xyz).tolist())
        e.cbars[eid] = CBar(eid, b.pid, ga, gb, x=tuple(float(v) for v in x))
        members[eid] = (ga, gb)
    e.spc1s = [Spc1(1, "123456", tuple(ga for ga, _ in members.values()))]
    return e, members


@dataclass
class SplitEditor:
    """The split deck while the families cut it: the study's deck (``original``, read only), its
    edited copy (``deck``), the cut pairs so far and the grids split so far."""
    original: Deck
    deck: Deck
    K_e: dict[int, np.ndarray]
    pairs: list[Pair]
    split_grids: dict[int, tuple[int, ...]]
    next_grid: int
    next_eid: int

    @classmethod
    def of(cls, deck: Deck, K_e: dict[int, np.ndarray]) -> "SplitEditor":
        d = copy.deepcopy(deck)
        # new elements go above every element ID of the deck, those of the cards it keeps for an
        # external solver (shells, solids) included: NASTRAN element IDs are unique over all
        return cls(deck, d, K_e, [], {}, max(d.grids) + 1, d.max_element_id() + 1)

    @property
    def members_at(self) -> dict[int, list[int]]:
        """Grid -> EIDs of the study's deck (before any cut)."""
        return members_at(self.original)

    def new_grid(self, like: int) -> int:
        """A new grid at the position of grid ``like``."""
        g = self.next_grid
        self.next_grid += 1
        self.deck.grids[g] = Grid(g, self.deck.grids[like].xyz)
        return g

    def new_eid(self) -> int:
        eid = self.next_eid
        self.next_eid += 1
        return eid

    def kdiag(self, eid: int, grid: int, comp: int) -> float:
        """Member ``eid``'s own diagonal stiffness at its end ``grid``, component ``comp``."""
        b = self.original.cbars[eid]
        end = 0 if b.ga == grid else 1
        return float(self.K_e[eid][6 * end + comp - 1, 6 * end + comp - 1])

    def connect(self, k0: float, a: DofLabel, b: DofLabel | None = None) -> int:
        """Bridge DOF ``a`` and DOF ``b`` (or ground) by a CELAS2 of stiffness ``k0``; returns the
        index of the new cut pair."""
        eid = self.new_eid()
        g2, c2 = b if b is not None else (0, 0)
        self.deck.springs[eid] = Spring(eid, a[0], a[1], g2, c2, k=float(k0), card="CELAS2")
        self.pairs.append(Pair(a, b, k0))
        return len(self.pairs) - 1


@dataclass
class SplitDeck:
    """The split deck, its cut pairs, the connection candidates its cuts make possible, each
    member's end DOFs in it and the grids split into branches (original grid first)."""
    deck: Deck
    pairs: list[Pair]
    connections: list["Effect"]
    member_dofs: dict[int, tuple[DofLabel, ...]]
    split_grids: dict[int, tuple[int, ...]]


def split_deck(deck: Deck, K_e: dict[int, np.ndarray], families: Sequence[type["Effect"]],
               ctx: "CandidateContext") -> SplitDeck:
    """The study's deck cut by every family in ``families`` (in that order), with the candidates
    each cut makes possible."""
    editor = SplitEditor.of(deck, K_e)
    connections: list = []
    for fam in families:
        connections += fam.cut(editor, ctx)
    d = editor.deck
    member_dofs = {eid: tuple((b.ga, c) for c in range(1, 7)) + tuple((b.gb, c) for c in range(1, 7))
                   for eid, b in d.cbars.items()}
    return SplitDeck(d, editor.pairs, connections, member_dofs, editor.split_grids)
