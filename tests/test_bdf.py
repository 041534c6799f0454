"""Bulk-data reader and writer: number parsing, card formats, continuations, includes, errors,
field formatters and write -> read round trips (solver_adapters.bdf, solver_adapters.bdf_write)."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from solver_adapters.bdf import parse_int, parse_real, read_deck, read_deck_text
from solver_adapters.bdf_write import (format_card, print_float_8, print_float_16,
                                       print_float_free, write_deck)
from solver_adapters.deck import CBar, Deck, Grid, Mat1, PBar, Pelas, Rbe2, Rod, Spc1, Spring
from solver_adapters.protocol import DeckFormatError, ModelError


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
def small(name: str, *fields: str, cont: str = "") -> str:
    """One small-field line (fields left-justified, the writer right-justifies: both are valid)."""
    data = [f.ljust(8) for f in fields] + [""] * (8 - len(fields))
    return (name.ljust(8) + "".join(d.ljust(8) for d in data) + cont).rstrip() + "\n"


def fixed_card(name: str, fields: list[str], large: bool) -> str:
    """A card in small or large field with implicit continuations."""
    per, width = (4, 16) if large else (8, 8)
    chunks = [fields[i:i + per] for i in range(0, max(len(fields), 1), per)]
    if large and len(chunks) % 2:
        chunks.append([])
    first = name + "*" if large else name
    return "".join(((first if k == 0 else ("*" if large else "")).ljust(8)
                    + "".join(f.ljust(width) for f in c)).rstrip() + "\n"
                   for k, c in enumerate(chunks))


def free_card(name: str, fields: list[str]) -> str:
    chunks = [fields[i:i + 8] for i in range(0, max(len(fields), 1), 8)]
    return "".join((name if k == 0 else "") + "," + ",".join(c) + "\n" for k, c in enumerate(chunks))


def in_format(fmt: str, name: str, fields: list[str]) -> str:
    return free_card(name, fields) if fmt == "free" else fixed_card(name, fields, fmt == "large")


def no_src(deck: Deck) -> dict:
    """The deck's entities with ``src`` blanked (it differs between formats by design)."""
    def strip(x):
        return dataclasses.replace(x, src="")
    return {"grids": {k: strip(v) for k, v in deck.grids.items()},
            "cbars": {k: strip(v) for k, v in deck.cbars.items()},
            "pbars": {k: strip(v) for k, v in deck.pbars.items()},
            "mat1s": {k: strip(v) for k, v in deck.mat1s.items()},
            "spc1s": [strip(v) for v in deck.spc1s],
            "rbe2s": {k: strip(v) for k, v in deck.rbe2s.items()},
            "pelas": {k: strip(v) for k, v in deck.pelas.items()},
            "springs": {k: strip(v) for k, v in deck.springs.items()},
            "rods": {k: strip(v) for k, v in deck.rods.items()},
            "prods": {k: strip(v) for k, v in deck.prods.items()},
            "spcadds": {k: strip(v) for k, v in deck.spcadds.items()}}


def assert_names(exc: DeckFormatError, file: str, line: int, card: str, field: int) -> None:
    """The error names file, line, card and field, as attributes and in its message."""
    assert (exc.file, exc.line, exc.card, exc.field) == (file, line, card, field), str(exc)
    message = str(exc)
    assert f"{file}:{line}" in message and f"card {card}" in message and f"field {field}" in message


BASE = (small("GRID", "1", "", "0.", "0.", "0.")
        + small("GRID", "2", "", "1.", "0.", "0.")
        + small("GRID", "3", "", "0.", "1.", "0.")
        + small("GRID", "4", "", "0.", "0.", "1.")
        + small("PBAR", "1", "1", "1.", "1.", "1.", "1.")
        + small("MAT1", "1", "1.+7", "", ".3")
        + small("PELAS", "7", "100."))
EIGHT_GRIDS = "".join(f"GRID,{i},,{i}.,0.,0.\n" for i in range(1, 9))


# --------------------------------------------------------------------------------------------
# numbers
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, value", [
    ("1.0", 1.0), ("1.", 1.0), (".5", 0.5), ("-.5", -0.5), ("+.5", 0.5), ("  2.5  ", 2.5),
    ("1.0E+3", 1.0e3), ("1.0e-3", 1.0e-3), ("1.0E3", 1.0e3), ("1.0D3", 1.0e3), ("1.0d-3", 1.0e-3),
    ("1.0+3", 1.0e3), ("1.0-3", 1.0e-3), ("-2.5-7", -2.5e-7), (".7+1", 7.0), ("70.-1", 7.0),
    ("7.E+0", 7.0), ("1.-300", 1e-300),
    ("0", 0.0), ("12", 12.0), ("-3", -3.0),  # lenient: integer text in a real field
    ("1E3", 1000.0),                          # lenient: exponent without a decimal point
])
def test_parse_real_accepts(text, value):
    assert parse_real(text) == value  # exact: each text is the shortest form of a double


@pytest.mark.parametrize("text", ["1.2.3", "abc", "1E", "nan", "NaN", "inf", "-inf", "1.0E+",
                                  "1+3", "--1", ".", "-", "", "1.0E3.0", "1 0", "E3", "1.0E+999",
                                  "0x10", "1_000.", "1.0E-3-2"])
def test_parse_real_rejects(text):
    with pytest.raises(DeckFormatError) as info:
        parse_real(text)
    assert info.value.value == text


@pytest.mark.parametrize("text, value", [("12", 12), ("-3", -3), ("+7", 7), (" 0 ", 0)])
def test_parse_int_accepts(text, value):
    assert parse_int(text) == value


@pytest.mark.parametrize("text, why", [("1.", "integer field given a real"),
                                       ("1.0E3", "integer field given a real"),
                                       ("2.5-7", "integer field given a real"),
                                       ("abc", "not an integer"), ("", "not an integer"),
                                       ("1 2", "not an integer"),
                                       ("12345678901", "out of range")])
def test_parse_int_rejects(text, why):
    with pytest.raises(DeckFormatError, match=why):
        parse_int(text)


