"""``blackbox import``: whole NASTRAN input files into study folders (docs/import.md).

The corpus (tests/data/decks/, sources in its README.md): public MYSTRAN test decks as their
authors wrote them, and decks written for these tests. For each accepted deck:

* ``loads.csv`` equals the loads computed by hand from the deck's cards (the arithmetic is in
  the comments of ``CORPUS``);
* the imported study solved by the reference solver agrees with MYSTRAN running the ORIGINAL
  input file (its own case control, loads and constraint selection). Tolerance: MYSTRAN prints 7
  significant digits, so a printed value is within 5e-7 of the exact one relative to the largest
  value of its table; RTOL = 1e-6 of the largest translation (rotation) of the subcase leaves a
  factor 2 for the solve's rounding.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from blackbox.adapters import make_adapter_for
from blackbox.commands import import_deck
from blackbox.commands.output import write_output
from blackbox.errors import StudyError
from blackbox.study import load_study
from solver_adapters.bdf import read_deck
from solver_adapters.casecontrol import read_case_control
from solver_adapters.loadcards import read_load_cards
from solver_adapters.protocol import DeckFormatError

from conftest import MYSTRAN_MARKS

DECKS = Path(__file__).resolve().parent / "data" / "decks"
RTOL = 1e-6  # MYSTRAN's 7 printed digits (module docstring)

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

# deck -> {case: {(grid, component): value}}, computed by hand from the deck's load cards
PORTAL_LOADS = {
    "101": {(4, 1): 1000.0},                                  # FORCE 10: 1000 (1, 0, 0)
    "102": {(5, 1): 200.0, (5, 3): 150.0,                     # 250 along 1->4 = (4, 0, 3)/5
            (2, 4): -40.0},                                   # 40 along 3->1 = (-1, 0, 0)
    # LOAD 30 = 2.0 (1.5 set 10 - 0.5 set 40); set 40: 100 (0, 1, 0) at 4,
    # -30 ((1,0,0) x (0,0,1) = (0,-1,0)) at 5, 2 (0, .5, -1) at 5
    "103": {(4, 1): 2.0 * 1.5 * 1000.0, (4, 2): 2.0 * -0.5 * 100.0, (5, 5): 2.0 * -0.5 * 30.0,
            (5, 2): 2.0 * -0.5 * 1.0, (5, 3): 2.0 * -0.5 * -2.0},
}
CORPUS = {
    # LOAD 1 = 1.0 (2.0 FORCE 11 + 3.0 MOMENT 12); FORCE 11: 1 (0, 3, -6); MOMENT 12: 1 (0, 2, 3)
    "BAR-I12.dat": {"1": {(201, 2): 6.0, (201, 3): -12.0, (201, 5): 6.0, (201, 6): 9.0}},
    # FORCE 17: 100 (2, 3, 6)
    "BAR-PINFLAG.dat": {"1": {(103, 1): 200.0, (103, 2): 300.0, (103, 3): 600.0}},
    "BAR-OFFSET.dat": {"1": {(102, 1): 200.0, (102, 2): 300.0, (102, 3): 600.0}},
    # FORCE 1 (two cards): 3 (0, 1, 0) + 1000 (1, 0, 0)
    "RBE2-02-CBAR-03.dat": {"1": {(113, 1): 1000.0, (113, 2): 3.0}},
    # subcase 35: FORCE 191 CID 13 (z13 = basic y) at grid 701 whose CD is 13: 120 along its z.
    # subcase 8: LOAD 26 = 2 (4 * 30 y at 201 + 3 * 25 z13 at 301 + 1 * 100 y at 401)
    "EXAMPLE1.dat": {"35": {(701, 3): 120.0},
                     "8": {(201, 2): 240.0, (301, 2): 150.0, (401, 2): 200.0}},
    "portal_joint.bdf": PORTAL_LOADS,
    # LOAD 2 = 1.0 (1.0 FORCE 1); FORCE 1: 100 (0, -1, 0)
    "appd.nas": {"1": {(5, 2): -100.0}},
    # global LOAD = 10 inherited by subcase 2 (which prints no displacements)
    "truss4.nas": {"1": {(4, 2): -1000.0}, "2": {(4, 2): -1000.0}, "3": {(3, 1): 2000.0}},
    # SUBCOM 3 and 4 combine subcases 1 and 2: skipped, 1 and 2 imported
    "truss5.nas": {"1": {(4, 2): -1000.0}, "2": {(3, 1): 2000.0}},
    # GRAV 1: 1.5 (2, 3, 4) in CORD2R 9 (x9 = basic z, y9 = basic x, z9 = basic y) = (4.5, 6, 3);
    # lumped mass: bars rho A = .1 * .4 per length, 2 long, half at each end (.04 at the ends,
    # .08 inside); CONM2 5 at 601 offset (.2, .3, .4): moment (.2, .3, .4) x 5 (4.5, 6, 3)
    "BAR-GRAV.dat": {"1": {**{(101, c + 1): 0.04 * v for c, v in enumerate((4.5, 6.0, 3.0))},
                           **{(g, c + 1): 0.08 * v for g in (201, 301, 401, 501)
                              for c, v in enumerate((4.5, 6.0, 3.0))},
                           **{(601, c + 1): 5.04 * v for c, v in enumerate((4.5, 6.0, 3.0))},
                           (601, 4): -7.5, (601, 5): 6.0, (601, 6): -0.75}},
}
# decks with enforced displacements, imported by the large-spring method (docs/import.md): their
# forces by hand; each enforced value is K x D at a handle grid (tests/test_enforced_displacement.py)
ENFORCED = {
    # SPC 1: grid 401 x held at .008, 501 x at .006 in both subcases; FORCE 1, FORCE 2 along x
    "RODDISPL-W-LOAD.dat": {"1": {(601, 1): 100.0, (701, 1): 120.0},
                            "2": {(201, 1): 240.0, (301, 1): 150.0, (401, 1): 200.0}},
}


def _loads(result) -> dict[str, dict[tuple[int, int], float]]:
    out: dict[str, dict[tuple[int, int], float]] = {}
    for row in result.loads_csv.splitlines()[1:]:
        case, grid, comp, value = row.split(",")
        out.setdefault(case, {})[(int(grid), int(comp))] = float(value)
    return out


def _study(result, tmp_path: Path) -> Path:
    out = tmp_path / "study"
    write_output(out, "import", result.write)
    return out


def _mystran_f06(deck: Path, tmp_path: Path):
    """MYSTRAN run on the original input file (its folder copied: INCLUDEs)."""
    from solver_adapters.nastran import mystran_binary, parse_f06
    run = tmp_path / "mystran"
    shutil.copytree(deck.parent, run)
    proc = subprocess.run([mystran_binary(), deck.name], cwd=run, capture_output=True, text=True,
                          timeout=300)
    f06 = run / (deck.stem + ".F06")
    assert f06.exists(), proc.stdout[-2000:]
    res = parse_f06(f06.read_text(errors="replace"))
    assert not res.errors, res.errors[:5]
    return res


# --------------------------------------------------------------------------------------------
# the corpus
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(CORPUS))
def test_corpus_loads_as_computed_by_hand(name):
    """Point loads are the deck's numbers multiplied out: equal; element loads (GRAV, PLOAD1)
    are sums of products, which round differently from the hand values in the last digits."""
    result = import_deck.run(DECKS / name)
    got = _loads(result)
    assert {c: set(v) for c, v in got.items()} == {c: set(v) for c, v in CORPUS[name].items()}
    for case, values in CORPUS[name].items():
        for dof, v in values.items():
            assert got[case][dof] == pytest.approx(v, rel=1e-12, abs=1e-12 * max(map(abs, values.values()))), (case, dof)
    assert result.cases == tuple(CORPUS[name])
    assert result.command == "import"


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_corpus_study_loads(name, tmp_path):
    study = load_study(_study(import_deck.run(DECKS / name), tmp_path))
    assert list(study.loads.cases) == list(CORPUS[name])
    read_deck(study.root / "model.bdf")       # the reader of every study accepts the model


@pytest.mark.parametrize("name", [pytest.param(n, marks=MYSTRAN_MARKS) for n in sorted(CORPUS) + sorted(ENFORCED)])
def test_corpus_reference_agrees_with_mystran_on_the_original_deck(name, tmp_path):
    study = load_study(_study(import_deck.run(DECKS / name), tmp_path))
    adapter = make_adapter_for(study, "reference")
    dofs = adapter.dofs()
    out = adapter.solve(study.loads, dofs)
    f06 = _mystran_f06(DECKS / name, tmp_path)
    compared = 0
    for j, case in enumerate(out.cases):
        table = f06.displacements.get(int(case), {})   # the deck's own output requests decide
        if not table:                                  # which subcases and grids are printed
            continue
        compared += 1
        printed = [i for i, (g, _) in enumerate(dofs) if g in table]
        mys = np.array([table[dofs[i][0]][dofs[i][1] - 1] for i in printed])
        ours = out.values[printed, j]
        for kind in ((1, 2, 3), (4, 5, 6)):
            rows = [k for k, i in enumerate(printed) if dofs[i][1] in kind]
            scale = np.abs(mys[rows]).max()
            if scale == 0.0:
                assert np.abs(ours[rows]).max() < 1e-30
                continue
            err = np.abs(ours[rows] - mys[rows]).max() / scale
            assert err <= RTOL, f"case {case}, components {kind}: {err:.2e} of the largest value"
    assert compared >= min(len(out.cases), 2)


def test_enforced_deck_forces_as_computed_by_hand_and_k_d_at_its_handles():
    """RODDISPL-W-LOAD.dat: the FORCE cards at their grids as in ENFORCED; each SPC value D on a
    handle grid tied to its DOF by an MPC, loaded by its spring's K x D in both cases."""
    name = "RODDISPL-W-LOAD.dat"
    result = import_deck.run(DECKS / name)
    got = _loads(result)
    lines = result.model_bdf.splitlines()
    handle = {(int(f[2]), int(f[3])): int(f[5]) for f in (ln.split(",") for ln in lines if ln.startswith("MPC,"))}
    k = {int(f[3]): float(f[2]) for f in (ln.split(",") for ln in lines if ln.startswith("CELAS2,"))}
    assert handle.keys() == {(401, 1), (501, 1)}
    for case, forces in ENFORCED[name].items():
        enforced = {(handle[(401, 1)], 1): k[handle[(401, 1)]] * 0.008, (handle[(501, 1)], 1): k[handle[(501, 1)]] * 0.006}
        assert got[case] == pytest.approx({**forces, **enforced}, rel=1e-15)


