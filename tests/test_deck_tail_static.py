"""Cards of real decks that a linear static solution reads its own way (issue 20): PBUSHT,
which NASTRAN uses only in frequency-response and nonlinear solutions (a static one takes the
PBUSH's nominal K, MSC QRG PBUSH remark 1).

References:

* closed forms. A CBUSH between coincident grids with CID 0 (MSC QRG CBUSH): six uncoupled
  springs along the basic axes, u_i = F_i / K_i at the loaded grid.
* MYSTRAN 18 run as a subprocess on the study written by the mystran adapter (MYSTRAN matches
  entry names on a prefix and reads a PBUSHT as a second PBUSH, ``*ERROR 1145``, so the
  original deck cannot run; the adapter hands it no PBUSHT).

Tolerances: closed forms to CLOSED = 1e-9 relative (a direct solve of a few DOFs in double
precision); MYSTRAN, which prints 7 significant digits, to RTOL = 1e-6 (tests/test_deck_tail.py).
"""

from __future__ import annotations

import pytest

from conftest import needs_mystran
from test_deck_tail import CLOSED, RTOL, _import, _solve
from test_deck_tail_elements import _study_against_mystran

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

KB = (1000.0, 2000.0, 3000.0, 4000.0, 5000.0, 6000.0)
LOADS = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0)

# pyNastran's sdbush01.bdf (a SOL 108 deck) has this layout: PBUSHT K and B tables on the
# CBUSH's PBUSH
BUSH = ("SOL 101\nCEND\nDISPLACEMENT = ALL\nSUBCASE 1\n  LOAD = 1\n  SPC = 1\nBEGIN BULK\n"
        "GRID,1,,0.,0.,0.\nGRID,2,,0.,0.,0.\nCBUSH,7,8,2,1,,,,0\n"
        f"PBUSH,8,K,{','.join(map(str, KB))}\n"
        "PBUSHT,8,K,101,101,101,101,101,101\n,B,103,103,103\n"
        "TABLED1,101\n,10.,700.,20.,700.,ENDT\nTABLED1,103\n,10.,30.,20.,30.,ENDT\n"
        "SPC1,1,123456,1\n"
        f"FORCE,1,2,,1.,{LOADS[0]},{LOADS[1]},{LOADS[2]}\n"
        f"MOMENT,1,2,,1.,{LOADS[3]},{LOADS[4]},{LOADS[5]}\nENDDATA\n")


def test_pbusht_leaves_the_nominal_stiffness_in_a_static_solution(tmp_path):
    result = _import(tmp_path, BUSH)
    assert any("PBUSHT 8 at" in n and "nominal K" in n for n in result.notes)
    assert "adapter = \"reference\"" in result.study_toml
    cases, report, u = _solve(result)
    got = [u[report.index((2, c)), 0] for c in range(1, 7)]
    assert got == pytest.approx([f / k for f, k in zip(LOADS, KB)], rel=CLOSED)


@needs_mystran
def test_pbusht_deck_agrees_with_mystran(tmp_path):
    assert _study_against_mystran(tmp_path, BUSH, 1) <= RTOL


def test_a_free_field_line_past_field_10_stays_a_located_error():
    """Vega's nas101prob2.dat writes MAT1,20,2.9+7,,.32,7.349-4,6.78-6,72.,24000.,24000.,24000.:
    ten fields after the name, where a card image has eight data fields and the continuation
    marker. pyNastran drops the fields past the ninth without a word (GE = 24000., the stress
    limits lost); whether the writer meant GE or ST SC SS is not in the line. An error that
    names the file and line and says how to split it, never a guess."""
    import re
    from solver_adapters.bdf import read_deck_text
    from solver_adapters.protocol import DeckFormatError
    line = "MAT1,20,2.9+7,,.32,7.349-4,6.78-6,72.,24000.,24000.,24000."
    with pytest.raises(DeckFormatError, match=re.escape("10 fields after field 1; at most 8 data")) as info:
        read_deck_text("GRID,1,,0.,0.,0.\n" + line + "\n", name="m.bdf")
    assert info.value.line == 2 and "split the line" in str(info.value)
    # written with a continuation, the same values read as MSC's field order gives them
    deck = read_deck_text("MAT1,20,2.9+7,,.32,7.349-4,6.78-6,72.,,+M\n+M,24000.,24000.,24000.\n", name="m.bdf")
    assert deck.mat1s[20].e == 2.9e7 and deck.mat1s[20].nu == 0.32
