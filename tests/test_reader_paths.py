"""The deck reader's two paths give the same deck (solver_adapters/bdf/reader.py).

The bulk path (the card table and the bulk converters) must read every deck the reference path
reads into an equal deck (every collection, in the same order), and must refuse (so that the
reference path gives its located error) every deck the reference path refuses. Checked on every
deck of the test data and the fixtures, on the conformance suite's generated decks in every
field style, and on a few hundred mutations of a deck that holds every modelled card.
"""

from __future__ import annotations

import dataclasses
import random
from pathlib import Path

import pytest

from solver_adapters.bdf import _RETRY, _includes, _policy, validate
from solver_adapters.bdf.reader import read_cards, read_table
from solver_adapters.bdf.table import CardTable
from solver_adapters.bdf.tokens import LineReader, group_cards
from solver_adapters.conformance import FIELD_STYLES, deck_text, write_generated_deck

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data"


def both(text: str, base: Path, name: str = "m.bdf", keep: bool = False):
    """``(bulk, reference)``: each the deck, or the exception it raised."""
    top = (base / name).resolve()
    try:
        fast = read_table(CardTable(text, name, base, _includes(_policy(base, ()), top)), keep, validate)
    except _RETRY as exc:
        fast = exc
    inc = _includes(_policy(base, ()), top)
    inc.files.append(name)
    try:
        slow = read_cards(group_cards(LineReader(inc).lines(text, name, base)), keep, validate)
        slow.files = inc.files
    except _RETRY as exc:
        slow = exc
    return fast, slow


def ordered(deck) -> dict:
    """Every field of the deck, dictionaries as their item lists (so the order counts too)."""
    return {f.name: (list(v.items()) if isinstance(v := getattr(deck, f.name), dict) else v)
            for f in dataclasses.fields(deck)}


def assert_same(text: str, base: Path, keep: bool = False, must_read: bool = False) -> None:
    fast, slow = both(text, base, keep=keep)
    if isinstance(slow, Exception):
        assert isinstance(fast, Exception), f"the bulk path read a deck the reference path refuses: {slow}"
        assert not must_read, str(slow)
        return
    assert not isinstance(fast, Exception), f"the bulk path refused a deck that reads: {fast!r}"
    assert ordered(fast) == ordered(slow)


DECKS = sorted(p for p in DATA.glob("*.bdf")) + sorted((DATA / "decks").glob("*.*"))
FIXTURES = sorted((ROOT / "fixtures").glob("*/model.bdf"))


@pytest.mark.parametrize("path", DECKS + FIXTURES, ids=lambda p: f"{p.parent.name}/{p.name}")
@pytest.mark.parametrize("keep", [False, True])
def test_every_data_deck_reads_the_same_on_both_paths(path, keep):
    if path.suffix not in (".bdf", ".dat", ".nas", ".inc", ".inp"):
        pytest.skip("not a deck")
    assert_same(path.read_text(errors="replace"), path.parent, keep=keep)


@pytest.mark.parametrize("style", FIELD_STYLES)
def test_generated_decks_read_the_same_in_every_style(style, tmp_path):
    path, _ = write_generated_deck(tmp_path / "gen")
    from solver_adapters.bdf import read_deck
    text = deck_text(read_deck(path), style)
    assert_same(text, tmp_path, must_read=True)


BASE = """$ every modelled card, mixed formats
GRDSET,,0,,,,0,6
GRID    1               0.      0.      0.              123456
GRID,2,,1.,0.,0.,,
GRID*   3                               2.              .5
*       .25                                     345
GRID,4,,2.,1.,0.
GRID    5               3.      1.      0.
GRID    6       0       3.      2.      1.5-1   0
CORD2R  7       0       0.      0.      0.      0.      0.      1.      +C7
+C7     1.      0.      0.
GRID    8       7       1.      1.      1.      7
BAROR,,7,,,0.,0.,1.
CBAR    1               1       2
CBAR,2,7,2,3,,,,
,,6,0.,0.,.1,0.,0.,.1
CBAR    3       8       3       4       1
CBAR    11      7       5       6       0.      1.      0.      BGG
CBAR    12      7       6       8       0.      0.      1.
CBEAM   13      19      4       6       0.      0.      1.
PBEAM   19      1       1.-3    2.-6    3.-6    0.      4.-6
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
PBAR,8,1,2.E-3,2.5E-6,1.5E-6,3.E-6,,,
,,,,,,,,,
,.8,.7
CROD,4,9,4,5
CROD    14      10      5       8
PROD,9,1,1.E-4,1.E-8
PROD    10      1       2.-4
CONROD,5,1,3,1,1.5E-4,2.E-8
MAT1,1,2.1E11,,.3
SPC1,1,123,1,THRU,2
SPC,2,5,12,0.,4,3
SPCADD,3,1,2
RBE2,6,4,123456,5
PELAS,11,1.E5,,,12,2.5E4
CELAS1,7,11,5,4
CELAS1,8,12,,,5,5
CELAS2,9,3.E4,4,6,5,6
CELAS2,10,-2.E3,5,1
PARAM,AUTOSPC,YES
CONM2   20      5               1.5
"""
TOKENS = ["", "0", "-1", "1", "2", "3", "7", "9", "12", "1.5", "1.-3", "-2.5+2", "1.0D2", "ABC",
          "1_0", "nan", "inf", "99999999999", "THRU", "GGG", "BGG", "GOO", "123456", "21", "0.",
          "+", "YES", "1E3", "-0."]