# --------------------------------------------------------------------------------------------
# what import writes
# --------------------------------------------------------------------------------------------
def test_directional_load_cards_give_the_same_loads():
    """FORCE1/MOMENT1/FORCE2/MOMENT2 (directions from grids) = the FORCE/MOMENT deck."""
    assert _loads(import_deck.run(DECKS / "portal_directional.bdf")) == PORTAL_LOADS


def test_model_keeps_the_bulk_data_as_written_without_loads(tmp_path):
    result = import_deck.run(DECKS / "portal_joint.bdf")
    text = result.model_bdf
    for card in ("FORCE ", "MOMENT ", "LOAD ", "SPC1    9"):
        assert not any(line.startswith(card) for line in text.splitlines()), card
    assert "GRID*   3                               4.0             0.0\n*       0.0\n" in text
    assert "GRID,21,,0.,0.,3.\n" in text
    assert "PBAR    1       7       2.0-3" in text          # the INCLUDE's content, inlined
    assert "INCLUDE '" not in text.replace("$ ---- INCLUDE '", "")
    assert "$ columns 1-2 and 3-4" in text                  # the author's comments stay
    assert text.rstrip().endswith("ENDDATA")
    folder = _study(result, tmp_path)
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        [".blackbox-output", "loads.csv", "model.bdf", "study.toml"])