# --------------------------------------------------------------------------------------------
# every card in all three formats
# --------------------------------------------------------------------------------------------
CARDS = [
    ("GRID", ["5", "0", "1.5", "-2.", "3.0+2", "0", "321"], "grids", 5,
     Grid(5, (1.5, -2.0, 300.0), "123")),
    ("GRID", ["6"], "grids", 6, Grid(6, (0.0, 0.0, 0.0), "")),
    ("CBAR", ["1", "", "1", "2", "0.", "1", "0"], "cbars", 1,           # PID defaults to EID
     CBar(1, 1, 1, 2, x=(0.0, 1.0, 0.0))),
    ("CBAR", ["2", "1", "1", "2", "3"], "cbars", 2, CBar(2, 1, 1, 2, g0=3)),
    ("CBAR", ["3", "1", "2", "1", ".0", "0.", "1.", "GGG", "", "", "0.", "0.", "0.", "0.", "0.",
              "0."], "cbars", 3, CBar(3, 1, 2, 1, x=(0.0, 0.0, 1.0))),
    ("PBAR", ["2", "1", "1.-2", "2.-6", "3.-6", "4.-6", "0.1", "", "1.", "1.", "-1.", "1.", "1.",
              "-1.", "-1.", "-1.", "0.5", "0.6"], "pbars", 2,
     PBar(2, 1, 1e-2, 2e-6, 3e-6, 4e-6, k1=0.5, k2=0.6)),
    ("PBAR", ["2", "1", "1.-2", "2.-6", "3.-6", "4.-6", "", "", "", "", "", "", "", "", "", "",
              "0.", ""], "pbars", 2, PBar(2, 1, 1e-2, 2e-6, 3e-6, 4e-6)),   # K1 = 0.: as blank
    ("MAT1", ["2", "2.1+11", "", "0.3", "7850."], "mat1s", 2,
     Mat1(2, 2.1e11, 2.1e11 / (2 * 1.3), 0.3)),
    ("MAT1", ["2", "2.0E11", "8.0E10"], "mat1s", 2, Mat1(2, 2.0e11, 8.0e10, 2.0e11 / 1.6e11 - 1)),
    ("MAT1", ["2", "", "8.0D10", ".25"], "mat1s", 2, Mat1(2, 2 * 8.0e10 * 1.25, 8.0e10, 0.25)),
    ("MAT1", ["2", "2.1+11"], "mat1s", 2, Mat1(2, 2.1e11, 0.0, 0.0)),    # QRG: G = NU = 0
    ("MAT1", ["2", "", "8.+10"], "mat1s", 2, Mat1(2, 0.0, 8e10, 0.0)),   # QRG: E = NU = 0
    ("MAT1", ["2", "2.+11", "7.+10", ".5"], "mat1s", 2, Mat1(2, 2e11, 7e10, 0.5)),  # as given
    ("SPC", ["5", "1", "123456", "0.", "2", "53"], "spc1s", 1, Spc1(5, "35", (2,))),
    ("CONROD", ["12", "1", "2", "1", "2.-4", "3.-8", "0.1", "0.5"], "rods", 12,
     Rod(12, 1, 2, mid=1, a=2e-4, j=3e-8, card="CONROD")),
    ("SPC1", ["3", "321", "1", "2", "3", "", "4", "4", "3", "2", "1"], "spc1s", 0,
     Spc1(3, "123", (1, 2, 3, 4, 4, 3, 2, 1))),
    ("SPC1", ["1", "123456", "1", "THRU", "99"], "spc1s", 0,    # absent grids of a range skipped
     Spc1(1, "123456", (1, 2, 3, 4))),
    ("RBE2", ["20", "1", "123", "2", "3", "THRU", "4", "", "", "1.-5"], "rbe2s", 20,
     Rbe2(20, 1, "123", (2, 3, 4))),
    ("PELAS", ["8", "1.+3", "0.01", "", "9", "-2.5+3"], "pelas", 9, Pelas(9, -2500.0)),
    ("CELAS1", ["7", "", "", "", "2", "5"], "springs", 7,       # PID = EID, ground end first
     Spring(7, 2, 5, 0, 0, pid=7, card="CELAS1")),
    ("CELAS2", ["31", "-1.5+4", "1", "6", "2", "6", "0.02", "0."], "springs", 31,
     Spring(31, 1, 6, 2, 6, k=-1.5e4, card="CELAS2")),
]


@pytest.mark.parametrize("name, fields, attr, key, expected", CARDS,
                         ids=[f"{c[0]}-{i}" for i, c in enumerate(CARDS)])
def test_card_in_all_formats(name, fields, attr, key, expected):
    decks = {fmt: read_deck_text(BASE + in_format(fmt, name, fields), name=f"{fmt}.bdf")
             for fmt in ("small", "large", "free")}
    canon = {fmt: no_src(d) for fmt, d in decks.items()}
    assert canon["small"] == canon["large"] == canon["free"]
    assert canon["small"][attr][key] == expected
    assert decks["large"].grids[1].src == "large.bdf:1"


def test_src_names_file_and_first_line():
    deck = read_deck_text(BASE + "$ comment\n" + fixed_card("CBAR", CARDS[4][1], large=True),
                          name="m.bdf")
    assert deck.cbars[3].src == "m.bdf:9"
    assert deck.pbars[1].src == "m.bdf:5"


