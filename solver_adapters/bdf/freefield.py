"""COSMIC NASTRAN's free-field input: its lines expanded into ordinary card images before a
deck is split (NASTRAN-95 User's Manual, section 2.4.1.2, "Free-Field Input").

A COSMIC free-field line (one with a comma, or starting with ``=`` or ``)``) separates its items
by commas, blanks, or both, and may use:

* ``=`` (the field of the card before), ``==`` (every trailing field of the card before),
  ``*(i)`` (the card before's field plus ``i``, a blank field counting as 0), ``%(E)`` (an
  increment ending at ``E`` on the last card generated), ``/`` (the operation of the field
  before);
* ``=(N)`` in field 1: ``N`` cards generated from the card before, each from the one before it,
  with the line's operations (a bare ``=(N)``: those of the line before); ``=`` in field 1: one
  such card; a continuation ID of the form ``+A-X`` in field 1 or 10 goes up by 1 from card to
  card, any other text of field 10 is not repeated (rules 13 and 14, and the manual's example 7,
  which applies them to ``=`` too);
* ``n)X``: ``X`` in field ``n``; ``)+X``: ``+X`` in field 10; ``)`` in field 1: the card before's
  field 10 (a continuation of it);

and a continuation line need not follow its parent: NASTRAN matches it by its ID. Expanded, the
generated lines are put after the line whose field 10 they continue.

Lines without any of these (ordinary fixed, large and comma-separated free field) are left as
they are, so a deck without them reads exactly as before; :func:`expand` returns None for it.
An expanded file is read line for line from the expanded text, and every line there keeps the
number of the line of the file it came from, so messages name the line the user wrote. Errors of
the notation (an increment of a blank field, ``=(N)`` with nothing before it) are located at
that line.
"""

from __future__ import annotations

import re

from solver_adapters.bdf.numbers import _INT, _real_or_none
from solver_adapters.protocol import DeckFormatError

_INDEX = re.compile(r"(\d+)\)(.*)")          # n)X: X in field n
_REPEAT = re.compile(r"=\((\d+)\)")          # =(N) in field 1
_INCR = re.compile(r"\*\((.+)\)")            # *(i)
_END = re.compile(r"%\((.+)\)")              # %(E)
_CONT_ID = re.compile(r"([+*][A-Z0-9]+-)(\d+)")   # +A-X (rule 13)
_SPECIAL = re.compile(r"^[=)]|\)|\*\(|%\(|==|(?:^|,)\s*[=/]+\s*(?:,|$)")


def _items(body: str) -> list[str]:
    """The items of a free-field line: split at commas, each piece at blanks; an empty piece
    is one blank field."""
    out: list[str] = []
    for piece in body.replace("\t", " ").split(","):
        s = piece.strip()
        if not s:
            out.append("")
            continue
        for tok in s.split():
            if set(tok) == {"/"}:
                out.extend("/" * len(tok))      # "///": three fields, each as the one before
            else:
                out.append(tok)
    return out


def equation_image(raw: str) -> bool:
    """Whether a line with commas is a DEQATN's fixed-field card image, whose commas are equation
    text: DEQATN in columns 1-8, or columns 1-8 blank before text that does not start with ``,``,
    ``+`` or ``*`` (its continuation; a free-field line starts with its card name or a comma)."""
    fixed = raw.expandtabs(8)
    columns = fixed[:8].strip().upper()
    return columns == "DEQATN" or (not columns and fixed.strip()[:1] not in ",+*")


def _is_cosmic(body: str) -> bool:
    """Whether a comment-free bulk line needs this module: it starts with ``=`` or ``)``, or is
    a comma-separated line (not a DEQATN's) with a replication or field-index item, or with two
    items separated by blanks only."""
    s = body.strip()
    if not s:
        return False
    if s[0] in "=)":
        return True
    if "," not in s:
        return False
    if s.split(",", 1)[0].strip().upper() == "DEQATN" or equation_image(body):
        return False                            # a DEQATN's equation: text with commas
    if _SPECIAL.search(s):
        return True
    return any(len(piece.split()) > 1 for piece in s.replace("\t", " ").split(","))


def needed(bodies: list[str], start: int, text: str | None = None) -> bool:
    """Whether any bulk line (from ``start`` on) is COSMIC free field (see :func:`_is_cosmic`).
    ``text``: the file's text, if at hand (without ``=``, ``)`` or ``,`` it has none)."""
    if text is not None and "=" not in text and ")" not in text and "," not in text:
        return False
    return any(("=" in b or ")" in b or "," in b) and _is_cosmic(b) for b in bodies[start:])


