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

Cards modelled: GRID, GRDSET (defaults for blank CP, CD, PS, SEID of GRID), CBAR (with pin flags
and offsets in the basic system), BAROR (defaults for CBAR), PBAR (with K1/K2 shear factors and I12),
CROD, PROD, CONROD, MAT1 (completed as NASTRAN does), SPC1, SPC (zero enforced value), SPCADD,
RBE2, PELAS, CELAS1, CELAS2. Cards in :data:`NO_EFFECT` (solver parameters, masses,
eigenvalue and dynamic-analysis controls) are accepted with no effect on a linear static solve and
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
from solver_adapters.deck import (CBar, Deck, Grid, Mat1, PBar, Pelas, Prod, Rbe2, Rod, Spc1, SpcAdd,
                                  Spring)
from solver_adapters.protocol import DeckFormatError, ModelError

__all__ = ["read_deck", "read_deck_text", "validate", "parse_int", "parse_real", "NO_EFFECT",
           "SUPPORTED"]

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
    def __init__(self) -> None:
        self.deck = Deck()
        self.stack: list[Path] = []
        self.ended = False
        # ID -> "CARD at file:line"; elements (CBAR, RBE2, CELASi) share one ID space, as do
        # properties (PBAR, PELAS)
        self.ids: dict[str, dict[int, str]] = {"GRID": {}, "element": {}, "property": {}, "MAT1": {},
                                               "SPCADD": {}}
        self.spc1_pending: list[tuple[int, str, list[int | tuple[int, int]], str]] = []
        # card name -> [count, first card] of every card that is neither modelled nor NO_EFFECT
        self.unsupported: dict[str, list] = {}
        # GRDSET defaults, applied in finish() (bulk data is unordered: GRDSET may come last)
        self.grdset: _Card | None = None
        self.first_blank: dict[str, int | None] = {"CP": None, "CD": None, "SEID": None}
        self.blank_ps: list[int] = []
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
        if card.name in NO_EFFECT:
            n, src = self.deck.no_effect.get(card.name, (0, card.src))
            self.deck.no_effect[card.name] = (n + 1, src)
            return
        parser = _PARSERS.get(card.name)
        if parser is None:
            entry = self.unsupported.setdefault(card.name, [0, card])
            entry[0] += 1
            return
        parser(self, card)

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
        items = list(self.unsupported.items())      # in the order of first appearance
        total = sum(n for n, _ in self.unsupported.values())
        lines = []
        for name, (n, c) in items:
            hint = _UNSUPPORTED_HINTS.get(name, "")
            lines.append(f"{name} x{n} (first at {c.src}){': ' + hint if hint else ''}")
        first = items[0][1][1]
        raise first.error(1, f"unknown card(s) or card(s) the reference solver does not model: "
                             f"{total} card(s) of {len(items)} type(s):\n  " + "\n  ".join(lines)
                          + f"\nsupported: {', '.join(SUPPORTED)}; accepted with no effect on a "
                            f"linear static solve: {', '.join(sorted(NO_EFFECT))}")

    def claim(self, kind: str, ident: int, card: _Card, i: int) -> None:
        table = self.ids[kind]
        if ident in table:
            raise card.error(i, f"duplicate {kind} ID {ident} (already defined by {table[ident]})")
        table[ident] = f"{card.name} at {card.src}"

    def finish(self) -> Deck:
        """GRDSET defaults into the GRIDs; SPC1 ``G1 THRU G2`` expanded (as in NASTRAN, grids of
        the range that do not exist are skipped)."""
        if self.grdset is not None:
            c = self.grdset
            for i, key, what in ((3, "CP", "coordinate systems are not supported: CP"),
                                 (7, "CD", "coordinate systems are not supported: CD"),
                                 (9, "SEID", "superelements are not supported: SEID")):
                gid = self.first_blank[key]
                value = _int(c, i, 0, minimum=0)
                if value != 0 and gid is not None:
                    raise c.error(i, f"{what} {value} of GRDSET is the default of every GRID whose "
                                     f"{key} is blank, e.g. GRID {gid} at {self.deck.grids[gid].src}; "
                                     f"GRDSET {key} must be 0 or blank")
            ps = _components(c, 8, required=False)
            if ps:
                for gid in self.blank_ps:
                    g = self.deck.grids[gid]
                    self.deck.grids[gid] = Grid(g.id, g.xyz, ps, g.src)
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
    """GRID; a blank CP, CD, PS or SEID takes the GRDSET value (applied in ``finish``)."""
    _max_fields(c, 9)
    gid = _int(c, 2)
    if _int(c, 3, 0, minimum=0) != 0:
        raise c.error(3, "coordinate systems are not supported: CP must be 0 or blank")
    xyz = (_real(c, 4, 0.0), _real(c, 5, 0.0), _real(c, 6, 0.0))
    if _int(c, 7, 0, minimum=0) != 0:
        raise c.error(7, "coordinate systems are not supported: CD must be 0 or blank")
    ps = _components(c, 8, required=False)
    if _int(c, 9, 0, minimum=0) != 0:
        raise c.error(9, "superelements are not supported: SEID must be blank")
    r.claim("GRID", gid, c, 2)
    r.deck.grids[gid] = Grid(gid, xyz, ps, c.src)
    for i, key in ((3, "CP"), (7, "CD"), (9, "SEID")):
        if not c.text(i) and r.first_blank[key] is None:
            r.first_blank[key] = gid
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
    """OFFT (field 9): with every CD = 0 the global and basic systems coincide, so GGG (the
    default) and BGG are the same; offsets in the element system (an ``O``) are not supported."""
    if c.text(9) not in ("", "GGG", "BGG"):
        raise c.error(9, "offset option OFFT not supported: only GGG (default) or BGG, offsets "
                         "in the basic system")