# --------------------------------------------------------------------------------------------
# continuations, comments, control sections
# --------------------------------------------------------------------------------------------
_SPC_DATA = ["1", "123456", "1", "2", "3", "4", "5", "6"]
CONTINUATIONS = {
    "small-explicit": small("SPC1", *_SPC_DATA, cont="+C1") + small("+C1", "7", "8"),
    "small-implicit-blank": small("SPC1", *_SPC_DATA) + small("", "7", "8"),
    "small-implicit-plus": small("SPC1", *_SPC_DATA) + small("+", "7", "8"),
    "small-marker-blank-child": small("SPC1", *_SPC_DATA, cont="+C1") + small("", "7", "8"),
    "large-explicit": ("SPC1*   1               123456          1               2               *S1\n"
                       "*S1     3               4               5               6               *S2\n"
                       "*S2     7               8\n"),
    "large-implicit": ("SPC1*   1               123456          1               2\n"
                       "*       3               4               5               6\n"
                       "*       7               8\n"),
    "free-trailing-comma": "SPC1,1,123456,1,2,3,4,5,6,\n,7,8\n",
    "free-explicit": "SPC1,1,123456,1,2,3,4,5,6,+A\n+A,7,8\n",
    "free-plus": "SPC1,1,123456,1,2,3,4,5,6\n+,7,8\n",
    # NASTRAN reads its input in either letter case: '+a' continues a card ending '+A'
    # (pyNastran's ar29sadl.bdf writes 'pbush1d, ..., +pb1' and '+PB1, ...')
    "free-marker-other-case": "SPC1,1,123456,1,2,3,4,5,6,+a1\n+A1,7,8\n",
    "small-marker-other-case": small("SPC1", *_SPC_DATA, cont="+c1") + small("+C1", "7", "8"),
    "free-large": "SPC1*,1,123456,1,2\n*,3,4,5,6\n*,7,8\n",
    "small-parent-free-child": small("SPC1", *_SPC_DATA) + ",7,8\n",
    "comments-between": (small("SPC1", *_SPC_DATA, cont="+C1") + "$ a comment\n\n"
                         "   $ indented comment\n" + small("+C1", "7", "8")),
    "tabs": "SPC1\t1\t123456\t1\t2\t3\t4\t5\t6\n\t7\t8\n",
    "trailing-comments": "SPC1,1,123456,1,2,3,4,5,6, $ eight fields\n,7,8 $ and two more\n",
}


@pytest.mark.parametrize("text", CONTINUATIONS.values(), ids=CONTINUATIONS.keys())
def test_continuations(text):
    deck = read_deck_text(EIGHT_GRIDS + text)
    assert no_src(deck)["spc1s"] == [Spc1(1, "123456", tuple(range(1, 9)))]
    assert deck.spc1s[0].src == "<string>:9"


def test_large_field_grid_with_explicit_marker():
    text = ("GRID*   7                               1.25            -3.5            *G7\n"
            "*G7     4.0E-1          0               246\n")
    assert no_src(read_deck_text(text))["grids"][7] == Grid(7, (1.25, -3.5, 0.4), "246")


def test_continuation_marker_mismatch():
    text = EIGHT_GRIDS + small("SPC1", *_SPC_DATA, cont="+A") + small("+B", "7", "8")
    with pytest.raises(DeckFormatError) as info:
        read_deck_text(text, name="c.bdf")
    assert_names(info.value, "c.bdf", 10, "SPC1", 1)


def test_continuation_without_card():
    with pytest.raises(DeckFormatError, match="continuation line without a card") as info:
        read_deck_text("$ first\n+,1,2\n", name="c.bdf")
    assert (info.value.file, info.value.line) == ("c.bdf", 2)


def test_comments_and_param_and_begin_end():
    text = ("$ header\nBEGIN BULK\nPARAM,POST,-1\nPARAM   AUTOSPC YES\n"
            "GRID,1,,0.,0.,0. $ a grid\n$GRID,2,,1.,0.,0.\nGRID    2               1.$comment\n"
            "ENDDATA\nthis is not read\nCQUAD4,1,2,3\n")
    deck = read_deck_text(text)
    assert sorted(deck.grids) == [1, 2] and deck.grids[2].xyz == (1.0, 0.0, 0.0)


def test_case_and_spacing_do_not_matter():
    text = "grid, 1 ,, 0. ,0.,0.\nGrId    2               1.0e0\n"
    assert sorted(read_deck_text(text).grids) == [1, 2]


def test_case_control_skipped():
    text = ("ID test\nSOL 101\nCEND\nTITLE = frame, with commas\nSUBCASE 1\n  LOAD = 1\n"
            "  SPC = 1\nBEGIN BULK\nGRID,1,,0.,0.,0.\nENDDATA\n")
    deck = read_deck_text(text)
    assert list(deck.grids) == [1] and deck.grids[1].src == "<string>:9"


def test_cend_without_begin_bulk():
    with pytest.raises(DeckFormatError, match="BEGIN BULK"):
        read_deck_text("SOL 101\nCEND\nGRID,1,,0.,0.,0.\n")


# --------------------------------------------------------------------------------------------
# INCLUDE
# --------------------------------------------------------------------------------------------
def test_include_nested(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "main.bdf").write_text(
        "BEGIN BULK\nINCLUDE 'sub/grids.bdf'\nCBAR,1,1,1,2,0.,1.,0.\nENDDATA\n")
    (tmp_path / "sub" / "grids.bdf").write_text(
        "GRID,1,,0.,0.,0.\nINCLUDE 'more.bdf' $ relative to sub/\n")
    (tmp_path / "sub" / "more.bdf").write_text(
        "$ more\nGRID,2,,1.,0.,0.\nPBAR,1,1,1.,1.,1.,1.\nMAT1,1,1.+7,,.3\n")
    deck = read_deck(tmp_path / "main.bdf")
    assert sorted(deck.grids) == [1, 2] and 1 in deck.cbars
    assert len(deck.files) == 3
    assert deck.grids[2].src.endswith("more.bdf:2") and deck.cbars[1].src.endswith("main.bdf:3")


def test_include_from_text_uses_base_dir(tmp_path):
    (tmp_path / "g.bdf").write_text("GRID,1,,0.,0.,0.\n")
    deck = read_deck_text("INCLUDE 'g.bdf'\nGRID,2,,1.,0.,0.\n", base_dir=tmp_path)
    assert sorted(deck.grids) == [1, 2]


@pytest.mark.parametrize("files", [
    {"a.bdf": "INCLUDE 'a.bdf'\n"},
    {"a.bdf": "GRID,1,,0.,0.,0.\nINCLUDE 'b.bdf'\n", "b.bdf": "$ b\nINCLUDE 'a.bdf'\n"},
], ids=["self", "two-files"])
def test_include_loop(tmp_path, files):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    with pytest.raises(DeckFormatError, match="INCLUDE loop") as info:
        read_deck(tmp_path / "a.bdf")
    assert info.value.card == "INCLUDE" and info.value.field == 2


