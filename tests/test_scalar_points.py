"""Scalar points (SPOINT): springs (CELAS1-4), SPC/SPC1, MPC and SLOAD on them (issue 20).

A scalar point is one degree of freedom with no position (MSC QRG SPOINT; CELAS1/CELAS2, SPC,
SPC1 and MPC name its DOF with component 0 or blank; CELAS3/CELAS4 join scalar points only;
SLOAD loads them). The reader holds it as a point whose component 1 is that DOF and whose
components 2-6 are held.

References:

* closed forms. Springs in series from a fixed point, load P at the free end: each spring
  carries P, so u_n = P * sum(1 / k_i) over the springs up to n. A chain of springs and a rod
  (axial stiffness E A / L) between fixed ends: the stiffness matrix assembled by hand below,
  solved with numpy. Two springs K joined by u_a = u_b with the far ends fixed and a load P at
  a: u_a = u_b = P / (2 K).
* MYSTRAN 18 run as a subprocess on the original deck (it reads SPOINT, CELAS3/CELAS4, SLOAD
  and SPC1 with component 0) or, for the forms it refuses (component blank in CELAS1/CELAS2 and
  MPC: ``*ERROR 1133``, ``*ERROR 1126``), on the study written by the mystran adapter, which
  writes component 1 there.

Tolerances: closed forms to CLOSED = 1e-9 relative (a direct solve of a few DOFs in double
precision); MYSTRAN, which prints 7 significant digits, to RTOL = 1e-6 (tests/test_deck_tail.py).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.bdf_write import write_deck
from solver_adapters.protocol import DeckFormatError, ModelError

from conftest import needs_mystran
from test_deck_tail import CLOSED, _import, _mystran, _solve
from test_deck_tail_elements import _study_against_mystran

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

K = {1: 1000.0, 2: 500.0, 3: 2000.0, 4: 800.0}
P = 10.0


def _deck(bulk: str, extra_cc: str = "") -> str:
    return (f"SOL 101\nCEND\nDISPLACEMENT = ALL\nSUBCASE 1\n  LOAD = 2\n  SPC = 3\n{extra_cc}"
            f"BEGIN BULK\n{bulk}ENDDATA\n")


# every spring card, scalar-point components blank as NASTRAN writes them (pyNastran's
# test_ese_cantilever.solver.bdf has this layout)
CHAIN = ("SPOINT,1,THRU,5\n"
         f"CELAS4,1,{K[1]},1,2\n"
         "CELAS3,2,10,2,3\nPELAS,10,500.\n"
         f"CELAS2,3,{K[3]},3,,4\n"
         "CELAS1,4,20,4,,5\nPELAS,20,800.\n"
         f"SLOAD,2,5,{P}\nSPC1,3,,1\n")


def _chain_closed() -> list[float]:
    out, u = [0.0], 0.0
    for i in (1, 2, 3, 4):
        u += P / K[i]
        out.append(u)
    return out


def test_spring_chain_on_scalar_points_matches_the_closed_form(tmp_path):
    result = _import(tmp_path, _deck(CHAIN))
    assert result.loads_csv.splitlines()[1:] == [f"1,5,1,{P!r}"]
    cases, report, u = _solve(result)
    for s, want in zip(range(1, 6), _chain_closed()):
        assert u[report.index((s, 1)), 0] == pytest.approx(want, rel=CLOSED, abs=1e-300)
        for c in range(2, 7):                       # the held components never move
            assert u[report.index((s, c)), 0] == 0.0


@needs_mystran
def test_spring_chain_agrees_with_mystran_through_the_study(tmp_path):
    assert _study_against_mystran(tmp_path, _deck(CHAIN), 1) <= 1e-6


@needs_mystran
def test_celas3_celas4_sload_agree_with_mystran_on_the_original_deck(tmp_path):
    """The forms MYSTRAN reads as written: CELAS3/CELAS4, SLOAD, SPC1 with component 0."""
    bulk = (f"SPOINT,1,2,3\nCELAS4,1,{K[1]},1,2\nCELAS3,2,10,2,3\nPELAS,10,{K[2]}\n"
            f"SLOAD,2,3,{P},2,4.\nSPC1,3,0,1\n")
    text = _deck(bulk)
    cases, report, u = _solve(_import(tmp_path, text))
    table = _mystran(tmp_path, text)[1]
    u2 = (P + 4.0) / K[1]
    u3 = u2 + P / K[2]
    for s, want in ((1, 0.0), (2, u2), (3, u3)):
        ours = u[report.index((s, 1)), 0]
        assert ours == pytest.approx(want, rel=CLOSED, abs=1e-300)
        assert table[s][0] == pytest.approx(ours, rel=1e-6, abs=1e-6 * u3)   # T1: the scalar DOF
        assert list(table[s][1:]) == [0.0] * 5


def test_mpc_on_scalar_points(tmp_path):
    """pyNastran's celas_mpc_series.solver.bdf: u2 = u3 ties two grounded springs."""
    bulk = ("SPOINT,1,THRU,4\nCELAS4,1,1000.,1,2\nCELAS4,2,1000.,3,4\nSLOAD,2,2,1.\n"
            "SPC1,3,,1,4\nMPC,10,2,,1.,3,,-1.\n")
    text = _deck(bulk, "  MPC = 10\n")
    cases, report, u = _solve(_import(tmp_path, text))
    for s, want in ((1, 0.0), (2, 1.0 / 2000.0), (3, 1.0 / 2000.0), (4, 0.0)):
        assert u[report.index((s, 1)), 0] == pytest.approx(want, rel=CLOSED, abs=1e-300)


