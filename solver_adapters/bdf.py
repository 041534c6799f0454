"""NASTRAN bulk-data reader: the card subset of ``docs/study-format.md`` into :class:`~solver_adapters.deck.Deck`.

Formats, mixed freely within one deck:

* small field: 8-column fields, 10 per line (name, 8 data fields, continuation marker in columns 73-80);
* large field: name ending in ``*`` (``GRID*``), 16-column data fields, 4 per line, ``*`` continuations;
* free field: comma separated (``GRID,1,,0.,0.,0.``; ``GRID*,`` gives 4 data fields per line);
* a line containing tabs is expanded to 8-column tab stops and then read as small/large field.

Continuations are either explicit (marker ``+xxx`` in field 10 matched by ``+xxx``/``*xxx`` in field 1
of the next line) or implicit (the next line's field 1 is blank, ``+`` or ``*``; in free field the
line starts with ``,``, ``+`` or ``*``). ``$`` starts a comment anywhere. ``BEGIN BULK`` and ``ENDDATA``
are optional; a deck with executive/case control (a ``CEND`` line) is read from ``BEGIN BULK`` on.
``INCLUDE 'file'`` is resolved relative to the including file (nested, loops detected).

Cards modelled: GRID (CP and CD systems), GRDSET, CORD1R/C/S and CORD2R/C/S (resolved to basic,
nested in any order), CBAR (pin flags, offsets; orientation and offsets turned into basic),
BAROR, PBAR (K1/K2, I12), PBARL (ROD, TUBE, BAR, BOX, I, CHAN, T, L), CBEAM/PBEAM/PBEAML (prismatic,
no warping), CROD, PROD, CONROD, MAT1 (completed as NASTRAN does), SPC1, SPC (zero enforced value),
SPCADD, RBE2, RBE3, CBUSH/PBUSH, PELAS, CELAS1, CELAS2, PARAM,AUTOSPC (on unless the deck says NO,
as in NASTRAN's SOL 101) and PARAM,EPZERO. Cards in
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
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from solver_adapters.errors import NumberFieldError as _NumberError
from solver_adapters.deck import (Bush, CBar, Coord, Deck, Grid, Mat1, PBar, PBush, Pelas, Prod,
                                  Rbe2, Rbe3, Rod, Spc1, SpcAdd, Spring, Unmodelled)
from solver_adapters.protocol import DeckFormatError, ModelError

__all__ = ["read_deck", "read_deck_text", "bulk_cards", "deck_from_cards", "validate", "parse_int",
           "parse_real", "NO_EFFECT", "SUPPORTED", "UNMODELLED", "NOT_PASSABLE", "ELEMENT_GRIDS",
           "unsupported_error", "unmodelled_error"]

# --------------------------------------------------------------------------------------------
# numbers
# --------------------------------------------------------------------------------------------
_INT = re.compile(r"[+-]?\d+")
# mantissa, then an explicit exponent (E/D) or NASTRAN's implicit one (1.0-3 = 1.0E-3)
_REAL = re.compile(r"([+-]?(?:\d+\.\d*|\.\d+|\d+))(?:[ED]([+-]?\d+)|([+-]\d+))?")
_MAX_INT = 2**31 - 1


def _to_int(s: str) -> int:
    if _INT.fullmatch(s):
        value = int(s)
        if abs(value) > _MAX_INT:
            raise _NumberError("integer out of range (32-bit)")
        return value
    if s and _real_or_none(s) is not None:
        raise _NumberError("integer field given a real")
    raise _NumberError("not an integer")


def _to_real(s: str) -> float:
    value = _real_or_none(s)
    if value is None:
        raise _NumberError("not a real number")
    if not np.isfinite(value):
        raise _NumberError("real number out of range")
    return value


def _real_or_none(s: str) -> float | None:
    m = _REAL.fullmatch(s.upper())
    if m is None:
        return None
    mantissa, explicit, implicit = m.groups()
    if implicit is not None and "." not in mantissa:
        return None
    exponent = explicit if explicit is not None else implicit
    return float(mantissa + ("e" + exponent if exponent is not None else ""))


def parse_int(text: str) -> int:
    """A NASTRAN integer (``12``, ``-3``, ``+7``). A real (``1.``) is an error, as in NASTRAN."""
    try:
        return _to_int(text.strip())
    except _NumberError as exc:
        raise DeckFormatError(str(exc), value=text) from None


def parse_real(text: str) -> float:
    """A NASTRAN real: ``1.0``, ``1.``, ``.5``, ``1.0E+3``, ``1.0D3``, ``1.0+3``, ``-2.5-7``.

    Lenient where NASTRAN is strict: integer text (``0``, ``12``) and an exponent without a decimal
    point (``1E3``) are accepted. The implicit-exponent form needs a decimal point (``1+3`` is an
    error). Non-finite values (``nan``, ``1.0E+999``) are errors.
    """
    try:
        return _to_real(text.strip())
    except _NumberError as exc:
        raise DeckFormatError(str(exc), value=text) from None


# --------------------------------------------------------------------------------------------
# lines and cards
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Field:
    text: str   # stripped, as written
    line: int   # physical line number (1-based)
    pos: int    # field position on that line (2..9 small, 2..5 large)


@dataclass
class _Line:
    file: str
    line: int
    first: str            # field 1: card name or continuation marker
    data: list[str]
    cont: str             # field 10 (continuation marker), stripped


@dataclass
class _Card:
    name: str
    file: str
    line: int
    fields: list[_Field]  # fields[0] is the name (NASTRAN field 1)
    cont: str = ""

    @property
    def src(self) -> str:
        return f"{self.file}:{self.line}"

    def text(self, i: int) -> str:
        """Field ``i`` stripped and upper-cased ("" beyond the end)."""
        return self.fields[i - 1].text.upper() if i <= len(self.fields) else ""

    def error(self, i: int, message: str) -> DeckFormatError:
        """A DeckFormatError at NASTRAN field ``i`` (1-based) of this card."""
        if i <= len(self.fields):
            f = self.fields[i - 1]
            line, value = f.line, f.text
            if line != self.line:
                message += f" (continuation line, field {f.pos} of that line)"
        else:
            line, value = self.fields[-1].line, ""
        return DeckFormatError(message, file=self.file, line=line, card=self.name, field=i,
                               value=value)


def _strip_comment(raw: str) -> str:
    """Text before the first ``$`` (on an INCLUDE line: the first ``$`` outside single quotes)."""
    if not raw.lstrip()[:7].upper() == "INCLUDE":
        return raw.partition("$")[0]
    quoted = False
    for i, ch in enumerate(raw):
        if ch == "'":
            quoted = not quoted
        elif ch == "$" and not quoted:
            return raw[:i]
    return raw


def _is_continuation(first: str) -> bool:
    return first == "" or first[0] in "+*"


def _split(raw: str, file: str, lineno: int) -> _Line:
    """One physical (comment-free, non-blank) line into field 1, data fields and field 10."""
    def fail(message: str) -> DeckFormatError:
        return DeckFormatError(message, file=file, line=lineno, value=raw.strip())

    if "," in raw:
        items = [s.strip() for s in raw.replace("\t", " ").split(",")]
        first = items[0].upper()
        large = first.endswith("*") or first.startswith("*")
        width = 4 if large else 8
        while len(items) > width + 2 and items[-1] == "":
            items.pop()                   # trailing commas beyond field 10
        if len(items) > width + 2:
            raise fail(f"free-field line has {len(items) - 1} fields after field 1; at most "
                       f"{width} data fields and a continuation marker fit on one line")
        data = items[1:width + 1]
        cont = items[width + 1] if len(items) > width + 1 else ""
        return _Line(file, lineno, first, data + [""] * (width - len(data)), cont)
    line = raw.expandtabs(8).rstrip()
    if len(line) > 80:
        raise fail("text beyond column 80 of a fixed-field line")
    line = line.ljust(80)
    first = line[:8].strip().upper()
    large = first.endswith("*") or first.startswith("*")
    width = 16 if large else 8
    data = [line[8 + width * k: 8 + width * (k + 1)].strip() for k in range(64 // width)]
    return _Line(file, lineno, first, data, line[72:80].strip().upper())


_BOUNDARY = object()  # between files: a card never continues across an INCLUDE
_INCLUDE = re.compile(r"INCLUDE\s*(?:'([^']*)'|\"([^\"]*)\"|([^\s'\"]+))\s*", re.IGNORECASE)
_BEGIN_BULK = re.compile(r"BEGIN\s+BULK\b.*", re.IGNORECASE)


class _Reader:
    def __init__(self, keep_unmodelled: bool = False) -> None:
        self.deck = Deck()
        # True: cards not modelled go to Deck.unmodelled (for an external solver) instead of
        # being errors; cards of NOT_PASSABLE stay errors
        self.keep_unmodelled = keep_unmodelled
        self.stack: list[Path] = []
        self.ended = False
        # ID -> "CARD at file:line"; elements (CBAR, RBE2, CELASi) share one ID space, as do
        # properties (PBAR, PELAS)
        self.ids: dict[str, dict[int, str]] = {"GRID": {}, "element": {}, "property": {}, "MAT1": {},
                                               "SPCADD": {}, "CORD": {}}
        self.spc1_pending: list[tuple[int, str, list[int | tuple[int, int]], str]] = []
        # card name -> [count, first card] of every card that is neither modelled nor NO_EFFECT
        self.unsupported: dict[str, list] = {}
        # GRDSET defaults, applied in finish() (bulk data is unordered: GRDSET may come last)
        self.grdset: _Card | None = None
        self.first_blank: dict[str, int | None] = {"CP": None, "CD": None, "SEID": None}
        self.blank_ps: list[int] = []
        self.blank_sys: dict[str, list[int]] = {"CP": [], "CD": []}
        self.grid_cards: dict[int, _Card] = {}     # GRIDs with a non-zero CP or CD (for errors)
        # coordinate-system cards, resolved in finish(): CID -> (kind, card, definition)
        self.cords: dict[int, tuple[str, _Card, tuple]] = {}
        self.cbar_offt: dict[int, str] = {}       # OFFT as written (blank: BAROR's or GGG)
        self.pending_cids: list[tuple[_Card, int]] = []   # CBUSH CIDs, checked in finish()
        # BAROR defaults, applied in finish(): CBARs with a blank PID, with no orientation
        self.baror: _Card | None = None
        self.pid_blank: list[int] = []
        self.orient_blank: list[tuple[int, _Card]] = []

    # ---- physical lines of one file (and its includes) ----------------------------------
    def lines(self, text: str, file: str, base_dir: Path):
        raw_lines = text.removeprefix("\ufeff").splitlines()
        uncommented = [_strip_comment(r) for r in raw_lines]
        start = 0
        if any(u.strip().upper() == "CEND" for u in uncommented):
            begin = [i for i, u in enumerate(uncommented) if _BEGIN_BULK.fullmatch(u.strip())]
            if not begin:
                raise DeckFormatError("the deck has a CEND line (executive/case control) but no "
                                      "BEGIN BULK", file=file)
            start = begin[0] + 1
        for k in range(start, len(raw_lines)):
            body, lineno = uncommented[k], k + 1
            stripped = body.strip()
            if not stripped or _BEGIN_BULK.fullmatch(stripped):
                continue
            if stripped[:7].upper() == "INCLUDE" and (len(stripped) == 7 or not stripped[7].isalnum()):
                yield _BOUNDARY
                yield from self.include(stripped, file, lineno, base_dir)
                yield _BOUNDARY
                if self.ended:
                    return
                continue
            line = _split(body, file, lineno)
            if line.first.rstrip("*") == "ENDDATA":
                self.ended = True
                return
            yield line

    def include(self, stripped: str, file: str, lineno: int, base_dir: Path):
        m = _INCLUDE.fullmatch(stripped)
        if m is None:
            raise DeckFormatError("expected INCLUDE 'file' (quoted, on one line)", file=file,
                                  line=lineno, card="INCLUDE", field=2, value=stripped[7:].strip())
        name = next(g for g in m.groups() if g is not None)
        path = (base_dir / name).resolve()
        if path in self.stack:
            chain = " -> ".join(str(p) for p in self.stack + [path])
            raise DeckFormatError(f"INCLUDE loop: {chain}", file=file, line=lineno,
                                  card="INCLUDE", field=2, value=name)
        try:
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise DeckFormatError(f"cannot read included file {path}: {exc.strerror or exc}",
                                  file=file, line=lineno, card="INCLUDE", field=2, value=name) from None
        shown = str(base_dir / name)
        self.deck.files.append(shown)
        self.stack.append(path)
        yield from self.lines(text, shown, path.parent)
        self.stack.pop()

    # ---- physical lines into cards ----------------------------------------------------
    def cards(self, lines):
        card: _Card | None = None
        for line in lines:
            if line is _BOUNDARY:
                if card is not None:
                    yield card
                card = None
                continue
            if _is_continuation(line.first):
                if card is None:
                    raise DeckFormatError("continuation line without a card before it",
                                          file=line.file, line=line.line, field=1, value=line.first)
                marker = line.first[1:]
                if card.cont and marker and card.cont[1:] != marker and card.cont != marker:
                    raise DeckFormatError(f"continuation marker does not match {card.cont!r} of the "
                                          f"card above", file=line.file, line=line.line,
                                          card=card.name, field=1, value=line.first)
            else:
                if card is not None:
                    yield card
                name = line.first.rstrip("*")
                card = _Card(name, line.file, line.line, [_Field(name, line.line, 1)])
            card.fields.extend(_Field(t, line.line, p) for p, t in enumerate(line.data, start=2))
            card.cont = line.cont
        if card is not None:
            yield card

    # ---- cards into the deck ------------------------------------------------------------
    def add(self, card: _Card) -> None:
        if card.name == "PARAM":
            _param(self, card)
        if card.name in NO_EFFECT:
            n, src = self.deck.no_effect.get(card.name, (0, card.src))
            self.deck.no_effect[card.name] = (n + 1, src)
            return
        parser = _PARSERS.get(card.name)
        if parser is None:
            if self.keep_unmodelled and card.name not in NOT_PASSABLE:
                self.keep(card)
                return
            entry = self.unsupported.setdefault(card.name, [0, card])
            entry[0] += 1
            return
        parser(self, card)

    def keep(self, card: _Card) -> None:
        """An unmodelled card into ``Deck.unmodelled``: its fields typed (integer, real, word,
        blank) as NASTRAN reads them, its grids when the card's layout is known (an element of
        :data:`ELEMENT_GRIDS`: those fields, which must be grid IDs; a property, material or
        other card that connects no grid: none; any other card: unknown). An element's EID joins
        the element ID space (NASTRAN: unique over all elements), so a clash is caught."""
        fields = tuple(_typed(f.text) for f in card.fields[1:])
        layout = ELEMENT_GRIDS.get(card.name)
        grids: tuple[int, ...] | None
        if layout is not None:
            grids = tuple(_int(card, i) for i in layout if card.text(i))
            self.claim("element", _int(card, 2), card, 2)
        else:
            grids = () if _connects_nothing(card.name) else None
        self.deck.unmodelled.append(Unmodelled(card.name, fields, card.src, grids))

    def apply_baror(self) -> None:
        """BAROR's PID and orientation into the CBARs that leave those fields blank."""
        b = self.baror
        pid = _int(b, 3, 0) if b is not None else 0
        if pid:
            for eid in self.pid_blank:
                self.deck.cbars[eid] = replace(self.deck.cbars[eid], pid=pid)
        x, g0 = _orientation(b) if b is not None else (None, None)
        for eid, c in self.orient_blank:
            if x is None and g0 is None:
                raise c.error(6, "orientation vector X1 X2 X3 or grid G0 required (blank here "
                                 "and no BAROR default)")
            self.deck.cbars[eid] = replace(self.deck.cbars[eid], x=x, g0=g0)

    def check_unsupported(self) -> None:
        """One DeckFormatError naming every unsupported card: count and first location of each.

        It points (file, line, field 1) at the first unsupported card of the deck."""
        if not self.unsupported:
            return
        raise unsupported_error([(name, n, c.src) for name, (n, c) in self.unsupported.items()],
                                keeping=self.keep_unmodelled)

    def claim(self, kind: str, ident: int, card: _Card, i: int) -> None:
        table = self.ids[kind]
        if ident in table:
            raise card.error(i, f"duplicate {kind} ID {ident} (already defined by {table[ident]})")
        table[ident] = f"{card.name} at {card.src}"

    def resolve_coordinates(self) -> None:
        """Coordinate systems into :class:`Coord` (basic origin and axes), GRID positions from
        their CP system into basic, CBAR orientation vectors and offsets from the grids' CD
        systems into basic. Definitions may chain in any order (a CORD2 in another system, a
        CORD1 on grids given in another system); a loop is an error."""
        deck = self.deck
        for gid, c in self.grid_cards.items():
            g = deck.grids[gid]
            for i, key, value in ((3, "CP", g.cp), (7, "CD", g.cd)):
                if value and value not in self.cords:
                    via = "" if c.name == "GRID" else f" (the GRDSET default of GRID {gid} at {g.src})"
                    raise c.error(i, f"{key} {value}{via}: coordinate system {value} is not defined "
                                     f"(no CORD1R/C/S or CORD2R/C/S with CID {value})")
        for cid, (kind, c, d) in self.cords.items():
            if c.name.startswith("CORD2"):
                if d[0] and d[0] not in self.cords:
                    raise c.error(3, f"RID {d[0]}: coordinate system {d[0]} is not defined")
            else:
                for k, g in enumerate(d[1]):
                    if g not in deck.grids:
                        raise c.error(d[0] + 1 + k, f"grid {g} does not exist (no GRID)")
        pending_grids: dict[int, list[int]] = {}
        for gid, g in deck.grids.items():
            if g.cp:
                pending_grids.setdefault(g.cp, []).append(gid)
        waiting = {gid for ids in pending_grids.values() for gid in ids}
        pending = dict(self.cords)
        while pending or pending_grids:
            progress = False
            for cid in list(pending):
                kind, c, d = pending[cid]
                if c.name.startswith("CORD2"):
                    rid, pts = d
                    if rid and rid not in deck.coords:
                        continue
                    pts = np.array(pts, float)
                    if rid:
                        pts = deck.coords[rid].to_basic(pts)
                else:
                    if any(g in waiting for g in d[1]):
                        continue
                    pts = np.array([deck.grids[g].xyz for g in d[1]], float)
                deck.coords[cid] = _coord_from_points(cid, kind, pts, c, d)
                del pending[cid]
                progress = True
            for cp in [k for k in pending_grids if k in deck.coords]:
                ids = pending_grids.pop(cp)
                xyz = deck.coords[cp].to_basic(np.array([deck.grids[g].xyz for g in ids], float))
                for gid, x in zip(ids, xyz.tolist()):
                    deck.grids[gid] = replace(deck.grids[gid], xyz=tuple(x))
                waiting.difference_update(ids)
                progress = True
            if not progress:
                cid, (kind, c, d) = next(iter(pending.items()))
                raise c.error(2, f"coordinate system {cid} cannot be resolved: its definition "
                                 f"depends on itself (systems {', '.join(map(str, sorted(pending)))} "
                                 f"refer to each other, directly or through grids)")
        with_cd = [gid for gid, g in deck.grids.items() if g.cd]
        try:
            frames = dict(zip(with_cd, deck.displacement_frames(with_cd)))
        except ValueError as exc:
            message, gid = exc.args
            raise self.grid_cards[gid].error(7, message) from None
        if not frames:
            return
        offt_default = self.baror.text(9) if self.baror is not None else ""
        for eid, b in deck.cbars.items():
            fa, fb = frames.get(b.ga), frames.get(b.gb)
            if fa is None and fb is None:
                continue
            offt = self.cbar_offt.get(eid) or offt_default or "GGG"
            x, wa, wb = b.x, b.wa, b.wb
            if fa is not None and x is not None and offt[0] == "G":
                x = tuple((fa.T @ np.array(x)).tolist())       # GA's CD components -> basic
            if fa is not None and wa is not None:
                wa = tuple((fa.T @ np.array(wa)).tolist())
            if fb is not None and wb is not None:
                wb = tuple((fb.T @ np.array(wb)).tolist())
            deck.cbars[eid] = replace(b, x=x, wa=wa, wb=wb)

    def finish(self) -> Deck:
        """GRDSET defaults into the GRIDs; SPC1 ``G1 THRU G2`` expanded (as in NASTRAN, grids of
        the range that do not exist are skipped)."""
        if self.grdset is not None:
            c = self.grdset
            gid = self.first_blank["SEID"]
            if _int(c, 9, 0, minimum=0) != 0 and gid is not None:
                raise c.error(9, f"superelements are not supported: SEID {_int(c, 9)} of GRDSET is "
                                 f"the default of every GRID whose SEID is blank, e.g. GRID {gid} at "
                                 f"{self.deck.grids[gid].src}; GRDSET SEID must be 0 or blank")
            ps = _components(c, 8, required=False)
            cp, cd = _int(c, 3, 0, minimum=0), _int(c, 7, 0, minimum=0)
            for key, value in (("CP", cp), ("CD", cd)):
                if value:
                    for gid in self.blank_sys[key]:
                        self.grid_cards.setdefault(gid, c)
                        self.deck.grids[gid] = replace(self.deck.grids[gid], **{key.lower(): value})
            if ps:
                for gid in self.blank_ps:
                    self.deck.grids[gid] = replace(self.deck.grids[gid], ps=ps)
        self.resolve_coordinates()
        for c, cid in self.pending_cids:
            if cid not in self.deck.coords:
                raise c.error(9, f"CID {cid}: coordinate system {cid} is not defined")
        self.apply_baror()
        for sid, comps, items, src in self.spc1_pending:
            grids: list[int] = []
            for item in items:
                if isinstance(item, tuple):
                    grids.extend(g for g in sorted(self.deck.grids) if item[0] <= g <= item[1])
                else:
                    grids.append(item)
            if grids:
                self.deck.spc1s.append(Spc1(sid, comps, tuple(grids), src))
        return self.deck