def test_only_the_selected_constraint_set_is_kept(tmp_path):
    """SPC = 2 (SPCADD of sets 5 and 6) is kept; set 9 (grid 4 fixed in x, y, z) is dropped, so
    grid 4 moves under the horizontal force of subcase 101."""
    result = import_deck.run(DECKS / "portal_joint.bdf")
    sets = sorted({s.sid for s in result.deck.spc1s})
    assert sets == [5, 6] and list(result.deck.spcadds) == [2]
    assert any("SPC = 2 selected: kept constraint set(s) 2, 5, 6; dropped set(s) 9" in n
               for n in result.notes)
    study = load_study(_study(result, tmp_path))
    adapter = make_adapter_for(study, "reference")
    out = adapter.solve(study.loads, [(4, 1)])
    assert out.values[0, 0] > 1e-6


def test_notes_say_each_skipped_kind_once():
    notes = import_deck.run(DECKS / "portal_joint.bdf").notes
    assert ("skipped 8 case-control commands with no effect on a linear static solution: title "
            "lines (TITLE, SUBTITLE, LABEL); output controls (ECHO, SET); output requests "
            "(DISPLACEMENT, SPCFORCE, STRESS)") in notes
    assert "skipped the executive control (SOL 101, TIME)" in notes
    assert "subcase 104 selects no load set (no LOAD = or TEMPERATURE(LOAD) =): not imported" in notes
    assert sum("case-control command" in n for n in notes) == 1
    assert any(n.startswith("dropped 8 load cards from model.bdf (FORCE x4, MOMENT x3, LOAD x1)")
               for n in notes), notes


