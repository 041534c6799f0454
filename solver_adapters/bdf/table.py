"""The card table: a whole deck split into lines, fields and cards in bulk.

Every physical data line becomes a row: field 1 (stripped, upper case), up to eight data fields
(stripped, as written; a large-field line fills four) and field 10, as numpy byte strings.
Fixed-field lines of plain ASCII text are split all at once (one ``S80`` array viewed as ten
8-byte columns); any other line (free field, tabs, other characters, text beyond column 80) is
split by :func:`.tokens._split`, the reference tokenizer. A card is a head line and the
continuation lines after it; :meth:`CardTable.matrix` gives the fields of many cards of one kind
as one array (column ``i - 1`` = NASTRAN field ``i``), which the bulk converters read.

Anything the reference tokenizer would refuse (a continuation without a card, unmatched markers,
bad free-field lines, INCLUDE errors) raises here too; the reader then reads the deck again with
the reference tokenizer, which raises the same error at the same point of the deck
(:func:`.reader.read`): the table only ever speeds up a deck that reads.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from solver_adapters.bdf.numbers import strings
from solver_adapters.bdf.tokens import (BEGIN_BULK, CARD_NAME, Includes, _Card, _split, section_error,
                                        _strip_comment, bulk_start, card_error, card_from_lines,
                                        is_include, not_bulk_data)
from solver_adapters.errors import IrregularTable as Irregular   # the table cannot be built
from solver_adapters.protocol import DeckFormatError



class _Chunk:
    """Consecutive data lines of one file (a card never continues from one chunk to the next)."""
    __slots__ = ("fidx", "lno", "body", "first", "cont", "data", "nd")

    def __init__(self, fidx, lno, body, first, cont, data, nd):
        self.fidx, self.lno, self.body, self.first, self.cont, self.data, self.nd = \
            fidx, lno, body, first, cont, data, nd


_PRINTABLE = bytes(range(32, 127)) + b"\n\r"


def _plain_mask(lines: list[str], text: str) -> np.ndarray:
    """Lines the bulk splitter may take: printable ASCII (no control character: bytes.strip
    and str.strip differ on some, and a numpy byte string ends at NUL), no comma, at most 80
    characters (the reference splitter takes the others)."""
    n = len(lines)
    if "," not in text and text.isascii() and not text.encode("ascii").translate(None, _PRINTABLE):
        return np.fromiter(map(len, lines), np.int64, n) <= 80
    return np.fromiter((len(b) <= 80 and b.isascii() and b.isprintable() and "," not in b
                        for b in lines), bool, n)


def _upper(a: np.ndarray) -> np.ndarray:
    """``a`` in upper case (a copy only if it has lower-case letters)."""
    if a.size and a.dtype.itemsize:
        u8 = a.view(np.uint8)
        if ((u8 >= 97) & (u8 <= 122)).any():
            return strings.upper(a)
    return a


def _split_plain(lines: list[str]):
    """``(first, cont, data, nd, blank)`` of plain fixed-field lines, all at once."""
    A = np.array(lines, dtype="S80")
    n = A.shape[0]
    F = A.view("S8").reshape(n, 10)
    first = _upper(strings.strip(F[:, 0]))
    large = strings.endswith(first, b"*") | strings.startswith(first, b"*")
    if large.any():
        data = np.zeros((n, 8), "S16")
        small = ~large
        data[small] = strings.strip(F[small, 1:9])
        L = F[large]
        data[large, :4] = strings.strip(np.stack([strings.add(L[:, 1 + 2 * k], L[:, 2 + 2 * k])
                                                  for k in range(4)], axis=1))
    else:
        data = strings.strip(F[:, 1:9])
    cont = _upper(strings.strip(F[:, 9]))
    early = (data[:, 7] == b"+") & (cont == b"") & ~large     # a marker one column early (tokens._split)
    if early.any():
        cont = cont.copy()
        data[early, 7], cont[early] = b"", b"+"
    nd = np.where(large, 4, 8).astype(np.int8)
    blank = (first == b"") & (cont == b"") & (data == b"").all(axis=1)
    return first, cont, data, nd, blank


def _widen(a: np.ndarray, width: int) -> np.ndarray:
    return a if a.dtype.itemsize >= width else a.astype(f"S{width}")


class _Builder:
    def __init__(self, includes: Includes) -> None:
        self.inc = includes
        self.chunks: list[_Chunk] = []
        self.ended = False

    def file(self, text: str, file: str, base_dir: Path, fidx: int, included: bool = False) -> None:
        raw = text.removeprefix("\ufeff").splitlines()
        if "$" in text:
            bodies = [_strip_comment(r) if "$" in r else r for r in raw]
            joined = "\n".join(bodies)
        else:
            bodies, joined = raw, text
        low = joined.lower()
        start = bulk_start(bodies, file) if "cend" in low and not included else 0
        bodies, numbers = self.inc.expand(bodies, start, file, joined)
        if numbers is not None:
            joined = "\n".join(bodies)
            low = joined.lower()
        number = (lambda k: numbers[k]) if numbers is not None else (lambda k: k + 1)
        n = len(bodies)
        skip: set[int] = set()
        includes: list[int] = []
        if "begin" in low or "include" in low:
            ended = False
            for k in range(start, n):
                s = bodies[k].strip()
                if not ended and s[:7].upper() == "ENDDATA":
                    ended = True          # the reference reader stops there, and reads no section after
                error = section_error(s, file, number(k)) if s and not ended else None
                if error is not None:
                    raise error
                if s and BEGIN_BULK.fullmatch(s):
                    skip.add(k)
                elif s and is_include(s):
                    skip.add(k)
                    includes.append(k)
        rows = np.arange(start, n)
        if skip:
            rows = rows[~np.isin(rows, list(skip))]
        lines = [bodies[k] for k in rows.tolist()]
        plain = _plain_mask(lines, joined)
        if plain.all():
            first, cont, data, nd, blank = _split_plain(lines)
            special = np.zeros(0, np.int64)
        else:
            m = len(lines)
            first, cont = np.zeros(m, "S8"), np.zeros(m, "S8")
            data, nd, blank = np.zeros((m, 8), "S16"), np.full(m, 8, np.int8), np.zeros(m, bool)
            p = np.flatnonzero(plain)
            if p.size:
                f, c, d, w, b = _split_plain([lines[i] for i in p.tolist()])
                first, cont = _widen(first, f.dtype.itemsize), _widen(cont, c.dtype.itemsize)
                first[p], cont[p], data[p], nd[p], blank[p] = f, c, d, w, b
            special = np.flatnonzero(~plain)
        cand = np.flatnonzero(strings.startswith(first, b"ENDDATA"))
        ends = [i for i in cand.tolist() if first[i].rstrip(b"*") == b"ENDDATA"]
        end = ends[0] if ends else len(lines)
        split = []
        for i in special[special < end].tolist():
            if not lines[i].strip():
                blank[i] = True
                continue
            line = _split(lines[i], file, number(int(rows[i])))      # raises the reference error
            if line.first.rstrip("*") == "ENDDATA":
                end = i
                break
            split.append((i, line.first.encode(), line.cont.encode(), [x.encode() for x in line.data]))
        if split:
            width = max(max(len(a), len(c), *map(len, d)) for _, a, c, d in split)
            first, cont, data = _widen(first, width), _widen(cont, width), _widen(data, width)
            for i, a, c, d in split:
                first[i], cont[i], nd[i] = a, c, len(d)
                data[i, :len(d)] = d
                data[i, len(d):] = b""
        if included and end:               # every line of an included file must be bulk data
            used = first[:end][~blank[:end]]
            bad = [n for n in np.unique(used).tolist()
                   if not CARD_NAME.fullmatch(n.decode("utf-8", "replace"))]
            if bad:
                i = int(np.flatnonzero(np.isin(first[:end], bad) & ~blank[:end])[0])
                raise not_bulk_data(file, number(int(rows[i])))
        # the include lines cut the file into chunks (a card never continues across them)
        cuts = np.searchsorted(rows, [k for k in includes])
        lo = 0
        for cut, inc in zip([*cuts.tolist(), len(rows)], [*includes, None]):
            stop = min(cut, end)
            keep = np.arange(lo, stop)
            keep = keep[~blank[lo:stop]]
            if keep.size:
                whole = keep.size == len(lines)
                lno = rows[keep] + 1 if numbers is None else np.asarray(numbers, np.int64)[rows[keep]]
                self.chunks.append(_Chunk(fidx, lno, lines if whole else [lines[i] for i in keep.tolist()],
                                          *((first, cont, data, nd) if whole else
                                            (first[keep], cont[keep], data[keep], nd[keep]))))
            if inc is None or cut > end:                 # no INCLUDE before ENDDATA is left
                self.ended = end < len(lines)
                return
            self.include(bodies[inc].strip(), file, number(inc), base_dir)
            if self.ended:
                return
            lo = cut

    def include(self, stripped: str, file: str, lineno: int, base_dir: Path) -> None:
        text, shown, path = self.inc.open(stripped, file, lineno, base_dir)
        self.inc.files.append(shown)
        self.inc.stack.append(path)
        self.file(text, shown, path.parent, len(self.inc.files) - 1, included=True)
        self.inc.stack.pop()


class CardTable:
    """The cards of one reading, in the deck's order (see the module docstring)."""

    def __init__(self, text: str, file: str, base_dir: Path, includes: Includes) -> None:
        self.includes = includes
        b = _Builder(includes)
        includes.files.append(file)
        b.file(text, file, base_dir, len(includes.files) - 1)
        self.files = includes.files
        chunks = b.chunks
        if not chunks:
            self._empty()
            return
        one = len(chunks) == 1
        width = max(c.data.dtype.itemsize for c in chunks)
        self.lfile = np.concatenate([np.full(len(c.body), c.fidx, np.int32) for c in chunks])
        self.lno = chunks[0].lno if one else np.concatenate([c.lno for c in chunks])
        self.body = chunks[0].body if one else [s for c in chunks for s in c.body]
        self.first = chunks[0].first if one else np.concatenate([_widen(c.first, width) for c in chunks])
        self.cont = chunks[0].cont if one else np.concatenate([_widen(c.cont, width) for c in chunks])
        self.data = chunks[0].data if one else np.concatenate([_widen(c.data, width) for c in chunks])
        self.nd = (chunks[0].nd if one else np.concatenate([c.nd for c in chunks])).astype(np.int64)
        boundary = np.zeros(len(self.body), bool)
        boundary[np.cumsum([0] + [len(c.body) for c in chunks[:-1]])] = True
        first = self.first
        iscont = (first == b"") | strings.startswith(first, b"+") | strings.startswith(first, b"*")
        if (iscont & boundary).any():
            raise Irregular("continuation line without a card")
        self._check_markers(iscont)
        self.head = np.flatnonzero(~iscont)
        self.end = np.append(self.head[1:], len(self.body))
        names = first[self.head]
        starred = np.flatnonzero(strings.endswith(names, b"*"))
        if starred.size:
            names = names.copy()
            names[starred] = strings.rstrip(names[starred], b"*")
        self.names = names
        self.flat_off = np.concatenate([[0], np.cumsum(self.nd)])
        self.all8 = bool((self.nd == 8).all())
        flat = self.data.ravel() if self.all8 else self.data[np.arange(8) < self.nd[:, None]]
        self.flat = np.append(flat, np.zeros(1, flat.dtype))
        self._names_str: list[str] | None = None

    def _empty(self) -> None:
        self.lfile = self.lno = self.head = self.end = self.nd = np.zeros(0, np.int64)
        self.body, self.first, self.cont = [], np.zeros(0, "S8"), np.zeros(0, "S8")
        self.data, self.all8 = np.zeros((0, 8), "S8"), True
        self.names, self.flat_off, self.flat = np.zeros(0, "S8"), np.zeros(1, np.int64), np.zeros(1, "S8")
        self._names_str = None

    def _check_markers(self, iscont: np.ndarray) -> None:
        """A continuation line's marker (``+xxx``/``*xxx``) must match field 10 of the line above."""
        idx = np.flatnonzero(iscont & (strings.str_len(self.first) > 1))
        if not idx.size:
            return
        prev = self.cont[idx - 1]
        idx, prev = idx[prev != b""], prev[prev != b""]
        for marker, above in zip(self.first[idx].tolist(), prev.tolist()):
            marker, above = marker.upper(), above.upper()       # either letter case, as NASTRAN
            if above[1:] != marker[1:] and above != marker[1:]:
                raise Irregular("continuation marker does not match")

    def __len__(self) -> int:
        return len(self.head)

    @property
    def name_list(self) -> list[str]:
        """Every card's name as text."""
        if self._names_str is None:
            u, inv = np.unique(self.names, return_inverse=True)
            text = [n.decode() for n in u.tolist()]
            self._names_str = [text[i] for i in inv.ravel().tolist()]
        return self._names_str

    def kinds(self, cards: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Card name -> the indices of its cards (ascending), in order of first appearance."""
        names = self.names if cards is None else self.names[cards]
        if not names.size:
            return {}
        u, first, inv = np.unique(names, return_index=True, return_inverse=True)
        order = np.argsort(inv, kind="stable")
        bounds = np.cumsum(np.bincount(inv, minlength=len(u)))
        out = {}
        for k in np.argsort(first).tolist():
            idx = order[(bounds[k - 1] if k else 0):bounds[k]]
            out[u[k].decode()] = idx if cards is None else cards[idx]
        return out

    def src(self, cards: np.ndarray) -> list[str]:
        """``"file:line"`` of each card."""
        heads = self.head[cards]
        files, lines = self.lfile[heads].tolist(), self.lno[heads].tolist()
        if len(self.files) == 1:
            f = self.files[0]
            return [f"{f}:{n}" for n in lines]
        return [f"{self.files[i]}:{n}" for i, n in zip(files, lines)]

    def matrix(self, cards: np.ndarray, nfields: int = 0) -> np.ndarray:
        """The fields of ``cards`` as one array ``(n, 1 + m)``: column ``i - 1`` holds NASTRAN
        field ``i`` (stripped, as written; ``b""`` beyond a card's end), column 0 the name. ``m``
        is the longest card's number of data fields, or ``nfields`` if larger."""
        heads = self.head[cards]
        nlines = self.end[cards] - heads
        k = int(nlines.max(initial=0))
        if self.all8 and (nlines == k).all():            # small field, the same number of lines
            block = self.data[heads[:, None] + np.arange(k)].reshape(len(cards), 8 * k)
        else:
            start = self.flat_off[heads]
            stop = self.flat_off[self.end[cards]]
            m = int((stop - start).max(initial=0))
            idx = start[:, None] + np.arange(m)
            block = self.flat[np.where(idx < stop[:, None], idx, len(self.flat) - 1)]
        parts = [self.names[cards][:, None].astype(block.dtype), block]
        if nfields > block.shape[1]:
            parts.append(np.zeros((len(cards), nfields - block.shape[1]), block.dtype))
        return np.concatenate(parts, axis=1)

    def card(self, c: int) -> _Card:
        """Card ``c`` as the reference tokenizer makes it (fields with their lines)."""
        f = self.files[int(self.lfile[self.head[c]])]
        rows = range(int(self.head[c]), int(self.end[c]))
        return card_from_lines([_split(self.body[i], f, int(self.lno[i])) for i in rows])


class TableCard:
    """A card of a :class:`CardTable` with the interface of :class:`.tokens._Card` (``name``,
    ``file``, ``line``, ``src``, ``fields``, ``text(i)``, ``error(i, message)``); its fields are
    made only when asked for."""
    __slots__ = ("table", "index", "name", "_card")

    def __init__(self, table: CardTable, index: int, name: str) -> None:
        self.table, self.index, self.name, self._card = table, index, name, None

    @property
    def file(self) -> str:
        return self.table.files[int(self.table.lfile[self.table.head[self.index]])]

    @property
    def line(self) -> int:
        return int(self.table.lno[self.table.head[self.index]])

    @property
    def src(self) -> str:
        return f"{self.file}:{self.line}"

    @property
    def last_line(self) -> int:
        return int(self.table.lno[self.table.end[self.index] - 1])

    @property
    def lines(self) -> set[int]:
        t = self.table
        return set(t.lno[t.head[self.index]:t.end[self.index]].tolist())

    @property
    def fields(self):
        if self._card is None:
            self._card = self.table.card(self.index)
        return self._card.fields

    def text(self, i: int) -> str:
        t = self.table
        if i == 1:
            return self.name
        k = int(t.flat_off[t.head[self.index]]) + i - 2
        if i < 1 or k >= int(t.flat_off[t.end[self.index]]):
            return ""
        return t.flat[k].decode().upper()

    def error(self, i: int, message: str) -> DeckFormatError:
        return card_error(self, i, message)


def table_cards(table: CardTable) -> list[TableCard]:
    """Every card of ``table`` as a :class:`TableCard`."""
    return [TableCard(table, i, n) for i, n in enumerate(table.name_list)]


def entities(cls, keys: tuple[str, ...], rows) -> list:
    """Frozen dataclass instances of ``cls`` from ``rows`` (tuples in the order of ``keys``, the
    class's fields). Made by filling each instance's ``__dict__`` (what the generated
    ``__init__`` does field by field, a third slower); a class with ``__slots__`` or a
    ``__post_init__`` is made by its constructor."""
    if hasattr(cls, "__slots__") or hasattr(cls, "__post_init__") or \
            tuple(f.name for f in dataclasses.fields(cls)) != keys:
        return [cls(*r) for r in rows]
    new = object.__new__
    out = []
    append = out.append
    for r in rows:
        o = new(cls)
        o.__dict__.update(zip(keys, r))
        append(o)
    return out
