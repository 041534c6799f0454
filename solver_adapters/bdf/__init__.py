"""NASTRAN bulk-data reader: the card subset of ``docs/study-format.md`` into :class:`~solver_adapters.deck.Deck`.

Organised as pyNastran organises cards: the tokenizer apart (:mod:`.tokens` one line at a time,
:mod:`.table` the whole deck at once), one module per card family (:mod:`.grids` GRID, GRDSET and
the coordinate systems; :mod:`.bars` CBAR, BAROR, PBAR, PBARL; :mod:`.beams` CBEAM, PBEAM,
PBEAML; :mod:`.sections` the PBARL/PBEAML library sections; :mod:`.rods` CROD, PROD, CONROD,
CTUBE, PTUBE; :mod:`.materials` MAT1; :mod:`.rigid` RBE2, RBAR, RBE3; :mod:`.springs` CBUSH,
PBUSH, PELAS, CELAS1/2; :mod:`.constraints` SPC, SPC1, SPCADD; :mod:`.params` PARAM and the
cards with no effect), what the reader knows of each name (:mod:`.catalog`), the reader itself
(:mod:`.reader`) and the cross-checks (:mod:`.checks`). A card family adds a card with a parser
(one card at a time, located errors) and, for the cards a large deck holds by the thousand, a
bulk converter.

Cards modelled: GRID (CP and CD systems), GRDSET, CORD1R/C/S and CORD2R/C/S (resolved to basic,
nested in any order), CBAR (pin flags, offsets; orientation and offsets turned into basic),
BAROR, PBAR (K1/K2, I12), PBARL (ROD, TUBE, TUBE2, BAR, BOX, I, CHAN, T, L), CBEAM/PBEAM/PBEAML
(prismatic, no warping), CROD, PROD, CONROD, CTUBE and PTUBE (a rod of the tube's A and J), MAT1
(completed as NASTRAN does), SPC1, SPC (zero enforced value), SPCADD, RBE2, RBAR (all six
independent components at one grid: an RBE2), RBE3, CBUSH/PBUSH, PELAS, CELAS1, CELAS2,
PARAM,AUTOSPC (on unless the deck says NO, as in NASTRAN's SOL 101) and PARAM,EPZERO. Cards in
:data:`NO_EFFECT` (solver parameters, masses, eigenvalue and dynamic-analysis controls) are
accepted with no effect on a linear static solve and
counted in ``Deck.no_effect`` (``Deck.summary()`` lists them once). Every other card is an error;
the whole deck is read first, so one message names every unsupported card with its count and its
first location.

Field numbers in error messages are NASTRAN's, counted over the whole card with the continuation
markers left out: field 1 is the card name, fields 2-9 are the first line's data, 10-17 the next
line's (for large field: 2-5, 6-9, ...). The line number is the physical line holding the field.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field as dataclass_field
from pathlib import Path

import numpy as np

from solver_adapters.bdf.catalog import (ELEMENT_GRIDS, NOT_PASSABLE, SUPPORTED, unmodelled_error,
                                         unsupported_error)
from solver_adapters.bdf.numbers import parse_int, parse_real
from solver_adapters.bdf.params import NO_EFFECT
from solver_adapters.bdf.reader import Fallback, read_cards, read_table
from solver_adapters.bdf.sections import pbarl_section
from solver_adapters.bdf.table import CardTable, Irregular, TableCard, table_cards
from solver_adapters.bdf.tokens import IncludePolicy, Includes, LineReader, group_cards
from solver_adapters.bdf.checks import validate
from solver_adapters.deck import Deck
from solver_adapters.protocol import DeckFormatError, ModelError

__all__ = ["read_deck", "read_deck_text", "bulk_cards", "deck_from_cards", "validate", "parse_int",
           "parse_real", "NO_EFFECT", "SUPPORTED", "UNMODELLED", "NOT_PASSABLE", "ELEMENT_GRIDS",
           "unsupported_error", "unmodelled_error", "pbarl_section", "IncludePolicy", "BulkInput",
           "read_bulk"]

UNMODELLED = ("error", "keep")
"""What the reader does with a card it does not model: ``"error"`` (the default: one message
naming every such card, as the reference solver needs) or ``"keep"`` (into ``Deck.unmodelled``,
for an external solver that models them; :data:`NOT_PASSABLE` cards stay errors)."""

_RETRY = (Irregular, Fallback, DeckFormatError, ModelError)
"""What makes the reader read a deck again on the reference path (see :mod:`.reader`)."""


def _text_of(p: Path) -> str:
    try:
        return p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise DeckFormatError(f"cannot read the deck: {exc.strerror or exc}", file=str(p)) from None


def _policy(base: Path, include_dirs) -> IncludePolicy:
    """INCLUDE may read inside ``base``'s folder tree and ``include_dirs`` (None: the folders
    of the user's configuration, ``include_dirs`` of :mod:`solver_adapters.userconfig`)."""
    if include_dirs is None:
        from solver_adapters.userconfig import configured_include_dirs
        include_dirs = configured_include_dirs()
    return IncludePolicy(base.resolve(), tuple(Path(d).resolve() for d in include_dirs))


def _includes(policy: IncludePolicy, top: Path) -> Includes:
    inc = Includes(policy)
    inc.stack.append(top)
    return inc