def test_include_missing_file(tmp_path):
    (tmp_path / "a.bdf").write_text("GRID,1,,0.,0.,0.\nINCLUDE 'nope.bdf'\n")
    with pytest.raises(DeckFormatError, match="cannot read included file") as info:
        read_deck(tmp_path / "a.bdf")
    assert_names(info.value, str(tmp_path / "a.bdf"), 2, "INCLUDE", 2)


def test_error_in_included_file_names_that_file(tmp_path):
    (tmp_path / "a.bdf").write_text("GRID,1,,0.,0.,0.\nINCLUDE 'b.bdf'\n")
    (tmp_path / "b.bdf").write_text("$ b\n\nGRID,2,,1.2.3,0.,0.\n")
    with pytest.raises(DeckFormatError) as info:
        read_deck(tmp_path / "a.bdf")
    assert_names(info.value, str(tmp_path / "b.bdf"), 3, "GRID", 4)


def test_missing_deck_file(tmp_path):
    with pytest.raises(DeckFormatError, match="cannot read the deck"):
        read_deck(tmp_path / "none.bdf")


# --------------------------------------------------------------------------------------------
# THRU
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("card, grids", [
    ("SPC1,1,123456,1,THRU,8", tuple(range(1, 9))),
    ("SPC1,1,123456,2,THRU,4,8", (2, 3, 4, 8)),
    ("SPC1,1,123456,7,1,THRU,2", (7, 1, 2)),
    ("SPC1,1,123456,5,THRU,100", (5, 6, 7, 8)),  # NASTRAN: absent grids of a range are skipped
])
def test_spc1_thru(card, grids):
    assert read_deck_text(EIGHT_GRIDS + card + "\n").spc1s[0].grids == grids


def test_rbe2_thru():
    deck = read_deck_text(EIGHT_GRIDS + "RBE2,1,1,123,2,THRU,5,8\n")
    assert deck.rbe2s[1].gm == (2, 3, 4, 5, 8)


@pytest.mark.parametrize("card, field, why", [
    ("SPC1,1,123456,THRU,8", 4, "THRU must follow"),
    ("SPC1,1,123456,5,THRU,3", 6, "below its start"),
    ("SPC1,1,123456,5,THRU", 5, "followed by"),
    ("RBE2,1,1,123,THRU,4", 5, "THRU must follow"),
])
def test_thru_errors(card, field, why):
    with pytest.raises(DeckFormatError, match=why) as info:
        read_deck_text(EIGHT_GRIDS + card + "\n", name="t.bdf")
    assert_names(info.value, "t.bdf", 9, card.split(",")[0], field)


