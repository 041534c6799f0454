"""SUPORT, SUPORT1 and inertia relief (PARAM,INREL,-1) in a linear static solution: the reader,
``blackbox import`` (loads.csv, model.bdf) and the reference solver (docs/import.md).

References:
* NASTRAN's semantics: MSC Nastran Linear Static Analysis User's Guide, chapter "Inertia
  Relief" (the r-set is removed from the a-set and held, u_r = 0; with PARAM,INREL,-1 the loads
  are first balanced by the rigid-body inertia loads M D m_r^-1 D^T P); OptiStruct PARAM,INREL
  (0: SUPORT treated as SPC); MSC QRG SUPORT (a DOF may not be in both the r-set and the s-set).
* Closed forms: a free-free bar under an end load F accelerates at a = F / (rho A L); the
  inertia loads give the axial force N(x) = F x / L, so relative to the support at x = 0 the bar
  stretches to u(x) = F x^2 / (2 E A L) (exact at the grids of a lumped-mass model: the lumped
  inertia loads of a uniform bar are its consistent ones). A transverse end load gives the body
  the rigid-body acceleration of Newton-Euler, a = F / m and alpha = F (L - x_c) / I_c (I_c the
  lumped masses' moment of inertia about their centre); the balanced point loads bend the beam
  held at x = 0 as a cantilever: v(x) = sum_i P_i x^2 (3 a_i - x) / (6 E I) for x <= a_i, and
  a_i^2 (3 x - a_i) / (6 E I) beyond (Gere & Timoshenko, cantilever under a point load;
  Euler-Bernoulli bars are exact for point loads at the grids).
* MYSTRAN 18 (the real binary): it holds SUPORT DOFs in a static solution as NASTRAN does
  without inertia relief (compared on the original deck), and has no inertia relief (no
  PARAM,INREL: compared on the imported study through the mystran adapter, which checks the
  run deck's r-set, not the relief).

Tolerances: closed forms 1e-12 relative (a few operations on exact element matrices and a
6x6 solve); MYSTRAN prints 7 significant digits: 1e-6 of each subcase's largest value.
"""

from __future__ import annotations

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.errors import ModelError
from solver_adapters.protocol import DeckFormatError

from conftest import needs_mystran
from test_deck_tail import _agree, _import, _mystran, _solve
from test_deck_tail_elements import _study_against_mystran

CLOSED = 1e-12
N, LEN = 10, 10.0
E, AREA, I1, I2, J, RHO = 1.0e4, 2.0, 0.5, 0.3, 0.2, 0.5

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


def _bar(case: str, bulk: str, *, params: str = "PARAM,INREL,-1\n") -> str:
    """A free bar of N CBARs along x (grids 1..N+1, LEN long, mass RHO AREA per length),
    rotation about its axis held at grid 1 (a bar's lumped mass has no rotational inertia)."""
    grids = "".join(f"GRID,{i + 1},,{i * LEN / N},0.,0.\n" for i in range(N + 1))
    bars = "".join(f"CBAR,{i + 1},1,{i + 1},{i + 2},0.,1.,0.\n" for i in range(N))
    return (f"SOL 101\nCEND\nSPC = 9\n{case}BEGIN BULK\n{params}{grids}{bars}"
            f"PBAR,1,1,{AREA},{I1},{I2},{J}\nMAT1,1,{E},,0.3,{RHO}\nSPC1,9,4,1\n{bulk}ENDDATA\n")


def _rows(result) -> dict[tuple[str, int, int], float]:
    return {(r.split(",")[0], int(r.split(",")[1]), int(r.split(",")[2])): float(r.split(",")[3])
            for r in result.loads_csv.splitlines()[1:]}


def _u(report, u, j: int, grid: int, comp: int) -> float:
    return float(u[report.index((grid, comp)), j]) if (grid, comp) in report else 0.0


