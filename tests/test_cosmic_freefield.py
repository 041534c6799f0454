"""COSMIC NASTRAN's free-field input (solver_adapters.bdf.freefield): blanks as separators,
``=``, ``==``, ``*(i)``, ``%(E)``, ``/``, ``=(N)``, ``n)X``, ``)+X``, ``)`` in field 1, and
continuation lines away from their parents.

References: the NASTRAN-95 User's Manual, section 2.4.1.2 (rules 1-26) and its examples 1-7 in
2.4.1.2.1, whose generated card images are the expected values below; a frame written in free
field must be the same structure as its fixed-field twin, read field by field, so their
solutions are compared bit for bit; MYSTRAN, which reads no free-field replication, solving the
study ``blackbox import`` made of it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from blackbox.commands import import_deck
from conftest import needs_mystran
from solver_adapters.bdf import read_deck_text
from solver_adapters.bdf.freefield import expand, needed
from solver_adapters.bdf.numbers import typed
from solver_adapters.bdf.tokens import _split, _strip_comment
from solver_adapters.protocol import DeckFormatError
from test_deck_tail import _solve

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _images(*lines: str) -> list[list]:
    """The card images (fields 1-10, typed) the lines expand to."""
    out, _ = expand([_strip_comment(x) for x in lines], 0, "t.dat", _split)
    images = []
    for body in out:
        line = _split(body, "t.dat", 1)
        fields = [line.first, *line.data, line.cont]
        while fields and fields[-1] == "":
            fields.pop()
        images.append([typed(f) for f in fields])
    return images


def _cards(table: str) -> list[list]:
    """The manual's table of generated cards: one card per line, fields separated by '|'."""
    return [[typed(f) for f in row.split("|")] for row in table.strip().splitlines()]


@pytest.mark.parametrize("lines, table", [
    # example 1: "=", "*(i)", "==", then "=(3)" repeating the line's increments
    (("GRID, 2, 3, 1.0 2.0,, 4,316", "=, *(1), =, *(.2), == $", "=(3)"),
     """GRID|2|3|1.0|2.0||4|316
        GRID|3|3|1.2|2.0||4|316
        GRID|4|3|1.4|2.0||4|316
        GRID|5|3|1.6|2.0||4|316
        GRID|6|3|1.8|2.0||4|316"""),
    # example 2: the same cards by "%(E)", an increment that ends at E
    (("grid,2,3,1.0,2.0,,4,316", "=(4),*(1),=,%(1.8),=="),
     """GRID|2|3|1.0|2.0||4|316
        GRID|3|3|1.2|2.0||4|316
        GRID|4|3|1.4|2.0||4|316
        GRID|5|3|1.6|2.0||4|316
        GRID|6|3|1.8|2.0||4|316"""),
    # example 3: a field index "7)"
    (("Grid, 2 3 1.0 2.0, 7) 4, 316",), "GRID|2|3|1.0|2.0||4|316"),
    # example 4: "10)+abc", and ")" in field 1 continuing the card before
    (("Tabled3,62, 126.9, 30.0 10)+abc", "),  1.23e+4,  5.67+8, 1234567. endt"),
     """TABLED3|62|126.9|30.0||||||+ABC
        +ABC|1.23E+4|5.67+8|1234567.|ENDT"""),
    # example 5: ")+aBc" for field 10
    (("taBLed3, 62 126.9 30.0 )+aBc",), "TABLED3|62|126.9|30.0||||||+ABC"),
    # example 7: continuation IDs +A-X counted up, continuations placed after their parents
    (("PBAR, 3, 4, 5.0 , 6.0, )+ABC-1", "= , *(1), =, *(2.)  ==", "=(2)",
      "+ABC-1, 7.7  8.8  9  )+DEF-22", "=(3),=="),
     """PBAR|3|4|5.0|6.0|||||+ABC-1
        +ABC-1|7.7|8.8|9||||||+DEF-22
        PBAR|4|4|7.0|6.0|||||+ABC-2
        +ABC-2|7.7|8.8|9||||||+DEF-23
        PBAR|5|4|9.0|6.0|||||+ABC-3
        +ABC-3|7.7|8.8|9||||||+DEF-24
        PBAR|6|4|11.0|6.0|||||+ABC-4
        +ABC-4|7.7|8.8|9||||||+DEF-25"""),
    # rule 25: "/" is the field before's operation ("///" three times)
    (("CTRAPRG, 1,1,3,4,2,.0,12", "=(2), *(1) *(2),///, =="),
     """CTRAPRG|1|1|3|4|2|.0|12
        CTRAPRG|2|3|5|6|4|.0|12
        CTRAPRG|3|5|7|8|6|.0|12"""),
    # MSC replication in free field, a blank field incremented as 0 (pyNastran's dbxdra7.bdf,
    # whose grids before these carry CD = 1)
    (("GRID,   123,    1,      25.,    -60.4,  0.,", "=,      *(1),   =,      =,      *(14.8),=,      *(1)",
      "=,      *(1),   =,      =,      *(14.8),=,      ==", "=(1)"),
     """GRID|123|1|25.|-60.4|0.
        GRID|124|1|25.|-45.6|0.|1
        GRID|125|1|25.|-30.8|0.|1
        GRID|126|1|25.|-16.0|0.|1"""),
])
def test_the_manuals_examples_expand_to_its_card_images(lines, table):
    assert _images(*lines) == _cards(table)