def _pin(c: _Card, i: int) -> str:
    """Pin flag digits (element components 1-6 released at that end); blank or 0: none."""
    return "" if c.text(i) in ("", "0") else _components(c, i, required=False)


def _cbar(r: _Reader, c: _Card) -> None:
    """CBAR: EID PID GA GB X1/G0 X2 X3 OFFT / PA PB W1A W2A W3A W1B W2B W3B.

    A blank PID, orientation or OFFT takes the BAROR value (applied in ``finish``); a blank PID
    without BAROR PID is the EID. Offsets are in the basic system (every CD is 0)."""
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
    r.deck.cbars[eid] = CBar(eid, pid, ga, gb, x, g0, c.src, pa, pb,
                             wa if any(wa) else None, wb if any(wb) else None)
    if not c.text(3):
        r.pid_blank.append(eid)
    if x is None and g0 is None:
        r.orient_blank.append((eid, c))


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


_PARSERS = {"GRID": _grid, "GRDSET": _grdset, "CBAR": _cbar, "BAROR": _baror, "PBAR": _pbar, "CROD": _crod,
            "PROD": _prod, "CONROD": _conrod, "MAT1": _mat1, "SPC1": _spc1, "SPC": _spc,
            "SPCADD": _spcadd, "RBE2": _rbe2, "PELAS": _pelas, "CELAS1": _celas, "CELAS2": _celas}
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
_CORD = "coordinate systems are not supported"
_UNSUPPORTED_HINTS = {
    **{k: _LOADS for k in ("FORCE", "FORCE1", "FORCE2", "MOMENT", "MOMENT1", "MOMENT2", "LOAD",
                           "GRAV", "PLOAD", "PLOAD1", "PLOAD2", "PLOAD4", "TEMP", "TEMPD", "SPCD")},
    **{k: _CORD for k in ("CORD1R", "CORD2R", "CORD1C", "CORD2C", "CORD1S", "CORD2S")},
}


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
def read_deck(path: str | Path) -> Deck:
    """Read and :func:`validate` the bulk data of ``path`` (INCLUDEs relative to its folder)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise DeckFormatError(f"cannot read the deck: {exc.strerror or exc}", file=str(p)) from None
    return read_deck_text(text, name=str(p), base_dir=p.parent)


def read_deck_text(text: str, name: str = "<string>", base_dir: Path | None = None) -> Deck:
    """Read and :func:`validate` bulk data given as text; ``name`` is the file named in errors.

    INCLUDEs are resolved relative to ``base_dir`` (default: the current directory).
    """
    reader = _Reader()
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
        if b.pid not in deck.pbars:
            other = (" (it is a PELAS)" if b.pid in deck.pelas
                     else " (it is a PROD)" if b.pid in deck.prods else "")
            bad(b, "CBAR", b.eid, f"property PID {b.pid} not found (no PBAR){other}")
        need_grids(b, "CBAR", b.eid, [b.ga, b.gb] + ([b.g0] if b.g0 is not None else []), "grid")
        if b.ga == b.gb:
            bad(b, "CBAR", b.eid, f"GA and GB are the same grid {b.ga}")
            continue
        if b.ga not in deck.grids or b.gb not in deck.grids:
            continue
        xa, xb = np.array(deck.grids[b.ga].xyz), np.array(deck.grids[b.gb].xyz)
        axis = xb - xa                    # v is measured from grid GA, the axis between bar ends
        if b.wa is not None or b.wb is not None:
            axis = axis + np.array(b.wb or (0.0, 0.0, 0.0)) - np.array(b.wa or (0.0, 0.0, 0.0))
        if np.linalg.norm(axis) <= _ZERO_LENGTH * max(np.abs(xa).max(), np.abs(xb).max()):
            what = "the bar ends (offsets included)" if b.wa or b.wb else f"grids {b.ga} and {b.gb}"
            bad(b, "CBAR", b.eid, f"zero length: {what} coincide")
            continue
        if b.g0 is not None:
            if b.g0 in (b.ga, b.gb):
                bad(b, "CBAR", b.eid, f"G0 {b.g0} is one of the bar's own grids")
                continue
            if b.g0 not in deck.grids:
                continue
            v = np.array(deck.grids[b.g0].xyz) - xa
        else:
            v = np.array(b.x)
        nv, na = np.linalg.norm(v), np.linalg.norm(axis)
        if nv == 0.0:
            bad(b, "CBAR", b.eid, "orientation vector is zero")
        elif np.linalg.norm(np.cross(v, axis)) <= _PARALLEL_SINE * nv * na:
            bad(b, "CBAR", b.eid, "orientation vector is parallel to the bar axis")
    for e in deck.rbe2s.values():
        need_grids(e, "RBE2", e.eid, [e.gn], "independent grid GN")
        need_grids(e, "RBE2", e.eid, e.gm, "dependent grid(s)")
        if e.gn in e.gm:
            bad(e, "RBE2", e.eid, f"GN {e.gn} is also a dependent grid")
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
    for s in deck.springs.values():
        need_grids(s, s.card, s.eid, [g for g in (s.g1, s.g2) if g != 0], "grid(s)")
        if s.card == "CELAS1" and s.pid not in deck.pelas:
            other = " (it is a PBAR)" if s.pid in deck.pbars else ""
            bad(s, s.card, s.eid, f"property PID {s.pid} not found (no PELAS){other}")
    if problems:
        shown = "\n  ".join(problems[:50])
        more = f"\n  ... and {len(problems) - 50} more" if len(problems) > 50 else ""
        raise ModelError(f"{len(problems)} model error(s):\n  {shown}{more}")