# --------------------------------------------------------------------------------------------
# SUPORT without inertia relief: held as NASTRAN holds it
# --------------------------------------------------------------------------------------------
def test_suport_is_held_like_an_spc(tmp_path):
    """A cantilever whose root is a SUPORT solves as the same cantilever with an SPC1 root."""
    bulk = "FORCE,1,11,,1.,0.,1.,0.\n"
    held = _import(tmp_path, _bar("LOAD = 1\n", bulk + "SUPORT,1,12356\n", params=""), "a.dat")
    spc = _import(tmp_path, _bar("LOAD = 1\n", bulk + "SPC1,9,12356,1\n", params=""), "b.dat")
    ca, ra, ua = _solve(held)
    cb, rb, ub = _solve(spc)
    assert "SUPORT,1,12356" in held.model_bdf
    assert any(n.startswith("note: SUPORT DOFs without inertia relief") for n in held.notes)
    tip = _u(ra, ua, 0, N + 1, 2)
    assert tip == pytest.approx(LEN ** 3 / (3 * E * I1), rel=CLOSED)   # v = F L^3 / (3 E I)
    assert tip == pytest.approx(_u(rb, ub, 0, N + 1, 2), rel=CLOSED)


def test_suport_fields_and_sets_are_checked(tmp_path):
    for bulk, field, words in [
        ("SUPORT,1,17\n", 3, "digits 1-6"),
        ("SUPORT,1,1,2,2,3,3,4,4,+A\n+A,5,5\n", 10, "at most 9 fields"),
        ("SUPORT,99,1\n", None, "SUPORT .reference DOFs.: grid.s. 99 does not exist"),
        ("SUPORT,1,1\nSPC1,9,1,1\n", 3, "also held by an SPC/SPC1"),
        ("SUPORT1,5,1,18\n", 4, "digits 1-6"),
        ("SUPORT1,,1,1\n", 2, "required integer"),
    ]:
        with pytest.raises((DeckFormatError, ModelError), match=words) as exc:
            read_deck_text(_bar("", bulk, params="").split("BEGIN BULK\n")[1], name="m.bdf")
        if field is not None:
            assert exc.value.field == field, bulk


def test_suport1_is_selected_by_the_case_control(tmp_path):
    """SUPORT1 = 5 keeps set 5 (held), drops set 6 with a note; without SUPORT1 = every SUPORT1
    card is dropped (NASTRAN applies none); subcases selecting different sets are refused."""
    bulk = "FORCE,1,11,,1.,0.,1.,0.\nSUPORT1,5,1,12356\nSUPORT1,6,11,12356\n"
    res = _import(tmp_path, _bar("SUPORT1 = 5\nLOAD = 1\n", bulk, params=""))
    assert "SUPORT1,5,1,12356" in res.model_bdf and "SUPORT1,6" not in res.model_bdf
    assert any("SUPORT1 = 5 selected" in n and "dropped set(s) 6" in n for n in res.notes)
    cases, report, u = _solve(res)
    assert _u(report, u, 0, N + 1, 2) == pytest.approx(LEN ** 3 / (3 * E * I1), rel=CLOSED)
    res = _import(tmp_path, _bar("LOAD = 1\n", bulk + "SPC1,9,12356,1\n", params=""), "none.dat")
    assert "SUPORT1" not in res.model_bdf.split("$\n", 1)[1]
    with pytest.raises(DeckFormatError, match="different SUPORT1 sets"):
        _import(tmp_path, _bar("SUBCASE 1\nSUPORT1 = 5\nLOAD = 1\nSUBCASE 2\nSUPORT1 = 6\nLOAD = 1\n",
                               bulk, params=""), "two.dat")
    with pytest.raises(DeckFormatError, match="no\nSUPORT1 with SID 7|no SUPORT1 with SID 7") as exc:
        _import(tmp_path, _bar("SUPORT1 = 7\nLOAD = 1\n", bulk, params=""), "seven.dat")
    assert exc.value.line == 4


