"""RFORCE, the centrifugal load of a steady rotation, imported as NASTRAN's nodal loads on the
lumped mass (solver_adapters/elementloads.py, docs/import.md).

References: NASTRAN's definition (MSC and Autodesk Nastran QRG RFORCE: A in revolutions per unit
time, w = 2 pi A R with R = (R1, R2, R3) as given, the load at a grid its translational mass
times -w x (w x r)), worked by hand for the loads; MYSTRAN 18 for the displacements, which reads
A in radians per unit time (its run of a MYSTRAN benchmark deck, SB-BAR-RFORCE-OFFSET.DAT,
matches ours to 1.8e-16 once A is read so): its deck gets 2 pi A.

Tolerances: the hand loads are products of the deck's numbers (1e-12 relative); MYSTRAN prints 7
digits and its A is written with 8 (relative 3e-8): RTOL = 1e-6 as in tests/test_deck_tail.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from blackbox.commands import import_deck
from solver_adapters.protocol import DeckFormatError

from conftest import needs_mystran
from test_deck_tail import _agree, _mystran, _solve

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

A = 3.0                      # revolutions per unit time
R = (0.0, 0.0, 2.0)          # not a unit vector: w = 2 pi A R
DECK = f"""SOL 101
CEND
LOAD = 5
SPC = 1
DISPLACEMENT = ALL
BEGIN BULK
GRID,1,,0.5,0.,0.
GRID,2,,1.5,0.,0.
GRID,3,,2.5,0.3,0.
CBAR,1,7,1,2,0.,1.,0.
CBAR,2,7,2,3,0.,1.,0.
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3,7800.
SPC1,1,123456,1
CONM2,11,2,,5.,0.,0.,.2
CONM2,12,3,,3.,.1,.2,0.
RFORCE,5,1,,{A},{R[0]},{R[1]},{R[2]}
ENDDATA
"""


def _run(tmp_path, text=DECK):
    p = tmp_path / "rforce.dat"
    p.write_text(text)
    return import_deck.run(p)


def test_loads_by_hand(tmp_path):
    """The axis runs along z through grid 1 (x = 0.5): w = 2 pi 3 x 2 = 12 pi, w^2 = 144 pi^2.
    Lumped masses: bar 1 (length 1) 7800 x 1e-3 x 1 / 2 = 3.9 at each end; bar 2 (length
    sqrt(1.09)) 3.9 sqrt(1.09) at each end; the CONM2s 5 at grid 2 (offset (0, 0, .2)) and 3 at
    grid 3 (offset (.1, .2, 0)). Each grid's load: its mass times w^2 times its distance from the
    axis, outwards (grid 2: (1, 0) from the axis; grid 3: (2, .3)); a CONM2's moment about its
    grid is its offset crossed with its force."""
    w2 = (2 * math.pi * A * 2.0) ** 2
    half2 = 0.5 * 7.8 * math.sqrt(1.09)
    m2, m3 = 3.9 + half2 + 5.0, half2 + 3.0
    f2 = np.array([1.0, 0.0, 0.0]) * m2 * w2
    f3 = np.array([2.0, 0.3, 0.0]) * m3 * w2
    mom2 = np.cross([0.0, 0.0, 0.2], np.array([1.0, 0.0, 0.0]) * 5.0 * w2)
    mom3 = np.cross([0.1, 0.2, 0.0], np.array([2.0, 0.3, 0.0]) * 3.0 * w2)
    want = {(2, c + 1): v for c, v in enumerate([*f2, *mom2])} | {(3, c + 1): v for c, v in enumerate([*f3, *mom3])}
    rows = [r.split(",") for r in _run(tmp_path).loads_csv.splitlines()[1:]]
    got = {(int(r[1]), int(r[2])): float(r[3]) for r in rows}
    scale = max(abs(v) for v in want.values())
    for dof in set(want) | set(got):
        assert got.get(dof, 0.0) == pytest.approx(want.get(dof, 0.0), abs=1e-12 * scale), dof


@needs_mystran
def test_displacements_agree_with_mystran(tmp_path):
    """MYSTRAN running the deck with A given in its radians per unit time (2 pi A) against the
    imported study solved by the reference solver, every grid, to RTOL."""
    cases, report, u = _solve(_run(tmp_path))
    mys = DECK.replace(f"RFORCE,5,1,,{A},", f"RFORCE,5,1,,{2 * math.pi * A:.8g},")
    ref = _mystran(tmp_path, mys)[1]
    grids = [1, 2, 3]
    ours = np.array([[u[report.index((g, c)), 0] for c in range(1, 7)] for g in grids])
    _agree(ours, np.array([ref[g] for g in grids]), "RFORCE")


@pytest.mark.parametrize("card, field, says", [
    ("RFORCE,5,1,,3.,0.,0.,1.,2", "field 9", "METHOD 2"),
    ("RFORCE,5,1,,3.,0.,0.,1.,,+R\n+R,1.5", "field 10", "RACC"),
    ("RFORCE,5,1,,3.,0.,0.,0.", "field 6", "zero"),
    ("RFORCE,5,9,,3.,0.,0.,1.", "field 3", "grid 9 does not exist"),
])
def test_what_is_not_imported_is_a_located_error(card, field, says, tmp_path):
    text = DECK.replace(f"RFORCE,5,1,,{A},{R[0]},{R[1]},{R[2]}", card)
    with pytest.raises(DeckFormatError) as e:
        _run(tmp_path, text)
    assert "RFORCE" in str(e.value) and field in str(e.value) and says in str(e.value)