def read_deck(path: str | Path, unmodelled: str = "error", include_dirs=None) -> Deck:
    """Read and :func:`validate` the bulk data of ``path`` (INCLUDEs relative to its folder, and
    only regular files inside its folder tree or one of ``include_dirs``, default the user's
    configured folders). ``unmodelled``: see :data:`UNMODELLED`."""
    p = Path(path)
    return read_deck_text(_text_of(p), name=str(p), base_dir=p.parent, unmodelled=unmodelled,
                          include_dirs=include_dirs)


def read_deck_text(text: str, name: str = "<string>", base_dir: Path | None = None,
                   unmodelled: str = "error", include_dirs=None) -> Deck:
    """Read and :func:`validate` bulk data given as text; ``name`` is the file named in errors.

    INCLUDEs are resolved relative to ``base_dir`` (default: the current directory), and only
    regular files inside its folder tree or one of ``include_dirs`` (default: the user's
    configured folders) are read. ``unmodelled``: see :data:`UNMODELLED`.
    """
    if unmodelled not in UNMODELLED:
        raise ValueError(f"unmodelled must be one of {UNMODELLED}, got {unmodelled!r}")
    keep = unmodelled == "keep"
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    policy = _policy(base, include_dirs)
    top = (base / Path(name).name).resolve()
    try:
        deck = read_table(CardTable(text, name, base, _includes(policy, top)), keep, validate)
    except _RETRY:
        inc = _includes(policy, top)
        inc.files.append(name)
        deck = read_cards(group_cards(LineReader(inc).lines(text, name, base)), keep, validate)
        deck.files = inc.files
    if deck.no_effect:
        logging.getLogger(__name__).info("%s: %s", name, deck.summary())
    return deck


@dataclass
class BulkInput:
    """Every bulk-data card of an input file as read (not interpreted), the files read (the
    input file first), the text of each included file as read (by the name in ``files``) and
    which INCLUDE line read which file (``(file, line) -> name``); ``expanded``: the lines read,
    each with its line number, of a file with COSMIC free-field lines (:mod:`.freefield`)."""
    cards: list
    files: list[str]
    texts: dict[str, str]
    included: dict[tuple[str, int], str]
    expanded: dict[str, tuple[list[str], list[int]]] = dataclass_field(default_factory=dict)

    def lines_of(self, cards) -> dict[str, set[int]]:
        """File -> the physical lines ``cards`` were read from."""
        out: dict[str, set[int]] = {}
        tables: dict[int, tuple[CardTable, list[int]]] = {}
        for c in cards:
            if isinstance(c, TableCard):
                tables.setdefault(id(c.table), (c.table, []))[1].append(c.index)
            else:
                out.setdefault(c.file, set()).update(c.lines)
        for t, chosen in tables.values():
            idx = np.array(chosen, np.int64)
            rows = np.zeros(len(t.body) + 1, np.int64)          # +1 at a card's head, -1 after
            np.add.at(rows, t.head[idx], 1)
            np.add.at(rows, t.end[idx], -1)
            mask = np.cumsum(rows[:-1]) > 0
            for f in np.unique(t.lfile[mask]).tolist():
                sel = mask & (t.lfile == f)
                out.setdefault(t.files[f], set()).update(t.lno[sel].tolist())
        return out


def read_bulk(path: str | Path, text: str | None = None, include_dirs=None) -> BulkInput:
    """The :class:`BulkInput` of the input file ``path`` (INCLUDEs resolved within its folder
    tree or ``include_dirs``, executive and case control skipped). ``text``: the file's text,
    if already read."""
    p = Path(path)
    if text is None:
        text = _text_of(p)
    policy = _policy(p.parent, include_dirs)
    try:
        inc = _includes(policy, p.resolve())
        table = CardTable(text, str(p), p.parent, inc)
        cards = table_cards(table)
    except (Irregular, DeckFormatError):
        inc = _includes(policy, p.resolve())
        inc.files.append(str(p))
        cards = list(group_cards(LineReader(inc).lines(text, str(p), p.parent)))
    return BulkInput(cards, inc.files, inc.texts, inc.included, inc.expanded)


def bulk_cards(path: str | Path, text: str | None = None, include_dirs=None):
    """``(cards, files)``: every bulk-data card of the input file ``path`` as read, not interpreted
    (INCLUDEs resolved, executive and case control skipped), and the files read. For readers of
    cards this module does not model, such as the load cards of :mod:`solver_adapters.loadcards`
    read by ``blackbox import``. Each card has ``name``, ``file``, ``line``, ``src``, ``fields``
    (with their physical lines) and ``error(i, msg)``. ``text``: the file's text, if already read."""
    b = read_bulk(path, text, include_dirs)
    return b.cards, b.files


def deck_from_cards(cards, unmodelled: str = "error") -> Deck:
    """The validated :class:`Deck` of cards from :func:`bulk_cards` (a chosen subset of them);
    errors name the cards' own files and lines. ``unmodelled``: see :data:`UNMODELLED`."""
    if unmodelled not in UNMODELLED:
        raise ValueError(f"unmodelled must be one of {UNMODELLED}, got {unmodelled!r}")
    keep = unmodelled == "keep"
    cards = list(cards)
    table = cards[0].table if cards and isinstance(cards[0], TableCard) else None
    if table is not None and all(isinstance(c, TableCard) and c.table is table for c in cards):
        try:
            return read_table(table, keep, validate, np.array([c.index for c in cards], np.int64))
        except _RETRY:
            pass
    deck = read_cards(cards, keep, validate)
    return deck