# --------------------------------------------------------------------------------------------
# field accessors (i = NASTRAN field number, 1-based)
# --------------------------------------------------------------------------------------------
_REQUIRED = object()


def _int(card: _Card, i: int, default=_REQUIRED, *, minimum: int | None = 1) -> int:
    text = card.text(i)
    if not text:
        if default is _REQUIRED:
            raise card.error(i, "required integer field is blank")
        return default
    try:
        value = _to_int(text)
    except _NumberError as exc:
        raise card.error(i, str(exc)) from None
    if minimum is not None and value < minimum:
        raise card.error(i, f"must be >= {minimum}")
    return value


def _real(card: _Card, i: int, default=_REQUIRED) -> float:
    text = card.text(i)
    if not text:
        if default is _REQUIRED:
            raise card.error(i, "required real field is blank")
        return default
    try:
        return _to_real(text)
    except _NumberError as exc:
        raise card.error(i, str(exc)) from None


def _components(card: _Card, i: int, *, required: bool) -> str:
    """Component digits 1-6, no repeats, returned sorted (``"321"`` -> ``"123"``)."""
    text = card.text(i)
    if not text:
        if required:
            raise card.error(i, "required component field is blank")
        return ""
    if not re.fullmatch(r"[1-6]+", text) or len(set(text)) != len(text):
        raise card.error(i, "components must be digits 1-6 without repeats")
    return "".join(sorted(text))