class _Op:
    """What a generated card's field is: ``kind`` "value" (``text``), "same", "blank",
    "incr" (``step``)."""
    __slots__ = ("kind", "text", "step")

    def __init__(self, kind: str, text: str = "", step: int | float = 0) -> None:
        self.kind, self.text, self.step = kind, text, step


def _number(text: str) -> int | float | None:
    t = text.strip().upper()
    if _INT.fullmatch(t):
        return int(t)
    return _real_or_none(t)


def _real_text(v: float) -> str:
    s = f"{v:.12g}"
    if "e" in s:
        m, e = s.split("e")
        return (m if "." in m else m + ".") + "E" + e
    return s if "." in s or "n" in s else s + "."


def _next_id(text: str) -> str | None:
    m = _CONT_ID.fullmatch(text.upper())
    return f"{m.group(1)}{int(m.group(2)) + 1}" if m else None


class _Expander:
    def __init__(self, file: str) -> None:
        self.file = file
        self.prev: list[str] | None = None      # the card image before: fields 1..10
        self.ops: list[_Op] | None = None       # the operations of the last generating line

    def fail(self, lineno: int, message: str, value: str = "") -> DeckFormatError:
        return DeckFormatError(f"free-field input: {message}", file=self.file, line=lineno,
                               value=value)

    def plain(self, image: list[str] | None) -> None:
        self.prev, self.ops = image, None

    def line(self, body: str, lineno: int) -> list[list[str]]:
        """The card images of one COSMIC free-field line."""
        items = _items(body)
        given: dict[int, str] = {}
        rest_same_from: int | None = None
        pos = 1
        for k, tok in enumerate(items):
            if tok == ")" and k == 0:
                if self.prev is None:
                    raise self.fail(lineno, "')' in field 1 continues the card before, and there "
                                            "is none", tok)
                given[1] = self.prev[9]
                pos = 2
                continue
            m = _INDEX.fullmatch(tok)
            if m:
                n = int(m.group(1))
                if not 1 <= n <= 10:
                    raise self.fail(lineno, f"field index {n}) is not a field of a card (1-10)", tok)
                pos = n
                if m.group(2):
                    given[pos] = m.group(2)
                    pos += 1
                continue
            if tok.startswith(")"):
                given[10] = tok[1:]
                pos = 11
                continue
            if tok == "==":
                rest_same_from = pos
                break
            if tok == "/":
                if pos - 1 not in given:
                    raise self.fail(lineno, "'/' repeats the field before it, and there is none", tok)
                given[pos] = given[pos - 1]
                pos += 1
                continue
            if pos > 10:
                raise self.fail(lineno, "more than ten fields on one card image", tok)
            given[pos] = tok
            pos += 1
        first = given.get(1, "")
        rep = _REPEAT.fullmatch(first)
        if rep or first == "=":
            return self.generate(given, rest_same_from, int(rep.group(1)) if rep else 1,
                                 repeated=bool(rep), lineno=lineno, body=body)
        # an ordinary card, whose fields may still refer to the card before
        ops = [self.op(given.get(i), i, lineno, 1, rest_same_from) for i in range(1, 11)]
        if any(o.kind in ("same", "incr") for o in ops) and self.prev is None:
            raise self.fail(lineno, "'=', '==', '*(i)' and '%(E)' refer to the card before, and "
                                    "there is none", body.strip())
        image = [self.apply(o, i, lineno) for i, o in enumerate(ops, start=1)]
        self.prev = image
        self.ops = ops
        return [image]

    def op(self, tok: str | None, i: int, lineno: int, n: int, rest_same_from: int | None) -> _Op:
        if tok is None:
            return _Op("same") if rest_same_from is not None and i >= rest_same_from else _Op("blank")
        if tok == "":
            return _Op("blank")
        if tok == "=":
            return _Op("same")
        m = _INCR.fullmatch(tok)
        if m:
            step = _number(m.group(1))
            if step is None:
                raise self.fail(lineno, f"the increment of field {i} is not a number", tok)
            return _Op("incr", step=step)
        m = _END.fullmatch(tok)
        if m:
            end = _number(m.group(1))
            before = _number(self.prev[i - 1]) if self.prev is not None else None
            if end is None or before is None:
                raise self.fail(lineno, f"'%(E)' in field {i} needs a number there on the card "
                                        f"before and a number E", tok)
            step = (end - before) / n
            if isinstance(end, int) and isinstance(before, int) and (end - before) % n == 0:
                step = (end - before) // n
            return _Op("incr", step=step)
        return _Op("value", text=tok)

    def apply(self, op: _Op, i: int, lineno: int) -> str:
        if op.kind == "value":
            return op.text
        if op.kind == "blank":
            return ""
        before = self.prev[i - 1]
        if op.kind == "same":
            return before
        value = 0 if before == "" else _number(before)    # a blank field counts as 0
        if value is None:
            raise self.fail(lineno, f"'*(i)' increments field {i} of the card before, which holds "
                                    f"{before!r}, not a number", before)
        out = value + op.step
        return str(out) if isinstance(out, int) else _real_text(out)

    def generate(self, given: dict[int, str], rest_same_from: int | None, n: int, repeated: bool,
                 lineno: int, body: str) -> list[list[str]]:
        if self.prev is None:
            raise self.fail(lineno, "'=' and '=(N)' in field 1 duplicate the card before, and "
                                    "there is none", body.strip())
        if n < 1:
            raise self.fail(lineno, "=(N) needs N >= 1", given.get(1, ""))
        bare = len(given) == 1 and rest_same_from is None
        if bare and repeated:
            ops = self.ops or [_Op("same")] * 10
        else:
            ops = [_Op("same")] + [self.op(given.get(i), i, lineno, n, rest_same_from)
                                   for i in range(2, 11)]
        images = []
        for k in range(n):
            image = [self.apply(o, i, lineno) for i, o in enumerate(ops, start=1)]
            # rules 13 and 14: a continuation ID +A-X goes up by one from card to card, any other
            # text of field 10 is not repeated (the manual's example 7 does so for "=" as well)
            image[0] = _next_id(self.prev[0]) or image[0]
            if ops[9].kind == "same" or (ops[9].kind == "value" and k > 0):
                image[9] = _next_id(self.prev[9]) or ""
            images.append(image)
            self.prev = image
        self.ops = ops
        return images


