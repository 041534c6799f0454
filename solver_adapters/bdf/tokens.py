"""Physical lines into cards, one line at a time: comments, the three formats, continuations,
INCLUDE, BEGIN BULK / ENDDATA.

Formats, mixed freely within one deck:

* small field: 8-column fields, 10 per line (name, 8 data fields, continuation marker in columns 73-80);
* large field: name ending in ``*`` (``GRID*``), 16-column data fields, 4 per line, ``*`` continuations;
* free field: comma separated (``GRID,1,,0.,0.,0.``; ``GRID*,`` gives 4 data fields per line);
* a line containing tabs is expanded to 8-column tab stops and then read as small/large field.

Continuations are either explicit (marker ``+xxx`` in field 10 matched by ``+xxx``/``*xxx`` in field 1
of the next line) or implicit (the next line's field 1 is blank, ``+`` or ``*``; in free field the
line starts with ``,``, ``+`` or ``*``). ``$`` starts a comment anywhere. ``BEGIN BULK`` and ``ENDDATA``
are optional; a deck with executive/case control (a ``CEND`` line) is read from ``BEGIN BULK`` on.
``INCLUDE 'file'`` is resolved relative to the including file (nested, loops detected), within
the limits of :class:`IncludePolicy`.

This is the reader's reference tokenizer: :mod:`.table` splits the same lines in bulk and falls
back to this one for anything irregular, so both give the same cards and the same errors.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from solver_adapters.bdf import freefield
from solver_adapters.protocol import DeckFormatError


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

    @property
    def last_line(self) -> int:
        """The physical line of the card's last field."""
        return max(f.line for f in self.fields)

    @property
    def lines(self) -> set[int]:
        """The physical lines the card was read from."""
        return {f.line for f in self.fields}

    def text(self, i: int) -> str:
        """Field ``i`` stripped and upper-cased ("" beyond the end)."""
        return self.fields[i - 1].text.upper() if i <= len(self.fields) else ""

    def error(self, i: int, message: str) -> DeckFormatError:
        """A DeckFormatError at NASTRAN field ``i`` (1-based) of this card."""
        return card_error(self, i, message)


def card_error(card, i: int, message: str) -> DeckFormatError:
    """A DeckFormatError at NASTRAN field ``i`` of ``card`` (anything with ``name``, ``file``,
    ``line`` and ``fields``): the physical line of that field, and which field of that line."""
    if i <= len(card.fields):
        f = card.fields[i - 1]
        line, value = f.line, f.text
        if line != card.line:
            message += f" (continuation line, field {f.pos} of that line)"
    else:
        line, value = card.fields[-1].line, ""
    return DeckFormatError(message, file=card.file, line=line, card=card.name, field=i, value=value)


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
        head = raw.split(",", 2)
        if head[0].strip().upper() == "DEQATN" and len(head) == 3:
            # free field: DEQATN,EQID,equation (the equation's own commas kept)
            return _Line(file, lineno, "DEQATN", [head[1].strip(), head[2].strip()] + [""] * 6, "")
        if freefield.equation_image(raw):
            # a DEQATN's equation (columns 17-72 of its first line, 9-72 of the next) holds
            # commas as text: a fixed-field card image, the equation one field (a blank field 1
            # before text with commas is no free-field line, which starts with its card name
            # or a comma)
            fixed = raw.expandtabs(8).rstrip()
            if len(fixed) > 80:
                raise fail("text beyond column 80 of a fixed-field line")
            fixed = fixed.ljust(80)
            first = fixed[:8].strip().upper()
            data = [fixed[8:16].strip(), fixed[16:72].strip()] if first else [fixed[8:72].strip()]
            return _Line(file, lineno, first, data + [""] * (8 - len(data)), fixed[72:80].strip().upper())
        items = [s.strip() for s in raw.replace("\t", " ").split(",")]
        first = items[0].upper()
        large = first.endswith("*") or first.startswith("*")
        width = 4 if large else 8
        while len(items) > width + 2 and items[-1] == "":
            items.pop()                   # trailing commas beyond field 10
        if len(items) > width + 2:
            # NASTRAN's free-field line is the ten fields of a card image: field 10 is the
            # continuation marker, and nothing follows it. Readers differ on the rest (pyNastran
            # drops every field past the ninth without a word), so which card field a value past
            # field 9 was meant for is the writer's guess: an error, never a guess of ours.
            raise fail(f"free-field line has {len(items) - 1} fields after field 1; at most "
                       f"{width} data fields and a continuation marker fit on one line (field "
                       f"{width + 2} is the continuation marker: a value there or beyond would be "
                       f"lost or read as a field its writer may not have meant); split the line: "
                       f"end it with a continuation marker such as +A and go on on a line "
                       f"starting with +A")
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
    cont = line[72:80].strip().upper()
    if not large and data[7] == "+" and not cont:
        # a lone + in field 9 with field 10 blank is the continuation marker written one column
        # early (column 72, not 73: TACS's beam_model_pbarl_rect.bdf, which MYSTRAN 18 reads so);
        # a + alone is no value of any field (table._split_plain reads it the same way)
        data[7], cont = "", "+"
    return _Line(file, lineno, first, data, cont)