def _blank(card: _Card, i: int, what: str, *, zero_ok: bool = False) -> None:
    text = card.text(i)
    if text and not (zero_ok and _real_or_none(text) == 0.0):
        raise card.error(i, f"{what} not supported (must be blank)")


def _max_fields(card: _Card, n: int) -> None:
    for i in range(n + 1, len(card.fields) + 1):
        if card.text(i):
            raise card.error(i, f"{card.name} has at most {n} fields")


def _ignored_reals(card: _Card, fields) -> None:
    for i in fields:
        _real(card, i, 0.0)  # read for well-formedness only


# --------------------------------------------------------------------------------------------
# card parsers
# --------------------------------------------------------------------------------------------
def _grid(r: _Reader, c: _Card) -> None:
    """GRID ID CP X1 X2 X3 CD PS SEID; a blank CP, CD, PS or SEID takes the GRDSET value (applied
    in ``finish``, which also converts X1-X3 from the CP system to basic)."""
    _max_fields(c, 9)
    gid = _int(c, 2)
    cp = _int(c, 3, 0, minimum=0)
    xyz = (_real(c, 4, 0.0), _real(c, 5, 0.0), _real(c, 6, 0.0))
    cd = _int(c, 7, 0, minimum=0)
    ps = _components(c, 8, required=False)
    if _int(c, 9, 0, minimum=0) != 0:
        raise c.error(9, "superelements are not supported: SEID must be blank")
    r.claim("GRID", gid, c, 2)
    r.deck.grids[gid] = Grid(gid, xyz, ps, c.src, cp, cd)
    if cp or cd:
        r.grid_cards[gid] = c
    for i, key in ((3, "CP"), (7, "CD"), (9, "SEID")):
        if not c.text(i):
            if r.first_blank[key] is None:
                r.first_blank[key] = gid
            if key != "SEID":
                r.blank_sys[key].append(gid)
    if not c.text(8):
        r.blank_ps.append(gid)


def _grdset(r: _Reader, c: _Card) -> None:
    """GRDSET: defaults for the GRID fields CP (3), CD (7), PS (8), SEID (9); checked and applied
    to the GRIDs in ``finish`` (a non-zero CP, CD or SEID is an error once a GRID would use it)."""
    _max_fields(c, 9)
    for i in (2, 4, 5, 6):
        _blank(c, i, f"GRDSET field {i}")
    for i in (3, 7, 9):
        _int(c, i, 0, minimum=0)
    _components(c, 8, required=False)
    if r.grdset is not None:
        raise c.error(1, f"only one GRDSET is allowed (the first is at {r.grdset.src})")
    r.grdset = c


def _orientation(c: _Card) -> tuple[tuple[float, float, float] | None, int | None]:
    """Fields 6-8 of CBAR/BAROR: ``(x, None)``, ``(None, g0)`` or ``(None, None)`` if blank."""
    if _INT.fullmatch(c.text(6)):
        for i in (7, 8):
            if c.text(i):
                raise c.error(i, "field 6 is an integer (G0), so X2 and X3 must be blank; "
                                 "write a real X1 (e.g. 0.) for an orientation vector")
        return None, _int(c, 6)
    if any(c.text(i) for i in (6, 7, 8)):
        return (_real(c, 6, 0.0), _real(c, 7, 0.0), _real(c, 8, 0.0)), None
    return None, None


def _offt(c: _Card) -> None:
    """OFFT (field 9): GGG (the default: orientation vector in GA's CD system, offsets in the CD
    systems of GA and GB) or BGG (orientation vector in basic); the reader converts both to basic
    (``resolve_coordinates``). Offsets in the element system (an ``O``) are not supported."""
    if c.text(9) not in ("", "GGG", "BGG"):
        raise c.error(9, "offset option OFFT not supported: only GGG (default) or BGG, offsets "
                         "in the basic system")


def _pin(c: _Card, i: int) -> str:
    """Pin flag digits (element components 1-6 released at that end); blank or 0: none."""
    return "" if c.text(i) in ("", "0") else _components(c, i, required=False)


def _cbar(r: _Reader, c: _Card) -> None:
    """CBAR: EID PID GA GB X1/G0 X2 X3 OFFT / PA PB W1A W2A W3A W1B W2B W3B.

    A blank PID, orientation or OFFT takes the BAROR value (applied in ``finish``); a blank PID
    without BAROR PID is the EID. The orientation vector and offsets are converted to basic in
    ``resolve_coordinates``."""
    _max_fields(c, 17)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    x, g0 = _orientation(c)
    _offt(c)
    pa, pb = _pin(c, 10), _pin(c, 11)
    wa = tuple(_real(c, i, 0.0) for i in (12, 13, 14))
    wb = tuple(_real(c, i, 0.0) for i in (15, 16, 17))
    r.claim("element", eid, c, 2)
    if c.text(9):
        r.cbar_offt[eid] = c.text(9)
    r.deck.cbars[eid] = CBar(eid, pid, ga, gb, x, g0, c.src, pa, pb,
                             wa if any(wa) else None, wb if any(wb) else None)
    if not c.text(3):
        r.pid_blank.append(eid)
    if x is None and g0 is None:
        r.orient_blank.append((eid, c))


def _cbeam(r: _Reader, c: _Card) -> None:
    """CBEAM: EID PID GA GB X1/G0 X2 X3 OFFT / PA PB W1A W2A W3A W1B W2B W3B / SA SB, modelled as
    the CBAR element (a prismatic beam without warping). BIT (tapered beams), the warping scalar
    points SA, SB and BEAMOR defaults are not supported: errors."""
    _max_fields(c, 19)
    for i, name in ((18, "SA"), (19, "SB")):
        if c.text(i):
            raise c.error(i, f"warping scalar point {name} not supported (no warping): must be blank")
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    x, g0 = _orientation(c)
    if x is None and g0 is None:
        raise c.error(6, "orientation vector X1 X2 X3 or grid G0 required (BEAMOR defaults are "
                         "not supported)")
    if c.text(9) and _real_or_none(c.text(9)) is not None:
        raise c.error(9, "BIT (built-in twist of a tapered beam) not supported: field 9 must be "
                         "blank, GGG or BGG")
    _offt(c)
    pa, pb = _pin(c, 10), _pin(c, 11)
    wa = tuple(_real(c, i, 0.0) for i in (12, 13, 14))
    wb = tuple(_real(c, i, 0.0) for i in (15, 16, 17))
    r.claim("element", eid, c, 2)
    r.cbar_offt[eid] = c.text(9) or "GGG"          # BAROR does not apply to CBEAM
    r.deck.cbars[eid] = CBar(eid, pid, ga, gb, x, g0, c.src, pa, pb,
                             wa if any(wa) else None, wb if any(wb) else None, card="CBEAM")


_SO = ("YES", "YESA", "NO")


