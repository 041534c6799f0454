"""Thermal loads (TEMPERATURE(LOAD), TEMP, TEMPD, TEMPRB, MAT1 A and TREF) in ``blackbox import``
and the reference solver (docs/import.md).

References: closed forms of a bar's free thermal strain alpha (T - TREF) (a member clamped at both
ends does not move and pushes on its supports with E A alpha dT; a free end moves alpha dT L; a
gradient TP bends a cantilever to v(L) = -alpha TP L^2 / 2, Timoshenko & Goodier, Theory of
Elasticity, thermal stresses in beams) and MYSTRAN 18 running the same deck (the real binary).

Tolerances: closed forms 1e-12 relative (a handful of operations on exact element matrices);
MYSTRAN prints 7 significant digits: 1e-6 of each subcase's largest translation (rotation).
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from blackbox.commands import import_deck
from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import DeckFormatError, LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran

RTOL = 1e-6
CLOSED = 1e-12
E, A, ALPHA, TREF, L = 2.1e11, 1.0e-3, 1.2e-5, 20.0, 2.0
I1, I2 = 2.0e-6, 3.0e-6

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _import(tmp_path: Path, text: str, name: str = "deck.dat"):
    path = tmp_path / name
    path.write_text(text)
    return import_deck.run(path)


def _rows(result) -> dict[tuple[str, int, int], float]:
    return {(r.split(",")[0], int(r.split(",")[1]), int(r.split(",")[2])): float(r.split(",")[3])
            for r in result.loads_csv.splitlines()[1:]}


def _solve(result):
    """The imported study solved by the reference solver: ``(cases, report dofs, values)``."""
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    rows = _rows(result)
    cases = list(dict.fromkeys(c for c, _, _ in rows))
    dofs = list(dict.fromkeys((g, k) for _, g, k in rows))
    F = np.zeros((len(dofs), len(cases)))
    for (c, g, k), v in rows.items():
        F[dofs.index((g, k)), cases.index(c)] += v
    adapter = ReferenceAdapter(deck)
    report = list(adapter.dofs())
    return cases, report, adapter.solve(LoadMatrix.from_dense(dofs, F, cases), report).values


def _line(case: str, bulk: str, element: str) -> str:
    """Grids 1-2-3 along x (L each), the two members ``element`` (format with EID, GA, GB)."""
    return (f"SOL 101\nCEND\nSPC = 1\n{case}BEGIN BULK\nGRID,1,,0.,0.,0.\nGRID,2,,{L},0.,0.\n"
            f"GRID,3,,{2 * L},0.,0.\n" + element.format(1, 1, 2) + element.format(2, 2, 3) +
            f"PBAR,7,1,{A},{I1},{I2},4.E-6\nPROD,8,1,{A},4.E-6\nMAT1,1,{E},8.E10,,,{ALPHA},{TREF}\n"
            f"{bulk}ENDDATA\n")


BAR = "CBAR,{},7,{},{},0.,1.,0.\n"
ROD = "CROD,{},8,{},{}\n"
CONROD = "CONROD,{},{},{},1," + f"{A},4.E-6\n"


@pytest.mark.parametrize("element", [BAR, ROD, CONROD])
def test_member_clamped_at_both_ends_does_not_move(element, tmp_path):
    """Clamped at grids 1 and 3, 50 degrees above TREF (TEMPD): the middle grid stays put, and
    the load on each support is E A alpha dT along the member (the support's reaction is its
    opposite), the two members' loads at the middle grid cancelling."""
    deck = _line("TEMP(LOAD) = 9\n", "SPC1,1,123456,1,3\nTEMPD,9,70.\n" +
                 ("SPC1,1,456,2\n" if element != BAR else ""), element)
    result = _import(tmp_path, deck)
    rows = _rows(result)
    n = E * A * ALPHA * 50.0
    assert rows[("1", 1, 1)] == pytest.approx(-n, rel=CLOSED)
    assert rows[("1", 3, 1)] == pytest.approx(n, rel=CLOSED)
    assert ("1", 2, 1) not in rows
    assert set(rows) == {("1", 1, 1), ("1", 3, 1)}
    _, report, u = _solve(result)
    assert np.abs(u).max() == 0.0


