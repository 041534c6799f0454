"""``blackbox import`` of decks written for other solutions and of case-control commands the
import does not model (docs/import.md, "Decks of other solutions" and the case-control table):

* a deck of another solution sequence (SOL 103, 105, 106, 200 ...) is imported for its structure
  and the static load sets its subcases select, with a note naming the deck's own solution;
* a deck without any static load set is a located error (exit 2) naming what its subcases select;
* commands with no effect on a linear static solution are skipped, all in ONE note;
* commands that change the static solution are refused at their line; an unknown command is a
  located error with the known names closest to it.

The decks are the three-grid cantilever of tests/test_import.py (``BULK``) with a FORCE set; the
loads expected are the FORCE card's numbers (10 along z at grid 3), exact.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from blackbox.commands import import_deck
from solver_adapters.bdf import read_deck_text
from solver_adapters.casecontrol import read_case_control
from solver_adapters.protocol import DeckFormatError

from test_import import BULK

FORCE = "FORCE   5       3               10.     0.      0.      1.\n"
STATIC_LOADS = "case,grid,component,value\n1,3,3,10.0\n"

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _deck(tmp_path: Path, sol: str, case_control: str, bulk: str = FORCE) -> Path:
    p = tmp_path / "deck.bdf"
    p.write_text(f"SOL {sol}\nCEND\n{case_control}BEGIN BULK\n{BULK}{bulk}ENDDATA\n")
    return p


# --------------------------------------------------------------------------------------------
# decks of other solutions
# --------------------------------------------------------------------------------------------
def test_modal_deck_whose_load_names_no_set_has_no_static_case(tmp_path):
    """SOL 103 does not read LOAD =; one naming no set (pyNastran's cbar_modes.solver.bdf: LOAD = 2
    and no load cards) is nothing to import, said as such. In SOL 101 the same selection is an
    error naming the set."""
    p = _deck(tmp_path, "103", "SPC = 1\nSUBCASE 1\n  LOAD = 9\n  METHOD = 10\n")
    with pytest.raises(DeckFormatError, match="no static load case to import: the deck's solution is SOL 103"):
        import_deck.run(p)
    p = _deck(tmp_path, "101", "SPC = 1\nSUBCASE 1\n  LOAD = 9\n")
    with pytest.raises(DeckFormatError, match="load set 9 .*not found"):
        import_deck.run(p)


def test_buckling_deck_gives_its_static_subcase(tmp_path):
    """SOL 105: subcase 1 is the static preload (LOAD = 5), subcase 2 the eigenvalue problem
    (METHOD, STATSUB): case 1 imported with the FORCE as written, subcase 2 named in a note."""
    p = _deck(tmp_path, "105", "SPC = 1\nSUBCASE 1\n  LOAD = 5\nSUBCASE 2\n  METHOD = 10\n"
                               "  STATSUB = 1\n", FORCE + "EIGB    10      INV     0.      1.+5\n")
    result = import_deck.run(p)
    assert result.loads_csv == STATIC_LOADS
    notes = "\n".join(result.notes)
    assert ("note: the deck's own solution is SOL 105 (buckling), not linear statics: imported its "
            "structure and, as linear static load cases, the load sets its subcases select: "
            "1 (LOAD = 5)") in notes
    assert "subcase 2 selects no load set (no LOAD = or TEMPERATURE(LOAD) =): not imported" in notes
    assert "selections of other solutions (METHOD, STATSUB)" in notes


@pytest.mark.parametrize("sol, extra", [
    ("106", "NLPARM = 3\n"), ("200", "ANALYSIS = STATICS\nDESOBJ = 10\n"),
    ("SESTATIC", ""), ("101", "")])
def test_other_solutions_give_the_same_study_as_sol_101(tmp_path, sol, extra):
    """The structure and the selected static load sets do not depend on the deck's SOL: the
    study of a SOL 106/200 deck equals that of the same deck as SOL 101."""
    ref = import_deck.run(_deck(tmp_path / "a" if tmp_path.joinpath("a").mkdir() is None else tmp_path,
                                "101", "SPC = 1\nLOAD = 5\n"))
    (tmp_path / "b").mkdir()
    result = import_deck.run(_deck(tmp_path / "b", sol, f"SPC = 1\n{extra}LOAD = 5\n"))
    assert result.loads_csv == ref.loads_csv == STATIC_LOADS
    assert result.model_bdf == ref.model_bdf
    static = sol in ("101", "SESTATIC")
    assert any("not linear statics" in n for n in result.notes) is not static


def test_modal_deck_without_load_is_a_located_error(tmp_path):
    p = _deck(tmp_path, "103", "SPC = 1\nDISP = ALL\nSUBCASE 1\n  METHOD = 10\nSUBCASE 2\n"
                               "  METHOD = 11\n  SDAMP = 4\n", "EIGRL   10                      4\n")
    with pytest.raises(DeckFormatError) as exc:
        import_deck.run(p)
    msg = str(exc.value)
    assert msg.startswith(f"{p}: no static load case to import: the deck's solution is SOL 103 "
                          f"(normal modes), not linear statics, and no subcase selects a static "
                          f"load set with LOAD = (subcase 1: METHOD = 10; subcase 2: METHOD = 11, "
                          f"SDAMPING = 4)"), msg


def test_cli_exit_2_without_static_load(tmp_path, capsys):
    from blackbox.cli import main
    p = _deck(tmp_path, "103", "SPC = 1\nMETHOD = 10\n", "EIGRL   10                      4\n")
    assert main(["import", str(p), "--out", str(tmp_path / "s")]) == 2
    assert "no static load case to import" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


# --------------------------------------------------------------------------------------------
# commands with no effect, refused commands, unknown commands
# --------------------------------------------------------------------------------------------
NO_EFFECT = ("TITLE = T\nECHO = NONE\nDISP(PRINT) = ALL\nMETHOD = 10\nRMETHOD = 11\nDESOBJ = 10\n"
             "DESSUB = 2\nDESGLB = 3\nTSTEPNL = 10\nTSTEP = 11\nNLPARM = 3\nSDAMP = 4\nFREQ = 5\n"
             "ANALYSIS = STATICS\nDLOAD = 6\nFMETHOD = 7\nTRIM = 8\nB2GG = BB\nMPFACTOR = ALL\n"
             "K2PP = KAX\nM2PP = MAX\nAEROF = 99\nAPRES = ALL\n")


def test_no_effect_commands_are_one_note(tmp_path):
    result = import_deck.run(_deck(tmp_path, "101", f"SPC = 1\nLOAD = 5\n{NO_EFFECT}"))
    assert result.loads_csv == STATIC_LOADS
    lines = [n for n in result.notes if "case-control command" in n]
    # K2PP and M2PP: matrices of the p-set, used only in dynamic response (OptiStruct's and
    # Autodesk Nastran's K2PP references)
    assert lines == ["skipped 23 case-control commands with no effect on a linear static solution: "
                     "title lines (TITLE); output controls (ECHO); output requests (DISPLACEMENT, "
                     "AEROF, APRESSURE); "
                     "selections of other solutions (METHOD, RMETHOD, TSTEPNL, TSTEP, NLPARM, "
                     "SDAMPING, FREQUENCY, ANALYSIS, DLOAD, FMETHOD, TRIM, B2GG, MPFACTOR, K2PP, M2PP); design "
                     "optimisation (DESOBJ, DESSUB, DESGLB)"]


@pytest.mark.parametrize("command, named", [
    ("P2G = PDMIG", "P2G (direct load input)"),
    ("K42GG = KAX", "K42GG"), ("M2GG = MDMIG", "M2GG"), ("LOADSET = 35", "LOADSET"),
    ("DEFORM = 2", "DEFORM"), ("CLOAD = 2", "CLOAD")])
def test_commands_that_change_the_solution_are_refused(tmp_path, command, named):
    p = _deck(tmp_path, "101", f"SPC = 1\nLOAD = 5\n{command}\n")
    with pytest.raises(DeckFormatError) as exc:
        import_deck.run(p)
    msg = str(exc.value)
    assert msg.startswith(f"{p}:5, card {command.split('=')[0].split('(')[0].strip()}"), msg
    assert f"the case-control command {named}" in msg and "changes the static solution" in msg


@pytest.mark.parametrize("command, hint", [
    ("METHD = 5", "did you mean METHOD"), ("RMETOD = 3", "did you mean RMETHOD"),
    ("FROBNICATE = 2", None)])
def test_unknown_command_is_located_with_did_you_mean(tmp_path, command, hint):
    p = _deck(tmp_path, "101", f"SPC = 1\nLOAD = 5\n{command}\n")
    with pytest.raises(DeckFormatError) as exc:
        import_deck.run(p)
    msg = str(exc.value)
    assert msg.startswith(f"{p}:5, card {command.split('=')[0].split('(')[0].strip()}") and \
        "unknown case-control command" in msg, msg
    assert (hint in msg) if hint else ("did you mean" not in msg)


def test_tstepnl_and_tstep_are_two_commands():
    cc = read_case_control("SOL 129\nCEND\nTSTEPNL = 1\nTSTEP = 2\nTSTE = 3\nBEGIN BULK\n", "x")
    assert cc.skipped["selections of other solutions"] == ("TSTEPNL", "TSTEP")
    assert cc.subcases[0].others == ("TSTEPNL = 1", "TSTEP = 3")


def test_autospc_no_is_carried_into_the_model(tmp_path):
    """Case-control AUTOSPC = NO: model.bdf gets PARAM,AUTOSPC,NO, which the study reader
    applies (a singular DOF is then an error instead of a constraint); YES is the default."""
    result = import_deck.run(_deck(tmp_path, "101", "SPC = 1\nAUTOSPC(NOPRINT) = NO\nLOAD = 5\n"))
    assert "PARAM,AUTOSPC,NO" in result.model_bdf.splitlines()
    assert read_deck_text(result.model_bdf, name="model.bdf").autospc is False
    assert any(n.startswith("AUTOSPC = NO at ") for n in result.notes)
    yes = import_deck.run(_deck(tmp_path, "101", "SPC = 1\nAUTOSPC = YES\nLOAD = 5\n"))
    assert "AUTOSPC" not in yes.model_bdf and read_deck_text(yes.model_bdf, name="m").autospc


def test_dynamic_excitation_and_condensation_cards_have_no_effect(tmp_path):
    """RLOAD1/TLOAD1/DLOAD/TABLED1 (selected by DLOAD only), ASET1/OMIT1 (a static reduction
    to them is exact), QSET1 (a dynamic reduction's generalized coordinates, here a scalar
    point: component modes added to the exact static basis), SEQGP (the order of the unknowns)
    and DMI (a matrix for DMAP or the aerodynamics, never added to a static solution's
    stiffness: that is DMIG by K2GG) are accepted as cards with no effect: the reference adapter
    stays."""
    extra = ("DLOAD   20      1.      1.      21\nRLOAD1  21      22                      23\n"
             "TLOAD1  24      22                      23\nTABLED1 23\n        0.      1.      1.      1."
             "      ENDT\nASET1   123456  2\nOMIT1   3       1\nSEQGP   1       2       2       1\n"
             "SPOINT  90\nQSET1   0       90\n"
             "DMI     WKK     0       3       1       0               2       1\n"
             "DMI     WKK     1       1       1.12    1.12\n")
    result = import_deck.run(_deck(tmp_path, "101", "SPC = 1\nLOAD = 5\n", FORCE + extra))
    assert result.loads_csv == STATIC_LOADS
    assert set(result.deck.no_effect) >= {"DLOAD", "RLOAD1", "TLOAD1", "TABLED1", "ASET1", "OMIT1", "SEQGP", "QSET1", "DMI"}
    assert not result.deck.unmodelled and 'adapter = "reference"' in result.study_toml


def test_random_analysis_cards_have_no_effect(tmp_path):
    extra = "RANDT1  30      5       0.      1.\nTABRND1 31\n        1.      1.      2.      1.      ENDT\n"
    result = import_deck.run(_deck(tmp_path, "101", "SPC = 1\nLOAD = 5\n", FORCE + extra))
    assert set(result.deck.no_effect) >= {"RANDT1", "TABRND1"} and not result.deck.unmodelled


# --------------------------------------------------------------------------------------------
# a CBUSH without orientation (MYSTRAN's benchmark deck Bush_Bar/bush_15.DAT has one)
# --------------------------------------------------------------------------------------------
BUSH = """\
GRID    1               0.      0.      0.
GRID    2               0.      0.      10.
SPC1    1       123456  1
SPC1    1       12456   2
CBUSH   1       1       1       2
PBUSH   1       K       {k}
FORCE   5       2               1000.   0.      0.      1.
"""


def test_cbush_without_orientation_is_axial_along_ga_gb(tmp_path):
    """No GO, X or CID between distinct grids: the element x axis is GA -> GB and only K1, K4
    may be given (MSC QRG, CBUSH). The axial spring K1 = 1500 under 1000 along GA -> GB (z)
    moves grid 2 by 1000 / 1500 (closed form)."""
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study
    p = tmp_path / "b.bdf"
    p.write_text("SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\n" + BUSH.format(k="1500.") + "ENDDATA\n")
    out = tmp_path / "s"
    out.mkdir()
    import_deck.run(p).write(out)
    study = load_study(out)
    u = make_adapter_for(study, "reference").solve(study.loads, [(2, 3)]).values[0, 0]
    assert u == pytest.approx(1000.0 / 1500.0, rel=1e-12)


def test_cbush_without_orientation_and_lateral_stiffness_is_refused(tmp_path):
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study
    p = tmp_path / "b.bdf"
    p.write_text("SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\n" + BUSH.format(k="1500.   10.")
                 + "ENDDATA\n")
    out = tmp_path / "s"
    out.mkdir()
    import_deck.run(p).write(out)
    study = load_study(out)
    with pytest.raises(Exception, match="CBUSH 1: without an orientation vector .* K1 and K4 only"):
        make_adapter_for(study, "reference").solve(study.loads, [(2, 3)])