def _image_text(image: list[str]) -> str:
    """One card image as a line the readers split back into the same ten fields: fixed field
    when every field fits in 8 columns, else comma-separated free field."""
    fields = [f.upper() if i in (0, 9) else f for i, f in enumerate(image)]
    if all(len(f) <= 8 and "," not in f and " " not in f for f in fields):
        return "".join(f"{f:<8}" for f in fields).rstrip() or ","
    while len(fields) > 1 and fields[-1] == "":
        fields.pop()
    return ",".join(fields) if fields[0] else "," + ",".join(fields[1:])


def _key(marker: str) -> str:
    m = marker.upper()
    return m[1:] if m[:1] in "+*" else m


def _reorder(lines: list[str], nums: list[int], firsts: list[str], conts: list[str]):
    """Continuation lines placed after the line whose field 10 they continue, when they do not
    follow it already and exactly one line has that ID (as NASTRAN sorts its bulk data)."""
    owners: dict[str, list[int]] = {}
    for i, c in enumerate(conts):
        if c:
            owners.setdefault(_key(c), []).append(i)
    floating: dict[int, list[int]] = {}         # owner line -> the block continuing it
    order: list[int] = []
    i, n = 0, len(lines)
    while i < n:
        f = firsts[i]
        explicit = len(f) > 1 and f[0] in "+*"
        above = conts[order[-1]] if order else ""
        follows = order and (not above or _key(above) == _key(f))
        owner = owners.get(_key(f), []) if explicit else []
        if explicit and not (follows and above) and len(owner) == 1 and owner[0] != i - 1:
            block = [i]
            j = i + 1
            while j < n and (firsts[j] in ("", "+", "*") or (len(firsts[j]) > 1 and firsts[j][0] in "+*"
                                                             and conts[block[-1]]
                                                             and _key(conts[block[-1]]) == _key(firsts[j]))):
                block.append(j)
                j += 1
            floating[owner[0]] = block
            i = j
            continue
        order.append(i)
        i += 1
    if not floating:
        return lines, nums
    out: list[int] = []
    placed: set[int] = set()

    def emit(k: int) -> None:
        out.append(k)
        block = floating.get(k)
        if block is not None and block[0] not in placed:
            placed.add(block[0])
            for b in block:
                emit(b)

    for k in order:
        emit(k)
    for block in floating.values():          # an owner that came after, or a loop: leave them
        if block[0] not in placed:
            out.extend(block)
    return [lines[k] for k in out], [nums[k] for k in out]