# --------------------------------------------------------------------------------------------
# malformed input: DeckFormatError naming file, line, card and field
# --------------------------------------------------------------------------------------------
MALFORMED = [
    ("unknown card", "CQUAD4,1,1,1,2,3,4\n", 8, "CQUAD4", 1, "unknown card"),
    ("bad real", "GRID,5,,1.2.3,0.,0.\n", 8, "GRID", 4, "not a real"),
    ("bad real in large field", "GRID*   5                               1.0             abc\n"
                                "*       0.\n", 8, "GRID", 5, "not a real"),
    ("integer field given a real", "GRID,5.,,0.,0.,0.\n", 8, "GRID", 2, "given a real"),
    ("duplicate GRID", "GRID,1,,0.,0.,0.\n", 8, "GRID", 2, "duplicate GRID ID 1"),
    ("duplicate element across cards", "CBAR,9,1,1,2,0.,0.,1.\nCELAS2,9,1.,1,1\n", 9, "CELAS2",
     2, "duplicate element ID 9"),
    ("duplicate property across cards of one family", "PBARL,1,1,,BAR\n,.1,.1\n", 8, "PBARL", 2,
     "duplicate property ID 1 (already defined by PBAR at bad.bdf:5)"),
    ("duplicate property of one card", "PELAS,8,5.,,,7,6.\n", 8, "PELAS", 6, "duplicate property ID 7"),
    ("CP undefined", "GRID,5,1,0.,0.,0.\n", 8, "GRID", 3, "coordinate system 1 is not defined"),
    ("CD undefined", "GRID,5,,0.,0.,0.,2\n", 8, "GRID", 7, "coordinate system 2 is not defined"),
    ("CORD2R RID undefined", "CORD2R,3,4,0.,0.,0.,0.,0.,1.\n,1.,0.,0.\n", 8, "CORD2R", 3,
     "RID 4: coordinate system 4 is not defined"),
    ("CORD2R B at A", "CORD2R,3,,0.,0.,0.,0.,0.,0.\n,1.,0.,0.\n", 8, "CORD2R", 7, "coincides"),
    ("CORD2R C on z", "CORD2R,3,,0.,0.,0.,0.,0.,1.\n,0.,0.,2.\n", 9, "CORD2R", 10, "on the z axis"),
    ("CORD2C duplicate", "CORD2C,3,,0.,0.,0.,0.,0.,1.\nCORD1R,3,1,2,3\n", 9, "CORD1R", 2,
     "duplicate CORD ID 3"),
    ("CORD1R missing grid", "CORD1R,3,1,2,99\n", 8, "CORD1R", 5, "grid 99 does not exist"),
    ("CORD1R same grid", "CORD1R,3,1,2,2\n", 8, "CORD1R", 3, "three different grids"),
    ("CORD loop", "CORD2R,3,4,0.,0.,0.,0.,0.,1.\n,1.,0.,0.\nCORD2R,4,3,0.,0.,0.,0.,0.,1.\n,1.,0.,0.\n",
     8, "CORD2R", 2, "depends on itself"),
    ("SEID", "GRID,5,,0.,0.,0.,,,3\n", 8, "GRID", 9, "superelements"),
    ("PS repeated digit", "GRID,5,,0.,0.,0.,,121\n", 8, "GRID", 8, "without repeats"),
    ("PS digit 7", "GRID,5,,0.,0.,0.,,7\n", 8, "GRID", 8, "digits 1-6"),
    ("CBAR pin flag 7", small("CBAR", "9", "1", "1", "2", "0.", "0.", "1.") + small("", "127"),
     9, "CBAR", 10, "digits 1-6"),
    ("CBAR pin flags PB repeated", "CBAR,9,1,1,2,0.,0.,1.\n,,4566\n", 9, "CBAR", 11, "repeats"),
    ("CBAR offset not a real", "CBAR,9,1,1,2,0.,0.,1.\n,,,abc\n", 9, "CBAR", 12, "not a real"),
    ("CBAR OFFT", "CBAR,9,1,1,2,0.,0.,1.,EEG\n", 8, "CBAR", 9, "OFFT"),
    ("CBAR OFFT orientation in the offset system", "CBAR,9,1,1,2,0.,0.,1.,OOO\n", 8, "CBAR", 9, "OFFT"),
    ("BAROR twice", "BAROR,,1,,,0.,0.,1.\nBAROR,,1\n", 9, "BAROR", 1, "only one BAROR"),
    ("BAROR G0 and X2", "BAROR,,1,,,3,1.\n", 8, "BAROR", 7, "G0"),
    ("CBAR G0 with X2", "CBAR,9,1,1,2,3,1.,0.\n", 8, "CBAR", 7, "G0"),
    ("CBAR no orientation", "CBAR,9,1,1,2\n", 8, "CBAR", 6, "orientation"),
    ("CBAR too many fields", "CBAR,9,1,1,2,0.,0.,1.\n,,,,,,,,,\n,1\n", 10, "CBAR", 18,
     "at most 17"),
    ("MAT1 NU 0.7", "MAT1,2,2.1+11,,0.7\n", 8, "MAT1", 5, "-1 < NU <= 0.5"),
    ("MAT1 NU -1", "MAT1,2,2.1+11,,-1.\n", 8, "MAT1", 5, "-1 < NU <= 0.5"),
    ("MAT1 none", "MAT1,2\n", 8, "MAT1", 3, "E or G"),
    ("MAT1 only NU", "MAT1,2,,,.3\n", 8, "MAT1", 3, "E or G"),
    ("MAT1 negative E", "MAT1,2,-1.,,.3\n", 8, "MAT1", 3, ">= 0"),
    ("MAT1 G zero, NU blank", "MAT1,2,2.+11,0.\n", 8, "MAT1", 4, "undefined"),
    ("MAT1 E and G zero", "MAT1,2,0.,,.3\n", 8, "MAT1", 3, "both zero"),
    ("SPC enforced value", "SPC,1,1,123,0.1\n", 8, "SPC", 5, "enforced displacement"),
    ("SPC second enforced value", "SPC,1,1,123,,2,3,-1.\n", 8, "SPC", 8, "enforced displacement"),
    ("SPC no component", "SPC,1,1\n", 8, "SPC", 4, "component 0 or blank names scalar points, but point 1 is no SPOINT"),
    ("PBAR K1 negative", "PBAR,2,1,1.,1.,1.,1.\n,,,,,,,,\n,-1.\n", 10, "PBAR", 18, "> 0"),
    ("PBAR K2 without area", "PBAR,2,1,,1.,1.,1.\n,,,,,,,,\n,,1.\n", 10, "PBAR", 19, "area"),
    ("GRDSET twice", "GRDSET,,,,,,,3\nGRDSET,,,,,,,3\n", 9, "GRDSET", 1, "only one GRDSET"),
    ("GRDSET CP undefined", "GRDSET,,2\n", 8, "GRDSET", 3, "coordinate system 2 is not defined"),
    ("GRDSET CD undefined", "GRDSET,,,,,,1\n", 8, "GRDSET", 7, "GRID 1 at bad.bdf:1"),
    ("GRDSET SEID used", "GRDSET,,,,,,,,4\n", 8, "GRDSET", 9, "superelements"),
    ("GRDSET X1", "GRDSET,,,1.\n", 8, "GRDSET", 4, "must be blank"),
    ("CROD second element half written", "CROD,9,1,1,2,3\n", 8, "CROD", 8, "second CROD"),
    ("CROD too many fields", "CROD,9,1,1,2,3,1,2,3,+A\n+A,4\n", 9, "CROD", 10, "at most 9"),
    ("PROD without A", "PROD,9,1\n", 8, "PROD", 4, "required real"),
    ("PBAR I12 too large", "PBAR,2,1,1.,1.,1.,1.\n,,,,,,,,\n,,,1.\n", 10, "PBAR", 20, "I1 * I2 > I12^2"),
    ("PBARL type HAT1", "PBARL,2,1,,HAT1\n,.1,.01,.1,.02,.01\n", 8, "PBARL", 5, "TYPE HAT1 not supported"),
    ("PBARL angle leg", "PBARL,2,1,,L\n,.1,.1,.1,.01\n", 9, "PBARL", 12, "horizontal leg thickness DIM3"),
    ("PBARL group", "PBARL,2,1,MYLIB,BAR\n,.1,.1\n", 8, "PBARL", 4, "GROUP MYLIB"),
    ("PBARL dimension zero", "PBARL,2,1,,BAR\n,.1,0.\n", 9, "PBARL", 11, "DIM2 must be > 0"),
    ("PBARL dimension missing", "PBARL,2,1,,TUBE\n,.1\n", 9, "PBARL", 11, "required real"),
    ("PBARL tube inside out", "PBARL,2,1,,TUBE\n,.1,.2\n", 9, "PBARL", 11, "inner radius"),
    ("PBARL TUBE2 wall thicker than the radius", "PBARL,2,1,,TUBE2\n,.1,.2\n", 9, "PBARL", 11, "wall thickness"),
    ("PBARL box walls", "PBARL,2,1,,BOX\n,.1,.1,.05,.01\n", 9, "PBARL", 12, "horizontal walls"),
    ("PBARL too many dims", "PBARL,2,1,,ROD\n,.1,0.,.3\n", 9, "PBARL", 12, "at most 11"),
    ("CELAS2 without K", "CELAS2,9,,1,1\n", 8, "CELAS2", 3, "required real"),
    ("CELAS scalar point", "CELAS2,9,1.,1,0\n", 8, "CELAS2", 5, "names a scalar point, but point 1 is no SPOINT"),
    ("CELAS both grounded", "CELAS2,9,1.\n", 8, "CELAS2", 4, "grounded"),
    ("CELAS two digits", "CELAS1,9,7,1,12\n", 8, "CELAS1", 5, "one digit"),
    ("SPC1 component 0", "SPC1,1,0,1\n", 8, "SPC1", 3, "point 1 is no SPOINT"),
    ("SPC1 component 7", "SPC1,1,7,1\n", 8, "SPC1", 3, "digits 1-6"),
    ("SPC1 no grids", "SPC1,1,123\n", 8, "SPC1", 4, "at least one grid"),
    ("RBE2 real in grid list", "RBE2,9,1,123,2,3.,4\n", 8, "RBE2", 6, "given a real"),
    ("RBE2 text in grid list", "RBE2,9,1,123,2,abc\n", 8, "RBE2", 6, "not an integer"),
    ("RBE2 after ALPHA TREF", "RBE2,9,1,123,2,1.-5,20.,3.\n", 8, "RBE2", 6, "ALPHA and TREF"),
    ("negative ID", "GRID,-5,,0.,0.,0.\n", 8, "GRID", 2, ">= 1"),
    ("too many free fields", "GRID,5,,0.,0.,0.,,,,+A,1\n", 8, None, None, "at most 8 data"),
    ("beyond column 80", small("GRID", "5", "", "0.", "0.", "0.").rstrip("\n").ljust(80) + "X\n",
     8, None, None, "column 80"),
    ("bad INCLUDE", "INCLUDE 'x.bdf\n", 8, "INCLUDE", 2, "INCLUDE 'file'"),
]