FREE = """ID    FRAME,FREEFLD
APP   DISP
SOL   1,0
CEND
TITLE = OCTAGONAL FRAME, PULLED APART ACROSS EACH DIAMETER (FREE-FIELD INPUT)
SPC = 1
LOAD = 1
DISP = ALL
BEGIN BULK
GRDSET,8)345
GRID,  1  0   0.     75.     0.
GRID,  2  0  53.033  53.033  ==
GRID,  3  0  75.      0.     ==
GRID,  4  0  53.033 -53.033  ==
GRID,  5  0   0.    -75.     ==
GRID,  6  0 -53.033 -53.033  ==
GRID,  7  0 -75.      0.     ==
GRID,  8  0 -53.033  53.033  ==
SPC,1,1,126
CBAR,  1  1   1   2   0.  0.  1.
=(2),*(1),=, *(1),/,==
CBAR,  4  2   4   5   0.  0.  1.
=(3),*(1),=, *(1),/,==
CBAR,  8  2   8   1   0.  0.  1.
PBAR, 1  1   1.  .83333  .83333  1.6 )+P-1
=(1),*(1),=,*(.5),==
+P-1, ,,,,,,, )+Q-1
=(1),==
+Q-1, .8333 .8333
=(1), *(.05)  /
MAT1,  1  1.E7,, 0.3
FORCE1, 1  1   26516.5  5   1
=(3),  =,*(1),       = *(1),/
FORCE1, 1  5   26516.5  1   5
=(3),  =,*(1),       = *(1),/
ENDDATA
"""

FIXED = """SOL 101
CEND
SPC = 1
LOAD = 1
DISP = ALL
BEGIN BULK
GRDSET                                                  345
GRID    1       0       0.      75.     0.
GRID    2       0       53.033  53.033  0.
GRID    3       0       75.     0.      0.
GRID    4       0       53.033  -53.033 0.
GRID    5       0       0.      -75.    0.
GRID    6       0       -53.033 -53.033 0.
GRID    7       0       -75.    0.      0.
GRID    8       0       -53.033 53.033  0.
SPC     1       1       126
CBAR    1       1       1       2       0.      0.      1.
CBAR    2       1       2       3       0.      0.      1.
CBAR    3       1       3       4       0.      0.      1.
CBAR    4       2       4       5       0.      0.      1.
CBAR    5       2       5       6       0.      0.      1.
CBAR    6       2       6       7       0.      0.      1.
CBAR    7       2       7       8       0.      0.      1.
CBAR    8       2       8       1       0.      0.      1.
PBAR    1       1       1.      .83333  .83333  1.6
+
+       .8333   .8333
PBAR    2       1       1.5     .83333  .83333  1.6
+
+       .8833   .8833
MAT1    1       1.E7            0.3
FORCE1  1       1       26516.5 5       1
FORCE1  1       2       26516.5 6       2
FORCE1  1       3       26516.5 7       3
FORCE1  1       4       26516.5 8       4
FORCE1  1       5       26516.5 1       5
FORCE1  1       6       26516.5 2       6
FORCE1  1       7       26516.5 3       7
FORCE1  1       8       26516.5 4       8
ENDDATA
"""