@pytest.mark.parametrize("element", [BAR, ROD, CONROD])
def test_free_end_moves_alpha_dt_l(element, tmp_path):
    """Clamped at grid 1 only: grid temperatures 30, 50, 80 (TEMP) make the members' mean
    temperatures 40 and 65, so the free end moves alpha ((40 - TREF) + (65 - TREF)) L."""
    deck = _line("SUBCASE 4\n  TEMPERATURE(LOAD) = 9\n",
                 "SPC1,1,123456,1\nTEMP,9,1,30.,2,50.,3,80.\n" +
                 ("SPC1,1,23456,2,3\n" if element != BAR else ""), element)
    _, report, u = _solve(_import(tmp_path, deck))
    tip = u[report.index((3, 1)), 0]
    assert tip == pytest.approx(ALPHA * ((40.0 - TREF) + (65.0 - TREF)) * L, rel=CLOSED)
    assert u[report.index((2, 1)), 0] == pytest.approx(ALPHA * (40.0 - TREF) * L, rel=CLOSED)
    others = [i for i, (g, c) in enumerate(report) if c != 1]
    assert np.abs(u[others]).max(initial=0.0) <= 1e-12 * abs(tip)


def test_bar_gradients_bend_a_cantilever(tmp_path):
    """TEMPRB on a one-bar cantilever (v = basic y): a uniform gradient TP1 = 3 curves plane 1
    by v'' = -alpha TP1 (v(L) = -alpha TP1 L^2 / 2, theta_z = -alpha TP1 L), a gradient TP2
    varying from -4 at A to 2 at B curves plane 2 by w'' = -alpha TP2(x) (w(L) = -alpha L^2
    (TP2A / 3 + TP2B / 6), theta_y = -w'(L) = alpha L (TP2A + TP2B) / 2), and the mean of TA
    = 30, TB = 40 stretches it by alpha (35 - TREF) L."""
    deck = ("SOL 101\nCEND\nSPC = 1\nTEMP(LOAD) = 9\nBEGIN BULK\nGRID,1,,0.,0.,0.\n"
            f"GRID,2,,{L},0.,0.\nCBAR,1,7,1,2,0.,1.,0.\nPBAR,7,1,{A},{I1},{I2},4.E-6\n"
            f"MAT1,1,{E},8.E10,,,{ALPHA},{TREF}\nSPC1,1,123456,1\nTEMPRB,9,1,30.,40.,3.,3.,-4.,2.\nENDDATA\n")
    _, report, u = _solve(_import(tmp_path, deck))
    tip = {c: u[report.index((2, c)), 0] for c in range(1, 7)}
    expect = {1: ALPHA * (35.0 - TREF) * L, 2: -ALPHA * 3.0 * L**2 / 2, 6: -ALPHA * 3.0 * L,
              3: -ALPHA * L**2 * (-4.0 / 3 + 2.0 / 6), 5: ALPHA * L * (-4.0 + 2.0) / 2, 4: 0.0}
    for c, value in expect.items():
        assert tip[c] == pytest.approx(value, rel=CLOSED, abs=1e-15), c


def test_pin_flag_releases_the_thermal_axial_force(tmp_path):
    """A bar whose axial component is released at end A (PA = 1) between two clamped grids
    carries no axial force, so its thermal strain loads nothing: the case sums to zero and is
    left out, and no other case remains."""
    deck = ("SOL 101\nCEND\nSPC = 1\nTEMP(LOAD) = 9\nBEGIN BULK\nGRID,1,,0.,0.,0.\n"
            f"GRID,2,,{L},0.,0.\nCBAR,1,7,1,2,0.,1.,0.\n,1\nPBAR,7,1,{A},{I1},{I2},4.E-6\n"
            f"MAT1,1,{E},8.E10,,,{ALPHA},{TREF}\nSPC1,1,123456,1\nSPC1,1,23456,2\nTEMPD,9,99.\nENDDATA\n")
    with pytest.raises(DeckFormatError, match="every selected load set is zero"):
        _import(tmp_path, deck)


def test_springs_and_bushes_take_no_thermal_load(tmp_path):
    """A CELAS2 and a CBUSH beside the bar: the loads are the bar's alone (NASTRAN's springs
    and bushes have no expansion coefficient; MYSTRAN gives ELAS and BUSH elements no
    temperature)."""
    base = _line("TEMP(LOAD) = 9\n", "SPC1,1,123456,1,3\nTEMPD,9,70.\n", BAR)
    extra = "CELAS2,11,5.E5,2,2,3,2\nCBUSH,12,13,2,3,,,,0\nPBUSH,13,K,1.E6,1.E6,1.E6,1.E3,1.E3,1.E3\n"
    plain = _rows(_import(tmp_path, base, "a.dat"))
    springs = _rows(_import(tmp_path, base.replace("ENDDATA", extra + "ENDDATA"), "b.dat"))
    assert springs == plain


