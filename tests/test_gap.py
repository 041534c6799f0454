"""CGAP/PGAP gap elements in a linear static solution: the reader, ``blackbox import``, the
reference solver, the write-back of diagnose's decks, and the adapters that cannot run them.

References:
* NASTRAN's rule (MSC QRG CGAP remark 1: in a linear solution the gap is linear with its
  initial stiffness, which the initial opening U0 sets; MSC QRG PGAP: KA is the axial stiffness
  of the closed gap, KB of the open gap (blank: 1e-14 KA), KT the transverse stiffness of the
  closed gap (blank: MU1 KA)): closed (U0 <= 0) the gap is K = KA e e^T + KT (I - e e^T)
  between the translations of GA and GB, e the gap axis (GA -> GB, or CID's x axis); open
  (U0 > 0) K = KB e e^T.
* Closed forms: a gap from a held grid to a loaded one moves the loaded grid by
  (F . e) / KA along e and by the rest of F over KT across it; an open gap beside a rod of
  stiffness E A / L stretches by F / (E A / L + KB).
* MYSTRAN 18 has no gap element: the mystran adapter refuses CGAP by name before it runs, as do
  the OpenSees and FRAMESOLVE adapters.

Tolerance: 1e-12 relative (a 3x3 or 1x1 solve on exact element stiffnesses).
"""

from __future__ import annotations

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.bdf_write import write_deck
from solver_adapters.errors import ModelError, UnsupportedFeatureError
from solver_adapters.protocol import DeckFormatError, LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from test_deck_tail import _import, _solve

CLOSED = 1e-12
KA, KT, KB = 2.0e5, 3.0e3, 40.0
E_AXIS = np.array([1.0, 2.0, 2.0]) / 3.0

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _bulk(pgap: str, cgap: str = "CGAP,7,5,1,2\n", extra: str = "") -> str:
    """Grid 1 held, grid 2 three along E_AXIS, the gap between them."""
    x = 3.0 * E_AXIS
    return (f"GRID,1,,0.,0.,0.\nGRID,2,,{x[0]},{x[1]},{x[2]}\nSPC1,1,123456,1\n{cgap}{pgap}{extra}")


def _solve_bulk(bulk: str, force) -> np.ndarray:
    deck = read_deck_text(bulk, name="m.bdf")
    adapter = ReferenceAdapter(deck)
    report = [(2, c) for c in (1, 2, 3)]
    F = LoadMatrix.from_dense(report, np.asarray(force, float)[:, None], ["1"])
    return adapter.solve(F, report).values[:, 0]


def test_closed_gap_is_axial_ka_and_transverse_kt():
    F = np.array([10.0, -4.0, 7.0])
    u = _solve_bulk(_bulk(f"PGAP,5,0.,,{KA},,{KT}\n"), F)
    axial = F @ E_AXIS
    expect = axial / KA * E_AXIS + (F - axial * E_AXIS) / KT
    assert np.allclose(u, expect, rtol=CLOSED, atol=0.0)
    # an interference (U0 < 0) is closed too; KT blank is MU1 KA
    u = _solve_bulk(_bulk(f"PGAP,5,-0.01,,{KA},,,0.25\n"), F)
    expect = axial / KA * E_AXIS + (F - axial * E_AXIS) / (0.25 * KA)
    assert np.allclose(u, expect, rtol=CLOSED, atol=0.0)


@pytest.mark.parametrize("kb, k_open", [(f"{KB}", KB), ("", 1e-14 * KA)])
def test_open_gap_is_kb_along_its_axis_only(kb, k_open):
    """U0 > 0: the gap beside a CROD (E A / L along the same axis, x) takes KB (blank: 1e-14 KA)
    of the axial load and nothing across (KT is the closed gap's): with AUTOSPC off a transverse
    load finds no stiffness."""
    bulk = ("GRID,1,,0.,0.,0.\nGRID,2,,3.,0.,0.\nSPC1,1,123456,1\nSPC1,1,456,2\nCGAP,7,5,1,2\n"
            f"PGAP,5,0.2,,{KA},{kb},{KT}\nCROD,8,9,1,2\nPROD,9,3,0.01\nMAT1,3,1.E6,,0.3\n")
    u = _solve_bulk(bulk + "PARAM,AUTOSPC,NO\nSPC1,1,23,2\n", [6.0, 0.0, 0.0])
    assert u[0] == pytest.approx(6.0 / (1.0e6 * 0.01 / 3.0 + k_open), rel=CLOSED)
    with pytest.raises(Exception, match="no diagonal term at these free components.*2:T2, 2:T3"):
        _solve_bulk(bulk + "PARAM,AUTOSPC,NO\n", [0.0, 0.0, 1.0])