BOUNDARY = object()  # between files: a card never continues across an INCLUDE
_INCLUDE = re.compile(r"INCLUDE\s*(?:'([^']*)'|\"([^\"]*)\"|([^\s'\"]+))\s*", re.IGNORECASE)
CARD_NAME = re.compile(r"[A-Z][A-Z0-9]{0,7}\*?|[+*].{0,7}|")
"""Field 1 of a bulk-data line: a card name (a letter, then letters and digits, at most 8;
``*`` for large field) or a continuation (blank, ``+...`` or ``*...``)."""


def not_bulk_data(file: str, lineno: int) -> DeckFormatError:
    """The error for a line of an included file that is no bulk-data card: it names the line,
    never what the line holds (the file may be anything a deck points to)."""
    return DeckFormatError("the included file is not bulk data: this line is no card (field 1 "
                           "is neither a card name nor a continuation); its content is not shown",
                           file=file, line=lineno, field=1)
BEGIN_BULK = re.compile(r"BEGIN\s+BULK\b.*", re.IGNORECASE)
_ORPHAN = re.compile(r"^[+*]\S", re.MULTILINE)       # a line that may continue a card away from it


_SECTION = re.compile(r"BEGIN\b\s*(.*)", re.IGNORECASE)


def section_error(stripped: str, file: str, lineno: int) -> DeckFormatError | None:
    """The error for a comment-free, stripped bulk-data line that opens a bulk data section
    other than the main one (``BEGIN SUPER = 2``, ``BEGIN BULK SUPER=2``, ``BEGIN AUXMODEL``):
    its cards belong to another structure (a superelement, an auxiliary model), and read as the
    main model's they would change it without a word. ``None`` for any other line (a second
    ``BEGIN BULK`` is skipped)."""
    if stripped[:5].upper() != "BEGIN":
        return None
    m = _SECTION.fullmatch(stripped)
    if m is None or " ".join(m.group(1).upper().split()) == "BULK":
        return None
    return DeckFormatError(f"{stripped!r} opens a bulk data section of its own (a superelement's, an "
                           f"auxiliary model's): the import reads one structure, the main bulk data, "
                           f"and such a section is not read", file=file, line=lineno, card="BEGIN",
                           value=stripped)


def is_include(stripped: str) -> bool:
    """A comment-free, stripped line that is an INCLUDE statement."""
    return stripped[:7].upper() == "INCLUDE" and (len(stripped) == 7 or not stripped[7].isalnum())


def bulk_start(uncommented: list[str], file: str) -> int:
    """Index of the first bulk-data line: 0, or after BEGIN BULK when the file has a CEND line."""
    if not any(u.strip().upper() == "CEND" for u in uncommented):
        return 0
    begin = next((i for i, u in enumerate(uncommented) if BEGIN_BULK.fullmatch(u.strip())), None)
    if begin is None:
        raise DeckFormatError("the deck has a CEND line (executive/case control) but no "
                              "BEGIN BULK", file=file)
    return begin + 1


