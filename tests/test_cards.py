"""Cards of real decks: every unsupported card named at once, cards accepted with no effect, GRDSET,
SPC/SPCADD, MAT1 completion, PBAR K1/K2 shear flexibility and I12, CROD/PROD/CONROD, CBAR pin
flags and offsets, BAROR.

References, each independent of the reference solver:

* closed form. Cantilever of length L with a tip force P, Timoshenko beam (Timoshenko & Gere,
  *Mechanics of Materials*, shear deflection of a cantilever; Przemieniecki, *Theory of Matrix
  Structural Analysis*, sec. 5.6): tip deflection P L^3 / (3 E I) + P L / (K G A), tip rotation
  P L^2 / (2 E I) (shear does not rotate the section); tip moment M: rotation M L / (E I),
  deflection M L^2 / (2 E I). Rods in series: axial sum P L_i / (E_i A_i), torsion sum
  T L_i / (G_i J_i). A node held by rods alone: K = sum EA/L n n^T (translations) and
  sum GJ/L n n^T (rotations), n the rods' unit directions (direct stiffness method).
* MYSTRAN run as a real subprocess (``MystranAdapter``) on the same deck files, which MYSTRAN
  reads itself (PBAR K1/K2/I12, CBAR pins/offsets, BAROR, CROD, PROD, CONROD, GRDSET, SPC,
  SPCADD, MAT1 completion, PARAM, CONM2, EIGRL are MYSTRAN cards).

Tolerances: RTOL = 1e-9 against closed form (a direct sparse solve of a few DOFs in double
precision is exact to ~1e-13; any wrong term is O(1e-2) or more); RTOL_F06 = 1e-6 against
MYSTRAN, which prints 7 significant digits (5e-7 relative), leaving a factor 2 for its solve.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from solver_adapters.bdf import NO_EFFECT, SUPPORTED, read_deck, read_deck_text
from solver_adapters.bdf_write import write_deck
from solver_adapters.deck import Grid, PBar
from solver_adapters.protocol import DeckFormatError, LoadMatrix
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.reference import frame

from conftest import needs_mystran

DATA = Path(__file__).parent / "data"
RTOL = 1e-9
RTOL_F06 = 1e-6


pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")   # MYSTRAN run dirs below tmp_path


def unit_loads(grid: int, scale: float = 1.0) -> LoadMatrix:
    """Six load cases: a unit force/moment (times ``scale``) on each component of ``grid``."""
    return LoadMatrix.from_dense([(grid, c) for c in range(1, 7)], np.eye(6) * scale,
                                 [f"c{c}" for c in range(1, 7)])


def against_mystran(path: Path, grid: int, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Displacements of every DOF under ``unit_loads(grid, scale)``: (reference, MYSTRAN)."""
    from solver_adapters.nastran import MystranAdapter
    ref = ReferenceAdapter(path)
    report = list(ref.dofs())
    loads = unit_loads(grid, scale)
    return ref.solve(loads, report).values, MystranAdapter(path).solve(loads, report).values


def assert_close_to_mystran(ref: np.ndarray, mys: np.ndarray) -> None:
    """Entry by entry to RTOL_F06; entries that are zero in exact arithmetic (uncoupled
    components) are compared absolutely at RTOL_F06 times the largest displacement."""
    np.testing.assert_allclose(mys, ref, rtol=RTOL_F06, atol=RTOL_F06 * np.abs(ref).max())


