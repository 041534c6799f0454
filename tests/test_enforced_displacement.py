"""Enforced displacements (SPC with a value D, SPCD) imported by the large-spring method
(blackbox/commands/enforced.py, docs/import.md).

References: beam theory's closed forms for a cantilever (Euler-Bernoulli; the reference solver's
cubic elements are exact at the nodes for end loads and end displacements) and MYSTRAN 18 running
the original input file (its own SPC D and SPCD).

Tolerances: the large spring leaves the enforced DOF short of D by k/K with K = 1e8 x the largest
diagonal stiffness (k <= that diagonal), so closed forms are held to 1e-7 relative (10x that
bound, which also covers the rounding of the stiff solve). MYSTRAN prints 7 significant digits:
RTOL = 1e-6 of each subcase's largest translation (rotation), as in tests/test_deck_tail.py.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from blackbox.commands import import_deck
from solver_adapters.protocol import DeckFormatError

from conftest import needs_mystran
from test_deck_tail import _agree, _mystran, _solve

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

L, E, NU = 2.0, 2.1e11, 0.3
I1, I2, J, A = 2.0e-6, 3.0e-6, 4.0e-6, 1.0e-3
D_AXIAL = 1.0e-3       # SPC value: the tip pulled along the beam in every subcase
D_TIP = 1.0e-2         # SPCD (subcase 1): the tip pushed in z
D_BASE = 4.0e-3        # SPCD through LOAD 20 = 2.0 x (0.5 x set 21): the base settles in y
P = 1.0e3              # FORCE at mid-span in y, LOAD 20 = 2.0 x (1.0 x set 22)

DECK = f"""SOL 101
CEND
SPC = 1
DISPLACEMENT = ALL
SUBCASE 1
  LOAD = 10
SUBCASE 2
  LOAD = 20
BEGIN BULK
GRID,1,,0.,0.,0.
GRID,2,,0.5,0.,0.
GRID,3,,1.,0.,0.
GRID,4,,1.5,0.,0.
GRID,5,,2.,0.,0.
CBAR,1,7,1,2,0.,1.,0.
CBAR,2,7,2,3,0.,1.,0.
CBAR,3,7,3,4,0.,1.,0.
CBAR,4,7,4,5,0.,1.,0.
PBAR,7,1,{A:.4E},{I1:.4E},{I2:.4E},{J:.4E}
MAT1,1,{E:.4E},,{NU}
$ the base clamped, its y translation in the set so that an SPCD can move it
SPC1,1,123456,1
$ the tip: z held (moved by the SPCD of subcase 1), x pulled by D_AXIAL in every subcase
SPC,1,5,3,0.,5,1,{D_AXIAL}
SPCD,10,5,3,{D_TIP}
LOAD,20,2.,0.5,21,1.,22
SPCD,21,1,2,{D_BASE / 1.0}
FORCE,22,3,,{P / 2.0},0.,1.,0.
ENDDATA
"""


def _table(u, report, grids):
    return np.array([[u[report.index((g, c))] for c in range(1, 7)] for g in grids])


def test_enforced_values_against_beam_theory(tmp_path):
    """Subcase 1: tip z at D_TIP with the base clamped, w(x) = D x^2 (3L - x) / (2 L^3) and the
    rotation about y -dw/dx; the axial pull u(x) = D_AXIAL x / L. Subcase 2: the base settles by
    2 x 0.5 x D_BASE in y (the whole beam moves with it: the clamp turns nothing) and the mid-span
    force 2 x 1 x P/2 = P gives the cantilever's P x^2 (3a - x) / (6 E I) (x <= a), P a^2 (3x - a)
    / (6 E I) beyond, a = L/2; the tip's z is held at zero there, which a y load does not feel."""
    res = import_deck.run(_write(tmp_path))
    assert any("large-spring method" in n for n in res.notes)
    cases, report, u = _solve(res)
    assert cases == ["1", "2"]
    x = np.array([0.0, 0.5, 1.0, 1.5, 2.0])
    grids = [1, 2, 3, 4, 5]
    t1, t2 = _table(u[:, 0], report, grids), _table(u[:, 1], report, grids)
    w = D_TIP * x**2 * (3 * L - x) / (2 * L**3)
    ry = -D_TIP * (6 * L * x - 3 * x**2) / (2 * L**3)
    ax = D_AXIAL * x / L
    np.testing.assert_allclose(t1[:, 2], w, rtol=0, atol=1e-7 * D_TIP)
    np.testing.assert_allclose(t1[:, 4], ry, rtol=0, atol=1e-7 * abs(ry).max())
    np.testing.assert_allclose(t1[:, 0], ax, rtol=0, atol=1e-7 * D_AXIAL)
    a, EI = L / 2, E * I1      # y bending of a CBAR with v = (0, 1, 0): plane 1, I1
    v = np.where(x <= a, P * x**2 * (3 * a - x) / (6 * EI), P * a**2 * (3 * x - a) / (6 * EI))
    settle = 2.0 * 0.5 * D_BASE
    np.testing.assert_allclose(t2[:, 1], settle + v, rtol=0, atol=1e-7 * (settle + v.max()))
    np.testing.assert_allclose(t2[:, 0], ax, rtol=0, atol=1e-7 * D_AXIAL)
    assert np.abs(t2[:, 2]).max() < 1e-7 * D_TIP