def _pbeam(r: _Reader, c: _Card) -> None:
    """PBEAM as a prismatic beam: PID MID A I1 I2 I12 J NSM / C1..F2 (end A stress points) /
    [SO X/XB A I1 I2 I12 J NSM [/ C1..F2 when SO = YES]] ... / K1 K2 S1 S2 NSI(A) NSI(B) CW(A)
    CW(B) / M1(A) M2(A) M1(B) M2(B) N1(A) N2(A) N1(B) N2(B) (MSC QRG).

    Every station (end B included) must have end A's A, I1, I2, I12, J (blank: end A's value);
    a different value is a tapered beam (error). K1, K2 default 1.0 (shear stiffness K A G, as
    in NASTRAN; 0.0: rigid in shear). Shear relief S1, S2, warping CW and the offsets of the
    centre of gravity and neutral axis M, N must be blank or 0 (errors otherwise). NSM, NSI
    and the stress recovery points are read and have no effect."""
    n_groups = (len(c.fields) - 1 + 7) // 8

    def first(g: int) -> int:              # NASTRAN field number of group g's first field
        return 8 * (g - 1) + 2

    pid, mid = _int(c, 2), _int(c, 3)
    end_a = tuple(_real(c, i, 0.0) for i in (4, 5, 6, 7, 8))     # A I1 I2 I12 J
    _real(c, 9, 0.0)                                              # NSM
    _ignored_reals(c, range(10, 18))                              # C1(A) .. F2(A)
    g = 3
    names = ("A", "I1", "I2", "I12", "J")
    while g <= n_groups and c.text(first(g)) in _SO:
        f0 = first(g)
        so = c.text(f0)
        xxb = _real(c, f0 + 1)
        if not 0.0 < xxb <= 1.0:
            raise c.error(f0 + 1, "X/XB must be in (0, 1]")
        for k, name in enumerate(names):
            value = _real(c, f0 + 2 + k, end_a[k])
            if value != end_a[k]:
                raise c.error(f0 + 2 + k, f"tapered beam not supported: {name} at X/XB = {xxb:g} "
                                          f"is {value:g}, at end A {end_a[k]:g} (only prismatic "
                                          f"beams, every station equal to end A)")
        _real(c, f0 + 7, 0.0)
        g += 1
        if so == "YES":
            _ignored_reals(c, range(first(g), first(g) + 8))
            g += 1
    if n_groups - g + 1 > 2:
        raise c.error(first(g + 2), "PBEAM has fields after its M/N line (or a station without "
                                    "SO = YES, YESA or NO)")
    kf = first(g)
    k = []
    for i in (kf, kf + 1):
        value = _real(c, i, 1.0)
        if value < 0.0:
            raise c.error(i, "shear stiffness factor must be >= 0 (0.0: rigid in shear)")
        if value and end_a[0] == 0.0:
            raise c.error(i, "shear stiffness factor needs a non-zero area A (0.0: rigid in shear)")
        k.append(value or None)
    for i, what in ((kf + 2, "shear relief S1"), (kf + 3, "shear relief S2"),
                    (kf + 6, "warping coefficient CW(A)"), (kf + 7, "warping coefficient CW(B)")):
        if _real(c, i, 0.0) != 0.0:
            raise c.error(i, f"{what} not supported: must be blank or 0.0")
    _ignored_reals(c, (kf + 4, kf + 5))                           # NSI(A), NSI(B)
    for i in range(kf + 8, kf + 16):
        if _real(c, i, 0.0) != 0.0:
            raise c.error(i, "offsets of the centre of gravity / neutral axis (M1..N2) not "
                             "supported: must be blank or 0.0")
    a, i1, i2, i12, j = end_a
    if i12 != 0.0:
        if not i1 * i2 > i12 * i12:
            raise c.error(7, "product of inertia I12 needs I1 * I2 > I12^2")
        if k[0] or k[1]:
            raise c.error(kf, "shear flexibility (K1/K2, default 1.0) together with a non-zero "
                              "I12 is not supported: set K1 = K2 = 0.0 or I12 = 0.0")
    r.claim("property", pid, c, 2)
    r.deck.pbars[pid] = PBar(pid, mid, a, i1, i2, j, c.src, k[0], k[1], i12, card="PBEAM")


def _pbeaml(r: _Reader, c: _Card) -> None:
    """PBEAML: PID MID GROUP TYPE / DIM1(A) .. DIMn(A) NSM(A) [SO X/XB DIM1 .. DIMn NSM] ... as
    a prismatic beam: every station's dimensions (blank: end A's) must equal end A's (a
    different one is a tapered beam: error). Section constants as for PBARL."""
    pid, mid, kind, dims = _library_section(c, max_fields=False)
    if kind in _UNSYMMETRIC:
        # NASTRAN's CBEAM keeps the transverse shear flexibility of such a section (PBEAM's K1/K2
        # default 1.0) together with its I12; the reference solver models shear flexibility and
        # I12 only apart (as PBAR does), so the beam would silently differ
        raise c.error(5, f"section TYPE {kind} (unsymmetric, I12 != 0) is not supported on PBEAML: "
                         f"its shear flexibility together with I12 is not modelled; use PBARL on a CBAR "
                         f"(NASTRAN ignores K1/K2 there when I12 is not zero)")
    n = len(dims)
    f = 11 + n
    while f <= len(c.fields):
        if not any(c.text(i) for i in range(f, len(c.fields) + 1)):
            break
        if c.text(f) not in _SO:
            raise c.error(f, "expected SO (YES, YESA or NO) of the next station")
        xxb = _real(c, f + 1)
        if not 0.0 < xxb <= 1.0:
            raise c.error(f + 1, "X/XB must be in (0, 1]")
        for k in range(n):
            value = _real(c, f + 2 + k, dims[k])
            if value != dims[k]:
                raise c.error(f + 2 + k, f"tapered beam not supported: DIM{k + 1} at X/XB = "
                                         f"{xxb:g} is {value:g}, at end A {dims[k]:g}")
        _real(c, f + 2 + n, 0.0)                                   # NSM
        f += n + 3
    _library_pbar(r, c, pid, mid, kind, dims)


def _baror(r: _Reader, c: _Card) -> None:
    """BAROR: defaults for CBAR fields PID (3), X1 X2 X3 or G0 (6-8), OFFT (9)."""
    _max_fields(c, 9)
    for i in (2, 4, 5):
        _blank(c, i, f"BAROR field {i}")
    _int(c, 3, 0)
    _orientation(c)
    _offt(c)
    if r.baror is not None:
        raise c.error(1, f"only one BAROR is allowed (the first is at {r.baror.src})")
    r.baror = c


def _pbar(r: _Reader, c: _Card) -> None:
    """PBAR: PID MID A I1 I2 J NSM / C1 C2 D1 D2 E1 E2 F1 F2 / K1 K2 I12.

    K1, K2 (fields 18, 19): shear stiffness per unit length K1*A*G (plane 1), K2*A*G (plane 2).
    Blank is NASTRAN's default, infinite shear stiffness (Euler-Bernoulli); 0.0 is taken the same
    way (as MYSTRAN does). I12 (field 20): product of inertia, I1 * I2 > I12^2 required (QRG).
    NASTRAN ignores K1/K2 when I12 is non-zero; here that combination is an error instead.
    """
    _max_fields(c, 20)
    pid, mid = _int(c, 2), _int(c, 3)
    a, i1, i2, j = (_real(c, i, 0.0) for i in (4, 5, 6, 7))
    _ignored_reals(c, [8] + list(range(10, 18)))  # NSM, stress recovery points C..F
    _blank(c, 9, "field 9")
    k: list[float | None] = []
    for i in (18, 19):
        value = _real(c, i, None)
        if value is not None and value < 0.0:
            raise c.error(i, "shear area factor must be > 0 (blank or 0.0: no shear flexibility)")
        if value and a == 0.0:
            raise c.error(i, "shear area factor needs a non-zero area A (NASTRAN: K1, K2 must be "
                             "blank if A = 0.0)")
        k.append(value or None)
    i12 = _real(c, 20, 0.0)
    if i12 != 0.0:
        if not i1 * i2 > i12 * i12:
            raise c.error(20, "product of inertia I12 needs I1 * I2 > I12^2")
        if k[0] or k[1]:
            raise c.error(20, "K1/K2 together with a non-zero I12: NASTRAN ignores K1/K2 then; "
                              "remove K1/K2 (or I12)")
    r.claim("property", pid, c, 2)
    r.deck.pbars[pid] = PBar(pid, mid, a, i1, i2, j, c.src, k[0], k[1], i12)


# PBARL section types: number of dimensions DIM1..DIMn (MSC QRG, PBARL)
_PBARL_DIMS = {"ROD": 1, "TUBE": 2, "BAR": 2, "BOX": 4, "I": 6, "CHAN": 4, "T": 4, "L": 4}
# types whose section is not symmetric about y or z (I12 != 0): PBARL only (see _pbeaml)
_UNSYMMETRIC = frozenset({"L"})