# --------------------------------------------------------------------------------------------
# unsupported cards: one message with every name, its count and first location
# --------------------------------------------------------------------------------------------
def test_every_unsupported_card_named_in_one_message(tmp_path):
    (tmp_path / "part.bdf").write_text("CQUAD4,7,1,1,2,3,4\nRBE3,8,,1,123,1.,123,2\n")
    (tmp_path / "model.bdf").write_text(
        "SOL 101\nCEND\nLOAD = 1\nBEGIN BULK\n"          # case control: skipped, not reported
        "GRID,1,,0.,0.,0.\nGRID,2,,1.,0.,0.\nGRID,3,,1.,1.,0.\nGRID,4,,0.,1.,0.\n"
        "FORCE,1,2,,1.,0.,0.,1.\n"                        # line 9
        "CQUAD4,5,1,1,2,3,4\n"                            # line 10
        "PARAM,POST,-1\n"
        "INCLUDE 'part.bdf'\n"
        "FORCE,1,3,,1.,0.,0.,1.\nMOMENT,2,3,,1.,0.,0.,1.\n"
        "CORD2R,9,,0.,0.,0.,0.,0.,1.\n,1.,0.,0.\n"        # line 15
        "CQUAD4,6,1,1,2,3,4\nENDDATA\n")
    with pytest.raises(DeckFormatError) as info:
        read_deck(tmp_path / "model.bdf")
    exc, msg = info.value, str(info.value)
    main, part = str(tmp_path / "model.bdf"), str(tmp_path / "part.bdf")
    assert (exc.file, exc.line, exc.card, exc.field) == (main, 9, "FORCE", 1)   # the first one
    assert "8 card(s) of 5 type(s)" in msg
    for name, count, where in (("FORCE", 2, f"{main}:9"), ("CQUAD4", 3, f"{main}:10"),
                               ("RBE3", 1, f"{part}:2"), ("MOMENT", 1, f"{main}:14"),
                               ("CORD2R", 1, f"{main}:15")):
        assert f"{name} x{count} (first at {where})" in msg, name
    assert re.search(r"FORCE x2 \(first at [^)]*\): loads are not part of the model", msg)
    assert re.search(r"CORD2R x1 \(first at [^)]*\): coordinate systems are not supported", msg)
    assert "PARAM" not in msg.split("supported:")[0]          # accepted cards are not listed


def test_no_effect_set_is_explicit():
    """The accepted-without-effect cards are named; none of them is a modelling card."""
    assert {"PARAM", "CONM2", "EIGRL"} <= NO_EFFECT
    assert not NO_EFFECT & set(SUPPORTED)
    modelling = {"CBEAM", "CQUAD4", "RBE3", "CBUSH", "MPC", "FORCE", "SPCD", "CORD2R", "PBARL"}
    assert not NO_EFFECT & modelling


def test_no_effect_cards_listed_once_in_the_summary():
    deck = read_deck(DATA / "shear_cantilever.bdf")
    src = str(DATA / "shear_cantilever.bdf")
    assert deck.no_effect == {"PARAM": (2, f"{src}:13"), "CONM2": (1, f"{src}:30"),
                              "EIGRL": (1, f"{src}:31")}
    summary = deck.summary()
    assert summary.count("PARAM") == 1 and "PARAM x2" in summary and "CONM2 x1" in summary
    assert summary.startswith("5 GRID, 4 CBAR, 1 PBAR, 1 MAT1")


# --------------------------------------------------------------------------------------------
# GRDSET, SPC, SPCADD, MAT1
# --------------------------------------------------------------------------------------------
def test_grdset_fills_blank_fields_in_any_order():
    deck = read_deck(DATA / "rod_line.bdf")
    assert [deck.grids[g].ps for g in (1, 2, 3)] == ["123456", "2356", "2356"]
    # bulk data is unordered: a GRDSET after the GRIDs applies as well; explicit 0 CP/CD is fine
    text = "GRID,1,0,0.,0.,0.,0\nGRID,2,,1.,0.,0.,,1\nGRDSET,,0,,,,0,345,0\n"
    deck = read_deck_text(text)
    assert deck.grids[1] == Grid(1, (0.0, 0.0, 0.0), "345", "<string>:1")
    assert deck.grids[2].ps == "1"


def test_grdset_coordinate_system_unused_is_harmless_used_is_an_error():
    assert read_deck_text("GRDSET,,5,,,,6\nGRID,1,0,0.,0.,0.,0\n").grids[1].ps == ""
    with pytest.raises(DeckFormatError, match=r"GRID 2 at t.bdf:3.*GRDSET CD must be 0") as info:
        read_deck_text("GRDSET,,,,,,6\nGRID,1,,0.,0.,0.,0\nGRID,2,,0.,0.,1.\n", name="t.bdf")
    assert (info.value.line, info.value.card, info.value.field) == (1, "GRDSET", 7)