def _import(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return import_deck.run(path)


def test_a_free_field_frame_is_its_fixed_field_twin(tmp_path):
    """Read field by field, the free-field deck's cards are the twin's: the same loads (FORCE1
    generated by "=(3)") and the same solution to the last bit; model.bdf holds the expanded
    card images, which read without this module."""
    free, fixed = _import(tmp_path, "free.dat", FREE), _import(tmp_path, "fixed.dat", FIXED)
    assert free.loads_csv == fixed.loads_csv
    cf, rf, uf = _solve(free)
    cx, rx, ux = _solve(fixed)
    assert (cf, rf) == (cx, rx)
    np.testing.assert_array_equal(uf, ux)
    assert np.abs(uf).max() > 1e-3                          # the frame does deform
    body = free.model_bdf.split("BEGIN BULK")[-1]
    assert "=(" not in body and "==" not in body
    assert not needed([_strip_comment(x) for x in free.model_bdf.splitlines()], 0)
    deck = read_deck_text(free.model_bdf)
    assert deck.pbars[2].k1 == pytest.approx(0.8833, rel=0, abs=0)    # .8333 + .05, printed exactly
    assert deck.grids[6].ps == "345" and deck.grids[6].xyz == (-53.033, -53.033, 0.0)


@needs_mystran
def test_the_imported_free_field_frame_agrees_with_mystran(tmp_path):
    """MYSTRAN runs model.bdf (the expanded card images) through the mystran adapter; it prints
    7 significant digits, so 1e-6 of the largest displacement."""
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study
    result = _import(tmp_path, "free.dat", FREE)
    (tmp_path / "study").mkdir()
    result.write(tmp_path / "study")
    study = load_study(tmp_path / "study")
    cases, report, ours = _solve(result)
    out = make_adapter_for(study, "mystran", cache=False).solve(study.loads, report)
    got = out.values[:, [list(out.cases).index(c) for c in cases]]
    assert np.abs(got - ours).max() <= 1e-6 * np.abs(ours).max()


@pytest.mark.parametrize("lines, line, says", [
    (("=(3),*(1)",), 1, "duplicate the card before, and there is none"),
    (("GRID,1,,0.,0.,0.", "GRID,2,,A,0.,0.", "=(2),*(1),,*(1.)"), 3, "not a number"),
    (("GRID,1,,0.,0.,0.", "=(1),*(1),,*(x)"), 2, "is not a number"),
    (("GRID,1,,0.,0.,0.", "=(1),*(1),,x"), 2, "not a real"),
])
def test_notation_and_field_errors_name_the_line_written(lines, line, says):
    """An error of the notation, or of a field of a generated card, is located at the line the
    user wrote (``=(N)`` makes N cards of one line)."""
    with pytest.raises(DeckFormatError) as err:
        read_deck_text("\n".join(lines) + "\n", name="t.dat")
    assert err.value.line == line and says in str(err.value)


def test_a_line_whose_cards_the_import_would_split_is_an_error(tmp_path):
    """"=(2)" makes SPC1 sets 2 and 3 of one line; SPC = 2 keeps one and drops the other, which
    cannot be done to one line of the deck as written: a located error, never a lost set."""
    text = FIXED.replace("SPC = 1", "SPC = 2").replace(
        "SPC     1       1       126", "SPC1,1,126,1\n=(2),*(1),=,*(1)")
    path = tmp_path / "split.dat"
    path.write_text(text)
    with pytest.raises(DeckFormatError) as err:
        import_deck.run(path)
    assert err.value.line == text.splitlines().index("=(2),*(1),=,*(1)") + 1
    assert "write those cards on lines of their own" in str(err.value)


@pytest.mark.parametrize("line", ["GRID,1,,0.,0.,0.", "GRID*,1,,0.,0.,+", "DEQATN,10,F(A,B) = A + B",
                                  "DEQATN  7       A(X,Y)=X", "                (RL**2,1.)/ABS(S)",
                                  "CBAR    1       1       1       2       0.      0.      1."])
def test_other_lines_are_left_as_they_are(line):
    """MSC free field, large field, a DEQATN's equation and fixed field are no COSMIC free
    field: a deck of them is not expanded at all."""
    assert not needed([line], 0)


T01231A = Path(__file__).parent / "data" / "decks" / "t01231a.inp"
"""NASA's NASTRAN-95 demonstration deck T01-23-1A: a plane truss of CBARs in COSMIC free field
(``GRDSET,8)246``, ``=`` cards, PBAR continuations four cards below their parents), settled by
four SPCDs of -1.0 beside one FORCE."""


def _spc_twin(model_bdf: str) -> str:
    """MYSTRAN's input for T01-23-1A: the import's expanded cards before its enforced-displacement
    section, the four settlements as SPC values (MYSTRAN 18 reads SPCD without applying it),
    and the FORCE."""
    body = model_bdf.split("$ ---- blackbox import: enforced")[0].split("\n")
    body = [b for b in body if b and not b.startswith("$")]
    return ("SOL 101\nCEND\nSPC = 1\nLOAD = 10\nDISP = ALL\nBEGIN BULK\n" + "\n".join(body)
            + "\nSPC,1,1,3,-1.0,2,3,-1.0\nSPC,1,4,3,-1.0,6,3,-1.0\n"
            "FORCE,10,1,,110.0,0.0,0.0,-1.0\nENDDATA\n")


@needs_mystran
def test_nasas_free_field_truss_agrees_with_mystran(tmp_path):
    """T01-23-1A imports (its SPCDs by large springs of 1e15) and its solution agrees with
    MYSTRAN holding the settlements by SPC values, and with MYSTRAN solving the study itself
    through the mystran adapter, which picks MYSTRAN's band solver for the large springs (its
    default SuperLU was 1.1e-4 off there); 1e-6 of the largest translation (7 printed digits)."""
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study
    from solver_adapters.nastran import banded_solver
    from test_deck_tail import _mystran
    result = import_deck.run(T01231A)
    assert result.cases == ("1",) and any("4 more by SPCD" in n for n in result.notes)
    assert banded_solver(read_deck_text(result.model_bdf)) and not banded_solver(result.deck)
    cases, report, ours = _solve(result)
    index = {d: i for i, d in enumerate(report)}
    table = _mystran(tmp_path / "twin", _spc_twin(result.model_bdf))[1]
    grids = sorted(g for g in table if (g, 1) in index)
    assert len(grids) == 11
    ref = np.array([[table[g][c - 1] for c in (1, 2, 3)] for g in grids])
    got = np.array([[ours[index[(g, c)], 0] for c in (1, 2, 3)] for g in grids])
    scale = np.abs(ref).max()
    assert np.abs(got - ref).max() <= 1e-6 * scale
    (tmp_path / "study").mkdir()
    result.write(tmp_path / "study")
    study = load_study(tmp_path / "study")
    out = make_adapter_for(study, "mystran", cache=False).solve(study.loads, report)
    assert np.abs(out.values[:, 0] - ours[:, 0]).max() <= 1e-6 * scale


def test_continuations_away_from_their_parents_in_fixed_field(tmp_path):
    """NASTRAN-95 sorts the bulk data and matches a continuation by its ID, so a fixed-field deck
    may put continuations anywhere (NASA's ACOSS decks list six CONM2s, then their six
    continuations): the frame with its PBAR continuations moved below the MAT1, in the other
    order, is the frame as written, to the last bit; a continuation no card names is still an
    error at its line."""
    def pbar(n: int, a: str, i: str, k: str) -> tuple[str, str]:
        head = f"PBAR    {n:<8d}1       {a:<8s}.83333  .83333  1.6".ljust(72) + f"+P{n}A"
        return head, (f"+P{n}A".ljust(72) + f"+P{n}B\n" + f"+P{n}B".ljust(8) + f"{k:<8s}{k:<8s}")
    h1, c1 = pbar(1, "1.", ".83333", ".8333")
    h2, c2 = pbar(2, "1.5", ".83333", ".8833")
    body = FIXED.split("PBAR    1")[0]
    rest = FIXED.split("MAT1")[1]
    moved = body + f"{h1}\n{h2}\nMAT1" + rest.split("\n", 1)[0] + f"\n{c2}\n{c1}\n" + rest.split("\n", 1)[1]
    a, b = _import(tmp_path, "moved.dat", moved), _import(tmp_path, "fixed.dat", FIXED)
    ca, ra, ua = _solve(a)
    cb, rb, ub = _solve(b)
    assert (ca, ra) == (cb, rb)
    np.testing.assert_array_equal(ua, ub)
    assert read_deck_text(a.model_bdf).pbars[2].k1 == pytest.approx(0.8833, rel=0, abs=0)
    orphan = moved.replace(h1 + "\n", h1 + "\n" + "+ZZ".ljust(8) + "1.\n", 1)
    with pytest.raises(DeckFormatError) as e:
        _import(tmp_path, "orphan.dat", orphan)
    assert e.value.line == orphan.splitlines().index("+ZZ".ljust(8) + "1.") + 1


def test_two_scalar_springs_on_one_celas3_or_celas4_card():
    """NASTRAN-95's CELAS3/CELAS4 define one or two springs a card (User's Manual, CELAS3 remark
    3). Scalar point 1 held; springs 1-2 (CELAS3 10, k = 100), 2-3 (its second, PELAS 8,
    k = 300), 3-4 (CELAS4 20, k = 50) and 4 to ground (its second, k = 25): a unit load at 4
    stretches the chain 1-2-3 and the two last springs in parallel, closed form."""
    from solver_adapters.protocol import LoadMatrix
    from solver_adapters.reference import ReferenceAdapter
    deck = read_deck_text("SPOINT,1,THRU,4\nPELAS,7,100.,,,8,300.\n"
                          "CELAS3,10,7,1,2,11,8,2,3\nCELAS4,20,50.,3,4,21,25.,4\nSPC1,1,0,1\n")
    assert sorted(deck.springs) == [10, 11, 20, 21] and deck.springs[21].g2 == 0
    report = [(p, 1) for p in (2, 3, 4)]
    u = ReferenceAdapter(deck).solve(LoadMatrix.from_dense([(4, 1)], np.array([[1.0]]), ["1"]), report)
    # 4 to ground directly (k = 25) in parallel with the chain 4-3-2-1 (1/50 + 1/300 + 1/100)
    chain = 1.0 / (1 / 50 + 1 / 300 + 1 / 100)
    u4 = 1.0 / (25.0 + chain)
    f = chain * u4                                     # the force through the chain
    np.testing.assert_allclose(u.values[:, 0], [f / 100, f / 100 + f / 300, u4], rtol=1e-12)


def test_grid_ps_zero_is_no_constraint():
    """NASTRAN-95 allows PS 0 (GRID: "Integer >= 0 or blank"): no permanent constraint, and not
    blank, so the GRDSET's PS does not replace it."""
    deck = read_deck_text("GRDSET,,,,,,,3\nGRID,1,,0.,0.,0.,,0\nGRID,2,,1.,0.,0.\n"
                          "GRID    3               2.      0.      0.              0\n")
    assert {g: deck.grids[g].ps for g in deck.grids} == {1: "", 2: "3", 3: ""}


_ARM = """GRID,1,,0.,0.,0.
GRID,2,,1.,0.,0.
GRID,3,,1.,.4,0.
GRID,4,,1.,0.,.3
GRID,5,,1.,.2,.2
CBAR,10,1,1,2,0.,0.,1.
PBAR,1,1,1.,.5,.8,.3
MAT1,1,1000.,,.3
SPC1,1,123456,1
"""


@pytest.mark.parametrize("rigid, rbe2", [
    ("CRIGD1,20,2,3,4,5\n", "RBE2,20,2,123456,3,4,5\n"),
    ("CRIGD1,20,2,3,THRU,5\n", "RBE2,20,2,123456,3,4,5\n"),
    ("CRIGD2,20,2,3,123,4,123\nCRIGD2,21,2,5,123456\n", "RBE2,20,2,123,3,4\nRBE2,21,2,123456,5\n"),
])
def test_nastran95_crigd1_crigd2_are_the_rbe2s_they_describe(rigid, rbe2):
    """CRIGD1 couples all six components of its dependent grids to the reference grid, CRIGD2 the
    listed ones (NASTRAN-95 User's Manual): read, they are the RBE2s of that reference grid, so the
    cantilever with its rigid arms gives the same displacements bit for bit; a CRIGD2 whose grids
    list different components is refused at that field."""
    from solver_adapters.protocol import LoadMatrix
    from solver_adapters.reference import ReferenceAdapter
    a, b = read_deck_text(_ARM + rigid), read_deck_text(_ARM + rbe2)
    assert [(e.gn, e.cm, e.gm) for e in a.rbe2s.values()] == [(e.gn, e.cm, e.gm) for e in b.rbe2s.values()]
    report = [(g, c) for g in (2, 3, 4, 5) for c in range(1, 7)]
    loads = LoadMatrix.from_dense([(3, 2), (4, 3), (5, 1)], np.eye(3), ["a", "b", "c"])
    ua, ub = (ReferenceAdapter(d).solve(loads, report).values for d in (a, b))
    assert np.array_equal(ua, ub) and np.abs(ua).max() > 0


def test_a_crigd2_with_different_components_and_other_cosmic_rigid_elements_are_refused():
    with pytest.raises(DeckFormatError, match="CRIGD2 with different components") as info:
        read_deck_text(_ARM + "CRIGD2,20,2,3,123,4,12\n")
    assert info.value.field == 7
    with pytest.raises(DeckFormatError, match="rigid elements other than CRIGD1 and CRIGD2"):
        read_deck_text(_ARM + "CRIGDR,20,2,3,1\n", unmodelled="keep")