def test_property_ids_are_unique_within_their_family_only():
    """A PELAS, PROD, PBUSH and PGAP may share ID 1 with the PBAR: each element names a property
    of its own family (PROPERTY_FAMILIES), so each gets its own card, as in NASTRAN."""
    from solver_adapters.bdf.reader import PROPERTY_FAMILIES
    deck = read_deck_text(BASE + "PELAS,1,5.\nPROD,1,1,.5\nPBUSH,1,K,1.,2.,3.\nPGAP,1,,,1.+6\n"
                          "CELAS1,10,1,1,1,2,1\nCROD,11,1,1,3\nCBAR,12,1,1,4,0.,1.,0.\n"
                          "CBUSH,13,1,2,3,0.,0.,1.\nCGAP,14,1,3,4,1.,0.,0.\n", name="shared.bdf")
    assert (deck.pelas[1].k, deck.prods[1].a, deck.pbars[1].a, deck.pbushes[1].k[:3], deck.pgaps[1].ka) == \
        (5.0, 0.5, 1.0, (1.0, 2.0, 3.0), 1e6)
    assert set(PROPERTY_FAMILIES.values()) == {"bar", "rod", "bush", "elas", "gap"}


@pytest.mark.parametrize("text, line, card, field, why", [m[1:] for m in MALFORMED],
                         ids=[m[0] for m in MALFORMED])
def test_malformed(text, line, card, field, why):
    with pytest.raises(DeckFormatError, match=re.escape(why)) as info:
        read_deck_text(BASE + text, name="bad.bdf")
    exc = info.value
    if card is None:  # line-level errors: no card yet
        assert (exc.file, exc.line) == ("bad.bdf", line) and f"bad.bdf:{line}" in str(exc)
    else:
        assert_names(exc, "bad.bdf", line, card, field)


def test_continuation_error_names_continuation_line():
    text = BASE + small("CBAR", "9", "1", "1", "2", "0.", "0.", "1.") + "$ c\n" + small("", "", "7")
    with pytest.raises(DeckFormatError, match="digits 1-6 .*continuation line, field 3") as info:
        read_deck_text(text, name="p.bdf")
    assert_names(info.value, "p.bdf", 10, "CBAR", 11)


# --------------------------------------------------------------------------------------------
# model errors (validate): ModelError naming src and card
# --------------------------------------------------------------------------------------------
MODEL_ERRORS = [
    ("missing grid", "CBAR,20,1,1,99,0.,0.,1.\n", "CBAR 20", "99"),
    ("missing G0", "CBAR,20,1,1,2,99\n", "CBAR 20", "99"),
    ("missing PBAR", "CBAR,20,5,1,2,0.,0.,1.\n", "CBAR 20", "PID 5"),
    ("PELAS as PBAR", "CBAR,20,7,1,2,0.,0.,1.\n", "CBAR 20", "it is a PELAS"),
    ("missing MAT1", "PBAR,5,9,1.,1.,1.,1.\n", "PBAR 5", "MID 9"),
    ("GA == GB", "CBAR,20,1,1,1,0.,0.,1.\n", "CBAR 20", "same grid"),
    ("zero length", "GRID,9,,0.,0.,0.\nCBAR,20,1,1,9,0.,0.,1.\n", "CBAR 20", "zero length"),
    ("parallel vector", "CBAR,20,1,1,2,-2.,0.,0.\n", "CBAR 20", "parallel"),
    ("parallel G0", "GRID,9,,5.,0.,0.\nCBAR,20,1,1,2,9\n", "CBAR 20", "parallel"),
    ("zero vector", "CBAR,20,1,1,2,0.,0.,0.\n", "CBAR 20", "zero"),
    ("RBE2 missing GM", "RBE2,20,1,123,2,98\n", "RBE2 20", "98"),
    ("RBE2 GN in GM", "RBE2,20,1,123,2,1\n", "RBE2 20", "also a dependent"),
    ("SPC1 missing grid", "SPC1,4,123,1,97\n", "SPC1 4", "97"),
    ("spring missing grid", "CELAS2,20,1.,96,1\n", "CELAS2 20", "96"),
    ("CELAS1 missing PELAS", "CELAS1,20,8,1,1\n", "CELAS1 20", "PID 8"),
    ("CROD PBAR as PROD", "CROD,20,1,1,2\n", "CROD 20", "it is a PBAR"),
    ("CROD missing grid", "PROD,9,1,1.\nCROD,20,9,1,95\n", "CROD 20", "95"),
    ("CONROD missing MAT1", "CONROD,20,1,2,9,1.\n", "CONROD 20", "MID 9"),
    ("CONROD zero length", "GRID,9,,0.,0.,0.\nCONROD,20,1,9,1,1.\n", "CONROD 20", "zero length"),
    ("PROD missing MAT1", "PROD,9,8,1.\n", "PROD 9", "MID 8"),
    ("CBAR PROD as PBAR", "PROD,9,1,1.\nCBAR,20,9,1,2,0.,0.,1.\n", "CBAR 20", "it is a PROD"),
    ("SPCADD missing set", "SPC1,3,123,1\nSPCADD,9,3,4\n", "SPCADD 9", "set(s) 4 not found"),
    ("SPCADD SID of a set", "SPC,9,1,123\nSPCADD,9,9\n", "SPCADD 9", "also the ID of an SPC"),
]