def pbarl_section(kind: str, d: tuple[float, ...]) -> tuple[float, ...]:
    """``(A, I1, I2, J, K1, K2, I12)`` of a PBARL section from its dimensions ``d`` (DIM1...), in
    NASTRAN's element axes: y is the section's height direction (plane 1, I1 about z), z its
    width direction (plane 2, I2 about y); I12 = int y z dA about the centroid (zero but for
    L). ``ValueError(field offset, message)`` for dimensions that give no section (a wall
    thicker than the section).

    A, I1, I2 are exact for the idealized shape (rectangles, circles), about the centroid.
    J: ROD, TUBE exact (polar moment); BAR Roark's series for a solid rectangle
    (a b^3 (1/3 - 0.21 b/a (1 - b^4 / (12 a^4))), a >= b, within 0.5 % of St Venant's value);
    BOX Bredt's thin-walled closed section on the wall mid-line, 4 A_m^2 / sum(s_i / t_i);
    I, CHAN, T the open thin-walled sum of (1/3) b t^3 over the walls. K1, K2 (shear area
    factors, plane 1 and 2): the values MYSTRAN 18 computes for PBARL (BD_PBARL.f90): 5/6 for
    BAR, 6/7 for ROD, Cowper's tube factor with NU = 0, the web (or wall) area fraction for
    BOX, I, CHAN and T (5/6 of the flange fraction across the flanges; Cowper's T-section factor
    in the web plane of T). NASTRAN's own K1/K2 for PBARL are not documented in the QRG.

    L (an angle; NX Nastran Element Library Reference, PBARL TYPE L): DIM1 the width of the
    horizontal leg (along z, its thickness DIM3 along y), DIM2 the height of the vertical leg
    (along y, its thickness DIM4 along z); the element axes start at the shear center, the
    intersection of the legs' mid-lines, and the legs run along +y and +z from the corner (the
    Element Library's figure: vertical leg on the left, horizontal leg at the bottom, y up and z
    to the right as in its T section; the sign of I12 follows from this choice, which no run of
    NASTRAN could confirm here: MYSTRAN has no L). As for every PBARL the bar's axis is the grid line (PBARL does
    not offset the neutral axis from the shear center). A, I1, I2 and I12 are exact for the
    two rectangles (horizontal leg DIM1 x DIM3, vertical leg DIM4 x (DIM2 - DIM3) above it),
    about the centroid; I12 = int y z dA is negative (the legs lie in the quadrants +z/-y and
    -z/+y of the centroid). J is the open thin-walled sum over the legs' mid-line lengths,
    (b DIM3^3 + h DIM4^3) / 3 with b = DIM1 - DIM4/2, h = DIM2 - DIM3/2 (the Element Library's
    formula). K1, K2: none (Euler-Bernoulli): NASTRAN ignores a PBAR's K1/K2 when I12 is not
    zero (QRG PBAR), and an angle's I12 never is.
    """
    pi = np.pi
    if kind == "ROD":
        (r,) = d
        i = pi * r**4 / 4
        return pi * r * r, i, i, 2 * i, 6 / 7, 6 / 7, 0.0
    if kind == "TUBE":
        r1, r2 = d
        if not r2 < r1:
            raise ValueError(1, "inner radius DIM2 must be smaller than the outer radius DIM1")
        i = pi * (r1**4 - r2**4) / 4
        m2 = (r2 / r1) ** 2
        k = 6 * (1 + m2) ** 2 / (7 * (1 + m2) ** 2 + 20 * m2)
        return pi * (r1 * r1 - r2 * r2), i, i, 2 * i, k, k, 0.0
    if kind == "BAR":
        b, h = d                                  # DIM1 width (z), DIM2 height (y)
        a, t = max(b, h), min(b, h)
        j = a * t**3 * (1 / 3 - 0.21 * t / a * (1 - t**4 / (12 * a**4)))
        return b * h, b * h**3 / 12, h * b**3 / 12, j, 5 / 6, 5 / 6, 0.0
    if kind == "BOX":
        b, h, th, tv = d                          # width, height, horizontal / vertical walls
        bi, hi = b - 2 * tv, h - 2 * th
        if bi <= 0:
            raise ValueError(3, "vertical walls DIM4 fill the width DIM1 (2 DIM4 >= DIM1)")
        if hi <= 0:
            raise ValueError(2, "horizontal walls DIM3 fill the height DIM2 (2 DIM3 >= DIM2)")
        am = (b - tv) * (h - th)
        j = 4 * am * am / (2 * (b - tv) / th + 2 * (h - th) / tv)
        return (b * h - bi * hi, (b * h**3 - bi * hi**3) / 12, (h * b**3 - hi * bi**3) / 12, j,
                hi / h, bi / b, 0.0)
    if kind == "I":
        h, wb, wt, tw, tb, tt = d                 # depth, bottom/top flange widths, thicknesses
        hw = h - tb - tt
        if hw <= 0:
            raise ValueError(4, "flange thicknesses DIM5 + DIM6 fill the depth DIM1")
        if tw > min(wb, wt):
            raise ValueError(3, "web thickness DIM4 exceeds a flange width")
        parts = [(wb, tb, tb / 2), (tw, hw, tb + hw / 2), (wt, tt, h - tt / 2)]  # (z, y size, y_c)
        a = sum(w * t for w, t, _ in parts)
        yc = sum(w * t * y for w, t, y in parts) / a
        i1 = sum(w * t**3 / 12 + w * t * (y - yc) ** 2 for w, t, y in parts)
        i2 = sum(t * w**3 / 12 for w, t, _ in parts)
        j = (wb * tb**3 + wt * tt**3 + (h - (tb + tt) / 2) * tw**3) / 3
        return a, i1, i2, j, hw * tw / a, 5 / 6 * (wb * tb + wt * tt) / a, 0.0
    if kind == "CHAN":
        b, h, tw, tf = d                          # width (z), height (y), web, flange thickness
        if h - 2 * tf <= 0:
            raise ValueError(3, "flange thickness DIM4 fills the height DIM2 (2 DIM4 >= DIM2)")
        if tw >= b:
            raise ValueError(2, "web thickness DIM3 fills the width DIM1")
        hw, bf = h - 2 * tf, b - tw
        a = hw * tw + 2 * b * tf
        i1 = (b * h**3 - bf * hw**3) / 12
        parts = [(h, tw, tw / 2), (2 * tf, bf, tw + bf / 2)]    # (y size, z size, z_c)
        zc = sum(hh * w * z for hh, w, z in parts) / a
        i2 = sum(hh * w**3 / 12 + hh * w * (z - zc) ** 2 for hh, w, z in parts)
        j = (2 * b * tf**3 + hw * tw**3) / 3
        return a, i1, i2, j, hw / h, bf / b, 0.0
    if kind == "T":
        b, h, tf, tw = d                          # flange width (z), height (y), thicknesses
        hw = h - tf
        if hw <= 0:
            raise ValueError(2, "flange thickness DIM3 fills the height DIM2")
        if tw > b:
            raise ValueError(3, "web thickness DIM4 exceeds the flange width DIM1")
        a = b * tf + hw * tw
        yc = (b * tf * (hw + tf / 2) + hw * tw * hw / 2) / a
        i1 = b * tf**3 / 12 + b * tf * (hw + tf / 2 - yc) ** 2 + tw * hw**3 / 12 + hw * tw * (yc - hw / 2) ** 2
        i2 = (tf * b**3 + hw * tw**3) / 12
        j = (b * tf**3 + hw * tw**3) / 3
        m = b * tf / ((hw + tf / 2) * tw)
        n = b / (hw + tf / 2)
        k1 = 10 * (1 + 4 * m) ** 2 / (12 + 96 * m + 276 * m * m + 192 * m**3 + 30 * n * n * m * (1 + m))
        return a, i1, i2, j, k1, 5 / 6 * b * tf / a, 0.0
    if kind == "L":
        b, h, t1, t2 = d                          # width (z), height (y), their legs' thicknesses
        if not t1 < h:
            raise ValueError(2, "horizontal leg thickness DIM3 fills the height DIM2 (DIM3 >= DIM2)")
        if not t2 < b:
            raise ValueError(3, "vertical leg thickness DIM4 fills the width DIM1 (DIM4 >= DIM1)")
        # (z0, z1, y0, y1) of the two rectangles, from the corner of the legs' mid-lines
        parts = [(-t2 / 2, b - t2 / 2, -t1 / 2, t1 / 2), (-t2 / 2, t2 / 2, t1 / 2, h - t1 / 2)]
        areas = [(z1 - z0) * (y1 - y0) for z0, z1, y0, y1 in parts]
        a = sum(areas)
        zc = sum(ar * (z0 + z1) / 2 for ar, (z0, z1, _, _) in zip(areas, parts)) / a
        yc = sum(ar * (y0 + y1) / 2 for ar, (_, _, y0, y1) in zip(areas, parts)) / a
        i1 = i2 = i12 = 0.0
        for ar, (z0, z1, y0, y1) in zip(areas, parts):
            dz, dy = (z0 + z1) / 2 - zc, (y0 + y1) / 2 - yc
            i1 += ar * ((y1 - y0) ** 2 / 12 + dy * dy)
            i2 += ar * ((z1 - z0) ** 2 / 12 + dz * dz)
            i12 += ar * dz * dy                   # a rectangle's own product about its centre is 0
        j = ((b - t2 / 2) * t1**3 + (h - t1 / 2) * t2**3) / 3
        return a, i1, i2, j, None, None, i12
    raise KeyError(kind)


def _pbarl(r: _Reader, c: _Card) -> None:
    """PBARL: PID MID GROUP TYPE / DIM1 ... DIMn NSM (MSC QRG). The section's A, I1, I2, J, K1,
    K2 (:func:`pbarl_section`) make an equivalent PBAR; NSM has no effect on the stiffness."""
    pid, mid, kind, dims = _library_section(c, max_fields=True)
    _library_pbar(r, c, pid, mid, kind, dims)


def _library_section(c: _Card, *, max_fields: bool) -> tuple[int, int, str, tuple[float, ...]]:
    """The common head of PBARL and PBEAML: PID MID GROUP TYPE, fields 6-9 blank, then the
    section's DIM1..DIMn (> 0) and NSM; ``max_fields``: nothing may follow NSM (PBARL)."""
    pid, mid = _int(c, 2), _int(c, 3)
    group = c.text(4)
    if group not in ("", "MSCBML0"):
        raise c.error(4, f"GROUP {group} not supported: only the standard library MSCBML0 (blank)")
    kind = c.text(5)
    if kind not in _PBARL_DIMS:
        raise c.error(5, f"section TYPE {kind or '(blank)'} not supported; supported: "
                         f"{', '.join(_PBARL_DIMS)}")
    for i in (6, 7, 8, 9):
        _blank(c, i, f"field {i}")
    n = _PBARL_DIMS[kind]
    if max_fields:
        _max_fields(c, 10 + n)
    dims = tuple(_real(c, 10 + k) for k in range(n))
    for k, v in enumerate(dims):
        if v <= 0.0:
            raise c.error(10 + k, f"dimension DIM{k + 1} must be > 0")
    _real(c, 10 + n, 0.0)                   # NSM (of end A for PBEAML)
    return pid, mid, kind, dims


def _library_pbar(r: _Reader, c: _Card, pid: int, mid: int, kind: str, dims: tuple[float, ...]) -> None:
    """The equivalent PBAR of a library section (:func:`pbarl_section`), under the card's name."""
    try:
        a, i1, i2, j, k1, k2, i12 = pbarl_section(kind, dims)
    except ValueError as exc:
        raise c.error(10 + exc.args[0], f"{kind} section: {exc.args[1]}") from None
    r.claim("property", pid, c, 2)
    r.deck.pbars[pid] = PBar(pid, mid, a, i1, i2, j, c.src, k1, k2, i12, card=c.name)


