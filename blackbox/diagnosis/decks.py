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
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING, Sequence

import numpy as np

from blackbox.diagnosis.split import Pair
from solver_adapters.protocol import CBar, Deck, Grid, Spc1, Spring
from solver_adapters.protocol import DofLabel

if TYPE_CHECKING:
    from blackbox.diagnosis.effects.base import CandidateContext, Effect

__all__ = ["members_at", "member_axes", "constrained_grids", "unsplittable_grids", "unmodelled_notes", "element_deck",
           "cards_at", "member_ends", "member_frames", "in_member_frames", "SplitEditor", "SplitDeck", "split_deck",
           "prune_spcadds"]


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
    not have. So these grids are not undeclared-joint candidates (:func:`unmodelled_notes`). The
    same holds for a grid that a stiffness matrix couples (a DMIG, a GENEL)."""
    held: dict[int, list[str]] = {g: list(cards) for g, cards in deck.unmodelled_grids().items()} \
        if deck.unmodelled else {}
    for m in getattr(deck, "dmigs", {}).values():
        for g in dict.fromkeys(g for (g, _), _, _ in m.terms):
            held.setdefault(g, []).append(m.label)
    if not held:
        return {}
    at = members_at(deck)
    # grids no cut touches anyway (constrained, in an RBE2, on a spring) are left out
    sprung = {g for s in deck.springs.values() for g in (s.g1, s.g2) if g}
    other = set(constrained_grids(deck)) | rbe2_grids(deck) | sprung
    return {g: cards for g, cards in sorted(held.items())
            if len(at.get(g, ())) >= 2 and g not in other}


def unmodelled_notes(deck: Deck) -> list[str]:
    """What the diagnosis leaves aside on a deck with cards the reader does not model (shells,
    solids, solved by an external adapter) or one with stiffness matrices at grids where bars meet
    (DMIG, GENEL), one sentence each, for ``diagnosis.json`` ``notes``."""
    notes = []
    if deck.unmodelled:
        kinds = ", ".join(f"{n} x{k}" for n, (k, _) in deck.unmodelled_counts().items())
        notes.append(f"the deck holds cards the diagnosis does not edit ({kinds}): they stay in every "
                     f"edited deck as they are; member_stiffness candidates are the CBAR and rod members only")
    skipped = unsplittable_grids(deck)
    if skipped:
        cards = sorted({c.split()[0] for cs in skipped.values() for c in cs})
        grids = list(skipped)
        notes.append(f"undeclared_joint: {len(grids)} grid(s) where bars meet {'/'.join(cards)} elements are "
                     f"not candidates ({', '.join(map(str, grids[:20]))}{' ...' if len(grids) > 20 else ''}): "
                     f"the cut splits the bars there but not the {'/'.join(cards)}, which would stay rigidly "
                     f"joined to one bar and flexibly to the others")
    return notes


def cards_at(deck: Deck, grid: int) -> list[str]:
    """The cards of ``deck`` that bear on ``grid``: the GRID with its CP/CD systems, the
    elements, rigid elements, springs and constraint sets on it (``"CBAR 108 (offsets)"``), for
    messages that must name what is involved."""
    if grid not in deck.grids:
        return []
    g = deck.grids[grid]
    out = [f"GRID {grid}" + "".join(f" {k} {v} ({deck.coords[v].card} at {deck.coords[v].src or '?'})"
                                    for k, v in (("CP", g.cp), ("CD", g.cd)) if v and v in deck.coords)]
    for b in deck.cbars.values():
        if grid in (b.ga, b.gb):
            extra = [w for w, on in (("offsets", b.wa is not None or b.wb is not None),
                                     ("pin flags", bool(b.pa or b.pb))) if on]
            out.append(f"{b.card} {b.eid}" + (f" ({', '.join(extra)})" if extra else ""))
    out += [f"{r.card} {r.eid}" for r in deck.rods.values() if grid in (r.ga, r.gb)]
    out += [f"{r.card} {r.eid}" for r in deck.rbe2s.values() if grid in (r.gn, *r.gm)]
    out += [f"{r.card} {r.eid}" for r in deck.rbe3s.values()
            if grid == r.refgrid or any(grid in gs for _, _, gs in r.groups)]
    out += [f"CBUSH {b.eid}" for b in deck.bushes.values() if grid in (b.ga, b.gb)]
    out += [f"{s.card} {s.eid}" for s in deck.springs.values() if grid in (s.g1, s.g2)]
    out += [m.label for m in getattr(deck, "dmigs", {}).values() if any(g == grid for (g, _), _, _ in m.terms)]
    sets = sorted({s.sid for s in deck.spc1s if grid in s.grids})
    out += [f"SPC set {sid}" + "".join(f" (in SPCADD {a.sid})" for a in deck.spcadds.values() if sid in a.sets)
            for sid in sets]
    return out


def element_deck(deck: Deck) -> tuple[Deck, dict[int, tuple[int, int]], dict[int, np.ndarray]]:
    """Every CBAR alone (same EID, PID, pin flags and offsets; G0 turned into a vector), and
    every rod (CROD, CTUBE, CONROD: same EID and section), end a clamped. Returns the deck,
    ``{eid: (grid_a, grid_b)}`` in it and ``{eid: k (6,)}``: the grounded springs at end b of a
    rod or of a bar with pin flags. Each member has its own two grids and
    nothing else is in the deck but those springs, so the members are separate structures: one
    load case can load every member at once (:func:`blackbox.diagnosis.runs.element_flexibility`).

    The grids are in basic (no CP, no CD), so ``K_e`` comes out in basic whatever the study's
    displacement systems (:func:`in_member_frames` turns it into the split deck's components);
    orientation vectors and offsets are held in basic by the reader already. A pin flag releases
    a component of the bar's end from its grid, so a member pinned at either end is a
    mechanism as a cantilever; its end b is then held by grounded springs of known stiffness
    (``E A / L`` along, ``E I / L`` about each axis: the order of the member's own), which the
    element run subtracts exactly (:func:`blackbox.diagnosis.runs.element_stiffness`). A rod
    carries only axial force and torque, so its end b is always held so: ``E A / L`` on each
    translation, ``G J / L`` about each axis (``E A L`` when it has no J: then it carries no
    torque, and any spring there is subtracted exactly)."""
    e = Deck(pbars=dict(deck.pbars), mat1s=dict(deck.mat1s), prods=dict(deck.prods))
    members, tips = {}, {}
    eid_spring = max([*deck.cbars, *deck.rods]) + 1 if (deck.cbars or deck.rods) else 1
    for i, eid in enumerate(sorted(deck.cbars)):
        b = deck.cbars[eid]
        ga, gb = 2 * i + 1, 2 * i + 2
        xa, xb = deck.grids[b.ga].xyz, deck.grids[b.gb].xyz
        e.grids[ga] = Grid(ga, xa)
        e.grids[gb] = Grid(gb, xb)
        x = b.x if b.g0 is None else tuple(np.subtract(deck.grids[b.g0].xyz, xa).tolist())
        e.cbars[eid] = CBar(eid, b.pid, ga, gb, x=tuple(float(v) for v in x), pa=b.pa, pb=b.pb,
                            wa=b.wa, wb=b.wb)
        members[eid] = (ga, gb)
        if b.pa or b.pb:
            p = deck.pbars[b.pid]
            E = deck.mat1s[p.mid].e
            L = float(np.linalg.norm(np.subtract(xb, xa))) or 1.0
            k_t, k_r = E * p.a / L, E * max(p.i1, p.i2, p.j) / L
            tips[eid] = np.array([k_t] * 3 + [k_r] * 3)
            for c in range(1, 7):
                e.springs[eid_spring] = Spring(eid_spring, gb, c, 0, 0, k=float(tips[eid][c - 1]))
                eid_spring += 1
    for i, eid in enumerate(sorted(deck.rods), start=len(deck.cbars)):
        r = deck.rods[eid]
        ga, gb = 2 * i + 1, 2 * i + 2
        xa, xb = deck.grids[r.ga].xyz, deck.grids[r.gb].xyz
        e.grids[ga] = Grid(ga, xa)
        e.grids[gb] = Grid(gb, xb)
        e.rods[eid] = replace(r, ga=ga, gb=gb)
        members[eid] = (ga, gb)
        mid, area, j = deck.rod_section(r)
        mat = deck.mat1s[mid]
        L = float(np.linalg.norm(np.subtract(xb, xa))) or 1.0
        k_r = mat.g * j / L if j > 0.0 and mat.g > 0.0 else mat.e * area * L
        tips[eid] = np.array([mat.e * area / L] * 3 + [k_r] * 3)
        for c in range(1, 7):
            e.springs[eid_spring] = Spring(eid_spring, gb, c, 0, 0, k=float(tips[eid][c - 1]))
            eid_spring += 1
    e.spc1s = [Spc1(1, "123456", tuple(ga for ga, _ in members.values()))]
    return e, members, tips


def member_ends(deck: Deck, eid: int) -> tuple[int, int]:
    """``(grid_a, grid_b)`` of member ``eid``: a CBAR (CBEAM) or a rod."""
    m = deck.cbars.get(eid) or deck.rods[eid]
    return m.ga, m.gb


def member_axes(deck: Deck, eid: int) -> np.ndarray | None:
    """``(3, 3)``: the element axes of CBAR ``eid`` in basic, as rows: x from end A to end B
    (between the offset ends), y along the part of the orientation vector normal to x, z = x
    cross y (NASTRAN's CBAR axes). ``None`` for a bar of zero length or an orientation vector
    along it (the model refuses such a bar)."""
    b = deck.cbars[eid]
    xa = np.asarray(deck.grids[b.ga].xyz, float)
    xb = np.asarray(deck.grids[b.gb].xyz, float)
    r = (xb + np.asarray(b.wb or (0.0, 0.0, 0.0), float)) - (xa + np.asarray(b.wa or (0.0, 0.0, 0.0), float))
    n = float(np.linalg.norm(r))
    if n == 0.0:
        return None
    ex = r / n
    v = np.asarray(b.x if b.g0 is None else np.subtract(deck.grids[b.g0].xyz, xa), float)
    y = v - (v @ ex) * ex
    ny = float(np.linalg.norm(y))
    if not np.isfinite(ny) or ny <= 1e-9 * max(float(np.linalg.norm(v)), 1e-300):
        return None
    ey = y / ny
    return np.vstack([ex, ey, np.cross(ex, ey)])


def member_frames(deck: Deck, eid: int) -> np.ndarray:
    """``(12, 12)``: the rotation from basic to the displacement components of member ``eid``'s
    grids (its CD systems), ``u_cd = Lambda u_basic`` over ``a1..a6, b1..b6``."""
    Ra, Rb = deck.displacement_frames(list(member_ends(deck, eid)))
    L = np.zeros((12, 12))
    L[0:3, 0:3] = L[3:6, 3:6] = Ra
    L[6:9, 6:9] = L[9:12, 9:12] = Rb
    return L


def in_member_frames(deck: Deck, eid: int, K: np.ndarray) -> np.ndarray:
    """A member matrix over ``a1..a6, b1..b6`` in basic (``K_e`` of the element run, or its
    parts ``(p, 12, 12)``) in the components of its grids' CD systems: ``Lambda K Lambda^T``."""
    ga, gb = member_ends(deck, eid)
    if not (deck.grids[ga].cd or deck.grids[gb].cd):
        return K
    L = member_frames(deck, eid)
    return L @ K @ L.T


def prune_spcadds(d: Deck) -> None:
    """SPCADDs of an edited deck name only the SPC sets it still has: a set whose every grid a
    cut released is gone, and an SPCADD left with no set goes too (NASTRAN rejects an SPCADD
    naming a set that does not exist; the study format applies every remaining set anyway)."""
    have = {s.sid for s in d.spc1s}
    for sid, a in list(d.spcadds.items()):
        sets = tuple(k for k in a.sets if k in have or k in d.spcadds)
        if not sets:
            del d.spcadds[sid]
        elif sets != a.sets:
            d.spcadds[sid] = replace(a, sets=sets)


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

    @cached_property
    def members_at(self) -> dict[int, list[int]]:
        """Grid -> EIDs of the study's deck (before any cut; built once: every cut asks, and
        at 1e5 DOFs rebuilding it per cut cost a minute)."""
        return members_at(self.original)

    def new_grid(self, like: int) -> int:
        """A new grid at the position of grid ``like``, with its displacement system (CD), so
        that a spring between the two bridges the same directions."""
        g = self.next_grid
        self.next_grid += 1
        old = self.deck.grids[like]
        self.deck.grids[g] = Grid(g, old.xyz, cd=old.cd)
        return g

    def new_eid(self) -> int:
        eid = self.next_eid
        self.next_eid += 1
        return eid

    def kdiag(self, eid: int, grid: int, comp: int) -> float:
        """Member ``eid``'s own diagonal stiffness at its end ``grid``, component ``comp`` (of the
        grid's displacement system)."""
        b = self.original.cbars[eid]
        end = 0 if b.ga == grid else 1
        K = in_member_frames(self.original, eid, self.K_e[eid])
        return float(K[6 * end + comp - 1, 6 * end + comp - 1])

    def bridge(self, grid: int, comp: int, eids: Sequence[int], combine: str = "min") -> float:
        """``K0`` of a cut at ``grid``, component ``comp``: the smallest (``combine="min"``) or
        the sum (``"sum"``) of the members ``eids``' own diagonal stiffness there, leaving out a
        member that has none (a pin flag releases that component of its end: its diagonal is
        rounding, ~1e-9 of the others). When none has any, the largest diagonal of any member at
        the grid among the components of the same kind (translations or rotations). Never
        ~0: a cut bridged by nothing would leave the split deck a mechanism there."""
        ks = np.array([self.kdiag(e, grid, comp) for e in eids])
        group = (1, 2, 3) if comp <= 3 else (4, 5, 6)
        top = max(self.kdiag(e, grid, c) for e in self.members_at.get(grid, eids) for c in group)
        live = ks > 1e-6 * top
        if not live.any():
            return float(top)
        return float(ks[live].sum() if combine == "sum" else ks[live].min())

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
    prune_spcadds(d)
    member_dofs = {eid: tuple((b.ga, c) for c in range(1, 7)) + tuple((b.gb, c) for c in range(1, 7))
                   for eid, b in [*d.cbars.items(), *d.rods.items()]}
    return SplitDeck(d, editor.pairs, connections, member_dofs, editor.split_grids)