# --------------------------------------------------------------------------------------------
# inertia relief: closed forms
# --------------------------------------------------------------------------------------------
def test_free_bar_under_an_axial_end_load(tmp_path):
    """F = 1 along x at the free end: the balanced loads are F less the lumped inertia loads
    m_i F / m, and the bar stretches to u(x) = F x^2 / (2 E A L) relative to grid 1."""
    res = _import(tmp_path, _bar("LOAD = 1\n", "FORCE,1,11,,1.,1.,0.,0.\nSUPORT,1,12356\n"))
    assert "INREL" not in res.model_bdf and "SUPORT,1,12356" in res.model_bdf
    assert any(n.startswith("inertia relief (PARAM,INREL,-1") for n in res.notes)
    rows = _rows(res)
    m = RHO * AREA * LEN
    for i in range(N + 1):
        mi = RHO * AREA * LEN / N * (0.5 if i in (0, N) else 1.0)
        expect = (1.0 if i == N else 0.0) - mi * 1.0 / m
        assert rows[("1", i + 1, 1)] == pytest.approx(expect, rel=CLOSED)
    cases, report, u = _solve(res)
    for i in range(N + 1):
        x = i * LEN / N
        assert _u(report, u, 0, i + 1, 1) == pytest.approx(x * x / (2 * E * AREA * LEN), rel=CLOSED, abs=1e-300)


def test_free_beam_under_a_transverse_end_load(tmp_path):
    """F = 1 along y at the free end: Newton-Euler gives the lumped masses' acceleration
    a(x) = F / m + alpha (x - x_c), alpha = F (L - x_c) / I_c; the beam held at grid 1 bends
    under the balanced point loads as a cantilever under point loads does."""
    res = _import(tmp_path, _bar("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,12356\n"))
    x = np.linspace(0.0, LEN, N + 1)
    mi = np.full(N + 1, RHO * AREA * LEN / N)
    mi[[0, -1]] *= 0.5
    m, xc = mi.sum(), (mi * x).sum() / mi.sum()
    alpha = 1.0 * (LEN - xc) / (mi * (x - xc) ** 2).sum()
    P = -mi * (1.0 / m + alpha * (x - xc))
    P[-1] += 1.0
    rows = _rows(res)
    for i in range(N + 1):
        assert rows[("1", i + 1, 2)] == pytest.approx(P[i], rel=CLOSED, abs=CLOSED)
    assert abs(P.sum()) < CLOSED and abs((P * x).sum()) < CLOSED        # balanced
    cases, report, u = _solve(res)
    for k in range(N + 1):
        xk = x[k]
        v = sum(p * (xk ** 2 * (3 * a - xk) if xk <= a else a ** 2 * (3 * xk - a))
                for p, a in zip(P, x)) / (6 * E * I1)
        assert _u(report, u, 0, k + 1, 2) == pytest.approx(v, rel=CLOSED, abs=1e-15)


FRAME = """SOL 101
CEND
DISP = ALL
SUBCASE 1
  LOAD = 1
SUBCASE 2
  LOAD = 2
BEGIN BULK
PARAM,INREL,-1
PARAM,WTMASS,0.5
CORD2R,5,,0.,0.,0.,0.,0.,1.
,0.,1.,0.
GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.,5
GRID,3,,2.,1.5,0.
GRID,4,,2.,1.5,1.
CBAR,1,1,1,2,0.,0.,1.
CBAR,2,1,2,3,0.,0.,1.
CBAR,3,1,3,4,1.,0.,0.
PBAR,1,1,0.01,2.E-5,3.E-5,4.E-5
MAT1,1,2.E11,,0.3
CONM2,11,1,,10.,0.1,0.,0.2
,1.,0.1,2.,0.2,0.3,3.
CONM2,12,2,5,20.,0.,0.3,0.
,2.,0.,1.,0.,0.,1.5
CONM2,13,3,,15.
,0.5,,0.5,,,0.5
CONM2,14,4,,5.,0.,0.,0.1
,0.2,,0.2,,,0.2
FORCE,1,4,,100.,1.,2.,-1.
MOMENT,1,3,,50.,0.,0.,1.
FORCE,2,2,5,80.,1.,0.,0.
SUPORT,1,123456
ENDDATA
"""
"""A free space frame of three bars (no density), CONM2 masses with offsets and inertia (one in
a rectangular CID), a grid with a CD system, PARAM,WTMASS, held at grid 1."""


