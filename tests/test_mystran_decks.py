"""The MYSTRAN run deck is written from the parsed model: every format a user may write reads the
same, grounded springs work, unmodelled cards (shells) pass re-formatted, diagnose's edited decks
run.

Tolerances: MYSTRAN prints 7 significant digits (docs/mystran.md), so its displacements are held
to RTOL_F06 = 1e-6 of each case's largest displacement against the reference solver (as the
conformance suite does). Two MYSTRAN runs of decks that describe the same model in different
spellings are held to the same bound (they may round differently in the last printed digit).
Round trips through our own reader and writer are exact (the writer prints the shortest digits
that read back bit for bit when they fit 16 characters).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from solver_adapters.bdf import read_deck, read_deck_text
from solver_adapters.conformance import FIELD_STYLES, deck_text, write_generated_deck
from solver_adapters.nastran import (MystranAdapter, NastranDialect, RawCard, case_control, model_ids,
                                     passthrough_cards, raw_card_text, read_model)
from solver_adapters.protocol import DeckFormatError, LoadMatrix, ScalarSpring
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.subprocess import BaseDeck, run_solver

from conftest import fixture_diagnosis, needs_mystran

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data"
RTOL_F06 = 1e-6

pytestmark = [pytest.mark.usefixtures("runs_under_tmp_path"),
              # one xdist worker for the modules that share conftest.fixture_diagnosis's cache
              pytest.mark.xdist_group("fixture_diagnosis")]


# --------------------------------------------------------------------------------------------
# round trips: read -> run-deck bulk data -> read
# --------------------------------------------------------------------------------------------
def _plain(x):
    """An entity as the run deck can give it back: no source location, a grid's position in basic
    (CP 0), a CBEAM/PBEAM/PBEAML/PBARL as the CBAR/PBAR it is written as, an RBAR as its RBE2, a
    CTUBE/PTUBE as its CROD/PROD."""
    if isinstance(x, (tuple, list)):
        return tuple(_plain(v) for v in x)
    if dataclasses.is_dataclass(x):
        values = {f.name: _plain(getattr(x, f.name)) for f in dataclasses.fields(x)}
        values.pop("src", None)
        if "cp" in values:
            values["cp"] = 0
        if type(x).__name__ in ("CBar", "PBar", "Rbe2", "Rod", "Prod"):
            values["card"] = None
        return (type(x).__name__, tuple(sorted(values.items())))
    return x


REAL_RTOL = 1e-11
"""A real the reader computed (MAT1's G from E and NU, a PBARL's section constants, a position
converted from a CP system) may need 17 digits; a 16-character field keeps 11 to 15 (fewer when an
exponent is needed), so such reals come back within 1e-11 relative; the others exactly."""


def _close(a, b, path="") -> None:
    if isinstance(a, float) and isinstance(b, float):
        assert math.isclose(a, b, rel_tol=REAL_RTOL, abs_tol=1e-300) or (abs(a) < 1e-14 and abs(b) < 1e-14), (path, a, b)
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _close(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), (path, a, b)
        for i, (u, v) in enumerate(zip(a, b)):
            _close(u, v, f"{path}[{i}]")
    else:
        assert a == b, (path, a, b)


def _entities(deck) -> dict:
    out = {}
    for f in dataclasses.fields(deck):
        if f.name in ("files", "no_effect", "coords") or f.name.endswith("_src"):
            continue
        v = getattr(deck, f.name)
        out[f.name] = ({k: _plain(e) for k, e in v.items()} if isinstance(v, dict)
                       else tuple(sorted((_plain(e) for e in v), key=repr)) if isinstance(v, list) else v)
    return out


def _run_bulk(path: Path, springs=()) -> tuple[str, object]:
    dialect = NastranDialect()
    model = read_model(path, "pass")
    lines, ids = dialect.bulk_lines(BaseDeck(path, model), springs)
    return "\n".join(lines) + "\n", (model, ids)


ROUND_TRIP_DECKS = ["cbar_pins_offsets.bdf", "cbeam_cantilevers.bdf", "coord_cantilever.bdf", "coord_frame.bdf",
                    "pbar_i12.bdf", "pbarl_angle.bdf", "pbarl_cantilevers.bdf", "rbe3_posts.bdf", "rod_line.bdf",
                    "rod_tripod.bdf", "shear_cantilever.bdf"]

EVERY_CARD = """$ every card the reader models, in mixed formats
GRDSET,,0,,,,0,6
GRID    1               0.      0.      0.              123456
GRID,2,,1.,0.,0.,,
GRID*   3                               2.              .5
*       .25                                     345
GRID,4,,2.,1.,0.
GRID,5,,3.,1.,0.
BAROR,,7,,,0.,0.,1.
CBAR    1               1       2
CBAR,2,7,2,3,,,,
,,6,0.,0.,.1,0.,0.,.1
CBAR,3,8,3,4,1
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
PBAR,8,1,2.E-3,2.5E-6,1.5E-6,3.E-6,,,
,,,,,,,,,
,.8,.7
CROD,4,9,4,5
PROD,9,1,1.E-4,1.E-8
CONROD,5,1,3,1,1.5E-4,2.E-8
MAT1,1,2.1E11,,.3
SPC1,1,123,1,THRU,2
SPC,2,5,12,0.,4,3
SPCADD,3,1,2
RBE2,6,4,123456,5
PELAS,11,1.E5,,,12,2.5E4
CELAS1,7,11,5,4
CELAS1,8,12,,,5,5
CELAS2,9,3.E4,4,6,5,6
CELAS2,10,-2.E3,5,1
GRID,6,,4.,1.,0.
RBAR,12,5,6,123456,,,12345
GRID,7,,4.,2.,0.
CTUBE,13,14,6,7
PTUBE,14,1,.05,.004
GRID,8,,4.,2.,.5
GRID,9,,4.,2.,1.
CRIGD1,25,7,8
CRIGD2,26,7,9,123456
SPOINT,20,21
CELAS3,15,11,20,21
CELAS4,16,4.E4,21
CELAS2,17,5.E4,20,,4,1
MPC,30,20,,1.,5,2,-.5
MPCADD,31,30
SUPORT,7,3
SUPORT1,40,7,12
"""


@pytest.mark.parametrize("name", ROUND_TRIP_DECKS + ["every_card", "generated", "cube", "car"])
def test_run_deck_reads_back_as_the_model(name, tmp_path):
    """Every modelled card is written back: reading the run deck's bulk data gives the model
    (grounded springs end on the fixed dummy grid, the only addition)."""
    if name == "every_card":
        path = tmp_path / "every.bdf"
        path.write_text(EVERY_CARD)
    elif name == "generated":
        path, _ = write_generated_deck(tmp_path / "gen")
    elif name in ("cube", "car"):
        path = ROOT / "fixtures" / name / "model.bdf"
    elif name == "rbe3_posts.bdf":
        # as MYSTRAN can run it: the RBE3 independents translational and in basic (the mystran
        # adapter refuses the others, docs/mystran.md "RBE3")
        path = tmp_path / name
        path.write_text((DATA / name).read_text().replace(".7,123456,14", ".7,123,14")
                        .replace("GRID,13,,1.2,.9,1.6,5", "GRID,13,,1.2,.9,1.6"))
    else:
        path = DATA / name
    text, (model, ids) = _run_bulk(path)
    again = read_deck_text(text.replace("$ ----", "$"), name="run.bdf", base_dir=tmp_path)
    grounded = [s for s in model.springs.values() if s.g2 == 0]
    if grounded:
        ground = again.grids.pop(ids.ground_grid)
        assert ground.ps == "123456" and ground.xyz == (0.0, 0.0, 0.0)
        for s in grounded:
            t = again.springs[s.eid]
            assert (t.g2, t.c2) == (ids.ground_grid, s.c1)
            # a grounded CELAS3/CELAS4 ends on that grid as the CELAS1/CELAS2 it is
            assert t.card == {"CELAS3": "CELAS1", "CELAS4": "CELAS2"}.get(s.card, s.card)
            again.springs[s.eid] = dataclasses.replace(t, g2=0, c2=0, card=s.card)
    # SUPORT/SUPORT1 are written as the SPC1 they are in a static solution (docs/mystran.md)
    model.spc1s = [dataclasses.replace(s, card="SPC1") for s in model.spc1s]
    want, got = _entities(model), _entities(again)
    coords_w, coords_g = model.coords, again.coords
    _close(got, want)
    assert coords_g.keys() == coords_w.keys()
    for cid, c in coords_w.items():    # written as CORD2x in basic: equal to rounding
        assert coords_g[cid].kind == c.kind
        np.testing.assert_allclose(coords_g[cid].origin, c.origin, rtol=0, atol=1e-14 * (1 + np.abs(c.origin).max()))
        np.testing.assert_allclose(coords_g[cid].axes, c.axes, rtol=0, atol=1e-14)


def test_every_card_deck_covers_every_written_card(tmp_path):
    """The EVERY_CARD deck holds each card the writer handles but the coordinate systems, CBEAM
    and the beam/bar sections, which the decks of ROUND_TRIP_DECKS cover."""
    from solver_adapters.nastran import WRITTEN
    names = {ln.split(",")[0].split()[0].rstrip("*") for ln in EVERY_CARD.splitlines()[1:]
             if ln[:1] not in (" ", "*", ",", "+")}
    assert WRITTEN - names == {"CORD1R", "CORD1C", "CORD1S", "CORD2R", "CORD2C", "CORD2S",
                               "CBEAM", "PBEAM", "PBEAML", "PBARL"}


@pytest.mark.parametrize("style", FIELD_STYLES)
def test_every_style_gives_the_same_run_deck(style, tmp_path):
    """The user's spelling does not reach MYSTRAN: the run deck of a deck spelt in any style is
    the run deck of its large-field spelling (small field only rounds the values it cannot hold
    in 8 characters, so the comparison is the large-field deck's own small-field reading)."""
    model = read_deck(ROOT / "fixtures" / "car" / "model.bdf")
    paths = {}
    for s in ("large", "small", style):
        paths[s] = tmp_path / s / "model.bdf"
        paths[s].parent.mkdir(exist_ok=True)
        paths[s].write_text(deck_text(model, s))
    same_as = "small" if style.startswith("small") else "large"
    body = lambda p: [ln for ln in _run_bulk(p)[0].splitlines() if not ln.startswith("$")]
    assert body(paths[style]) == body(paths[same_as])


def test_raw_cards_are_refieldded_exactly():
    card = RawCard("CQUAD4", ("101", "3", "1", "2", "12", "11", "", "1.25-3", "", "", "", "", ".5"), "m.bdf:4")
    lines = raw_card_text(card).splitlines()
    assert lines[0].startswith("CQUAD4*") and all(ln[:1] == "*" for ln in lines[1:]) and len(lines) % 2 == 0
    fields = [ln.ljust(72)[8 + 16 * k: 24 + 16 * k].strip() for ln in lines for k in range(4)]
    assert fields[:13] == ["101", "3", "1", "2", "12", "11", "", ".00125", "", "", "", "", ".5"]
    with pytest.raises(DeckFormatError, match="longer than 16"):
        raw_card_text(RawCard("PARAM", ("ABCDEFGHIJKLMNOPQ", "1"), "m.bdf:9"))


def test_new_ids_clear_every_id_of_the_deck(tmp_path):
    p = tmp_path / "m.bdf"
    p.write_text(EVERY_CARD + "SPOINT,50,THRU,60\nCQUAD4,400,3,1,2,3,4\nPSHELL,3,1,.01,1\n")
    model = read_model(p, "pass")
    ids = model_ids(model, passthrough_cards(p))
    assert ids.ground_grid == 61 and ids.first_eid == 401


# --------------------------------------------------------------------------------------------
# MYSTRAN: quirks that can no longer change the model
# --------------------------------------------------------------------------------------------
E, NU = 2.1e11, 0.3
FRAME = """GRID,1,,0.,0.,0.,,123456
GRID,2,,.5,.2,.3
CBAR,1,7,1,2,0.,0.,1.
CBAR,2,7,2,3,0.,0.,1.
CBAR,3,7,3,4,0.,0.,1.
GRID,4,,1.5,.4,1.2
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3
"""
GRID3 = {  # grid 3 at (1.0, 0.4, 0.7), written the ways MYSTRAN 18 misreads verbatim
    "plus_then_bare_star": "GRID*   3                               1.0             0.4".ljust(72) + "+\n*       0.7\n",
    "apex": "GRID*   3                               1.0             0.4".ljust(72) + "+APEX\n*APEX   0.7\n",
}
TIP_LOADS = LoadMatrix.from_dense([(4, c) for c in range(1, 7)], np.eye(6) * 1e3, [f"c{c}" for c in range(1, 7)])


def _raw_run(tmp_path: Path, bulk: str, loads: LoadMatrix, report) -> np.ndarray:
    """The bulk data copied verbatim into a run deck (as the adapter once did), run by MYSTRAN."""
    from solver_adapters.nastran import load_cards, mystran_binary
    tmp_path.mkdir(parents=True, exist_ok=True)
    deck = tmp_path / "raw.bdf"
    deck.write_text("\n".join(case_control(loads.n_cases, sorted({g for g, _ in report}), None)) + "\nBEGIN BULK\n"
                    + bulk + "".join(load_cards(loads, 1, idle_grid=1)) + "PARAM,AUTOSPC,N\nENDDATA\n")
    rec = run_solver([mystran_binary(), deck.name], tmp_path, timeout_s=60)
    return NastranDialect().read_results(tmp_path, deck, loads, list(report), rec)


def _rel(U, R) -> float:
    return float(np.max(np.abs(U - R) / np.max(np.abs(R), axis=0)))


@needs_mystran
@pytest.mark.parametrize("style", sorted(GRID3))
def test_grid_continuation_quirks_no_longer_change_the_model(style, tmp_path):
    path = tmp_path / "frame.bdf"
    path.write_text(FRAME + GRID3[style])
    assert read_deck(path).grids[3].xyz == (1.0, 0.4, 0.7)
    report = [(g, c) for g in (2, 3, 4) for c in range(1, 7)]
    R = ReferenceAdapter(path).solve(TIP_LOADS, report).values
    U = MystranAdapter(path).solve(TIP_LOADS, report).values
    assert _rel(U, R) <= RTOL_F06
    # the same text copied verbatim: MYSTRAN reads another grid 3 and says nothing
    V = _raw_run(tmp_path / "raw", FRAME + GRID3[style], TIP_LOADS, report)
    assert _rel(V, R) > 0.1


# --------------------------------------------------------------------------------------------
# MYSTRAN: springs to ground
# --------------------------------------------------------------------------------------------
@needs_mystran
def test_grounded_celas_in_the_deck(tmp_path):
    path = tmp_path / "sprung.bdf"
    path.write_text(FRAME.replace(",,123456", ",,12345") + GRID3["apex"]
                    + "CELAS2,20,4.E5,1,6\nPELAS,21,2.E5\nCELAS1,22,21,,,4,3\n")
    model = read_deck(path)
    assert {(s.g1, s.c1, s.g2) for s in model.springs.values()} == {(1, 6, 0), (4, 3, 0)}
    report = [(g, c) for g in (1, 2, 3, 4) for c in range(1, 7)]
    R = ReferenceAdapter(path).solve(TIP_LOADS, report).values
    U = MystranAdapter(path).solve(TIP_LOADS, report).values
    assert _rel(U, R) <= RTOL_F06
    with pytest.raises(Exception, match="1133|1021"):   # verbatim: MYSTRAN rejects the blank G2
        _raw_run(tmp_path / "raw", path.read_text(), TIP_LOADS, report)


@needs_mystran
def test_ignored_fields_are_an_error(tmp_path):
    """A PELAS with two properties, copied verbatim: MYSTRAN keeps the first, only warns about the
    second ("... SHOULD BE BLANK AND ARE IGNORED"); the dialect refuses the run. The adapter
    itself writes one property per PELAS, so the same deck runs through it."""
    from solver_adapters.protocol import SolverRunError
    bulk = FRAME + "GRID,3,,1.,.4,.7\nPELAS,30,1.E5,,,31,2.E5\nCELAS1,32,30,4,1,3,1\n"
    report = [(4, c) for c in range(1, 7)]
    with pytest.raises(SolverRunError, match="ignored fields"):
        _raw_run(tmp_path / "raw", bulk, TIP_LOADS, report)
    path = tmp_path / "pelas.bdf"
    path.write_text(bulk + "CELAS1,33,31,4,2,3,2\n")
    R = ReferenceAdapter(path).solve(TIP_LOADS, report).values
    assert _rel(MystranAdapter(path).solve(TIP_LOADS, report).values, R) <= RTOL_F06


@needs_mystran
def test_with_springs_to_ground_and_deck_springs_share_the_dummy_grid(tmp_path):
    path = tmp_path / "sprung.bdf"
    path.write_text(FRAME.replace(",,123456", ",,12345") + GRID3["apex"] + "CELAS2,20,4.E5,1,6\n")
    extra = [ScalarSpring((4, 3), None, 3.0e4), ScalarSpring((2, 1), (3, 1), 1.0e6)]
    report = [(g, c) for g in (2, 3, 4) for c in range(1, 7)]
    R = ReferenceAdapter(path).with_springs(extra).solve(TIP_LOADS, report).values
    U = MystranAdapter(path).with_springs(extra).solve(TIP_LOADS, report).values
    assert _rel(U, R) <= RTOL_F06
    text, (_, ids) = _run_bulk(path, extra)
    assert text.count("GRID*") == 5 and f"{ids.ground_grid}" in text


# --------------------------------------------------------------------------------------------
# MYSTRAN: cards the reader does not model (shells)
# --------------------------------------------------------------------------------------------
SHELL_FRAME = """GRID,1,,0.,0.,0.,,123456
GRID,2,,1.,0.,0.,,123456
GRID,3,,1.,0.,1.
GRID,4,,0.,0.,1.
GRID,5,,.5,0.,1.5
CBAR,1,7,1,4,1.,0.,0.
CBAR,2,7,2,3,1.,0.,0.
CBAR,3,7,4,5,0.,1.,0.
CBAR,4,7,3,5,0.,1.,0.
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3
PARAM,WTMASS,1.
"""
SHELL = "CQUAD4,10,3,1,2,3,4\nPSHELL,3,1,.002,1,,1\n"
SHELL_LARGE = ("CQUAD4* 10              3               1               2".ljust(72) + "+Q1\n"
               + "*Q1     3               4\n"
               + "PSHELL* 3               1               2.0E-3          1".ljust(72) + "+\n"
               + "*                       1\n")
SHELL_LOADS = LoadMatrix.from_dense([(5, 1), (5, 2), (3, 1), (4, 6)], np.eye(4) * 1e3, ["x5", "y5", "x3", "m4"])
SHELL_REPORT = [(g, c) for g in (3, 4, 5) for c in range(1, 7)]


@needs_mystran
def test_shell_deck_passes_through_reformatted(tmp_path):
    path = tmp_path / "shell.bdf"
    path.write_text(SHELL_FRAME + SHELL)
    with pytest.raises(DeckFormatError, match="CQUAD4"):
        MystranAdapter(path)                              # default: the reader's verdict
    a = MystranAdapter(path, unmodelled="pass")
    U = a.solve(SHELL_LOADS, SHELL_REPORT).values
    # MYSTRAN on the plain deck, copied verbatim: the shell is the same shell
    V = _raw_run(tmp_path / "raw", SHELL_FRAME + SHELL, SHELL_LOADS, SHELL_REPORT)
    assert _rel(U, V) <= RTOL_F06
    # the shell matters: without it the frame is far softer in its plane
    bare = tmp_path / "bare.bdf"
    bare.write_text(SHELL_FRAME)
    W = ReferenceAdapter(bare).solve(SHELL_LOADS, SHELL_REPORT).values
    assert _rel(U, W) > 0.5
    # spelt in large field with both continuation quirks: the same answer
    quirky = tmp_path / "quirky.bdf"
    quirky.write_text(SHELL_FRAME + SHELL_LARGE)
    Q = MystranAdapter(quirky, unmodelled="pass").solve(SHELL_LOADS, SHELL_REPORT).values
    assert _rel(Q, V) <= RTOL_F06


@pytest.mark.parametrize("card, why", [("FORCE,1,3,,1.,1.,0.,0.", "loads are not part of the model")])
def test_pass_refuses_cards_that_would_change_the_model_silently(card, why, tmp_path):
    path = tmp_path / "shell.bdf"
    path.write_text(SHELL_FRAME + SHELL + card + "\n")
    with pytest.raises(DeckFormatError, match=why):
        read_model(path, "pass")


# --------------------------------------------------------------------------------------------
# diagnose through MYSTRAN reaches the reference adapter's conclusions
# --------------------------------------------------------------------------------------------
def _bench():
    spec = importlib.util.spec_from_file_location("diagnose_mystran", ROOT / "benchmarks" / "diagnose_mystran.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def mystran_cache(tmp_path_factory):
    """One solver cache for this module's MYSTRAN diagnoses (solver_adapters/cache.py, keyed by
    the deck's and the loads' contents): most fixture folders share their deck and loads, and a
    batch MYSTRAN has solved once for one of them is read back for the next, as a study's own
    cache does. Every distinct batch still runs MYSTRAN."""
    return tmp_path_factory.mktemp("mystran_cache")


def _diagnose_agrees(name: str, cache: Path) -> None:
    """benchmarks/diagnose_mystran.py's comparison of one folder, the reference diagnosis shared
    with test_diagnose (``conftest.fixture_diagnosis``)."""
    from blackbox.adapters import ADAPTER_CACHE

    bench = _bench()
    folder = ROOT / "fixtures" / "undeclared" / name
    ref = fixture_diagnosis(folder, "reference")
    token = ADAPTER_CACHE.set(cache)
    try:
        mys, _ = bench.diagnose_doc(folder, "mystran")
    finally:
        ADAPTER_CACHE.reset(token)
    c = bench.compare(ref, mys, VALLEY_SIGMA.get(name, bench.PARAM_SIGMA))
    assert c["agree"], (name, bench._effects_text(ref), bench._effects_text(mys), c)


@needs_mystran
@pytest.mark.parametrize("name", ["none", "support_flexibility"])
def test_diagnose_through_mystran_agrees(name, mystran_cache):
    """``support_flexibility`` cuts the supports onto springs to ground (the split deck's
    grounded CELAS2, once rejected by MYSTRAN); ``none`` adds nothing."""
    _diagnose_agrees(name, mystran_cache)


VALLEY_SIGMA: dict[str, float] = {"shell_thick": 0.5}
"""Folders whose added parameters trade off along a valley of nearly equal chi2, and how far
apart (in the reference's standard errors) the two adapters' fits may end on it. ``shell_thick``:
the rigid zone's length and the joint's springs trade (a longer zone, softer springs), and
MYSTRAN's 7 printed digits end the fit at another point of the valley, measured on two machines
at 0.27-0.28 and below 0.05 standard errors (e_JC 58.0 mm +- 10.8 against 55.1 mm, alpha_19
0.892 against 0.900). Half a standard error leaves every interval the same to half its width;
the verdict and the effects and their places must still be the same."""


OUTPUT_ONLY = ("its effect acts on the readings alone: MYSTRAN runs for it the decks of the kinds the other "
               "folders of its deck run")
LEFT_OUT = {"shell_thin": "its diagnosis piles complex-joint refits over five rounds (many minutes per adapter); "
                         "its study is shell_thick's frame with a thinner wall, which is compared",
            **{k: OUTPUT_ONLY for k in ("sensor_gain", "sensor_offset", "sign_flip", "channel_swap",
                                        "misplaced_sensor")},
            **{k: "its effect scales a day's loads: load_scale compares the load kind through MYSTRAN (on the "
                  "cube), and the car deck's own decks run in the other car folders"
               for k in ("load_scale_day", "load_scale_group")},
            "joint_translation": "joint_translation_axes runs the same car deck with the same joint's translation "
                                 "springs, per axis (a superset of this folder's edited decks)",
            "member_stiffness": "member_bending runs the car deck's member edits (its section variant besides the "
                                "whole-member factor this folder adds)",
            "case_tilt": "its study is load_tilt's deck and declared loads with other readings: the same split run "
                         "and unit-load columns, which load_tilt compares"}
"""Folders not compared here, with the reason; ``python benchmarks/diagnose_mystran.py`` compares
every folder (docs/mystran.md). A data defect's folder differs from the others of its deck in its
readings only, so through MYSTRAN it runs the same kinds of deck (the shared cache reads most of
them back) and checks nothing of the solver the others do not; ``outlier``, whose decision turns on one
reading's size, stays."""


def _all_folders():
    for p in sorted((ROOT / "fixtures" / "undeclared").iterdir()):
        if not (p / "study.toml").is_file() or p.name in ("none", "support_flexibility") or p.name in LEFT_OUT:
            continue
        yield p.name


@pytest.mark.slow
@needs_mystran
@pytest.mark.parametrize("name", list(_all_folders()))
def test_diagnose_through_mystran_agrees_everywhere(name, mystran_cache):
    _diagnose_agrees(name, mystran_cache)