@dataclass(frozen=True)
class IncludePolicy:
    """Where an INCLUDE may read: regular files inside the folder tree of the deck the reading
    started from (``root``; None: any folder, for text read without a file) or inside one of
    ``allowed`` (folders the user allows, ``--include-dir``). Symbolic links are resolved first,
    so a link inside the tree that points outside it is outside."""
    root: Path | None = None
    allowed: tuple[Path, ...] = ()

    def inside(self, path: Path) -> bool:
        if self.root is None:
            return True
        return any(path == d or d in path.parents for d in (self.root, *self.allowed))


def _as_written_on_windows(base_dir: Path, name: str) -> str:
    """The name of an included file that does not exist as written, read as a deck written on
    Windows names it (NASTRAN there takes both): backslashes as separators and each part in any
    letter case, when exactly one existing path then matches; else ``name`` as written (the
    error then names it)."""
    if (base_dir / name).exists():
        return name
    parts = [p for p in name.replace("\\", "/").split("/")]
    if not parts or parts[0] == "" or ":" in parts[0]:
        return name                              # an absolute path: not guessed at
    here = base_dir
    for part in parts:
        if part in ("", "."):
            continue
        if part == ".." or (here / part).exists():
            here = here / part
            continue
        try:
            hits = [p for p in here.iterdir() if p.name.lower() == part.lower()]
        except OSError:
            return name
        if len(hits) != 1:
            return name
        here = hits[0]
    return os.path.relpath(here, base_dir) if here.exists() else name


@dataclass
class Includes:
    """The state of one reading: the files read (as named in messages), the chain of files being
    read (for loops) and the policy. Shared by both tokenizers."""
    policy: IncludePolicy = field(default_factory=IncludePolicy)
    files: list[str] = field(default_factory=list)
    stack: list[Path] = field(default_factory=list)
    texts: dict[str, str] = field(default_factory=dict)            # shown name -> text read
    included: dict[tuple[str, int], str] = field(default_factory=dict)  # (file, INCLUDE line) -> shown
    # shown name -> (lines, their line numbers) of a file with COSMIC free-field lines, expanded
    expanded: dict[str, tuple[list[str], list[int]]] = field(default_factory=dict)

    def expand(self, bodies: list[str], start: int, file: str,
               text: str | None = None) -> tuple[list[str], list[int] | None]:
        """A file's comment-free lines with COSMIC free-field lines expanded (:mod:`.freefield`)
        and the line number of each; the lines as they are and None when it has none. ``text``:
        the file's text, if at hand (a quick test before the lines are looked at)."""
        got = freefield.expand(bodies, start, file, _split, is_include,
                               lambda s: BEGIN_BULK.fullmatch(s) is not None, text)
        if got is None and _ORPHAN.search(text if text is not None else "\n".join(bodies[start:])) \
                and freefield.orphan_continuation(bodies, start, _split, file):
            got = freefield.expand(bodies, start, file, _split, is_include,
                                   lambda s: BEGIN_BULK.fullmatch(s) is not None, text, force=True)
        if got is None:
            return bodies, None
        self.expanded[file] = got
        return got

    def open(self, stripped: str, file: str, lineno: int, base_dir: Path) -> tuple[str, str, Path]:
        """``(text, shown name, resolved path)`` of the file an INCLUDE line names, read; a
        located error (the INCLUDE line, field 2) for a bad statement, a loop, a file outside
        the policy, anything but a regular file, or one that cannot be read. The error never
        quotes what the named file holds."""
        m = _INCLUDE.fullmatch(stripped)
        if m is None:
            raise DeckFormatError("expected INCLUDE 'file' (quoted, on one line)", file=file,
                                  line=lineno, card="INCLUDE", field=2, value=stripped[7:].strip())
        name = next(g for g in m.groups() if g is not None)

        def fail(message: str) -> DeckFormatError:
            return DeckFormatError(message, file=file, line=lineno, card="INCLUDE", field=2, value=name)

        name = _as_written_on_windows(base_dir, name)
        path = (base_dir / name).resolve()
        if path in self.stack:
            raise fail(f"INCLUDE loop: {' -> '.join(str(p) for p in self.stack + [path])}")
        if not self.policy.inside(path):
            raise fail(f"included file {path} is outside the deck's folder "
                       f"{self.policy.root}{' (symbolic links followed)' if path != Path(os.path.abspath(base_dir / name)) else ''}; "
                       f"allow its folder with --include-dir (or include_dirs in the user "
                       f"configuration) if you trust it")
        try:
            if path.exists() and not path.is_file():
                raise fail(f"included path {path} is not a regular file")
            text = path.read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise fail(f"cannot read included file {path}: {exc.strerror or exc}") from None
        if any(_strip_comment(u).strip().upper() == "CEND" for u in text.splitlines()):
            raise fail(f"included file {path} is not bulk data: it has a CEND line (executive and "
                       f"case control belong in the input file itself)")
        shown = str(base_dir / name)
        self.texts[shown] = text
        self.included[(file, lineno)] = shown
        return text, shown, path