def test_spc_and_spcadd_read():
    deck = read_deck(DATA / "shear_cantilever.bdf")
    assert [(s.sid, s.components, s.grids) for s in deck.spc1s] == [(100, "123456", (1,))]
    assert {k: (a.sid, a.sets) for k, a in deck.spcadds.items()} == {200: (200, (100,))}


def test_all_spc_sets_apply_without_case_control():
    """A clamp split over an SPC (set 1, zero value), an SPC1 (set 2) and joined by an SPCADD
    gives the same result as one SPC1 clamp: every set of the deck applies, as for SPC1 sets."""
    body = open(DATA / "shear_cantilever.bdf").read().split("BEGIN BULK\n")[1]
    body = body.replace("SPC     100     1       123456  0.",
                        "SPC     1       1       12      0.      1       3")
    body = body.replace("SPCADD  200     100\n", "").replace("ENDDATA\n", "SPC1,2,456,1\nENDDATA\n")
    split = read_deck_text(body)
    clamp = read_deck(DATA / "shear_cantilever.bdf")
    assert sorted((s.sid, s.components) for s in split.spc1s) == [(1, "12"), (1, "3"), (2, "456")]
    report = [(g, c) for g in range(1, 6) for c in range(1, 7)]
    a = ReferenceAdapter(split).solve(unit_loads(5), report).values
    b = ReferenceAdapter(clamp).solve(unit_loads(5), report).values
    np.testing.assert_array_equal(a, b)


def test_mat1_completed_from_any_two():
    """rod_line.bdf: MAT1 1 gives E, G (NU = E / 2G - 1), MAT1 2 gives G, NU (E = 2 (1 + NU) G)."""
    deck = read_deck(DATA / "rod_line.bdf")
    m1, m2 = deck.mat1s[1], deck.mat1s[2]
    assert (m1.e, m1.g, m1.nu) == (2e11, 7.5e10, 2e11 / (2 * 7.5e10) - 1)
    assert (m2.e, m2.g, m2.nu) == (2 * (1 + 0.33) * 2.6e10, 2.6e10, 0.33)


# --------------------------------------------------------------------------------------------
# PBAR K1/K2: Timoshenko bending
# --------------------------------------------------------------------------------------------
E, NU = 2.1e11, 0.3
G = E / (2 * (1 + NU))
A, I1, I2, K1, K2, LEN, TIP = 1e-3, 2e-5, 3e-5, 0.85, 0.7, 2.0, 5


def test_shear_cantilever_closed_form():
    """Bar along x, orientation vector y: plane 1 (deflection y) has I1 and K1, plane 2 (z) has
    I2 and K2. Shear adds P L / (K G A) to the tip deflection (~5 % here), nothing to the rotation."""
    deck = read_deck(DATA / "shear_cantilever.bdf")
    assert deck.pbars[7] == PBar(7, 1, A, I1, I2, 4e-6, deck.pbars[7].src, K1, K2)
    P = 1e3
    u = ReferenceAdapter(deck).solve(unit_loads(TIP, P), [(TIP, c) for c in range(1, 7)]).values
    assert u[1, 1] == pytest.approx(P * LEN**3 / (3 * E * I1) + P * LEN / (K1 * G * A), rel=RTOL)
    assert u[2, 2] == pytest.approx(P * LEN**3 / (3 * E * I2) + P * LEN / (K2 * G * A), rel=RTOL)
    assert u[5, 1] == pytest.approx(P * LEN**2 / (2 * E * I1), rel=RTOL)
    assert u[4, 2] == pytest.approx(-P * LEN**2 / (2 * E * I2), rel=RTOL)
    assert u[5, 5] == pytest.approx(P * LEN / (E * I1), rel=RTOL)              # tip moment
    assert u[1, 5] == pytest.approx(P * LEN**2 / (2 * E * I1), rel=RTOL)
    assert u[4, 4] == pytest.approx(P * LEN / (E * I2), rel=RTOL)
    shear_part = P * LEN / (K1 * G * A) / u[1, 1]
    assert shear_part > 0.04                       # the effect is far above the tolerances