def test_load_and_thermal_load_in_one_subcase_add_up(tmp_path):
    """TEMPERATURE = n (LOAD and MATERIAL in SOL 101) beside LOAD = m: the case is the sum, and
    the MATERIAL part is named as having no effect (no MATTi)."""
    bulk = "SPC1,1,123456,1\nTEMPD,9,70.\nFORCE,5,3,,1000.,1.,0.,0.\n"
    both = _import(tmp_path, _line("LOAD = 5\nTEMPERATURE = 9\n", bulk, BAR), "a.dat")
    load = _rows(_import(tmp_path, _line("LOAD = 5\n", bulk, BAR), "b.dat"))
    temp = _rows(_import(tmp_path, _line("TEMP(LOAD) = 9\n", bulk, BAR), "c.dat"))
    rows = _rows(both)
    for key in set(load) | set(temp):
        assert rows[key] == pytest.approx(load.get(key, 0.0) + temp.get(key, 0.0), rel=1e-15)
    assert any("TEMPERATURE(MATERIAL) = 9" in n and "no effect" in n for n in both.notes)


def test_initial_temperature_equal_to_tref_is_accepted(tmp_path):
    bulk = "SPC1,1,123456,1\nTEMPD,9,70.\nTEMPD,8,20.\n"
    plain = _rows(_import(tmp_path, _line("TEMP(LOAD) = 9\n", bulk, BAR), "a.dat"))
    init = _rows(_import(tmp_path, _line("TEMP(INIT) = 8\nTEMP(LOAD) = 9\n", bulk, BAR), "b.dat"))
    assert init == plain


@pytest.mark.parametrize("case, bulk, card, field, why", [
    ("TEMP(LOAD) = 9\n", "TEMP,9,1,70.,2,70.\n", "TEMP", 2, "gives grid 3 .*no temperature"),
    ("TEMP(LOAD) = 9\n", "TEMPD,9,70.\nTEMPP1,9,1,70.,0.\n", "TEMPP1", 1, "contains TEMPP1"),
    ("TEMP(LOAD) = 9\n", "TEMPRB,9,99,70.,70.\n", "TEMPRB", 3, "not a CBAR"),
    ("TEMP(LOAD) = 9\n", "TEMPD,9,70.\nRBE2,50,3,123,4,1.E-5\nGRID,4,,5.,0.,0.\n", "RBE2", 1,
     "rigid elements is not modelled"),
])
def test_what_is_not_modelled_is_refused_where_it_is(case, bulk, card, field, why, tmp_path):
    with pytest.raises(DeckFormatError, match=why) as info:
        _import(tmp_path, _line(case, "SPC1,1,123456,1\n" + bulk, BAR))
    assert (info.value.card, info.value.field) == (card, field)


def test_temperature_selection_errors_name_the_line(tmp_path):
    for case, why in (("TEMP(LOAD) = 7\n", "temperature set 7 .*not found"),
                      ("TEMPERATURE(LOAD,HTIME=ALL) = 9\n", "option must be"),
                      ("TEMP = 9\n", "temperature-dependent materials are not modelled")):
        bulk = "SPC1,1,123456,1\nTEMPD,9,70.\n" + ("MATT1,1,5\n" if "MATE" in why or "depend" in why else "")
        with pytest.raises(DeckFormatError, match=why):
            _import(tmp_path, _line(case, bulk, BAR))
    deck = _line("TEMP(LOAD) = 9\n", "SPC1,1,123456,1\nTEMPD,9,70.\n", BAR).replace("SOL 101", "SOL 103")
    with pytest.raises(DeckFormatError, match="not linear statics: its TEMPERATURE") as info:
        _import(tmp_path, deck)
    assert info.value.line == 4


def test_unselected_temperature_cards_are_dropped_unread(tmp_path):
    """A malformed TEMPRB that no subcase selects is dropped with the other load cards (the
    cards of a set are read when a subcase selects it)."""
    result = _import(tmp_path, _line("LOAD = 5\n", "SPC1,1,123456,1\nFORCE,5,3,,1.,1.\n"
                                     "TEMPRB,9,1,70.,70.,,,,,+\n+,1.,2.\n", BAR))
    assert "TEMPRB" not in result.model_bdf