@pytest.mark.parametrize("text, entity, why", [m[1:] for m in MODEL_ERRORS],
                         ids=[m[0] for m in MODEL_ERRORS])
def test_model_errors(text, entity, why):
    with pytest.raises(ModelError) as info:
        read_deck_text(BASE + text, name="model.bdf")
    message = str(info.value)
    line = 8 + text.count("\n") - 1
    assert f"model.bdf:{line}: {entity}" in message and why in message


def test_model_errors_are_all_listed():
    text = BASE + "CBAR,20,1,1,99,0.,0.,1.\nCELAS1,21,8,1,1\n"
    with pytest.raises(ModelError, match="2 model error") as info:
        read_deck_text(text)
    assert "CBAR 20" in str(info.value) and "CELAS1 21" in str(info.value)


# --------------------------------------------------------------------------------------------
# field formatters
# --------------------------------------------------------------------------------------------
def half_unit_of_last_digit(text: str) -> float:
    """Half a unit in the last printed digit of a NASTRAN real (``1.235-4`` -> 0.5e-7)."""
    m = re.fullmatch(r"-?(\d*)\.(\d*)(?:E?([+-]\d+))?", text.upper())
    return 0.5 * 10.0 ** (int(m.group(3) or 0) - len(m.group(2)))


FLOAT_8 = [  # value, expected text (the most precise that fits; normalised mantissa on ties)
    (0.0, "0."), (-0.0, "0."), (1.0, "1."), (-1.0, "-1."), (0.1, ".1"), (100.0, "100."),
    (1e-9, "1.-9"), (1e-5, "1.-5"), (1.23456789e12, "1234.6+9"), (-0.000123456, "-1.235-4"),
    (123456789.0, "1.2346+8"), (-123456789.0, "-1.235+8"), (12345678.0, "1.2346+7"),
    (1e-300, "1.-300"), (1e300, "1.+300"), (1 / 3, ".3333333"), (-1 / 3, "-.333333"),
    (2.1e11, "2.1+11"), (-1.2345678e-12, "-1.23-12"), (-123.456789, "-123.457"),
    (99999999.5, "1.+8"), (0.999999999, "1."), (5e-324, "5.-324"),
    (1.7976931348623157e308, "1.79+308"),  # rounding up would overflow: rounded down
    (2.2250738585072014e-308, "2.23-308"), (80769230769.23077, "80.769+9"),
]


@pytest.mark.parametrize("x, expected", FLOAT_8, ids=[repr(c[0]) for c in FLOAT_8])
def test_print_float_8(x, expected):
    text = print_float_8(x)
    assert text == expected and len(text) <= 8
    # Tolerance: the printed decimal is x correctly rounded to its last digit (at most half a
    # unit there; a whole unit where rounding up would overflow to inf and it rounds down);
    # reading it back to binary adds at most one ulp of x.
    units = 2 if abs(x) > 1.79e308 else 1
    assert abs(parse_real(text) - x) <= units * half_unit_of_last_digit(text) + 2 * math.ulp(x)


FLOAT_16 = [  # value, significant digits that 16 characters must keep
    (0.0, 0), (1.0, 1), (-1 / 3, 14), (1e-9, 1), (1.23456789e12, 9), (-0.000123456, 6),
    (math.pi, 15), (math.pi * 1e5, 15), (-math.pi * 1e-7, 12), (-math.e * 1e-17, 11),
    (-math.e * 1e-200, 10), (5e-324, 1), (1.7976931348623157e308, 11),
]


@pytest.mark.parametrize("x, digits", FLOAT_16, ids=[repr(c[0]) for c in FLOAT_16])
def test_print_float_16_and_free(x, digits):
    text = print_float_16(x)
    assert len(text) <= 16
    # Same tolerance reason as for 8 characters: correctly rounded to the last printed digit.
    # Where it falls short of full precision the cost is sign, point and exponent: "-d.ddd-17"
    # keeps 11 digits, "-d.ddd-200" 10; and never fewer digits than the value has.
    units = 2 if abs(x) > 1.79e308 else 1  # rounded down where rounding up overflows
    assert abs(parse_real(text) - x) <= units * half_unit_of_last_digit(text) + 2 * math.ulp(x)
    assert len(re.sub(r"[^0-9]", "", re.split(r"(?<=.)[+-]", text)[0]).strip("0")) >= digits
    assert parse_real(print_float_free(x)) == x   # free field keeps every bit


def test_print_float_rejects_non_finite():
    for f in (print_float_8, print_float_16, print_float_free):
        with pytest.raises(ValueError):
            f(float("nan"))


def test_format_card_layouts():
    fields = [1, "123456", *range(1, 12)]
    small_text = format_card("SPC1", fields, "small")
    assert small_text.splitlines() == ["SPC1           1  123456       1       2       3       4"
                                       "       5       6", "               7       8       9"
                                       "      10      11"]
    large_lines = format_card("SPC1", fields, "large").splitlines()
    assert large_lines[0].startswith("SPC1*   ") and len(large_lines) == 4
    assert all(line.startswith("*") for line in large_lines[1:])
    assert format_card("SPC1", fields, "free") == "SPC1,1,123456,1,2,3,4,5,6\n,7,8,9,10,11\n"
    assert format_card("GRID", [1, None, 0.0, None, None], "free") == "GRID,1,,0.0\n"
    with pytest.raises(ValueError, match="longer than 8"):
        format_card("GRID", [123456789], "small")
    with pytest.raises(ValueError, match="fmt must be"):
        format_card("GRID", [1], "wide")