def test_blank_or_zero_k_is_euler_bernoulli_bit_for_bit():
    """K1/K2 blank (and 0.0, NASTRAN's and MYSTRAN's reading) change nothing: the element matrix
    is, bit for bit, the Euler-Bernoulli one written out in its usual operation order."""
    rng = np.random.default_rng(3)
    L, Em, Gm, Am, Ia, Ib, Jm = (rng.uniform(0.1, 2.0, 50) for _ in range(7))
    k = frame.local_stiffness(L, Em, Gm, Am, Ia, Ib, Jm, np.full(50, np.inf), np.full(50, np.inf))
    assert np.array_equal(k, frame.local_stiffness(L, Em, Gm, Am, Ia, Ib, Jm))
    assert np.array_equal(k[:, 1, 1], 12 * Em * Ia / L**3)
    assert np.array_equal(k[:, 1, 5], 6 * Em * Ia / L**2)
    assert np.array_equal(k[:, 5, 5], 4 * Em * Ia / L)
    assert np.array_equal(k[:, 5, 11], 2 * Em * Ia / L)
    assert np.array_equal(k[:, 4, 10], 2 * Em * Ib / L)
    text = open(DATA / "shear_cantilever.bdf").read()
    blank = text.replace("+PB7B   .85     .7", "+PB7B")
    zero = text.replace("+PB7B   .85     .7", "+PB7B   0.      0.")
    report = [(g, c) for g in range(1, 6) for c in range(1, 7)]
    u_blank = ReferenceAdapter(read_deck_text(blank)).solve(unit_loads(TIP, 1e3), report).values
    u_zero = ReferenceAdapter(read_deck_text(zero)).solve(unit_loads(TIP, 1e3), report).values
    np.testing.assert_array_equal(u_blank, u_zero)
    assert u_blank[TIP * 6 - 5, 1] == pytest.approx(1e3 * LEN**3 / (3 * E * I1), rel=RTOL)


@needs_mystran
def test_shear_cantilever_mystran():
    ref, mys = against_mystran(DATA / "shear_cantilever.bdf", TIP, 1e3)
    assert_close_to_mystran(ref, mys)
    tip_y = 6 * (TIP - 1) + 1
    assert mys[tip_y, 1] == pytest.approx(1e3 * LEN**3 / (3 * E * I1) + 1e3 * LEN / (K1 * G * A),
                                          rel=RTOL_F06)


def test_i12_cantilever_closed_form():
    """Unsymmetric bending: with M = [[I1, I12], [I12, I2]] (I12 = int y z dA) the tip of a
    cantilever (Boresi & Schmidt, *Advanced Mechanics of Materials*, ch. 7, unsymmetric bending)
    moves (v, w) = (L^3 / 3E) M^-1 (Py, Pz) and turns (theta_z, -theta_y) = (L^2 / 2E) M^-1 (Py, Pz)
    under a tip force, (theta_z, -theta_y) = (L / E) M^-1 (Mz, -My) under a tip moment."""
    deck = read_deck(DATA / "pbar_i12.bdf")
    assert deck.pbars[7].i12 == 1e-6
    M = np.linalg.inv(np.array([[2e-6, 1e-6], [1e-6, 3e-6]]))
    P = 1e3
    u = ReferenceAdapter(deck).solve(unit_loads(5, P), [(5, c) for c in range(1, 7)]).values
    np.testing.assert_allclose(u[[1, 2]][:, [1, 2]], LEN**3 / (3 * E) * M * P, rtol=RTOL)
    rot = np.diag([1.0, -1.0])                               # (theta_z, -theta_y) from (R3, R2)
    np.testing.assert_allclose(rot @ u[[5, 4]][:, [1, 2]], LEN**2 / (2 * E) * M * P, rtol=RTOL)
    np.testing.assert_allclose(rot @ u[[5, 4]][:, [5, 4]] @ rot, LEN / E * M * P, rtol=RTOL)


