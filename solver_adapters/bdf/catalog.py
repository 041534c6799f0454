"""What the reader knows of each card name: the parsers (one module per card family), the
cards converted in bulk, the cards with no effect, those never handed to an external solver,
and the one message that names every card the reader cannot take."""

from __future__ import annotations

from solver_adapters.bdf import bars, beams, constraints, grids, materials, params, rigid, rods, springs
from solver_adapters.bdf.params import NO_EFFECT
from solver_adapters.deck import Deck
from solver_adapters.protocol import DeckFormatError

_FAMILIES = (grids, bars, beams, rods, materials, rigid, springs, constraints, params)

PARSERS = {name: p for m in _FAMILIES for name, p in m.PARSERS.items()}
"""Card name -> the parser that reads one card into the reader's state."""

BULK = {name: b for m in _FAMILIES for name, b in getattr(m, "BULK", {}).items()}
"""Card name -> the converter that reads many cards of that name at once (the cards it leaves
go to the card's parser)."""

SUPPORTED = tuple(sorted(PARSERS))
"""Cards read into the :class:`Deck` and modelled by the reference solver."""

# what to do instead, for unsupported cards often found in decks written by other programs
_LOADS = "loads are not part of the model: they come from the study's loads.csv"
_UNSUPPORTED_HINTS = {
    **{k: _LOADS for k in ("FORCE", "FORCE1", "FORCE2", "MOMENT", "MOMENT1", "MOMENT2", "LOAD",
                           "GRAV", "PLOAD", "PLOAD1", "PLOAD2", "PLOAD4", "TEMP", "TEMPD", "SPCD")},
}

NOT_PASSABLE = {
    **{k: "loads are not part of the model: they come from the load cases (loads.csv); a load "
          "set here would collide with the run deck's own" for k in
       ("FORCE", "FORCE1", "FORCE2", "MOMENT", "MOMENT1", "MOMENT2", "LOAD", "GRAV", "PLOAD",
        "PLOAD1", "PLOAD2", "PLOAD4", "TEMP", "TEMPD", "SPCD", "DEFORM", "RFORCE")},
    **{k: "MPC sets apply only when the case control selects them, which a run deck does not: "
          "the constraint would be dropped silently" for k in ("MPC", "MPCADD")},
    **{k: "superelements are not supported" for k in ("SEBULK", "SECONCT", "SESET")},
}
"""Unmodelled cards that stay errors even when a deck is read for an external solver
(``unmodelled="keep"``), and why: handed on, they would change the model without a word."""

ELEMENT_GRIDS: dict[str, tuple[int, ...]] = {
    **{k: (4, 5, 6, 7) for k in ("CQUAD4", "CQUADR", "CSHEAR")},
    **{k: (4, 5, 6) for k in ("CTRIA3", "CTRIAR")},
    "CQUAD8": tuple(range(4, 12)), "CTRIA6": tuple(range(4, 10)),
    "CHEXA": tuple(range(4, 24)), "CPENTA": tuple(range(4, 19)), "CTETRA": tuple(range(4, 14)),
    "CPYRAM": tuple(range(4, 17)), "CTUBE": (4, 5), "CBEND": (4, 5), "CVISC": (4, 5),
}
"""NASTRAN field numbers of the grids of element cards the reader does not model but knows the
layout of (MSC QRG: EID PID G1 G2 ...; a solid's midside grids may be blank): shells, solids,
tubes. The grids are checked (they must exist) and :meth:`Deck.unmodelled_grids` names them."""


def _connects_nothing(name: str) -> bool:
    """A card that joins no grid: a property or material (names from ``P``/``MAT``), a plot
    element, a table, a parameter, a coordinate system of another kind, a scalar point."""
    return (name.startswith(("P", "MAT", "TABLE")) and name not in ("PLOTEL",)) or name in (
        "PLOTEL", "SPOINT", "EPOINT", "CORD3G", "DTI", "DMI", "DMIG", "DEQATN")


def unsupported_error(entries, *, keeping: bool = False, lead: str = "",
                      external_hint: bool = True) -> DeckFormatError:
    """The one message naming unsupported cards: ``entries`` ``[(name, count, "file:line"), ...]``
    in the deck's order; the error points (file, line, field 1) at the first. ``keeping``: the
    deck was read for an external solver, so only :data:`NOT_PASSABLE` cards are in the list.
    ``lead`` opens the message; ``external_hint`` adds that an external adapter runs such cards."""
    total = sum(n for _, n, _ in entries)
    lines = []
    for name, n, src in entries:
        hint = NOT_PASSABLE.get(name, "") if keeping else _UNSUPPORTED_HINTS.get(name, "")
        lines.append(f"{name} x{n} (first at {src}){': ' + hint if hint else ''}")
    name, _, src = entries[0]
    file, _, line = src.rpartition(":")
    if keeping:
        head = "card(s) that cannot be handed to an external solver"
        tail = ""
    else:
        head = "unknown card(s) or card(s) the reference solver does not model"
        tail = (f"\nsupported: {', '.join(SUPPORTED)}; accepted with no effect on a linear static "
                f"solve: {', '.join(sorted(NO_EFFECT))}")
        if external_hint and any(e[0] not in NOT_PASSABLE for e in entries):
            tail += ("\nan external adapter (mystran, or a command with the nastran dialect) runs a "
                     "deck with elements the reference solver does not model (shells, solids): it "
                     "needs only the grids, joints and loads from the deck (study.toml [solver] "
                     "adapter, or --adapter)")
    return DeckFormatError(f"{lead}{head}: {total} card(s) of {len(entries)} type(s):\n  " + "\n  ".join(lines) + tail,
                           file=file or None, line=int(line) if line.isdigit() else None, card=name,
                           field=1, value=name)


def unmodelled_error(deck: Deck) -> DeckFormatError:
    """The reader's own error for a deck read with ``unmodelled="keep"`` whose unmodelled cards
    reach a solver that does not model them (the reference solver): the same message, every
    unmodelled card with its count and first location, as ``read_deck`` gives."""
    return unsupported_error([(name, n, src) for name, (n, src) in deck.unmodelled_counts().items()])