@needs_mystran
def test_mpc_on_scalar_points_agrees_with_mystran(tmp_path):
    bulk = ("SPOINT,1,THRU,4\nCELAS4,1,1000.,1,2\nCELAS4,2,1000.,3,4\nSLOAD,2,2,1.\n"
            "SPC1,3,,1,4\nMPC,10,2,,1.,3,,-1.\n")
    assert _study_against_mystran(tmp_path, _deck(bulk, "  MPC = 10\n"), 1) <= 1e-6


E, AREA, L = 2.0e11, 1.0e-4, 2.0
MIXED = (f"GRID,1,,0.,0.,0.\nGRID,2,,{L},0.,0.\nCROD,1,1,1,2\nPROD,1,1,{AREA}\nMAT1,1,{E},,.3\n"
         "SPC1,3,123456,1\nSPC1,3,23456,2\nSPOINT,10,11\n"
         "CELAS2,5,3.e6,2,1,10\nCELAS4,6,2.e6,10,11\nCELAS3,7,30,11\nPELAS,30,1.e6\n"
         f"FORCE,2,2,,1000.,1.,0.,0.\nSLOAD,2,11,-300.\n")


def _mixed_closed() -> np.ndarray:
    """u2 (grid 2 along x), s10, s11: the chain fixed - rod - 2 - k1 - 10 - k2 - 11 - k3 - fixed."""
    kr, k1, k2, k3 = E * AREA / L, 3.0e6, 2.0e6, 1.0e6
    Kc = np.array([[kr + k1, -k1, 0.0], [-k1, k1 + k2, -k2], [0.0, -k2, k2 + k3]])
    return np.linalg.solve(Kc, [1000.0, 0.0, -300.0])


def test_springs_between_a_grid_and_scalar_points(tmp_path):
    cases, report, u = _solve(_import(tmp_path, _deck(MIXED)))
    got = [u[report.index(d), 0] for d in ((2, 1), (10, 1), (11, 1))]
    assert got == pytest.approx(_mixed_closed().tolist(), rel=CLOSED)


@needs_mystran
def test_springs_between_a_grid_and_scalar_points_agree_with_mystran(tmp_path):
    assert _study_against_mystran(tmp_path, _deck(MIXED), 1) <= 1e-6


def test_written_deck_reads_back_the_same(tmp_path):
    """write_deck (diagnose's edited decks, the mystran run deck's model) keeps scalar points."""
    deck = read_deck_text(MIXED.replace("FORCE,2,2,,1000.,1.,0.,0.\nSLOAD,2,11,-300.\n", "")
                          + "SPOINT,21,THRU,23\nCELAS4,11,5.,21,22\nCELAS3,12,30,23\n"
                            "CELAS1,13,30,22,,2,1\nSPC1,3,,23\nMPC,4,21,,1.,2,1,-1.\n", name="m.bdf")
    back = read_deck_text(write_deck(deck), name="w.bdf")
    assert back.scalar_points() == deck.scalar_points() == {10, 11, 21, 22, 23}
    assert back.mpcs[0].terms == deck.mpcs[0].terms == ((21, 1, 1.0), (2, 1, -1.0))
    assert [(s.components, s.grids) for s in back.spc1s] == [(s.components, s.grids) for s in deck.spc1s]
    assert {e: (s.g1, s.c1, s.g2, s.c2, back.spring_stiffness(s)) for e, s in back.springs.items()} == \
        {e: (s.g1, s.c1, s.g2, s.c2, deck.spring_stiffness(s)) for e, s in deck.springs.items()}