class LineReader:
    """The physical data lines of a deck and its includes (the reference tokenizer)."""

    def __init__(self, includes: Includes) -> None:
        self.inc = includes
        self.ended = False

    def lines(self, text: str, file: str, base_dir: Path, included: bool = False):
        raw_lines = text.removeprefix("\ufeff").splitlines()
        uncommented = [_strip_comment(r) for r in raw_lines]
        start = 0 if included else bulk_start(uncommented, file)
        uncommented, numbers = self.inc.expand(uncommented, start, file, text)
        for k in range(start, len(uncommented)):
            body, lineno = uncommented[k], (numbers[k] if numbers else k + 1)
            stripped = body.strip()
            error = section_error(stripped, file, lineno)
            if error is not None:
                raise error
            if not stripped or BEGIN_BULK.fullmatch(stripped):
                continue
            if is_include(stripped):
                yield BOUNDARY
                yield from self.include(stripped, file, lineno, base_dir)
                yield BOUNDARY
                if self.ended:
                    return
                continue
            line = _split(body, file, lineno)
            if line.first.rstrip("*") == "ENDDATA":
                self.ended = True
                return
            if included and not CARD_NAME.fullmatch(line.first):
                raise not_bulk_data(file, lineno)
            yield line

    def include(self, stripped: str, file: str, lineno: int, base_dir: Path):
        text, shown, path = self.inc.open(stripped, file, lineno, base_dir)
        self.inc.files.append(shown)
        self.inc.stack.append(path)
        yield from self.lines(text, shown, path.parent, included=True)
        self.inc.stack.pop()


def group_cards(lines):
    """Physical lines (and BOUNDARY markers) into cards."""
    card: _Card | None = None
    for line in lines:
        if line is BOUNDARY:
            if card is not None:
                yield card
            card = None
            continue
        if _is_continuation(line.first):
            if card is None:
                raise DeckFormatError("continuation line without a card before it",
                                      file=line.file, line=line.line, field=1, value=line.first)
            # NASTRAN reads its input in either letter case (as upper case): so do the markers
            marker = line.first[1:].upper()
            above = card.cont.upper() if card.cont else card.cont
            if above and marker and above[1:] != marker and above != marker:
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


def card_from_lines(lines: list[_Line]) -> _Card:
    """The card of one head line and its continuation lines (already split)."""
    head = lines[0]
    name = head.first.rstrip("*")
    card = _Card(name, head.file, head.line, [_Field(name, head.line, 1)])
    for line in lines:
        card.fields.extend(_Field(t, line.line, p) for p, t in enumerate(line.data, start=2))
        card.cont = line.cont
    return card