def _newton_euler(loads: dict, masses, xyz: dict, frames: dict) -> dict:
    """The balanced loads by Newton-Euler: point masses (m, grid, cg offset, inertia about the
    cg, all in basic) accelerate as one rigid body under the applied loads (basic): a_c = F / m,
    I_c alpha = M_c; each mass gets the inertia force -m (a_c + alpha x (p - c)) at its cg and
    the moment -I alpha, carried to its grid; the result in each grid's CD."""
    m = sum(mm for mm, _, _, _ in masses)
    pts = {k: np.array(xyz[g]) + e for k, (_, g, e, _) in enumerate(masses)}
    c = sum(mm * pts[k] for k, (mm, _, _, _) in enumerate(masses)) / m
    F, M = np.zeros(3), np.zeros(3)
    for (g, comp), v in loads.items():
        vec = np.zeros(3)
        vec[(comp - 1) % 3] = v
        vec = frames[g].T @ vec
        if comp <= 3:
            F += vec
            M += np.cross(np.array(xyz[g]) - c, vec)
        else:
            M += vec
    Ic = np.zeros((3, 3))
    for k, (mm, _, _, I) in enumerate(masses):
        r = pts[k] - c
        Ic += I + mm * (r @ r * np.eye(3) - np.outer(r, r))
    a, alpha = F / m, np.linalg.solve(Ic, M)
    out = {}
    for (g, comp), v in loads.items():
        out[(g, comp)] = out.get((g, comp), 0.0) + v
    for k, (mm, g, e, I) in enumerate(masses):
        f = -mm * (a + np.cross(alpha, pts[k] - c))
        mom = np.cross(e, f) - I @ alpha
        for comp, val in enumerate(np.concatenate([frames[g] @ f, frames[g] @ mom]), start=1):
            out[(g, comp)] = out.get((g, comp), 0.0) + float(val)
    return out


def test_frame_with_conm2_inertia_balances_by_newton_euler(tmp_path):
    """The balanced loads of both cases against Newton-Euler on the CONM2 masses (the frame's
    bars have no density): every component at every grid."""
    res = _import(tmp_path, FRAME, "frame.dat")
    deck = read_deck_text(res.model_bdf, name="model.bdf")
    frames = {g: deck.displacement_frames([g])[0] for g in deck.grids}
    xyz = {g: deck.grids[g].xyz for g in deck.grids}
    w = 0.5
    cid5 = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # rows: axes in basic
    inertia = lambda i11, i21, i22, i31, i32, i33: np.array(      # noqa: E731
        [[i11, -i21, -i31], [-i21, i22, -i32], [-i31, -i32, i33]])
    masses = [(w * 10.0, 1, np.array([0.1, 0.0, 0.2]), w * inertia(1., .1, 2., .2, .3, 3.)),
              (w * 20.0, 2, cid5.T @ [0.0, 0.3, 0.0], w * cid5.T @ inertia(2., 0., 1., 0., 0., 1.5) @ cid5),
              (w * 15.0, 3, np.zeros(3), w * 0.5 * np.eye(3)),
              (w * 5.0, 4, np.array([0.0, 0.0, 0.1]), w * 0.2 * np.eye(3))]
    # case 2: FORCE in system 5 at grid 2, whose CD is 5 too: 80 along its component 1
    applied = {"1": {(4, 1): 100.0, (4, 2): 200.0, (4, 3): -100.0, (3, 6): 50.0},
               "2": {(2, 1): 80.0}}
    rows = _rows(res)
    for case, loads in applied.items():
        expect = _newton_euler(loads, masses, xyz, frames)
        scale = max(abs(v) for v in expect.values())
        got = {(g, k): v for (c, g, k), v in rows.items() if c == case}
        for key in set(expect) | set(got):
            assert got.get(key, 0.0) == pytest.approx(expect.get(key, 0.0), abs=CLOSED * scale), (case, key)