# --------------------------------------------------------------------------------------------
# against MYSTRAN
# --------------------------------------------------------------------------------------------
FRAME = """SOL 101
CEND
SPC = 1
DISP = ALL
SUBCASE 1
  TEMP(LOAD) = 10
SUBCASE 2
  LOAD = 5
  TEMPERATURE = 20
SUBCASE 3
  TEMPERATURE(LOAD) = 30
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
GRID,3,,2.,1.5,0.
GRID,4,,0.,1.5,1.
GRID,5,,2.,0.,2.
GRID,6,,4.,0.,0.,7
CORD2R,7,,0.,0.,0.,1.,1.,0.,+C7
+C7,0.,1.,1.
CBAR,1,7,1,2,0.,0.,1.
CBAR,2,8,2,3,0.,0.,1.,,+B2
+B2,,,.05,0.,.1,0.,-.05,.08
CBAR,3,9,3,4,1.,0.,0.,,+B3
+B3,15
CROD,4,11,4,1
CONROD,5,2,5,2,8.E-4,2.E-6
CBAR,6,8,2,6,0.,1.,1.
CELAS1,7,12,6,2,3,2
PELAS,12,4.E5
CBUSH,8,13,6,5,,,,0
PBUSH,13,K,1.E6,1.E6,1.E6,1.E4,1.E4,1.E4
PBAR,7,1,2.E-3,3.E-6,2.E-6,4.E-6
PBAR,8,1,1.5E-3,1.8E-6,1.2E-6,2.E-6,,,+P8
+P8,,,,,,,,,+Q8
+Q8,,,4.E-7
PBAR,9,1,1.E-3,1.E-6,1.5E-6,1.E-6
PROD,11,2,6.E-4,1.E-6
MAT1,1,2.1E11,8.1E10,,,1.2E-5,21.
MAT1,2,7.E10,2.6E10,,,2.3E-5
SPC1,1,123456,1,5
FORCE,5,3,,1000.,0.,0.,-1.
TEMP,10,1,20.,2,35.,3,50.
TEMP,10,4,10.
TEMPD,10,25.
TEMPD,20,60.
TEMPRB,30,1,30.,40.,3.,1.,-2.,4.
TEMPRB,30,2,25.,25.,-1.,2.,2.,2.
TEMPRB,30,3,10.,50.,4.,4.,1.,-3.
TEMPRB,30,6,21.,21.,5.,5.,0.,0.
TEMPRB,30,4,40.,60.
TEMPD,30,0.
ENDDATA
"""
"""A frame with every member the thermal load reaches (CBAR plain, with offsets, with a pin
flag PA = 15 releasing its axial force, with I12 in a grid with a CD system; a CROD and a
CONROD of a second material with TREF blank), a CELAS1 and a CBUSH (no thermal load), and the
three ways a subcase selects temperatures: TEMP + TEMPD (grid temperatures), TEMPERATURE = n
(LOAD and MATERIAL) beside a LOAD, TEMPRB with gradients varying along the bars beside TEMPD."""


def _mystran(run: Path, text: str) -> dict[int, dict[int, list[float]]]:
    from solver_adapters.nastran import mystran_binary, parse_f06
    run.mkdir(parents=True, exist_ok=True)
    (run / "m.dat").write_text(text)
    proc = subprocess.run([mystran_binary(), "m.dat"], cwd=run, capture_output=True, text=True, timeout=300)
    assert (run / "m.F06").exists(), proc.stdout[-2000:]
    res = parse_f06((run / "m.F06").read_text(errors="replace"))
    assert not res.errors, res.errors[:5]
    return res.displacements


@needs_mystran
def test_frame_agrees_with_mystran(tmp_path):
    """The imported frame solved by the reference solver against MYSTRAN running the deck as
    written, every grid and component (in each grid's CD system, as both print them)."""
    cases, report, u = _solve(_import(tmp_path, FRAME, "frame.dat"))
    ref = _mystran(tmp_path / "mystran", FRAME)
    grids = sorted(ref[1])
    for j, case in enumerate(cases):
        theirs = np.array([ref[int(case)][g] for g in grids])
        ours = np.array([[u[report.index((g, c)), j] if (g, c) in report else 0.0 for c in range(1, 7)]
                         for g in grids])
        for part in (slice(0, 3), slice(3, 6)):
            scale = np.abs(theirs[:, part]).max()
            assert scale > 0.0
            assert np.abs(ours[:, part] - theirs[:, part]).max() <= RTOL * scale, (case, part)
