"""MSC's multi-line TEMPRB and TEMPERATURE(INITIAL) in ``blackbox import`` (docs/import.md,
thermal loads).

References: MSC QRG TEMPRB (line 2: temperatures at the stress-recovery points C, D, E, F of
each end, "used for stress recovery only"; line 3 on: further elements, ``EIDa THRU EIDb``);
MSC QRG TEMPERATURE (case control) remark 6: in linear static analysis the thermal strain is
alpha (T - T0), T0 the TEMPERATURE(INITIAL) set's temperature when one is given, else the
material's TREF. Closed forms: a free end moves alpha sum (T - T0) L over the members; a
gradient TP bends a cantilever to v(L) = -alpha TP L^2 / 2. MYSTRAN 18 runs the equivalent
decks: one TEMPRB line per element (MYSTRAN reads a TEMPRB continuation as further elements
only), and a uniform initial temperature as every MAT1's TREF.

Tolerances: closed forms 1e-12 relative (a few operations on exact element matrices);
MYSTRAN prints 7 significant digits: 1e-6 of each subcase's largest translation (rotation).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from solver_adapters.protocol import DeckFormatError

from conftest import needs_mystran
from test_thermal_loads import (ALPHA, BAR, CLOSED, FRAME, L, ROD, RTOL, TREF, _import, _line,
                                _mystran, _rows, _solve)

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


@pytest.mark.parametrize("element", [BAR, ROD])
def test_initial_temperature_replaces_tref(element, tmp_path):
    """Clamped at grid 1, load temperature 70 (TEMPD), initial temperatures 10, 30, 50 at grids
    1, 2, 3 (element means 20 and 40; TREF 20 is not used): the free end moves
    alpha ((70 - 20) + (70 - 40)) L."""
    deck = _line("TEMP(INIT) = 8\nTEMP(LOAD) = 9\n",
                 "SPC1,1,123456,1\nTEMPD,9,70.\nTEMP,8,1,10.,2,30.,3,50.\n" +
                 ("SPC1,1,23456,2,3\n" if element != BAR else ""), element)
    result = _import(tmp_path, deck)
    _, report, u = _solve(result)
    assert u[report.index((3, 1)), 0] == pytest.approx(ALPHA * (50.0 + 30.0) * L, rel=CLOSED)
    assert u[report.index((2, 1)), 0] == pytest.approx(ALPHA * 50.0 * L, rel=CLOSED)
    uniform = _line("TEMP(INIT) = 8\nTEMP(LOAD) = 9\n", "SPC1,1,123456,1\nTEMPD,9,70.\nTEMPD,8,25.\n", BAR)
    _, report, u = _solve(_import(tmp_path, uniform, "u.dat"))
    assert u[report.index((3, 1)), 0] == pytest.approx(ALPHA * 45.0 * 2 * L, rel=CLOSED)


def test_initial_gradient_is_subtracted(tmp_path):
    """A cantilever bar with gradient TP1 = 5 under load and TP1 = 2 initially bends by the
    difference, v(L) = -alpha 3 L^2 / 2; the equal mean temperatures give no stretch."""
    deck = ("SOL 101\nCEND\nSPC = 1\nTEMP(INIT) = 8\nTEMP(LOAD) = 9\nBEGIN BULK\nGRID,1,,0.,0.,0.\n"
            f"GRID,2,,{L},0.,0.\nCBAR,1,7,1,2,0.,1.,0.\nPBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6\n"
            f"MAT1,1,2.1E11,8.E10,,,{ALPHA},{TREF}\nSPC1,1,123456,1\n"
            "TEMPRB,9,1,30.,30.,5.,5.\nTEMPRB,8,1,30.,30.,2.,2.\nENDDATA\n")
    _, report, u = _solve(_import(tmp_path, deck))
    assert u[report.index((2, 2)), 0] == pytest.approx(-ALPHA * 3.0 * L**2 / 2, rel=CLOSED)
    assert abs(u[report.index((2, 1)), 0]) <= 1e-12 * ALPHA * 3.0 * L**2


FOUR = ("SOL 101\nCEND\nSPC = 1\nTEMP(LOAD) = 9\nBEGIN BULK\n" +
        "".join(f"GRID,{g},,{(g - 1) * L},0.,0.\n" for g in range(1, 6)) +
        "".join(f"CBAR,{e},7,{e},{e + 1},0.,1.,0.\n" for e in (1, 2, 3, 4)) +
        f"PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6\nMAT1,1,2.1E11,8.E10,,,{ALPHA},{TREF}\nSPC1,1,123456,1\n"
        "{temprb}ENDDATA\n")


def test_msc_temprb_continuation(tmp_path):
    """One TEMPRB for four bars (MSC's layout: the stress-recovery temperatures on line 2, then
    element 2 and 3 THRU 4): each stretches by alpha ((TA + TB) / 2 - TREF) L; the stress-
    recovery temperatures load nothing (other values give the same loads)."""
    def card(c: str) -> str:          # small field, 8 columns each
        return ("TEMPRB  9       1       60.     80.                                     +\n"
                "+       " + c.ljust(8) * 8 + "+\n"
                "+       2       3       THRU    4\n")

    rows = _rows(_import(tmp_path, FOUR.format(temprb=card("100.")), "a.dat"))
    assert _rows(_import(tmp_path, FOUR.format(temprb=card("-500.")), "b.dat")) == rows
    _, report, u = _solve(_import(tmp_path, FOUR.format(temprb=card("")), "c.dat"))
    assert u[report.index((5, 1)), 0] == pytest.approx(ALPHA * (70.0 - TREF) * 4 * L, rel=CLOSED)


@pytest.mark.parametrize("lines, field, why", [
    ("+,,,,,,,,,+\n+,THRU,4\n", 18, "THRU needs an element ID before it"),
    ("+,,,,,,,,,+\n+,4,THRU,2\n", 20, "second ID must be larger"),
    ("+,,,,,,,,,+\n+,2,1\n", 19, "element 1 has a TEMPRB in set 9 already"),
    ("+,,,,,,,,,+\n+,2,1,THRU,3\n", 19, r"element 1 \(of 1 THRU 3\) has a TEMPRB"),
    ("+,,,,,,,,,+\n+,7\n", 18, "element 7 is not a CBAR"),
    ("+,1.,2.,X\n", 12, "not a real"),
])
def test_bad_temprb_continuations_are_located(lines, field, why, tmp_path):
    deck = FOUR.format(temprb="TEMPRB,9,1,60.,80.,,,,,+\n" + lines)
    with pytest.raises(DeckFormatError, match=why) as info:
        _import(tmp_path, deck)
    assert (info.value.card, info.value.field) == ("TEMPRB", field)


def test_initial_and_material_temperatures_together_are_refused(tmp_path):
    """MSC QRG TEMPERATURE remark 8: TEMPERATURE(MATERIAL) and TEMPERATURE(INITIAL) cannot be
    given in the same run."""
    deck = _line("TEMP(INIT) = 8\nTEMPERATURE = 9\n", "SPC1,1,123456,1\nTEMPD,9,70.\nTEMPD,8,20.\n", BAR)
    with pytest.raises(DeckFormatError, match="cannot both be given") as info:
        _import(tmp_path, deck)
    assert info.value.card == "TEMPERATURE"


# --------------------------------------------------------------------------------------------
# against MYSTRAN
# --------------------------------------------------------------------------------------------
def _against(tmp_path, ours_text: str, theirs_text: str) -> None:
    cases, report, u = _solve(_import(tmp_path, ours_text, "frame.dat"))
    ref = _mystran(tmp_path / "mystran", theirs_text)
    grids = sorted(ref[int(cases[0])])
    for j, case in enumerate(cases):
        theirs = np.array([ref[int(case)][g] for g in grids])
        ours = np.array([[u[report.index((g, c)), j] if (g, c) in report else 0.0 for c in range(1, 7)]
                         for g in grids])
        for part in (slice(0, 3), slice(3, 6)):
            scale = np.abs(theirs[:, part]).max()
            assert scale > 0.0
            assert np.abs(ours[:, part] - theirs[:, part]).max() <= RTOL * scale, (case, part)


@needs_mystran
def test_msc_temprb_agrees_with_mystran_on_one_line_per_element(tmp_path):
    """The thermal frame of test_thermal_loads with its subcase-3 TEMPRBs in MSC's layout (stress-
    recovery temperatures, then elements 3 and 6 THRU 7, bar 6 and the spring 7, which a
    TEMPRB does not reach, sharing bar 2's temperatures) against MYSTRAN running one TEMPRB
    line per element."""
    base = re.sub(r"TEMPRB,30,[236],.*\n", "", FRAME)
    ours = base.replace("TEMPD,30,0.\n", "TEMPD,30,0.\nTEMPRB,30,2,25.,35.,-1.,2.,2.,2.,+T\n"
                        "+T,1.,2.,3.,4.,5.,6.,7.,8.,+U\n+U,3,6,THRU,7\n")
    theirs = base.replace("TEMPD,30,0.\n", "TEMPD,30,0.\n" + "".join(
        f"TEMPRB,30,{e},25.,35.,-1.,2.,2.,2.\n" for e in (2, 3, 6)))
    _against(tmp_path, ours, theirs)


@needs_mystran
def test_initial_temperature_agrees_with_mystran(tmp_path):
    """The thermal frame with TEMP(INIT) = 40, a uniform 15 degrees (TEMPD), against MYSTRAN
    running the frame whose MAT1 TREFs are 15 (MSC's rule: the initial set replaces TREF); the
    subcase with TEMPERATURE = n (LOAD and MATERIAL) made TEMP(LOAD), as remark 8 requires."""
    ours = FRAME.replace("SPC = 1\n", "SPC = 1\nTEMP(INIT) = 40\n").replace(
        "TEMPERATURE = 20", "TEMP(LOAD) = 20").replace("ENDDATA", "TEMPD,40,15.\nENDDATA")
    theirs = FRAME.replace("TEMPERATURE = 20", "TEMP(LOAD) = 20").replace(
        "MAT1,1,2.1E11,8.1E10,,,1.2E-5,21.", "MAT1,1,2.1E11,8.1E10,,,1.2E-5,15.").replace(
        "MAT1,2,7.E10,2.6E10,,,2.3E-5", "MAT1,2,7.E10,2.6E10,,,2.3E-5,15.")
    assert theirs.count(",15.") == 2
    _against(tmp_path, ours, theirs)