def _write(tmp_path: Path, text: str = DECK) -> Path:
    p = tmp_path / "enforced.dat"
    p.write_text(text)
    return p


def test_model_keeps_the_other_constraints_and_says_what_replaced_them(tmp_path):
    """The SPC card holding the tip (z and x, both enforced) and the SPC1 clamping the base
    (its y enforced in subcase 2) are replaced: the base keeps 13456, the tip nothing. Each
    enforced DOF is tied by an MPC to a handle grid (IDs above the deck's) whose one free
    component carries a grounded CELAS2 (IDs above the elements); loads.csv has K x D there."""
    res = import_deck.run(_write(tmp_path))
    model = res.model_bdf
    lines = model.splitlines()
    assert "SPC1,1,13456,1" in lines
    assert not any(ln.startswith(("SPC,", "SPC1,1,123456")) for ln in lines)
    mpcs = {(int(f[2]), int(f[3])): int(f[5]) for f in (ln.split(",") for ln in lines if ln.startswith("MPC,"))}
    assert sorted(mpcs) == [(1, 2), (5, 1), (5, 3)]
    assert all(h >= 10 for h in mpcs.values())
    springs = {int(f[3]): float(f[2]) for f in (ln.split(",") for ln in lines if ln.startswith("CELAS2,"))}
    assert set(springs) == set(mpcs.values())
    rows = [r.split(",") for r in res.loads_csv.splitlines()[1:]]
    load = {(r[0], int(r[1]), int(r[2])): float(r[3]) for r in rows}
    tip_z, base_y = mpcs[(5, 3)], mpcs[(1, 2)]
    assert load[("1", tip_z, 3)] == pytest.approx(springs[tip_z] * D_TIP)
    assert load[("2", base_y, 2)] == pytest.approx(springs[base_y] * 2.0 * 0.5 * D_BASE)
    assert ("2", tip_z, 3) not in load          # held at zero by the spring alone


def _mystran_deck(sub: int) -> str:
    """Subcase ``sub`` for MYSTRAN 18 with SPC values only: it reads SPCD but does not apply it
    (a run of DECK moves neither the tip in subcase 1 nor the base in subcase 2), takes no SPCD
    set in a LOAD combination nor a load set of SPCDs alone, and one constraint set per run. So
    one run per subcase, its constraint set holding what the SPCDs enforce there, at their
    combined values, and the D_AXIAL pull; subcase 1 loads a zero force."""
    bulk = DECK.split("BEGIN BULK\n")[1]
    bulk = bulk[:bulk.index("$ the base")]
    settle = 2.0 * 0.5 * D_BASE
    spc = (f"SPC1,1,123456,1\nSPC,1,5,3,{D_TIP},5,1,{D_AXIAL}\nFORCE,10,2,,0.,0.,1.,0.\n" if sub == 1 else
           f"SPC1,1,13456,1\nSPC,1,1,2,{settle},5,3,0.\nSPC,1,5,1,{D_AXIAL}\nFORCE,10,3,,{P:.1f},0.,1.,0.\n")
    return f"SOL 101\nCEND\nDISPLACEMENT = ALL\nSPC = 1\nLOAD = 10\nBEGIN BULK\n{bulk}{spc}ENDDATA\n"


@needs_mystran
def test_enforced_values_agree_with_mystran(tmp_path):
    """MYSTRAN enforcing the same displacements with SPC values (:func:`_mystran_deck`, one run
    per subcase) against the study imported from DECK (SPC value, SPCD overriding it, SPCD
    scaled in a LOAD combination) and solved by the reference solver: every grid, to RTOL."""
    cases, report, u = _solve(import_deck.run(_write(tmp_path)))
    grids = [1, 2, 3, 4, 5]
    for j, sub in enumerate((1, 2)):
        ref = _mystran(tmp_path / f"s{sub}", _mystran_deck(sub))[1]
        ours = _table(u[:, j], report, grids)
        _agree(ours, np.array([ref[g] for g in grids]), f"subcase {sub}")


