"""What the reader knows of each card name: the parsers (one module per card family), the
cards converted in bulk, the cards with no effect, the NASTRAN cards it does not model (kept for
an external solver), those never handed to an external solver, and the one message that names
every card the reader cannot take (an unknown name with the known names closest to it)."""

from __future__ import annotations

import difflib

from solver_adapters.bdf import (bars, beams, constraints, design, gaps, grids, materials, matrices, params,
                                 rigid, rods, springs)
from solver_adapters.bdf.params import NO_EFFECT
from solver_adapters.deck import Deck
from solver_adapters.protocol import DeckFormatError

_FAMILIES = (grids, bars, beams, rods, materials, rigid, springs, gaps, constraints, params, design, matrices)

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
        "PLOAD1", "PLOAD2", "PLOAD4", "TEMP", "TEMPD", "SPCD", "DEFORM", "RFORCE", "RFORCE1",
        "ACCEL", "ACCEL1", "PLOADX1", "PLOADB3", "SLOAD", "TEMPP1", "TEMPRB", "QBDY1", "QVOL",
        "DAREA", "LSEQ", "CLOAD", "PRESAX", "FORCEAX", "MOMAX")},
    **{k: "superelements are not supported" for k in ("SEBULK", "SECONCT", "SESET")},
    **{k: "NASTRAN-95's rigid elements other than CRIGD1 and CRIGD2 are not supported (MYSTRAN has "
          "none of them)" for k in ("CRIGD3", "CRIGDR", "CRROD", "CRBAR", "CRBE3", "CRTRPLT", "CRSPLINE")},
}
"""Unmodelled cards that stay errors even when a deck is read for an external solver
(``unmodelled="keep"``), and why: handed on, they would change the model without a word."""

KNOWN_UNMODELLED = frozenset({
    # shells, solids, other elements and their properties
    "CQUAD4", "CQUADR", "CQUAD8", "CQUAD", "CQUADX", "CTRIA3", "CTRIAR", "CTRIA6", "CTRIAX",
    "CTRIAX6", "CSHEAR", "CHEXA", "CPENTA", "CTETRA", "CPYRAM", "CBEND",
    "CBEAM3",
    "CWELD", "CFAST", "CSEAM", "CBUSH1D", "CBUSH2D", "CRAC2D", "CRAC3D",
    "CUSER1", "CUSERIN", "CONV", "CHBDYE", "CHBDYG", "CHBDYP",
    "PSHELL", "PCOMP", "PCOMPG", "PCOMP1", "PSOLID", "PSHEAR", "PBEND",
    "PBCOMP", "PBEAM3", "PBRSECT", "PBMSECT", "PWELD", "PFAST",
    "PBUSH1D", "PBUSH2D", "PELAST", "PLPLANE", "PLSOLID", "PSHLN1", "PSHLN2",
    "PUSER1", "PUSERIN", "PHBDY", "PCONV",
    # materials other than MAT1, and temperature- or stress-dependent material tables
    "MAT2", "MAT3", "MAT8", "MAT9", "MAT10", "MAT11", "MATT1", "MATT2", "MATT8",
    "MATT9", "MATS1", "TABLEM1", "TABLEM2", "TABLEM3", "TABLEM4", "TABLES1", "TABLEST",
    # rigid elements other than RBE2, RBE3
    "RBAR1", "RBE1", "RROD", "RTRPLT", "RTRPLT1", "RSPLINE", "RJOINT",
    # degree-of-freedom sets, scalar points, sequencing
    "BSET", "BSET1",
    "CSET", "CSET1", "USET", "USET1", "SEQGP",
    # other coordinate systems, direct matrix input, tables, functions
    "CORD3G", "CORD3R", "DTI", "BEAMOR",
})
"""NASTRAN cards the reader knows and does not model: with ``unmodelled="keep"`` they are kept
for an external solver (which refuses those it cannot run), otherwise they are errors. A name
in none of the reader's lists is an unknown card: an error in both cases, with the known names
closest to it."""

ELEMENT_GRIDS: dict[str, tuple[int, ...]] = {
    **{k: (4, 5, 6, 7) for k in ("CQUAD4", "CQUADR", "CSHEAR")},
    **{k: (4, 5, 6) for k in ("CTRIA3", "CTRIAR")},
    "CQUAD8": tuple(range(4, 12)), "CTRIA6": tuple(range(4, 10)),
    "CHEXA": tuple(range(4, 24)), "CPENTA": tuple(range(4, 19)), "CTETRA": tuple(range(4, 14)),
    "CPYRAM": tuple(range(4, 17)), "CBEND": (4, 5),
}
"""NASTRAN field numbers of the grids of element cards the reader does not model but knows the
layout of (MSC QRG: EID PID G1 G2 ...; a solid's midside grids may be blank): shells, solids,
bends. The grids are checked (they must exist) and :meth:`Deck.unmodelled_grids` names them."""

_KNOWN = frozenset(PARSERS) | NO_EFFECT | KNOWN_UNMODELLED | frozenset(NOT_PASSABLE) | frozenset(ELEMENT_GRIDS)
_KNOWN_SORTED = sorted(_KNOWN)


def _connects_nothing(name: str) -> bool:
    """A card that joins no grid: a property or material (names from ``P``/``MAT``), a plot
    element, a table, a parameter, a coordinate system of another kind, a scalar point."""
    return (name.startswith(("P", "MAT", "TABLE")) and name not in ("PLOTEL",)) or name in (
        "PLOTEL", "SPOINT", "EPOINT", "CORD3G", "DTI", "DMI", "DMIG", "DEQATN")


def known(name: str) -> bool:
    """Whether ``name`` is a card the reader knows (models, accepts, keeps or refuses by name)."""
    return name in _KNOWN


def did_you_mean(name: str) -> str:
    """The hint for an unknown card name: the known names closest to it (difflib), if any."""
    close = difflib.get_close_matches(name, _KNOWN_SORTED, n=3, cutoff=0.6)
    return ("; did you mean " + " or ".join(close) + "?") if close else ""


def _unknown_hint(name: str) -> str:
    return "unknown card name (no NASTRAN bulk-data card the reader knows)" + did_you_mean(name)


def unsupported_error(entries, *, keeping: bool = False, lead: str = "",
                      external_hint: bool = True) -> DeckFormatError:
    """The one message naming unsupported cards: ``entries`` ``[(name, count, "file:line"), ...]``
    in the deck's order; the error points (file, line, field 1) at the first. ``keeping``: the
    deck was read for an external solver, so only :data:`NOT_PASSABLE` cards are in the list.
    ``lead`` opens the message; ``external_hint`` adds that an external adapter runs such cards."""
    total = sum(n for _, n, _ in entries)
    lines = []
    for name, n, src in entries:
        if not known(name):
            hint = _unknown_hint(name)
        else:
            hint = NOT_PASSABLE.get(name, "") if keeping else _UNSUPPORTED_HINTS.get(name, "")
        lines.append(f"{name} x{n} (first at {src}){': ' + hint if hint else ''}")
    name, _, src = entries[0]
    file, _, line = src.rpartition(":")
    if keeping:
        head = "unknown card(s) or card(s) that cannot be handed to an external solver"
        tail = ""
    else:
        head = "unknown card(s) or card(s) the reference solver does not model"
        tail = (f"\nsupported: {', '.join(SUPPORTED)}; accepted with no effect on a linear static "
                f"solve: {', '.join(sorted(NO_EFFECT))}")
        if external_hint and any(e[0] not in NOT_PASSABLE and known(e[0]) for e in entries):
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
