"""CSV tables of values at grid components: the one reader of ``loads.csv``.

``loads.csv`` is ``case,grid,component,value[,group]``, one row per loaded DOF, cases in order of
first appearance. Two rows for the same case and DOF are an error (a spreadsheet pasted twice is
more likely than a load meant to be summed). Files are read as UTF-8; a byte-order mark is
accepted; any other undecodable byte is reported with its offset. Every rejection names the file,
the line and the column (:class:`TableFormatError`).

It lives beside the solvers because the conformance checks read fixture loads too, and
``solver_adapters`` never imports ``blackbox``; the study reader adds its own checks on top.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Iterator, Sequence

import scipy.sparse as sp

from solver_adapters.errors import TableFormatError
from solver_adapters.protocol import DofLabel, LoadMatrix

LOADS_HEADER = ("case", "grid", "component", "value")


def read_text(path: str | Path) -> str:
    """A text file as UTF-8 (a leading byte-order mark dropped)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise TableFormatError("file not found", file=str(path)) from None
    except IsADirectoryError:
        raise TableFormatError("is a folder, not a file", file=str(path)) from None
    bom = b"\xef\xbb\xbf"
    body = raw[len(bom):] if raw.startswith(bom) else raw
    try:
        return body.decode("utf-8")
    except UnicodeDecodeError as exc:
        at = exc.start + (len(raw) - len(body))          # offset in the file, the mark included
        line = raw[:at].count(b"\n") + 1
        raise TableFormatError(f"not UTF-8 text: byte 0x{raw[at]:02x} at offset {at}",
                               file=str(path), line=line) from None


def rows(path: str | Path, header: Sequence[str], optional: Sequence[str] = ()) -> Iterator[tuple[int, dict]]:
    """``(line_no, {column: text})`` for every data row, after checking the header (``optional``
    columns may follow the required ones, in order). Blank rows and rows starting with ``#`` are
    skipped."""
    path = Path(path)
    reader = csv.reader(io.StringIO(read_text(path), newline=""))
    first = next(reader, None)
    got = [h.strip() for h in first or []]
    extra = got[len(header):]
    if first is None or got[:len(header)] != list(header) or extra != list(optional)[:len(extra)]:
        allowed = ",".join(header) + "".join(f"[,{o}]" for o in optional)
        raise TableFormatError(f"header must be {allowed}: {_header_mismatch(got if first else None, header, optional)}",
                               file=str(path), line=1)
    for row in reader:
        line = reader.line_num
        if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
            continue
        if len(row) != len(got):
            raise TableFormatError(f"expected {len(got)} columns, got {len(row)}", file=str(path), line=line)
        yield line, {h: c.strip() for h, c in zip(got, row)}


def _header_mismatch(got: list[str] | None, header: Sequence[str], optional: Sequence[str]) -> str:
    """Where a header line differs from the expected one, said without quoting the line: the
    file may not be a table at all, and an error message must not show what it holds."""
    if got is None:
        return "the file is empty"
    want = list(header) + list(optional)
    for i, (g, h) in enumerate(zip(got, want)):
        if g != h:
            return f"column {i + 1} of line 1 is not {h!r}"
    if len(got) < len(header):
        return f"line 1 has {len(got)} column(s), {len(header)} are needed"
    return f"line 1 has {len(got)} columns, at most {len(want)} are known"


def parse_int(text: str, path: str | Path, line: int, col: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise TableFormatError(f"expected an integer, got {text!r}", file=str(path), line=line, column=col) from None


def parse_float(text: str, path: str | Path, line: int, col: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise TableFormatError(f"expected a number, got {text!r}", file=str(path), line=line, column=col) from None
    if not math.isfinite(v):
        raise TableFormatError(f"value must be finite, got {text!r}", file=str(path), line=line, column=col)
    return v


def parse_dof(rec: dict, path: str | Path, line: int, grids: set[int] | None) -> DofLabel:
    """``(grid, component)`` of a row with ``case``, ``grid``, ``component`` columns."""
    if not rec["case"]:
        raise TableFormatError("empty case label", file=str(path), line=line, column="case")
    g = parse_int(rec["grid"], path, line, "grid")
    c = parse_int(rec["component"], path, line, "component")
    if not 1 <= c <= 6:
        raise TableFormatError(f"component must be 1..6, got {c}", file=str(path), line=line, column="component")
    if grids is not None and g not in grids:
        raise TableFormatError(f"grid {g} is not in the deck", file=str(path), line=line, column="grid")
    return (g, c)


def read_loads(path: str | Path, grids: set[int] | None = None) -> LoadMatrix:
    """``loads.csv`` as a :class:`LoadMatrix` (see the module docstring for the rules)."""
    entries: dict[tuple[str, DofLabel], tuple[float, int]] = {}
    load_groups(path)                  # every row of a case in one group
    for line, rec in rows(path, LOADS_HEADER, ("group",)):
        dof = parse_dof(rec, path, line, grids)
        val = parse_float(rec["value"], path, line, "value")
        key = (rec["case"], dof)
        if key in entries:
            raise TableFormatError(f"duplicate row for case {key[0]!r} grid {dof[0]} component {dof[1]} "
                                   f"(first on line {entries[key][1]})", file=str(path), line=line)
        entries[key] = (val, line)
    if not entries:
        raise TableFormatError("no load rows", file=str(path))
    cases = list(dict.fromkeys(c for c, _ in entries))
    dofs = list(dict.fromkeys(d for _, d in entries))
    ci = {c: j for j, c in enumerate(cases)}
    di = {d: i for i, d in enumerate(dofs)}
    r = [di[d] for _, d in entries]
    c = [ci[k] for k, _ in entries]
    v = [val for val, _ in entries.values()]
    return LoadMatrix(tuple(dofs), sp.csc_matrix((v, (r, c)), shape=(len(dofs), len(cases))), tuple(cases))


def load_groups(path: str | Path) -> dict[str, str]:
    """``{case: group}`` from the optional ``group`` column of ``loads.csv`` (empty without it).

    A group names the set-up a case was run in (a test day, a rig, a load cell); every row of a
    case must name the same group, and a file that has the column must fill it on every row."""
    out: dict[str, tuple[str, int]] = {}
    for line, rec in rows(path, LOADS_HEADER, ("group",)):
        if "group" not in rec:
            return {}
        g = rec["group"]
        if not g:
            raise TableFormatError("empty group (fill the column on every row, or drop it)",
                                   file=str(path), line=line, column="group")
        first = out.setdefault(rec["case"], (g, line))
        if first[0] != g:
            raise TableFormatError(f"case {rec['case']!r} is in group {first[0]!r} on line {first[1]} "
                                   f"and in group {g!r} here: a case is run in one set-up",
                                   file=str(path), line=line, column="group")
    return {c: g for c, (g, _) in out.items()}