def _mutate(text: str, rng: random.Random) -> str:
    lines = text.splitlines()
    k = rng.randrange(1, len(lines))
    line = lines[k]
    what = rng.random()
    if what < 0.1:
        del lines[k]
    elif what < 0.15:
        lines.insert(k, line)
    elif "," in line:
        items = line.split(",")
        items[rng.randrange(len(items))] = rng.choice(TOKENS)
        lines[k] = ",".join(items)
    else:
        width = 16 if line[:8].strip().endswith("*") or line.startswith("*") else 8
        slots = (64 // width)
        j = rng.randrange(slots + 1)
        line = line.ljust(80)
        start = 8 + width * j if j < slots else 0
        w = width if j < slots else 8
        lines[k] = (line[:start] + rng.choice(TOKENS).ljust(w)[:w] + line[start + w:]).rstrip()
    return "\n".join(lines) + "\n"


def test_base_deck_reads_on_the_bulk_path(tmp_path):
    fast, slow = both(BASE, tmp_path)
    assert not isinstance(slow, Exception), slow
    assert ordered(fast) == ordered(slow)
    assert len(fast.grids) == 7 and len(fast.cbars) == 6 and len(fast.rods) == 3


@pytest.mark.parametrize("seed", range(6))
def test_mutated_decks_agree(seed, tmp_path):
    """Random edits (a field replaced by a token that is sometimes right and often wrong, a
    line deleted or doubled) of the every-card deck: both paths agree on each."""
    rng = random.Random(seed)
    for _ in range(60):
        text = BASE
        for _ in range(rng.randint(1, 3)):
            text = _mutate(text, rng)
        assert_same(text, tmp_path, keep=rng.random() < 0.3)


def test_includes_read_the_same_on_both_paths(tmp_path):
    """Nested INCLUDEs (cards before, between and after them), and an ENDDATA inside an included
    file that ends the whole reading."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.bdf").write_text("GRID,3,,1.,1.,0.\nINCLUDE 'b.bdf'\nCBAR,2,7,2,3,0.,0.,1.\n")
    (tmp_path / "sub" / "b.bdf").write_text("$ b\nGRID    4               2.      1.      0.\n")
    main = ("GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nINCLUDE 'sub/a.bdf'\nCBAR,1,7,1,2,0.,0.,1.\n"
            "CBAR,3,7,3,4,0.,0.,1.\nPBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6\nMAT1,1,2.1E11,,.3\n")
    assert_same(main, tmp_path, must_read=True)
    (tmp_path / "sub" / "b.bdf").write_text("GRID,4,,2.,1.,0.\nENDDATA\nthis is never read\n")
    fast, slow = both(main, tmp_path)
    assert not isinstance(slow, Exception) and ordered(fast) == ordered(slow)
    assert set(fast.cbars) == set() and set(fast.grids) == {1, 2, 3, 4}


EARLY = """GRID           1       0      0.      0.      0.
GRID           2       0      .2      0.      0.
CBAR           1       1       1       2      0.      1.      0.
PBARL         1       1 MSCBML0     BAR                                {m}
+            .1      .05      0.
MAT1           1    7.+4              .3   2700.      0.      0.        {m}
+          2.7+3
"""


def test_a_continuation_marker_one_column_early_is_the_marker(tmp_path):
    """TACS's PBARL decks (FEMAP-style) put the lone "+" in column 72, field 9, which no card
    has as a value: both paths read it as field 10's marker, giving the deck with the marker in
    column 73; a "+" in field 9 beside a marker in field 10 stays the field's error."""
    early, proper = EARLY.format(m="+"), EARLY.format(m=" +")
    assert early.splitlines()[3][71] == "+" and proper.splitlines()[3][72] == "+"
    fast, slow = both(early, tmp_path)
    assert not isinstance(slow, Exception), slow
    assert ordered(fast) == ordered(slow)
    assert ordered(slow) == ordered(both(proper, tmp_path)[1])
    assert slow.mat1s[1].g == pytest.approx(7e4 / 2.6)
    fast, slow = both(EARLY.format(m="+A"), tmp_path)
    assert isinstance(slow, Exception) and isinstance(fast, Exception)