def _mat1(r: _Reader, c: _Card) -> None:
    """MAT1: MID E G NU (RHO A TREF GE ST SC SS MCSID read, no effect on a static stiffness).

    Completion, as in the MSC Nastran Quick Reference Guide, MAT1 remark 3 (E = 2 (1 + NU) G):

    ======  ======  ======  =========================================
    E       G       NU      result
    ======  ======  ======  =========================================
    given   given   given   used as given (also when inconsistent)
    given   given   blank   NU = E / (2 G) - 1
    given   blank   given   G = E / (2 (1 + NU))
    blank   given   given   E = 2 (1 + NU) G
    given   blank   blank   G = 0, NU = 0
    blank   given   blank   E = 0, NU = 0
    blank   blank   any     error: E or G must be given
    ======  ======  ======  =========================================

    Ranges (QRG): E >= 0, G >= 0, -1 < NU <= 0.5 for a given NU; E = G = 0 is an error.
    """
    _max_fields(c, 13)
    mid = _int(c, 2)
    e, g, nu = (_real(c, i, None) for i in (3, 4, 5))
    _ignored_reals(c, range(6, 13))  # RHO A TREF GE ST SC SS
    _int(c, 13, 0, minimum=0)        # MCSID
    for i, value, name in ((3, e, "E"), (4, g, "G")):
        if value is not None and value < 0.0:
            raise c.error(i, f"{name} must be >= 0")
    if nu is not None and not -1.0 < nu <= 0.5:
        raise c.error(5, "Poisson's ratio NU must satisfy -1 < NU <= 0.5")
    if e is None and g is None:
        raise c.error(3, "MAT1 needs E or G (blank E and G: no stiffness)")
    if e is not None and g is not None:
        if nu is None:
            if g == 0.0:
                raise c.error(4, "G = 0 with E given and NU blank: NU = E / (2 G) - 1 is undefined")
            nu = e / (2.0 * g) - 1.0
    elif g is None:
        g = e / (2.0 * (1.0 + nu)) if nu is not None else 0.0
        nu = 0.0 if nu is None else nu
    else:
        e = 2.0 * g * (1.0 + nu) if nu is not None else 0.0
        nu = 0.0 if nu is None else nu
    if e == 0.0 and g == 0.0:
        raise c.error(3, "E and G are both zero: the material has no stiffness")
    r.claim("MAT1", mid, c, 2)
    r.deck.mat1s[mid] = Mat1(mid, e, g, nu, c.src)


def _id_list(c: _Card, first: int, last: int) -> list[int | tuple[int, int]]:
    """Integers from field ``first`` on, blanks skipped, ``A THRU B`` kept as ``(A, B)``."""
    items: list[int | tuple[int, int]] = []
    i = first
    while i <= last:
        text = c.text(i)
        if text == "THRU":
            if not items or isinstance(items[-1], tuple):
                raise c.error(i, "THRU must follow a grid ID")
            j = next((k for k in range(i + 1, last + 1) if c.text(k)), None)
            if j is None:
                raise c.error(i, "THRU must be followed by a grid ID")
            hi = _int(c, j)
            if hi < items[-1]:
                raise c.error(j, f"THRU range end {hi} is below its start {items[-1]}")
            items[-1] = (items[-1], hi)
            i = j + 1
            continue
        if text:
            items.append(_int(c, i))
        i += 1
    return items


def _spc1(r: _Reader, c: _Card) -> None:
    sid = _int(c, 2)
    comps = _components(c, 3, required=True)
    items = _id_list(c, 4, len(c.fields))
    if not items:
        raise c.error(4, "SPC1 needs at least one grid")
    r.spc1_pending.append((sid, comps, items, c.src))


def _spc(r: _Reader, c: _Card) -> None:
    """SPC: SID G1 C1 D1 G2 C2 D2. Only a zero enforced value (D blank or 0.0) is supported: it
    is the SPC1 constraint of the same set; a non-zero D is an enforced displacement (error)."""
    _max_fields(c, 8)
    sid = _int(c, 2)
    for base in (3, 6):
        if base == 6 and not any(c.text(i) for i in (6, 7, 8)):
            break
        g = _int(c, base)
        comps = _components(c, base + 1, required=True)
        if _real(c, base + 2, 0.0) != 0.0:
            raise c.error(base + 2, "enforced displacement not supported: D must be 0.0 or blank")
        r.spc1_pending.append((sid, comps, [g], c.src))


def _spcadd(r: _Reader, c: _Card) -> None:
    """SPCADD: SID S1 S2 ... (the SPC/SPC1 sets it combines). All sets of a deck apply anyway
    (the case control, which could select one, is not read): SPCADD is checked, not needed."""
    sid = _int(c, 2)
    sets = [_int(c, i) for i in range(3, len(c.fields) + 1) if c.text(i)]
    if not sets:
        raise c.error(3, "SPCADD needs at least one set ID")
    r.claim("SPCADD", sid, c, 2)
    r.deck.spcadds[sid] = SpcAdd(sid, tuple(sets), c.src)


def _crod(r: _Reader, c: _Card) -> None:
    """CROD: EID PID (default EID) G1 G2."""
    _max_fields(c, 5)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5)
    r.claim("element", eid, c, 2)
    r.deck.rods[eid] = Rod(eid, ga, gb, pid=pid, card="CROD", src=c.src)


def _prod(r: _Reader, c: _Card) -> None:
    """PROD: PID MID A J C NSM (C: stress recovery, NSM: mass; no effect on the stiffness)."""
    _max_fields(c, 7)
    pid, mid = _int(c, 2), _int(c, 3)
    a, j = _real(c, 4), _real(c, 5, 0.0)
    _ignored_reals(c, (6, 7))
    r.claim("property", pid, c, 2)
    r.deck.prods[pid] = Prod(pid, mid, a, j, c.src)


def _conrod(r: _Reader, c: _Card) -> None:
    """CONROD: EID G1 G2 MID A J C NSM (C, NSM: no effect on the stiffness)."""
    _max_fields(c, 9)
    eid, ga, gb, mid = _int(c, 2), _int(c, 3), _int(c, 4), _int(c, 5)
    a, j = _real(c, 6, 0.0), _real(c, 7, 0.0)
    _ignored_reals(c, (8, 9))
    r.claim("element", eid, c, 2)
    r.deck.rods[eid] = Rod(eid, ga, gb, mid=mid, a=a, j=j, card="CONROD", src=c.src)


def _rbe2(r: _Reader, c: _Card) -> None:
    eid, gn = _int(c, 2), _int(c, 3)
    cm = _components(c, 4, required=True)
    last = len(c.fields)
    # optional ALPHA [TREF] after the grid list (thermal expansion: read, then ignored). Both are
    # reals, so they are told from grid IDs by their decimal point or exponent.
    nonblank = [i for i in range(5, last + 1) if c.text(i)]
    tail = [i for i in nonblank
            if not _INT.fullmatch(c.text(i)) and _real_or_none(c.text(i)) is not None]
    if tail:
        after = [i for i in nonblank if i > tail[0]]
        if len(after) > 1 or any(_INT.fullmatch(c.text(i)) for i in after):
            raise c.error(tail[0], "integer field given a real (only ALPHA and TREF, both reals, "
                                   "may follow the grid list)")
        for i in [tail[0]] + after:
            _real(c, i)
        last = tail[0] - 1
    gm: list[int] = []
    for item in _id_list(c, 5, last):
        if isinstance(item, tuple):
            if item[1] - item[0] > 1_000_000:
                raise c.error(5, f"THRU range {item[0]}-{item[1]} is too long")
            gm.extend(range(item[0], item[1] + 1))
        else:
            gm.append(item)
    if not gm:
        raise c.error(5, "RBE2 needs at least one dependent grid GM")
    r.claim("element", eid, c, 2)
    r.deck.rbe2s[eid] = Rbe2(eid, gn, cm, tuple(gm), c.src)


def _rbe3(r: _Reader, c: _Card) -> None:
    """RBE3: EID (blank) REFGRID REFC WT1 C1 G1,1 G1,2 ... WT2 C2 G2,1 ... [ALPHA a [TREF t]].

    Each weight group is a real WT, component digits C and one or more grids (blank fields
    between them are skipped). UM (dependent components moved to independent grids) is not
    supported (error); ALPHA and TREF are read and have no effect."""
    eid = _int(c, 2)
    _blank(c, 3, "field 3")
    ref = _int(c, 4)
    refc = _components(c, 5, required=True)
    last = len(c.fields)
    groups: list[tuple[float, str, tuple[int, ...]]] = []
    i = 6
    while i <= last:
        text = c.text(i)
        if not text:
            i += 1
            continue
        if text == "UM":
            raise c.error(i, "UM (dependent components on the independent grids) not supported")
        if text in ("ALPHA", "TREF"):
            j = next((k for k in range(i + 1, last + 1) if c.text(k)), None)
            if j is None:
                raise c.error(i, f"{text} must be followed by a real value")
            _real(c, j)
            i = j + 1
            continue
        if _INT.fullmatch(text):
            raise c.error(i, "weight WT must be a real (e.g. 1.0); an integer here would be a "
                             "grid without its weight and components")
        w = _real(c, i)
        if not w > 0.0:
            raise c.error(i, "weight WT must be > 0")
        comps = _components(c, i + 1, required=True)
        grids: list[int] = []
        j = i + 2
        while j <= last and (not c.text(j) or _INT.fullmatch(c.text(j))):
            if c.text(j):
                grids.append(_int(c, j))
            j += 1
        if not grids:
            raise c.error(i + 2, "weight group needs at least one grid")
        groups.append((w, comps, tuple(grids)))
        i = j
    if not groups:
        raise c.error(6, "RBE3 needs at least one weight group WT C G...")
    r.claim("element", eid, c, 2)
    r.deck.rbe3s[eid] = Rbe3(eid, ref, refc, tuple(groups), c.src)


def _cbush(r: _Reader, c: _Card) -> None:
    """CBUSH: EID PID GA GB GO/X1 X2 X3 CID / S OCID S1 S2 S3 (MSC QRG). The element axes are
    CID's (CID >= 0) or, with CID blank, x from GA to GB and the orientation vector (GO, or X
    in GA's CD system) in the x-y plane. S (default 0.5) places the springs on the line GA-GB.
    OCID and S1-S3 (a spring location off that line) are not supported: errors."""
    _max_fields(c, 14)
    eid = _int(c, 2)
    pid = _int(c, 3, eid)
    ga, gb = _int(c, 4), _int(c, 5, 0, minimum=0)
    x, g0 = _orientation(c)
    cid = _int(c, 9, None, minimum=0) if c.text(9) else None
    s = _real(c, 10, 0.5)
    if not 0.0 <= s <= 1.0:
        raise c.error(10, "spring location S must be in [0, 1]")
    if _int(c, 11, -1, minimum=-1) != -1:
        raise c.error(11, "OCID (spring location off the line GA-GB) not supported: blank or -1")
    for i in (12, 13, 14):
        if _real(c, i, 0.0) != 0.0:
            raise c.error(i, "offset S1-S3 of the spring location not supported: blank or 0.0")
    if cid is None and x is None and g0 is None and gb == 0:
        raise c.error(9, "a grounded CBUSH needs CID (or an orientation) for its element axes")
    if cid is not None and cid not in r.cords and cid != 0:
        r.pending_cids.append((c, cid))
    r.claim("element", eid, c, 2)
    r.deck.bushes[eid] = Bush(eid, pid, ga, gb, x, g0, cid, s, c.src)