def test_text_beyond_column_80_is_cut_with_a_note(tmp_path):
    result = import_deck.run(DECKS / "BAR-I12.dat")
    assert "ignored the text beyond column 80 of 1 fixed-field line (a card image ends at column 80)" \
        in result.notes
    assert all(len(line) <= 80 or line.startswith("$") for line in result.model_bdf.splitlines())


def test_study_toml_template_lists_the_candidate_joints(tmp_path):
    result = import_deck.run(DECKS / "portal_joint.bdf")
    assert "# [[joints]]\n# name = \"J2\"\n# grids = [2, 21]\n" in result.study_toml
    study = load_study(_study(result, tmp_path))
    assert study.name == "portal_joint" and not study.config.joints


def test_joint_option_declares_a_checked_joint(tmp_path):
    result = import_deck.run(DECKS / "portal_joint.bdf", joints=["J2:2,21"])
    assert "[[joints]]\nname = \"J2\"\ngrids = [2, 21]\n" in result.study_toml
    study = load_study(_study(result, tmp_path))
    assert [(j.name, list(j.grids)) for j in study.config.joints] == [("J2", [2, 21])]


@pytest.mark.parametrize("spec, message", [
    ("J2:21,2", "not tied to branch 1 grid 21"),       # GN must come first
    ("J2:2,4", "not coincident"),
    ("J2:2,99", "not in the deck"),
    ("J2:2", "expected NAME:G1,G2"),
    ("J2 2,21", "expected NAME:G1,G2"),
    ("J2:2,2", "named twice"),
])
def test_joint_option_errors(spec, message):
    with pytest.raises(StudyError, match=message):
        import_deck.run(DECKS / "portal_joint.bdf", joints=[spec])


# --------------------------------------------------------------------------------------------
# decks written here: each rule of docs/import.md
# --------------------------------------------------------------------------------------------
BULK = """\
GRID    1               0.      0.      0.
GRID    2               1.      0.      0.
GRID    3               2.      0.      0.
CBAR    1       1       1       2       0.      1.      0.
CBAR    2       1       2       3       0.      1.      0.
PBAR    1       1       1.0-4   1.0-8   1.0-8   2.0-8
MAT1    1       2.0+11          .3
SPC1    1       123456  1
SPC1    2       123     3
"""


def _deck(tmp_path: Path, case_control: str | None, loads: str, name: str = "deck.bdf") -> Path:
    head = "" if case_control is None else f"SOL 101\nCEND\n{case_control}BEGIN BULK\n"
    p = tmp_path / name
    p.write_text(head + BULK + loads + "ENDDATA\n")
    return p