def test_gap_axis_from_cid_when_its_grids_coincide():
    """Coincident grids: the axis is CID's x (CORD2R with x along basic y)."""
    bulk = ("GRID,1,,0.,0.,0.\nGRID,2,,0.,0.,0.\nSPC1,1,123456,1\nCGAP,7,5,1,2,,,,4\n"
            f"PGAP,5,,,{KA},,{KT}\nCORD2R,4,,0.,0.,0.,0.,0.,1.\n,0.,1.,0.\n")
    u = _solve_bulk(bulk, [1.0, 2.0, 0.0])
    assert np.allclose(u, [1.0 / KT, 2.0 / KA, 0.0], rtol=CLOSED, atol=1e-300)


@pytest.mark.parametrize("bulk, words", [
    (_bulk(f"PGAP,5,0.,,0.,,{KT}\n"), "KA .axial stiffness of the closed gap. must be > 0"),
    (_bulk(f"PGAP,5,0.,,{KA},-1.\n"), "KB must be >= 0"),
    (_bulk(f"PGAP,5,0.,,{KA},,-1.\n"), "KT must be >= 0"),
    (_bulk(f"PGAP,6,0.,,{KA}\n"), "CGAP 7: property PID 5 not found .no PGAP."),
    (_bulk(f"PGAP,5,0.,,{KA}\n", "CGAP,7,5,1,1\n"), "GA and GB are the same grid"),
    (_bulk(f"PGAP,5,0.,,{KA}\n", "CGAP,7,5,1,2,,,,44\n"), "CID 44"),
    ("GRID,1,,0.,0.,0.\nGRID,2,,0.,0.,0.\nCGAP,7,5,1,2\nPGAP,5,,,1.\n", "coincide: the gap axis needs CID"),
    (_bulk(f"PGAP,5,0.,,{KA}\n", extra="PARAM,CDITER,5\n"), "constrained displacement iteration"),
])
def test_bad_gap_fields_are_located(bulk, words):
    with pytest.raises((DeckFormatError, ModelError), match=words):
        read_deck_text(bulk, name="m.bdf")


def test_nonlinear_only_fields_are_noted():
    deck = read_deck_text(_bulk(f"PGAP,5,0.,2.5,{KA},,{KT},0.3,0.2\n"), name="m.bdf")
    assert any("nonlinear solution only" in n and "PGAP 5" in n for n in deck.notes)


def test_import_solves_a_gap_with_the_reference_solver(tmp_path):
    text = ("SOL 101\nCEND\nSPC = 1\nLOAD = 3\nBEGIN BULK\n" + _bulk(f"PGAP,5,0.,,{KA},,{KT}\n")
            + "FORCE,3,2,,9.,1.,2.,2.\nENDDATA\n")
    res = _import(tmp_path, text)
    assert 'adapter = "reference"' in res.study_toml and not res.deck.unmodelled
    cases, report, u = _solve(res)
    got = np.array([u[report.index((2, c)), 0] for c in (1, 2, 3)])
    assert np.allclose(got, 27.0 / KA * E_AXIS, rtol=CLOSED, atol=0.0)   # F (N1, N2, N3): 27 along e


def test_write_deck_keeps_gaps():
    """Diagnose's edited decks are written from the parsed model: the gaps survive."""
    deck = read_deck_text(_bulk(f"PGAP,5,0.2,,{KA},,{KT},0.1\n", "CGAP,7,5,1,2,0.,0.,1.\n"), name="m.bdf")
    for fmt in ("small", "large", "free"):
        back = read_deck_text(write_deck(deck, fmt).split("BEGIN BULK\n")[1], name="w.bdf")
        assert back.gaps[7].__dict__ | {"src": ""} == deck.gaps[7].__dict__ | {"src": ""}
        assert back.pgaps[5].linear() == deck.pgaps[5].linear()


def test_adapters_without_a_gap_element_refuse_it_by_name(tmp_path):
    from solver_adapters.legacy import unsupported_features
    from solver_adapters.nastran import MystranAdapter
    from solver_adapters.opensees import Translation
    path = tmp_path / "m.bdf"
    path.write_text(_bulk(f"PGAP,5,0.,,{KA},,{KT}\n") + "ENDDATA\n")
    deck = read_deck_text(path.read_text(), name=str(path))
    assert any(c == "CGAP 7" for c, _, _ in unsupported_features(deck))
    assert any(c == "CGAP 7" for c, _, _ in Translation(deck).refused)
    report = [(2, 1)]
    with pytest.raises((DeckFormatError, UnsupportedFeatureError), match="cannot run CGAP"):
        MystranAdapter(path).solve(LoadMatrix.from_dense(report, np.ones((1, 1)), ["1"]), report)
    assert not list(tmp_path.glob("**/*.F06"))          # refused before MYSTRAN ran