def test_solve_reports_one_component_per_scalar_point(tmp_path):
    from blackbox.cli import main
    result = _import(tmp_path, _deck(MIXED))
    from blackbox.commands.output import write_output
    study = tmp_path / "study"
    write_output(study, "import", result.write)
    assert main(["solve", str(study), "--out", str(tmp_path / "out")]) == 0
    rows = (tmp_path / "out" / "displacements.csv").read_text().splitlines()[1:]
    dofs = [(int(r.split(",")[1]), int(r.split(",")[2])) for r in rows]
    assert [c for g, c in dofs if g in (10, 11)] == [1, 1]
    assert sorted(c for g, c in dofs if g == 2) == [1, 2, 3, 4, 5, 6]


@pytest.mark.parametrize("bulk, line, card, field, why", [
    ("GRID,1,,0.,0.,0.\nSPOINT,1\n", 8, "SPOINT", 2, "duplicate GRID ID 1"),
    ("SPOINT,1,2\nCELAS2,1,1.,1,3,2\n", 8, "CELAS2", 5, "point 1 is a scalar point (SPOINT): its one component is 0"),
    ("SPOINT,1\nGRID,2,,0.,0.,0.\nCELAS4,1,1.,1,2\n", 9, "CELAS4", 5, "joins scalar points only, and point 2"),
    ("SPOINT,1\nGRID,2,,0.,0.,0.\nCELAS2,1,1.,1,,2\n", 9, "CELAS2", 7, "point 2 is no SPOINT"),
    ("SPOINT,1\nSPC1,3,123,1\n", 8, "SPC1", 3, "point 1 is a scalar point (SPOINT)"),
    ("SPOINT,1,2\nMPC,10,1,,1.,2,3,-1.\n", 9, "MPC", 7, "point 2 is a scalar point"),
])
def test_scalar_point_errors_are_located(bulk, line, card, field, why, tmp_path):
    mpc = "  MPC = 10\n" if "MPC," in bulk else ""
    text = (f"SOL 101\nCEND\nSUBCASE 1\n  LOAD = 2\n  SPC = 3\n{mpc}BEGIN BULK\n" + bulk
            + "SLOAD,2,1,1.\nSPC1,3,0,1\nENDDATA\n")
    with pytest.raises(DeckFormatError, match=re.escape(why)) as info:
        _import(tmp_path, text)
    exc = info.value
    assert (exc.line, exc.card, exc.field) == (line, card, field), str(exc)


@pytest.mark.parametrize("bulk, why", [
    (f"GRID,1,,0.,0.,0.\nSPOINT,2\nCROD,1,1,1,2\nPROD,1,1,{AREA}\nMAT1,1,{E},,.3\n",
     "CROD 1: point 2: scalar point(s) (SPOINT), which only CELAS springs, MPCs and SPCs can join"),
    ("GRID,1,,0.,0.,0.\nSPOINT,2\nRBE2,1,1,123,2\n", "RBE2 1: point 2: scalar point(s)"),
])
def test_elements_with_a_position_refuse_scalar_points(bulk, why):
    with pytest.raises(ModelError, match=re.escape(why)):
        read_deck_text(bulk, name="m.bdf")


@pytest.mark.parametrize("loads, why", [
    ("FORCE,2,1,,1.,1.,0.,0.\n", "point 1 is a scalar point (SPOINT): its load is an SLOAD"),
    ("SLOAD,2,5,1.\n", "point 5 is a GRID, not a scalar point (SPOINT)"),
    ("SLOAD,2,9,1.\n", "scalar point 9 does not exist (no SPOINT)"),
])
def test_loads_on_the_wrong_kind_of_point_are_located(loads, why, tmp_path):
    text = _deck("SPOINT,1\nGRID,5,,1.,0.,0.\nCELAS2,1,1.,1,,5,1\nSPC1,3,123456,5\n" + loads)
    with pytest.raises(DeckFormatError, match=re.escape(why)) as info:
        _import(tmp_path, text)
    assert info.value.line == 12 and info.value.field == 3


def test_framesolve_refuses_scalar_points():
    """A dialect that writes nodes with positions cannot carry a scalar point: refused, named."""
    from solver_adapters.legacy import unsupported_features
    deck = read_deck_text(MIXED.replace("FORCE,2,2,,1000.,1.,0.,0.\nSLOAD,2,11,-300.\n", ""), name="m.bdf")
    assert [c for c, _, _ in unsupported_features(deck) if c.startswith("SPOINT")] == ["SPOINT 10", "SPOINT 11"]