def test_deck_without_subcase_is_case_1(tmp_path):
    p = _deck(tmp_path, "SPC = 1\nLOAD = 5\n", "FORCE   5       3               10.     0.      0.      1.\n")
    result = import_deck.run(p)
    assert result.loads_csv == "case,grid,component,value\n1,3,3,10.0\n"
    assert "dropped set(s) 2 (not selected)" in " ".join(result.notes)


def test_defaults_above_the_first_subcase_are_inherited(tmp_path):
    p = _deck(tmp_path, "SPC = 1\nLOAD = 5\nSUBCASE 7\nSUBCASE 9\n  LOAD = 6\n",
              "FORCE   5       3               10.     0.      0.      1.\n"
              "MOMENT  6       2               2.      1.      0.      0.\n")
    assert _loads(import_deck.run(p)) == {"7": {(3, 3): 10.0}, "9": {(2, 4): 2.0}}


def test_bulk_data_only_with_one_load_set(tmp_path):
    p = _deck(tmp_path, None, "FORCE   5       3               10.     0.      0.      1.\n")
    result = import_deck.run(p)
    assert _loads(result) == {"1": {(3, 3): 10.0}}
    assert any("no case control: load set 5" in n for n in result.notes)
    assert {s.sid for s in result.deck.spc1s} == {1, 2}    # nothing selects: every set stays


def test_bulk_data_only_with_several_load_sets_is_an_error(tmp_path):
    p = _deck(tmp_path, None, "FORCE   5       3               10.     0.      0.      1.\n"
                              "FORCE   6       3               10.     0.      0.      1.\n")
    with pytest.raises(DeckFormatError, match="2 load sets \\(5, 6\\)"):
        import_deck.run(p)


def test_no_spc_selection_drops_every_constraint_set(tmp_path):
    p = _deck(tmp_path, "LOAD = 5\n", "FORCE   5       3               10.     0.      0.      1.\n")
    result = import_deck.run(p)
    assert not result.deck.spc1s
    assert any("NASTRAN applies none" in n for n in result.notes)