def _pbush(r: _Reader, c: _Card) -> None:
    """PBUSH: PID "K" K1..K6 / blank "B" B1..B6 / blank "GE" GE1..GE6 / blank "RCV" SA ST EA ET
    (one line each, any order, the keywords in field 3 of each line). The K line is the stiffness (blank: 0); damping B, GE and the stress recovery
    coefficients RCV are read and have no effect on a static solve. Other keywords (M, the
    frequency-dependent FREQ lines) are errors."""
    pid = _int(c, 2)
    k = (0.0,) * 6
    seen = set()
    # keyword fields: 3 on the first line, then the second field of each continuation line
    # (the first one blank), so that the keywords line up in field 3 of every line
    for i in range(3, len(c.fields) + 1, 8):
        key = c.text(i)
        if i > 3 and c.text(i - 1):
            raise c.error(i - 1, "field must be blank (a PBUSH continuation line starts with a "
                                 "blank field, then the keyword K, B, GE or RCV)")
        if not any(c.text(j) for j in range(i, i + 7)):
            continue
        if key not in ("K", "B", "GE", "RCV") or key in seen:
            raise c.error(i, f"PBUSH line keyword {key or '(blank)'} not supported: one each of "
                             f"K, B, GE, RCV")
        seen.add(key)
        values = tuple(_real(c, j, 0.0) for j in range(i + 1, i + 7))
        if key == "K":
            k = values
    if "K" not in seen:
        raise c.error(3, "PBUSH needs a K line (stiffnesses K1..K6)")
    r.claim("property", pid, c, 2)
    r.deck.pbushes[pid] = PBush(pid, k, c.src)


def _pelas(r: _Reader, c: _Card) -> None:
    _max_fields(c, 9)
    for base in (2, 6):
        if base == 6 and not any(c.text(i) for i in range(6, 10)):
            break
        pid, k = _int(c, base), _real(c, base + 1)
        _ignored_reals(c, (base + 2, base + 3))  # GE, S
        r.claim("property", pid, c, base)
        r.deck.pelas[pid] = Pelas(pid, k, c.src)


def _spring_end(c: _Card, ig: int) -> tuple[int, int]:
    g = _int(c, ig, 0, minimum=0)
    text = c.text(ig + 1)
    if g == 0:
        if text not in ("", "0"):
            raise c.error(ig + 1, "component given for a grounded end (G blank or 0)")
        return 0, 0
    if not re.fullmatch(r"[1-6]", text):
        raise c.error(ig + 1, "component must be one digit 1-6 (scalar points are not supported)")
    return g, int(text)


def _celas(r: _Reader, c: _Card) -> None:
    _max_fields(c, 7 if c.name == "CELAS1" else 9)
    eid = _int(c, 2)
    if c.name == "CELAS1":
        pid, k = _int(c, 3, eid), None
    else:
        pid, k = None, _real(c, 3)
        _ignored_reals(c, (8, 9))  # GE, S
    (g1, c1), (g2, c2) = _spring_end(c, 4), _spring_end(c, 6)
    if g1 == 0:
        if g2 == 0:
            raise c.error(4, "both ends of the spring are grounded")
        (g1, c1), (g2, c2) = (g2, c2), (g1, c1)
    r.claim("element", eid, c, 2)
    r.deck.springs[eid] = Spring(eid, g1, c1, g2, c2, k, pid, c.name, c.src)


def _param(r: _Reader, c: _Card) -> None:
    """PARAM,AUTOSPC (YES/NO; the last one of the deck wins; without one AUTOSPC is on, NASTRAN's
    SOL 101 default) and PARAM,EPZERO (its singularity ratio) are read; every other PARAM has no
    effect on the reference solver."""
    name = c.text(2)
    if name == "AUTOSPC":
        value = c.text(3)
        if value not in ("YES", "Y", "NO", "N"):
            raise c.error(3, "PARAM,AUTOSPC must be YES or NO")
        r.deck.autospc = value.startswith("Y")
        r.deck.autospc_src = c.src
    elif name == "EPZERO":
        value = _real(c, 3)
        if not 0.0 < value < 1.0:
            raise c.error(3, "PARAM,EPZERO must be in (0, 1)")
        r.deck.epzero = value


def _cord2(r: _Reader, c: _Card) -> None:
    """CORD2R/C/S: CID RID A1 A2 A3 B1 B2 B3 / C1 C2 C3 (MSC QRG): A the origin, B on the z axis,
    C in the x-z plane, all three in system RID (0 or blank: basic)."""
    _max_fields(c, 12)
    cid = _int(c, 2)
    rid = _int(c, 3, 0, minimum=0)
    if rid == cid:
        raise c.error(3, f"RID {rid} is the system itself")
    pts = tuple(tuple(_real(c, i + k, 0.0) for k in range(3)) for i in (4, 7, 10))
    r.claim("CORD", cid, c, 2)
    r.cords[cid] = (c.name[-1], c, (rid, pts))


def _cord1(r: _Reader, c: _Card) -> None:
    """CORD1R/C/S: CIDA G1A G2A G3A [CIDB G1B G2B G3B]: the system through three grids (G1 the
    origin, G2 on the z axis, G3 in the x-z plane), one or two systems per card."""
    _max_fields(c, 9)
    for base in (2, 6):
        if base == 6 and not any(c.text(i) for i in range(6, 10)):
            break
        cid = _int(c, base)
        grids = tuple(_int(c, base + k) for k in (1, 2, 3))
        if len(set(grids)) < 3:
            raise c.error(base + 1, "G1, G2 and G3 must be three different grids")
        r.claim("CORD", cid, c, base)
        r.cords[cid] = (c.name[-1], c, (base, grids))


def _coord_from_points(cid: int, kind: str, pts: np.ndarray, c: _Card, d: tuple) -> Coord:
    """The system with origin ``pts[0]``, z axis towards ``pts[1]``, x-z plane through ``pts[2]``
    (basic positions): z = (B - A)/|B - A|, y = z x (C - A) normalized, x = y x z (MSC QRG, CORD2R)."""
    a, b, cc = pts
    scale = max(np.abs(pts).max(), 1e-300)
    ez = b - a
    first = 4 if c.name.startswith("CORD2") else d[0] + 1    # field of A (CORD2) or G1 (CORD1)
    step = 3 if c.name.startswith("CORD2") else 1
    if np.linalg.norm(ez) <= _ZERO_LENGTH * scale:
        raise c.error(first + step, f"coordinate system {cid}: the z-axis point coincides with "
                                    f"the origin")
    ez = ez / np.linalg.norm(ez)
    ey = np.cross(ez, cc - a)
    if np.linalg.norm(ey) <= _PARALLEL_SINE * max(np.linalg.norm(cc - a), 1e-300):
        raise c.error(first + 2 * step, f"coordinate system {cid}: the x-z plane point lies on "
                                        f"the z axis")
    ey = ey / np.linalg.norm(ey)
    ex = np.cross(ey, ez)
    return Coord(cid, kind, tuple(a.tolist()), (tuple(ex.tolist()), tuple(ey.tolist()),
                                               tuple(ez.tolist())), c.name, c.src)


_PARSERS = {"GRID": _grid, "GRDSET": _grdset, "CBAR": _cbar, "BAROR": _baror, "PBAR": _pbar, "CROD": _crod,
            "PROD": _prod, "CONROD": _conrod, "MAT1": _mat1, "SPC1": _spc1, "SPC": _spc,
            "SPCADD": _spcadd, "RBE2": _rbe2, "RBE3": _rbe3, "CBUSH": _cbush, "PBUSH": _pbush, "PELAS": _pelas, "CELAS1": _celas, "CELAS2": _celas, "PBARL": _pbarl,
            "CBEAM": _cbeam, "PBEAM": _pbeam, "PBEAML": _pbeaml,
            **{f"CORD2{k}": _cord2 for k in "RCS"}, **{f"CORD1{k}": _cord1 for k in "RCS"}}
SUPPORTED = tuple(sorted(_PARSERS))
"""Cards read into the :class:`Deck` and modelled by the reference solver."""

NO_EFFECT = frozenset({
    "PARAM",                                                  # solver parameters
    "CONM1", "CONM2", "CMASS1", "CMASS2", "CMASS3", "CMASS4", "PMASS",   # mass
    "EIGR", "EIGRL", "EIGB", "EIGC",                          # eigenvalue extraction
    "FREQ", "FREQ1", "FREQ2", "TSTEP", "NLPARM",              # dynamic / nonlinear controls
})
"""Cards with no effect on a linear static solve: accepted, counted in ``Deck.no_effect``."""

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


def _typed(text: str) -> int | float | str | None:
    """A field's value as NASTRAN reads it: blank -> None, an integer, a real (any spelling,
    ``1.-3`` too), else the word (upper case)."""
    t = text.strip().upper()
    if not t:
        return None
    if _INT.fullmatch(t):
        return int(t)
    value = _real_or_none(t)
    return value if value is not None and np.isfinite(value) else t


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


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
UNMODELLED = ("error", "keep")
"""What the reader does with a card it does not model: ``"error"`` (the default: one message
naming every such card, as the reference solver needs) or ``"keep"`` (into ``Deck.unmodelled``,
for an external solver that models them; :data:`NOT_PASSABLE` cards stay errors)."""