@pytest.mark.parametrize("grid", [5, 15])
@needs_mystran
def test_i12_mystran(grid):
    """Both cantilevers of pbar_i12.bdf (one oblique, with an oblique orientation vector)."""
    ref, mys = against_mystran(DATA / "pbar_i12.bdf", grid, 1e3)
    assert_close_to_mystran(ref, mys)


# --------------------------------------------------------------------------------------------
# CROD / PROD / CONROD
# --------------------------------------------------------------------------------------------
def test_rods_in_series_closed_form():
    deck = read_deck(DATA / "rod_line.bdf")
    m1, m2 = deck.mat1s[1], deck.mat1s[2]
    (l1, a1, j1), (l2, a2, j2) = (1.5, 2e-4, 3e-8), (1.0, 1.2e-4, 5e-8)
    P, T = 1e3, 10.0
    loads = LoadMatrix.from_dense([(3, 1), (3, 4)], np.diag([P, T]), ["axial", "torque"])
    u = ReferenceAdapter(deck).solve(loads, [(2, 1), (3, 1), (2, 4), (3, 4)]).values
    assert u[0, 0] == pytest.approx(P * l1 / (m1.e * a1), rel=RTOL)
    assert u[1, 0] == pytest.approx(P * l1 / (m1.e * a1) + P * l2 / (m2.e * a2), rel=RTOL)
    assert u[2, 1] == pytest.approx(T * l1 / (m1.g * j1), rel=RTOL)
    assert u[3, 1] == pytest.approx(T * l1 / (m1.g * j1) + T * l2 / (m2.g * j2), rel=RTOL)
    assert u[0, 1] == 0.0 and u[2, 0] == 0.0                # axial and torsion uncoupled


def tripod_flexibility(deck) -> np.ndarray:
    """Apex flexibility 6x6 from the direct stiffness sum over the rods (module docstring)."""
    kt, kr = np.zeros((3, 3)), np.zeros((3, 3))
    apex = np.array(deck.grids[4].xyz)
    for r in deck.rods.values():
        mid, a, j = deck.rod_section(r)
        d = apex - np.array(deck.grids[r.ga].xyz)
        length = np.linalg.norm(d)
        n = d / length
        kt += deck.mat1s[mid].e * a / length * np.outer(n, n)
        kr += deck.mat1s[mid].g * j / length * np.outer(n, n)
    f = np.zeros((6, 6))
    f[:3, :3], f[3:, 3:] = np.linalg.inv(kt), np.linalg.inv(kr)
    return f


def test_rod_tripod_closed_form():
    deck = read_deck(DATA / "rod_tripod.bdf")
    assert deck.grids[4].xyz == (0.1, 0.2, 1.7)              # large field, explicit continuation
    u = ReferenceAdapter(deck).solve(unit_loads(4), [(4, c) for c in range(1, 7)]).values
    f = tripod_flexibility(deck)
    np.testing.assert_allclose(u, f, rtol=RTOL, atol=RTOL * np.abs(f).max() * 1e-3)


@pytest.mark.parametrize("name, grid, scale", [("rod_line", 3, 1e3), ("rod_tripod", 4, 1e3)])
@needs_mystran
def test_rods_mystran(name, grid, scale):
    ref, mys = against_mystran(DATA / f"{name}.bdf", grid, scale)
    assert_close_to_mystran(ref, mys)
    if name == "rod_tripod":
        np.testing.assert_allclose(mys[18:, :], scale * tripod_flexibility(read_deck(DATA / f"{name}.bdf")),
                                   rtol=RTOL_F06, atol=RTOL_F06 * np.abs(mys).max())


# --------------------------------------------------------------------------------------------
# CBAR pin flags, offsets, BAROR
# --------------------------------------------------------------------------------------------
PINS = DATA / "cbar_pins_offsets.bdf"


def test_baror_defaults_and_cbar_fields_read():
    deck = read_deck(PINS)
    assert (deck.cbars[2].pa, deck.cbars[2].pb, deck.cbars[2].wa) == ("6", "", None)
    b = deck.cbars[11]
    assert (b.pid, b.x, b.g0, b.wa, b.wb) == (8, (0.0, 1.0, 0.0), None, (0.0, 0.0, 0.1), (0.0, 0.0, 0.1))
    assert deck.cbars[1].pid == 7 and deck.cbars[1].x == (0.0, 1.0, 0.0)   # own fields win