@pytest.mark.parametrize("case_control, loads, parts", [
    ("SPC = 1\nLOAD = 8\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("load set 8", "LOAD = 8 at", "not found")),
    ("SPC = 4\nLOAD = 5\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("deck.bdf:3", "card SPC", "SPC = 4 selects a constraint set")),
    ("SPC = 1\nLOAD = 5\n", "PLOAD4  5       3       1.\n",
     ("deck.bdf:15", "card PLOAD4", "contains PLOAD4")),
    ("SPC = 1\nLOAD = 7\n", "LOAD    7       1.      1.      8\nLOAD    8       1.      1.      5\n"
                            "FORCE   5       3               1.      1.      0.      0.\n",
     ("card LOAD", "field 5", "nested LOAD")),
    ("SPC = 1\nLOAD = 5\n", "FORCE   5       3       4       1.      1.      0.      0.\n",
     ("deck.bdf:15", "card FORCE", "field 4", "CID 4 not found")),
    ("SPC = 1\nLOAD = 5\n", "FORCE   5       9               1.      1.      0.      0.\n",
     ("card FORCE", "field 3", "grid 9 does not exist")),
    ("SPC = 1\nLOAD = 5\n", "FORCE1  5       3       1.      2       2\n",
     ("card FORCE1", "field 6", "same grid")),
    ("SPC = 1\nLOAD = 5\n", "FORCE   5       3               1.      1.      0.      0.      7.\n",
     ("card FORCE", "field 9", "at most 8 fields")),
    ("SPC = 1\nMPC = 3\nLOAD = 5\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("deck.bdf:4", "card MPC", "selects a set the bulk data does not have")),
    ("SPC = 1\nLOAD = 5\nFROBNICATE = 2\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("deck.bdf:5", "unknown case-control command", "FROBNICATE")),
    ("SUBCASE 1\n LOAD = 5\nSUBCASE 1\n LOAD = 5\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("deck.bdf:5", "SUBCASE 1 appears twice")),
    ("SPC = 1\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("no static load case to import", "(subcase 1: no selection)")),
    ("SPC = 1\nLOAD = 5\nSUBSEQ 1.0, 2.0\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("deck.bdf:5", "SUBSEQ outside a SUBCOM")),
    ("SPC = 1\nLOAD = 5\nSYMCOM 3\n", "FORCE   5       3               1.      1.      0.      0.\n",
     ("deck.bdf:5", "card SYMCOM", "cannot be imported")),
])
def test_errors_name_the_place(tmp_path, case_control, loads, parts):
    with pytest.raises(DeckFormatError) as exc:
        import_deck.run(_deck(tmp_path, case_control, loads))
    for part in parts:
        assert part in str(exc.value), str(exc.value)


def test_subcases_of_different_constraint_sets_import_one_set(tmp_path):
    """A study has one set of supports: the subcases of the first imported subcase's set are
    imported and the others named in a note with the option that imports them (``--spc``);
    ``--spc 2`` imports subcase 3 alone, with set 2 kept and set 1 dropped; a set no subcase
    selects is an error."""
    cc = "SUBCASE 1\n SPC = 1\n LOAD = 5\nSUBCASE 2\n SPC = 2\n LOAD = 5\nSUBCASE 3\n SPC = 1\n LOAD = 6\n"
    loads = ("FORCE   5       3               1.      1.      0.      0.\n"
             "FORCE   6       3               2.      1.      0.      0.\n")
    p = _deck(tmp_path, cc, loads)
    first = import_deck.run(p)
    assert first.cases == ("1", "3")
    assert {s.sid for s in first.deck.spc1s} == {1}
    note = next(n for n in first.notes if "different constraint sets" in n)
    assert "left out subcase(s) 2 (SPC = 2)" in note and "--spc" in note
    second = import_deck.run(p, spc=2)
    assert second.cases == ("2",) and {s.sid for s in second.deck.spc1s} == {2}
    with pytest.raises(DeckFormatError, match="--spc 7: no imported subcase selects SPC = 7"):
        import_deck.run(p, spc=7)


@pytest.mark.parametrize("sol, loads, line, first", [
    ("103", "", 4, "no static load case to import"),       # a modal deck: nothing to import at all
    ("101", "LOAD = 5\n", 5, "superelement selections other than ALL"),
])
def test_a_refused_command_or_no_static_load_case_first(tmp_path, sol, loads, line, first):
    """A command the import refuses (here SUPER = 1) is what the message says, at its line, unless
    the deck has no static load case at all (a SOL 103 deck selecting no LOAD): that is said
    first, the refused command besides."""
    p = tmp_path / "deck.bdf"
    p.write_text(f"SOL {sol}\nCEND\nSPC = 1\n{loads}SUPER = 1\nBEGIN BULK\n" + BULK +
                 "FORCE   5       3               10.     0.      0.      1.\nENDDATA\n")
    with pytest.raises(DeckFormatError) as e:
        import_deck.run(p)
    where, _, said = str(e.value).partition(": ")
    assert f"deck.bdf:{line}" in where and said.startswith(first), str(e.value)
    assert "superelement selections other than ALL" in said and "SUPER = 1" in str(e.value)


def test_cend_without_begin_bulk(tmp_path):
    p = tmp_path / "d.bdf"
    p.write_text("SOL 101\nCEND\nLOAD = 1\n")
    with pytest.raises(DeckFormatError, match="no BEGIN BULK"):
        import_deck.run(p)


# --------------------------------------------------------------------------------------------
# the case-control and load-card readers
# --------------------------------------------------------------------------------------------
def test_case_control_reader():
    text = ("NASTRAN SYSTEM(442)=-1\nID X,Y\nSOL SESTATIC\nCEND\n"
            "TITLE = A, B $ comment\nSUBTI = S\nSEALL = ALL\nSET 3 = 1, 2,\n  3 THRU 9,\n 11\n"
            "DISP(PRINT,PLOT) = 3\nELFO = ALL\nPARAM,AUTOSPC,YES\nSPC = 1\n"
            "SUBCASE 4\n  LOAD = 40\nSUBCASE 5\n  LOAD = 50\n  SPC = 1\n  LABEL = L5\n"
            "OUTPUT(PLOT)\nSET 1 = ALL\nFIND SCALE, ORIGIN 1, SET 1\nPLOT\n"
            "BEGIN BULK\nGRID    1\n")
    cc = read_case_control(text, "x.bdf")
    assert cc.sol == "SESTATIC" and cc.executive == ("NASTRAN", "ID", "SOL")
    assert [(s.id, s.load, s.spc, s.load_line) for s in cc.subcases] == [(4, 40, 1, 16), (5, 50, 1, 18)]
    assert cc.subcases[0].title == "A, B" and cc.subcases[1].label == "L5"
    assert cc.skipped["output requests"] == ("DISPLACEMENT", "ELFORCE")
    assert cc.skipped["output controls"] == ("SET",)
    assert cc.skipped["plot commands"] == ("OUTPUT(PLOT)", "SET", "FIND", "PLOT")
    assert cc.skipped["case-control parameters"] == ("AUTOSPC",)
    assert cc.skipped["superelement controls"] == ("SEALL = ALL",)
    assert cc.bulk_line == 25
    assert read_case_control("GRID    1\n", "b.bdf") is None


def test_marks_beyond_column_72_of_the_case_control_are_not_read():
    """A case control framed by ``|`` in column 73 (a course deck of jlefanic/NASTRAN-Slides):
    NASTRAN reads columns 1-72 of a case-control card, and marks carry no value; text with a
    letter or digit beyond column 72 is read as written (here an error, not a lost value)."""
    framed = ("SOL 101\nCEND\nSUBCASE 1000\n" + "        SPC=1000".ljust(72) + "|\n"
              + "        LOAD=1000".ljust(72) + "|  \nBEGIN BULK\n")
    cc = read_case_control(framed, "x.dat")
    assert [(s.id, s.spc, s.load) for s in cc.subcases] == [(1000, 1000, 1000)]
    with pytest.raises(DeckFormatError, match="SPC must select a set by its integer ID") as err:
        read_case_control(framed.replace("|\n", "7\n", 1), "x.dat")
    assert err.value.line == 4


def test_load_combination_rules(tmp_path):
    from solver_adapters.bdf import bulk_cards
    p = tmp_path / "l.bdf"
    p.write_text("LOAD    7       2.      1.      8       1.      8\n")
    with pytest.raises(DeckFormatError, match="appears twice"):
        read_load_cards(bulk_cards(p)[0])
    p.write_text("LOAD    7       2.      1.      8\nFORCE   7       1               1.      1.\n")
    with pytest.raises(DeckFormatError, match="both a LOAD combination and a load set"):
        read_load_cards(bulk_cards(p)[0])


def test_load_and_constraint_cards_inside_an_include_are_dropped(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "loads.inc").write_text(
        "$ loads and constraints in a nested include\n"
        "FORCE   5       3               10.     0.      0.      1.\n"
        "SPC1    2       123     3\n"
        "INCLUDE 'more.inc'\n")
    (tmp_path / "sub" / "more.inc").write_text("MOMENT  5       2               1.      0.      1.      0.\n")
    bulk = BULK.replace("SPC1    2       123     3\n", "")
    p = tmp_path / "main.bdf"
    p.write_text("SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\n" + bulk + "INCLUDE 'sub/loads.inc'\nENDDATA\n")
    result = import_deck.run(p)
    assert _loads(result) == {"1": {(3, 3): 10.0, (2, 5): 1.0}}
    body = [line for line in result.model_bdf.splitlines() if not line.startswith("$")]
    assert not [line for line in body if line.split()[0] in ("FORCE", "MOMENT", "SPC1", "INCLUDE")
                and "123456" not in line], body
    # an included file's comments are not copied: import copies only what it read as cards
    assert "$ loads and constraints in a nested include" not in result.model_bdf
    assert "read main.bdf: 11 bulk cards in 3 files; 1 case (1)" in result.notes


def test_imported_study_identifies_its_joint(tmp_path):
    """The whole path: import with --joint, simulate measurements of a known joint stiffness
    (0.1 % noise), identify it back within its 95 % intervals."""
    from blackbox.commands import identify, simulate

    write_output(tmp_path / "study", "import",
                 import_deck.run(DECKS / "portal_joint.bdf", joints=["J2:2,21"]).write)
    truth = tmp_path / "truth.toml"
    truth.write_text('seed = 3\n\n[[joints]]\nname = "J2"\nmodel = "simple"\nvalue = 2.0e4\n\n'
                     '[noise]\nrelative = 0.001\nfloor = 0.02\n\n[measure]\njoint = true\n'
                     'away_grids = [4, 5]\n')
    write_output(tmp_path / "sim", "simulate", simulate.run(tmp_path / "study", truth).write)
    r = identify.run(load_study(tmp_path / "sim", need_measurements=True)).result
    assert r.converged and list(r.param_names) == ["kx12", "ky12", "kz12"]
    assert np.all(r.ci_low <= 2.0e4) and np.all(2.0e4 <= r.ci_high)
    assert np.all(np.abs(np.asarray(r.k) / 2.0e4 - 1.0) < 0.01)


def test_cli_import(tmp_path, capsys):
    """``blackbox import`` end to end: one summary line per kind skipped; exit 2 on a bad joint."""
    from blackbox.cli import main

    deck = Path(__file__).resolve().parent / "data" / "decks" / "portal_joint.bdf"
    assert main(["import", str(deck), "--out", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "output requests (DISPLACEMENT, SPCFORCE, STRESS)" in out and "3 case(s)" in out
    assert {p.name for p in (tmp_path / "s").iterdir()} >= {"model.bdf", "loads.csv", "study.toml"}
    assert main(["import", str(deck), "--out", str(tmp_path / "t"), "--joint", "J:1,999"]) == 2
    assert not (tmp_path / "t").exists()


SHELL = ("GRID    4               0.      1.      0.\nGRID    5               1.      1.      0.\n"
         "CQUAD4  11      7       1       2       5       4\nPSHELL  7       1       .002    1               1\n")


def test_shells_are_kept_for_mystran(tmp_path):
    """A deck with shells: model.bdf keeps them as written, study.toml names the mystran adapter
    (a note says why), the study loads; the reference adapter refuses it, naming every card.
    No PARAM,AUTOSPC is added: the reader applies NASTRAN's default itself."""
    p = _deck(tmp_path, "SPC = 1\nLOAD = 5\n", "FORCE   5       3               10.     0.      0.      1.\n" + SHELL)
    result = import_deck.run(p)
    assert any("kept 2 cards the reference solver does not model (CQUAD4 x1, PSHELL x1)" in n for n in result.notes)
    assert [u.name for u in result.deck.unmodelled] == ["CQUAD4", "PSHELL"]
    study_dir = _study(result, tmp_path)
    assert 'adapter = "mystran"' in (study_dir / "study.toml").read_text()
    assert "CQUAD4  11" in (study_dir / "model.bdf").read_text()
    assert "AUTOSPC" not in (study_dir / "model.bdf").read_text()
    study = load_study(study_dir)
    with pytest.raises(DeckFormatError, match=r"(?s)CQUAD4 x1 \(first at .*model.bdf:\d+\).*PSHELL x1"):
        make_adapter_for(study, "reference")


def test_mpc_is_kept_with_shells_when_selected(tmp_path):
    """An MPC set the case control selects is kept in model.bdf (for the mystran adapter here:
    the deck has a shell); one it does not select is dropped with a note."""
    card = "MPC     9       3       1       1.      2       1       -1.\n"
    force = "FORCE   5       3               10.     0.      0.      1.\n"
    result = import_deck.run(_deck(tmp_path, "SPC = 1\nMPC = 9\nLOAD = 5\n", force + SHELL + card))
    assert card.strip() in result.model_bdf and any("MPC = 9 selected" in n for n in result.notes)
    result = import_deck.run(_deck(tmp_path, "SPC = 1\nLOAD = 5\n", force + SHELL + card, "b.bdf"))
    assert card.strip() not in result.model_bdf and any("no subcase selects an MPC set" in n
                                                         for n in result.notes)