def test_spcd_on_a_free_dof_is_a_located_error(tmp_path):
    """NASTRAN requires an SPCD's DOF to be held by an SPC/SPC1 of the selected set."""
    text = DECK.replace("SPCD,10,5,3,", "SPCD,10,4,3,")
    with pytest.raises(DeckFormatError) as e:
        import_deck.run(_write(tmp_path, text))
    msg = str(e.value)
    assert "enforced.dat" in msg and "SPCD" in msg and "grid 4 component 3" in msg


def test_a_subcase_with_only_an_enforced_value_is_imported(tmp_path):
    """A load set holding only an SPCD is a case (the displacement is its load)."""
    text = DECK.replace(f"FORCE,22,3,,{P / 2.0},0.,1.,0.", "FORCE,22,3,,0.,0.,1.,0.")
    res = import_deck.run(_write(tmp_path, text))
    assert res.cases == ("1", "2")


def _portal_study(tmp_path):
    """tests/data/decks/portal_joint.bdf with two more subcases, one loaded by an SPCD settling
    the right column's base (grid 3, z), one by an SPCD pushing the left base (grid 1, x) beside
    a force; imported with its joint J2 (grids 2, 21) and measured from a simulation of the
    reference solver (k = 2e6 N m/rad, 2 % noise, seed 3)."""
    import shutil
    from blackbox.cli import main as cli
    decks = Path(__file__).parent / "data" / "decks"
    for name in ("portal_joint.bdf", "portal_props.inc"):
        shutil.copy(decks / name, tmp_path / name)
    text = (tmp_path / "portal_joint.bdf").read_text()
    text = text.replace("SUBCASE 104\n  SUBTITLE = NO LOAD: NOT IMPORTED\n",
                        "SUBCASE 105\n  LOAD = 60\nSUBCASE 106\n  LOAD = 70\nSUBCASE 107\n  LOAD = 50\n")
    text = text.replace("ENDDATA", "SPCD,60,3,3,0.002\nSPCD,70,1,1,0.001\nFORCE,70,5,0,300.,0.,1.,0.\nENDDATA")
    (tmp_path / "portal_enf.bdf").write_text(text)
    (tmp_path / "truth.toml").write_text(
        'seed = 3\n[[joints]]\nname = "J2"\nmodel = "simple"\nvalue = 2.0e6\n[noise]\nrelative = 0.02\n'
        'floor = 0.02\n[measure]\njoint = true\naway_grids = [3, 4, 5]\n'
        'cases = ["101", "102", "103", "105", "106", "107"]\n')
    assert cli(["import", str(tmp_path / "portal_enf.bdf"), "--out", str(tmp_path / "st"), "--joint", "J2:2,21"]) == 0
    assert cli(["simulate", str(tmp_path / "st"), "--truth", str(tmp_path / "truth.toml"),
                "--out", str(tmp_path / "sim")]) == 0
    return cli, tmp_path / "sim"


def test_an_imported_study_with_enforced_values_identifies_and_diagnoses(tmp_path):
    """End to end on the handles, MPCs and springs the import writes: identify finds the
    simulated joint (k = 2e6 inside each 95 % interval; the two well-determined springs within
    5 % of it), and diagnose, whose edited decks carry the MPCs and handle grids, adds nothing
    ("adequate"): the data hold no effect."""
    import json
    cli, sim = _portal_study(tmp_path)
    assert cli(["identify", str(sim), "--out", str(tmp_path / "oi")]) == 0
    params = json.loads((tmp_path / "oi" / "result.json").read_text())["parameters"]
    for p in params:
        assert p["ci_low"] <= 2.0e6 <= p["ci_high"], p
    assert sum(abs(p["value"] / 2.0e6 - 1) < 0.05 for p in params) >= 2
    cli(["diagnose", str(sim), "--out", str(tmp_path / "od")])
    diag = json.loads((tmp_path / "od" / "diagnosis.json").read_text())
    assert diag["verdict"] == "adequate" and not diag["added"]


@needs_mystran
def test_the_same_study_identifies_alike_through_mystran(tmp_path):
    """The mystran adapter runs the imported model (handle grids, MPCs, grounded CELAS2 of
    1e17): its identification equals the reference solver's to 1e-4 of each value (MYSTRAN's 7
    printed digits carried through the fit)."""
    import json
    cli, sim = _portal_study(tmp_path)
    got = {}
    for adapter in ("reference", "mystran"):
        assert cli(["identify", str(sim), "--out", str(tmp_path / adapter), "--adapter", adapter]) == 0
        got[adapter] = [p["value"] for p in json.loads((tmp_path / adapter / "result.json").read_text())["parameters"]]
    np.testing.assert_allclose(got["mystran"], got["reference"], rtol=1e-4)