def test_pin_flag_hinge_closed_form():
    """Bar 2 released in element component 6 at grid 2, grid 3 pinned: bar 2 carries no
    plane-1 shear, so grid 2 is a cantilever tip (a = 1.2): v = P a^3 / (3 E I1),
    theta_z = P a^2 / (2 E I1), and bar 2 turns rigidly about grid 3 (b = 0.8): theta_z3 = -v / b."""
    P, a, b, i1 = 1e3, 1.2, 0.8, 2e-6
    loads = LoadMatrix.from_dense([(2, 2)], np.array([[P]]), ["py"])
    u = ReferenceAdapter(PINS).solve(loads, [(2, 2), (2, 6), (3, 6)]).values[:, 0]
    v = P * a**3 / (3 * E * i1)
    assert u[0] == pytest.approx(v, rel=RTOL)
    assert u[1] == pytest.approx(P * a**2 / (2 * E * i1), rel=RTOL)
    assert u[2] == pytest.approx(-v / b, rel=RTOL)


def test_offset_closed_form():
    """Bars 11-13 (L = 1.6) run e = 0.1 above their grids (+z). An axial tip force P on grid 13
    reaches the bar end through the rigid offset with the moment M_y = -e P: u_x = P L / (E A)
    + e^2 P L / (E I2), w = e P L^2 / (2 E I2), theta_y = -e P L / (E I2)."""
    P, L, e, a, i2 = 1e3, 1.6, 0.1, 2e-3, 1.5e-6
    loads = LoadMatrix.from_dense([(13, 1)], np.array([[P]]), ["px"])
    u = ReferenceAdapter(PINS).solve(loads, [(13, 1), (13, 3), (13, 5)]).values[:, 0]
    assert u[0] == pytest.approx(P * L / (E * a) + e**2 * P * L / (E * i2), rel=RTOL)
    assert u[1] == pytest.approx(e * P * L**2 / (2 * E * i2), rel=RTOL)
    assert u[2] == pytest.approx(-e * P * L / (E * i2), rel=RTOL)


@pytest.mark.parametrize("grid", [2, 13])
@needs_mystran
def test_pins_offsets_baror_mystran(grid):
    ref, mys = against_mystran(PINS, grid, 1e3)
    assert_close_to_mystran(ref, mys)


def test_pins_leaving_a_rigid_body_motion_are_an_error():
    text = open(PINS).read().replace("\n        6\n", "\n        1       1\n")
    from solver_adapters.protocol import ModelError
    with pytest.raises(ModelError, match=r"cbar_pins_offsets.bdf:11: CBAR 2: pin flags PA=1 PB=1"):
        ReferenceAdapter(read_deck_text(text, name="cbar_pins_offsets.bdf")).solve(
            unit_loads(2), [(2, 1)])


def test_blank_orientation_without_baror_is_an_error():
    text = open(PINS).read().replace("BAROR           8", "$")
    with pytest.raises(DeckFormatError, match="no BAROR default") as info:
        read_deck_text(text, name="p.bdf")
    assert (info.value.line, info.value.card, info.value.field) == (17, "CBAR", 6)


@pytest.mark.parametrize("name", ["shear_cantilever", "rod_line", "rod_tripod", "cbar_pins_offsets",
                                  "pbar_i12"])
def test_new_cards_round_trip_through_the_writer(name):
    """Free field keeps every bit, so the deck read back is the same model (GRDSET resolved into
    each GRID's PS, SPC written as SPC1)."""
    deck = read_deck(DATA / f"{name}.bdf")
    again = read_deck_text(write_deck(deck, "free"))
    for attr in ("grids", "cbars", "pbars", "rods", "prods", "mat1s", "spcadds", "spc1s"):
        items = getattr(deck, attr)
        keys = items.keys() if isinstance(items, dict) else range(len(items))
        for k in keys:
            assert dataclasses.replace(getattr(again, attr)[k], src="") == \
                   dataclasses.replace(items[k], src=""), (attr, k)