def orphan_continuation(bodies: list[str], start: int, split, file: str) -> bool:
    """Whether a continuation line (from ``start`` on) names a marker other than field 10 of the
    line above it (a continuation away from its parent, as NASTRAN-95 decks place them: the
    bulk data is sorted before it is read, and continuations are matched by their ID)."""
    def fields(b: str, k: int) -> tuple[str, str] | None:
        """(field 1, field 10) of a line: columns 1-8 and 73-80 of a fixed-field small line
        (the common case, read without the splitter), else the splitter's."""
        if "\t" not in b:
            if "," not in b:
                if "*" not in b[:8]:
                    return b[:8].strip(), b[72:80].strip()
            else:
                parts = b.split(",", 10)
                if "*" not in parts[0]:
                    return parts[0].strip(), parts[9].strip() if len(parts) > 9 else ""
        try:
            line = split(b, file, k + 1)
        except DeckFormatError:
            return None                           # the reader will say what is wrong with it
        return line.first, line.cont or ""

    prev = ""
    owners: set[str] = set()            # field 10 of every line
    loose: set[str] = set()             # markers of continuations below a line without field 10
    for k in range(start, len(bodies)):
        b = bodies[k]
        if not b.strip():
            continue
        if b[:1] in "+*":
            got = fields(b, k)
            if got is None:
                return False
            if len(got[0]) > 1:
                if prev and _key(got[0]) != _key(prev):
                    return True
                if not prev:
                    loose.add(_key(got[0]))
        if len(b) > 72 or "," in b or "\t" in b:
            got = fields(b, k)
            if got is None:
                return False
            prev = got[1]
            if prev:
                owners.add(_key(prev))
        else:
            prev = ""
    return bool(loose & owners)


def expand(bodies: list[str], start: int, file: str, split, include=None,
           begin_bulk=None, text: str | None = None,
           force: bool = False) -> tuple[list[str], list[int]] | None:
    """The comment-free lines of a file with its COSMIC free-field lines (from ``start``, the
    first bulk line) expanded, and each line's number in the file (1-based); None when the file
    has none. ``split``: the readers' line splitter (``tokens._split``), which gives the fields of
    the other lines (the card before a replication may be one of them); ``include`` and
    ``begin_bulk``: whether a stripped line is an INCLUDE or a BEGIN BULK line (the tokenizer's
    tests), kept as they are (no card continues across an INCLUDE); ``text``: see :func:`needed`.
    ``force``: the lines are read this way without free-field lines too (their continuations
    put after their parents: :func:`orphan_continuation`)."""
    if not force and not needed(bodies, start, text):
        return None
    is_include = include or (lambda s: False)
    is_begin = begin_bulk or (lambda s: False)
    out, nums = list(bodies[:start]), list(range(1, start + 1))
    seg_lines: list[str] = []
    seg_nums: list[int] = []
    firsts: list[str] = []
    conts: list[str] = []
    ex = _Expander(file)

    def flush() -> None:
        lines, ns = _reorder(seg_lines, seg_nums, firsts, conts)
        out.extend(lines)
        nums.extend(ns)
        seg_lines.clear(), seg_nums.clear(), firsts.clear(), conts.clear()

    ended = False
    for k in range(start, len(bodies)):
        body, lineno = bodies[k], k + 1
        s = body.strip()
        if not s and not ended:
            continue                              # blank or comment only: no line of the deck
        if ended or is_begin(s) or is_include(s):
            flush()
            out.append(body)
            nums.append(lineno)
            if is_include(s):
                ex.plain(None)
            continue
        if _is_cosmic(body):
            for image in ex.line(body, lineno):
                seg_lines.append(_image_text(image))
                seg_nums.append(lineno)
                firsts.append(image[0].upper())
                conts.append(image[9].upper())
            continue
        try:
            line = split(body, file, lineno)
        except DeckFormatError:
            line = None                           # the reader will say what is wrong with it
        if line is not None and line.first.rstrip("*") == "ENDDATA":
            ended = True
            flush()
            out.append(body)
            nums.append(lineno)
            continue
        large = line is not None and (line.first.endswith("*") or line.first.startswith("*"))
        ex.plain(None if line is None or large else [line.first, *line.data, line.cont])
        seg_lines.append(body)
        seg_nums.append(lineno)
        firsts.append(line.first if line is not None else "?")
        conts.append(line.cont if line is not None else "")
    flush()
    return out, nums