def read_deck(path: str | Path, unmodelled: str = "error") -> Deck:
    """Read and :func:`validate` the bulk data of ``path`` (INCLUDEs relative to its folder).
    ``unmodelled``: see :data:`UNMODELLED`."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise DeckFormatError(f"cannot read the deck: {exc.strerror or exc}", file=str(p)) from None
    return read_deck_text(text, name=str(p), base_dir=p.parent, unmodelled=unmodelled)


def read_deck_text(text: str, name: str = "<string>", base_dir: Path | None = None,
                   unmodelled: str = "error") -> Deck:
    """Read and :func:`validate` bulk data given as text; ``name`` is the file named in errors.

    INCLUDEs are resolved relative to ``base_dir`` (default: the current directory).
    ``unmodelled``: see :data:`UNMODELLED`.
    """
    if unmodelled not in UNMODELLED:
        raise ValueError(f"unmodelled must be one of {UNMODELLED}, got {unmodelled!r}")
    reader = _Reader(keep_unmodelled=unmodelled == "keep")
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    reader.deck.files.append(name)
    reader.stack.append((base / Path(name).name).resolve())
    for card in reader.cards(reader.lines(text, name, base)):
        reader.add(card)
    reader.check_unsupported()
    deck = reader.finish()
    validate(deck)
    if deck.no_effect:
        logging.getLogger(__name__).info("%s: %s", name, deck.summary())
    return deck


def bulk_cards(path: str | Path, text: str | None = None):
    """``(cards, files)``: every bulk-data card of the input file ``path`` as read, not interpreted
    (INCLUDEs resolved, executive and case control skipped), and the files read. For readers of
    cards this module does not model, such as the load cards of :mod:`solver_adapters.loadcards`
    read by ``blackbox import``. Each card has ``name``, ``file``, ``line``, ``src``, ``fields``
    (with their physical lines) and ``error(i, msg)``. ``text``: the file's text, if already read."""
    p = Path(path)
    if text is None:
        try:
            text = p.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise DeckFormatError(f"cannot read the deck: {exc.strerror or exc}", file=str(p)) from None
    reader = _Reader()
    reader.deck.files.append(str(p))
    reader.stack.append(p.resolve())
    return list(reader.cards(reader.lines(text, str(p), p.parent))), reader.deck.files


def deck_from_cards(cards, unmodelled: str = "error") -> Deck:
    """The validated :class:`Deck` of cards from :func:`bulk_cards` (a chosen subset of them);
    errors name the cards' own files and lines. ``unmodelled``: see :data:`UNMODELLED`."""
    if unmodelled not in UNMODELLED:
        raise ValueError(f"unmodelled must be one of {UNMODELLED}, got {unmodelled!r}")
    reader = _Reader(keep_unmodelled=unmodelled == "keep")
    for card in cards:
        reader.add(card)
    reader.check_unsupported()
    deck = reader.finish()
    validate(deck)
    return deck


# Two directions closer than this (sine of the angle) give no usable element plane: the bar's
# y axis would be decided by the rounding of the input coordinates (about 1e-16 relative).
_PARALLEL_SINE = 1e-9
# A bar shorter than this fraction of its coordinates' magnitude has no direction above rounding.
_ZERO_LENGTH = 1e-12


def validate(deck: Deck) -> None:
    """Cross-reference checks; raise one :class:`ModelError` listing every problem found.

    CBAR -> PBAR -> MAT1, CBAR end grids and G0, GA != GB, non-zero length, orientation not
    parallel to the axis; PBAR K1/K2 need G > 0; CROD -> PROD -> MAT1, CONROD -> MAT1, rod grids
    and length; RBE2, SPC/SPC1 and spring grids; CELAS1 -> PELAS; SPCADD -> SPC/SPC1 sets.
    """
    problems: list[str] = []

    def bad(entity, card: str, ident: int, message: str) -> None:
        problems.append(f"{entity.src}: {card} {ident}: {message}")

    def need_grids(entity, card: str, ident: int, grids, what: str) -> None:
        missing = [g for g in grids if g not in deck.grids]
        if missing:
            bad(entity, card, ident, f"{what} {', '.join(map(str, missing[:10]))} "
                                     f"{'does' if len(missing) == 1 else 'do'} not exist (no GRID)")

    for g in deck.grids.values():
        for key, value in (("CP", g.cp), ("CD", g.cd)):
            if value and value not in deck.coords:
                bad(g, "GRID", g.id, f"{key} {value}: coordinate system not defined")
    for p in deck.pbars.values():
        if p.mid not in deck.mat1s:
            bad(p, "PBAR", p.pid, f"material MID {p.mid} not found (no MAT1)")
        elif (p.k1 or p.k2) and deck.mat1s[p.mid].g == 0.0:
            bad(p, "PBAR", p.pid, f"K1/K2 shear factors need a shear modulus, but MAT1 {p.mid} "
                                  f"has G = 0")
    for p in deck.prods.values():
        if p.mid not in deck.mat1s:
            bad(p, "PROD", p.pid, f"material MID {p.mid} not found (no MAT1)")
    for r in deck.rods.values():
        if r.pid is not None and r.pid not in deck.prods:
            other = (" (it is a PBAR)" if r.pid in deck.pbars
                     else " (it is a PELAS)" if r.pid in deck.pelas else "")
            bad(r, r.card, r.eid, f"property PID {r.pid} not found (no PROD){other}")
        if r.mid is not None and r.mid not in deck.mat1s:
            bad(r, r.card, r.eid, f"material MID {r.mid} not found (no MAT1)")
        need_grids(r, r.card, r.eid, [r.ga, r.gb], "grid")
        if r.ga == r.gb:
            bad(r, r.card, r.eid, f"G1 and G2 are the same grid {r.ga}")
        elif r.ga in deck.grids and r.gb in deck.grids:
            xa, xb = np.array(deck.grids[r.ga].xyz), np.array(deck.grids[r.gb].xyz)
            if np.linalg.norm(xb - xa) <= _ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max()):
                bad(r, r.card, r.eid, f"zero length: grids {r.ga} and {r.gb} coincide")
    for b in deck.cbars.values():
        wanted = ("PBEAM", "PBEAML") if b.card == "CBEAM" else ("PBAR", "PBARL")
        if b.pid not in deck.pbars:
            other = (" (it is a PELAS)" if b.pid in deck.pelas
                     else " (it is a PROD)" if b.pid in deck.prods else "")
            bad(b, b.card, b.eid, f"property PID {b.pid} not found (no {' or '.join(wanted)}){other}")
        elif deck.pbars[b.pid].card not in wanted:
            bad(b, b.card, b.eid, f"property PID {b.pid} is a {deck.pbars[b.pid].card}; a "
                                  f"{b.card} needs a {' or '.join(wanted)}")
        need_grids(b, b.card, b.eid, [b.ga, b.gb] + ([b.g0] if b.g0 is not None else []), "grid")
        if b.ga == b.gb:
            bad(b, b.card, b.eid, f"GA and GB are the same grid {b.ga}")
            continue
        if b.ga not in deck.grids or b.gb not in deck.grids:
            continue
        xa, xb = np.array(deck.grids[b.ga].xyz), np.array(deck.grids[b.gb].xyz)
        axis = xb - xa                    # v is measured from grid GA, the axis between bar ends
        if b.wa is not None or b.wb is not None:
            axis = axis + np.array(b.wb or (0.0, 0.0, 0.0)) - np.array(b.wa or (0.0, 0.0, 0.0))
        if np.linalg.norm(axis) <= _ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max()):
            what = "the bar ends (offsets included)" if b.wa or b.wb else f"grids {b.ga} and {b.gb}"
            bad(b, b.card, b.eid, f"zero length: {what} coincide")
            continue
        if b.g0 is not None:
            if b.g0 in (b.ga, b.gb):
                bad(b, b.card, b.eid, f"G0 {b.g0} is one of the bar's own grids")
                continue
            if b.g0 not in deck.grids:
                continue
            v = np.array(deck.grids[b.g0].xyz) - xa
        else:
            v = np.array(b.x)
        nv, na = np.linalg.norm(v), np.linalg.norm(axis)
        if nv == 0.0:
            bad(b, b.card, b.eid, "orientation vector is zero")
        elif np.linalg.norm(np.cross(v, axis)) <= _PARALLEL_SINE * nv * na:
            bad(b, b.card, b.eid, "orientation vector is parallel to the bar axis")
    for e in deck.rbe2s.values():
        need_grids(e, "RBE2", e.eid, [e.gn], "independent grid GN")
        need_grids(e, "RBE2", e.eid, e.gm, "dependent grid(s)")
        if e.gn in e.gm:
            bad(e, "RBE2", e.eid, f"GN {e.gn} is also a dependent grid")
    for e in deck.rbe3s.values():
        need_grids(e, "RBE3", e.eid, [e.refgrid], "reference grid REFGRID")
        indep = [g for _, _, gs in e.groups for g in gs]
        need_grids(e, "RBE3", e.eid, indep, "independent grid(s)")
        if e.refgrid in indep:
            bad(e, "RBE3", e.eid, f"REFGRID {e.refgrid} is also an independent grid")
    for b in deck.bushes.values():
        if b.pid not in deck.pbushes:
            bad(b, "CBUSH", b.eid, f"property PID {b.pid} not found (no PBUSH)")
        need_grids(b, "CBUSH", b.eid, [g for g in (b.ga, b.gb, b.g0) if g], "grid(s)")
        if b.ga == b.gb:
            bad(b, "CBUSH", b.eid, f"GA and GB are the same grid {b.ga}")
        elif b.cid is None and b.gb in deck.grids and b.ga in deck.grids:
            xa, xb = np.array(deck.grids[b.ga].xyz), np.array(deck.grids[b.gb].xyz)
            if np.linalg.norm(xb - xa) <= _ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max(), 1e-300):
                bad(b, "CBUSH", b.eid, "GA and GB coincide: the element axes need CID")
        if b.cid is not None and b.cid != 0 and b.cid not in deck.coords:
            bad(b, "CBUSH", b.eid, f"CID {b.cid}: coordinate system not defined")
    for s in deck.spc1s:
        need_grids(s, "SPC1", s.sid, s.grids, "grid(s)")
    spc_sets = {s.sid for s in deck.spc1s}
    for a in deck.spcadds.values():
        if a.sid in spc_sets:
            bad(a, "SPCADD", a.sid, f"SID {a.sid} is also the ID of an SPC/SPC1 set")
        missing = [k for k in a.sets if k not in spc_sets]
        if missing:
            bad(a, "SPCADD", a.sid, f"set(s) {', '.join(map(str, missing[:10]))} not found "
                                    f"(no SPC or SPC1 with that SID)")
    for u in deck.unmodelled:
        if u.grids:
            need_grids(u, u.name, u.fields[0], u.grids, "grid(s)")
    for s in deck.springs.values():
        need_grids(s, s.card, s.eid, [g for g in (s.g1, s.g2) if g != 0], "grid(s)")
        if s.card == "CELAS1" and s.pid not in deck.pelas:
            other = " (it is a PBAR)" if s.pid in deck.pbars else ""
            bad(s, s.card, s.eid, f"property PID {s.pid} not found (no PELAS){other}")
    if problems:
        shown = "\n  ".join(problems[:50])
        more = f"\n  ... and {len(problems) - 50} more" if len(problems) > 50 else ""
        raise ModelError(f"{len(problems)} model error(s):\n  {shown}{more}")