# --------------------------------------------------------------------------------------------
# write -> read round trips
# --------------------------------------------------------------------------------------------
def generated_deck(seed: int = 7) -> Deck:
    """A frame: a wavy line of bars, a 3-branch joint (coincident grids, RBE2 CM=123), springs."""
    rng = np.random.default_rng(seed)
    deck = Deck()
    n = 12
    for i in range(1, n + 1):
        xyz = (i * 0.25 + rng.normal() * 1e-3, rng.normal() * 0.1, rng.normal() * 1e-6)
        deck.grids[i] = Grid(i, tuple(float(v) for v in xyz), "123456" if i == 1 else "")
    for i in (101, 102):
        deck.grids[i] = dataclasses.replace(deck.grids[6], id=i, ps="")
    deck.grids[200] = Grid(200, (0.0, 0.0, 1.0e3 * rng.random()), "")
    for e in range(1, n):
        if e % 3:
            deck.cbars[e] = CBar(e, 1 + e % 2, e, e + 1, x=tuple(float(v) for v in
                                                                 rng.normal(size=3) + (0, 0, 2)))
        else:
            deck.cbars[e] = CBar(e, 1 + e % 2, e, e + 1, g0=200)
    for pid in (1, 2):
        a, i1, i2 = rng.random(3) * np.array([1e-2, 1e-5, 2e-5])
        deck.pbars[pid] = PBar(pid, pid, float(a), float(i1), float(i2), float(i1 + i2))
    deck.mat1s[1] = Mat1(1, 2.1e11, 2.1e11 / 2.6, 0.3)
    deck.mat1s[2] = Mat1(2, 7.0e10 * (1 + rng.random()), 2.6e10, 0.33)
    deck.spc1s.append(Spc1(1, "123456", (1, 12)))
    deck.spc1s.append(Spc1(2, "3", tuple(range(2, 12))))
    deck.rbe2s[500] = Rbe2(500, 6, "123", (101, 102))
    for pid in (31, 32, 33):
        deck.pelas[pid] = Pelas(pid, float(rng.lognormal(8, 2)))
    deck.springs[600] = Spring(600, 6, 4, 101, 4, k=float(-rng.lognormal(6, 1)), card="CELAS2")
    deck.springs[601] = Spring(601, 101, 5, 102, 5, pid=31, card="CELAS1")
    deck.springs[602] = Spring(602, 12, 2, 0, 0, pid=33, card="CELAS1")
    deck.springs[603] = Spring(603, 102, 6, 0, 0, k=1.0e-7 / 3, card="CELAS2")
    return deck


def _floats_and_rest(deck: Deck):
    """Every real of the deck in a fixed order, and everything else (with reals blanked)."""
    floats: list[float] = []

    def walk(x):
        if isinstance(x, float):
            floats.append(x)
            return None
        if isinstance(x, tuple):
            return tuple(walk(v) for v in x)
        if dataclasses.is_dataclass(x):
            return type(x)(**{f.name: walk(getattr(x, f.name)) for f in dataclasses.fields(x)})
        if isinstance(x, dict):
            return {k: walk(v) for k, v in sorted(x.items())}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return x
    rest = walk(no_src(deck))
    return np.array(floats), rest


def _through(deck: Deck, fmt) -> Deck:
    """``deck`` with every real replaced by what ``fmt`` writes and the reader reads back."""
    out = {}
    for name, value in no_src(deck).items():
        def conv(x):
            changes = {f.name: (parse_real(fmt(getattr(x, f.name))) if isinstance(getattr(
                x, f.name), float) else tuple(parse_real(fmt(v)) for v in getattr(x, f.name))
                if f.name in ("xyz", "x") and getattr(x, f.name) is not None
                else getattr(x, f.name)) for f in dataclasses.fields(x)}
            return type(x)(**changes)
        out[name] = ([conv(v) for v in value] if isinstance(value, list)
                     else {k: conv(v) for k, v in value.items()})
    return Deck(**out)


def test_round_trip_small():
    deck = generated_deck()
    back = read_deck_text(write_deck(deck, "small"), name="small.bdf")
    # exact: every real read back is exactly what print_float_8 wrote for it
    assert no_src(back) == no_src(_through(deck, print_float_8))
    x, rest = _floats_and_rest(deck)
    y, rest_back = _floats_and_rest(back)
    assert rest == rest_back
    # 8 characters keep at least 3 significant digits ("-1.23-12"): 5e-3 relative at worst
    assert np.allclose(y, x, rtol=5e-3, atol=0)


@pytest.mark.parametrize("seed", [0, 7, 45])
def test_round_trip_large(seed):
    deck = generated_deck(seed)
    back = read_deck_text(write_deck(deck, "large"), name="large.bdf")
    # exact: every real read back is exactly what print_float_16 wrote for it
    assert no_src(back) == no_src(_through(deck, print_float_16))
    x, rest = _floats_and_rest(deck)
    y, rest_back = _floats_and_rest(back)
    assert rest == rest_back
    # 1e-12 relative where 16 characters hold 13+ significant digits: positive values in
    # [1e-9, 1e15) ("1.234567890123-9", "123456789012345.") and negative ones in [1e-2, 1e14).
    # A negative value needing an exponent ("-1.23456789012-6": sign, point, 2-character
    # exponent) keeps 12 digits, so at worst half a unit in the 12th digit: 5e-12 relative.
    ax = np.abs(x)
    tight = ((x > 0) & (ax >= 1e-9) & (ax < 1e15)) | ((ax >= 1e-2) & (ax < 1e14))
    assert np.allclose(y[tight], x[tight], rtol=1e-12, atol=0)
    assert np.allclose(y, x, rtol=5e-12, atol=0)


def test_round_trip_free():
    deck = generated_deck()
    text = write_deck(deck, "free")
    assert text.startswith("$") and "BEGIN BULK\n" in text and text.endswith("ENDDATA\n")
    # free field writes repr digits, which read back bit for bit
    assert no_src(read_deck_text(text, name="free.bdf")) == no_src(deck)


def test_round_trip_is_stable():
    """A deck read from a written deck writes the same text again (formatting is idempotent)."""
    for fmt in ("small", "large", "free"):
        text = write_deck(generated_deck(3), fmt)
        assert write_deck(read_deck_text(text), fmt) == text