# --------------------------------------------------------------------------------------------
# refusals
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("case, bulk, params, card, words", [
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\n", "PARAM,INREL,-1\n", "PARAM", "needs SUPORT"),
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,12356\n", "PARAM,INREL,-2\n", None,
     "INREL,-2 .automatic inertia relief. is not imported"),
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,12356\n", "PARAM,INREL,1\n", None,
     "must be 0, -1 or -2"),
    # a seventh reference DOF: the r-set holds a deformation, not a rigid-body motion
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,12356,11,2\n", "PARAM,INREL,-1\n", "SUPORT",
     "deforms the structure"),
    # the structure held elsewhere along an r direction
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,12356\nSPC1,9,1,6\n", "PARAM,INREL,-1\n",
     "SUPORT", "deforms the structure"),
    # a spring to ground at the r-set itself: the rigid motion meets stiffness
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,12356\nCELAS2,99,1.E3,1,2\n",
     "PARAM,INREL,-1\n", "SUPORT", "meets stiffness"),
    # too few reference DOFs: a mechanism
    ("LOAD = 1\n", "FORCE,1,11,,1.,0.,1.,0.\nSUPORT,1,1235\n", "PARAM,INREL,-1\n", "SUPORT",
     "still a mechanism"),
])
def test_inertia_relief_refusals_are_located(tmp_path, case, bulk, params, card, words):
    with pytest.raises(Exception, match=words) as exc:
        _import(tmp_path, _bar(case, bulk, params=params))
    lines = _bar(case, bulk, params=params).splitlines()
    at = next(k + 1 for k, t in enumerate(lines) if t.startswith(card or "PARAM"))
    assert exc.value.line == at
    if card is not None:
        assert exc.value.card == card


def test_no_mass_on_a_rigid_motion_is_refused(tmp_path):
    """Rotation about the bar's axis has no inertia in a lumped bar mass: with it in the r-set,
    no acceleration can balance a torque."""
    text = _bar("LOAD = 1\n", "FORCE,1,11,,1.,1.,0.,0.\nSUPORT,1,123456\n").replace("SPC1,9,4,1\n", "")
    with pytest.raises(DeckFormatError, match="no inertia") as exc:
        _import(tmp_path, text)
    assert exc.value.card == "SUPORT"


def test_study_with_inrel_is_refused_by_the_reader():
    """A study's model.bdf with PARAM,INREL,-1 would solve unbalanced loads with the r-set held."""
    with pytest.raises(DeckFormatError, match="import the deck") as exc:
        read_deck_text(_bar("", "SUPORT,1,12356\n").split("BEGIN BULK\n")[1], name="m.bdf")
    assert exc.value.card == "PARAM" and exc.value.field == 3
    read_deck_text(_bar("", "SUPORT,1,12356\n", params="PARAM,INREL,0\n").split("BEGIN BULK\n")[1],
                   name="m.bdf")


# --------------------------------------------------------------------------------------------
# MYSTRAN
# --------------------------------------------------------------------------------------------
@needs_mystran
def test_suport_agrees_with_mystran_on_the_original_deck(tmp_path):
    """MYSTRAN needs six r-set DOFs: the frame held by SUPORT 123456 at grid 1, no relief."""
    text = FRAME.replace("PARAM,INREL,-1\n", "")
    cases, report, u = _solve(_import(tmp_path, text, "frame.dat"))
    ref = _mystran(tmp_path, text)
    grids = sorted(ref[1])
    for j, case in enumerate(cases):
        theirs = np.array([ref[int(case)][g] for g in grids])
        ours = np.array([[_u(report, u, j, g, c) for c in range(1, 7)] for g in grids])
        assert _agree(ours, theirs, f"case {case}") <= 1e-6


@needs_mystran
def test_relieved_study_agrees_with_mystran(tmp_path):
    """The imported study (balanced loads, SUPORT held) through the mystran adapter, whose run
    deck writes the r-set as a constraint."""
    assert _study_against_mystran(tmp_path, FRAME, 2) <= 1e-6
