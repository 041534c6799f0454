"""The FRAMESOLVE legacy-code fixture and its dialect (``solver_adapters.legacy``).

FRAMESOLVE is a separate program with its own element code, so agreement with the in-process
reference solver checks both the program and the dialect's translation of the BDF (plane
conventions, RBE2 ties, SPC1/PS, springs, loads). Every misbehaviour of the program must come
back as a typed error, never as numbers.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

from blackbox.study import read_loads
from solver_adapters.bdf import read_deck
from solver_adapters.legacy import (FRAMESOLVE, LegacyAdapter, LegacyDialect, fortran_real,
                                    parse_listing, real_field)
from solver_adapters.protocol import (LoadMatrix, ScalarSpring, SolverAdapter, SolverRunError,
                                      SolverTimeoutError, UnstableStructureError)
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.registry import make_adapter
from solver_adapters.subprocess import BaseDeck, CommandAdapter, RunRecord

from conftest import FIXTURES

AGREE = 1e-9
"""Relative agreement with the reference, measured against the largest magnitude of each load
case's column: both solvers are backward stable but factor in different orders, so an entry that
is (nearly) zero by symmetry carries round-off of size eps * cond * max|u| in either one, and an
entry-by-entry relative test would compare round-off with round-off. Measured: <= 2e-12 on both
fixtures (the listing carries 13 significant digits, 5e-14)."""

SAME_PROGRAM = 1e-12
"""Batch against one-by-one: the same program and matrix; only LAPACK's blocking over the number
of right-hand sides and the 13-digit listing differ."""


def _max_rel(a: np.ndarray, b: np.ndarray) -> float:
    scale = np.maximum(np.abs(b).max(axis=0), np.finfo(float).tiny)
    return float(np.max(np.abs(a - b) / scale))


@pytest.fixture(params=["cube", "car"])
def fixture(request, tmp_path):
    deck = FIXTURES / request.param / "model.bdf"
    loads = read_loads(FIXTURES / request.param / "loads.csv")
    return deck, loads, LegacyAdapter(deck, workdir_root=tmp_path), ReferenceAdapter(deck)


# --------------------------------------------------------------------------------------------
# agreement
# --------------------------------------------------------------------------------------------
def test_agrees_with_reference(fixture):
    deck, loads, legacy, reference = fixture
    assert isinstance(legacy, SolverAdapter)
    report = legacy.dofs()
    got = legacy.solve(loads, report).values
    want = reference.solve(loads, report).values
    assert _max_rel(got, want) <= AGREE
    assert legacy.stats.runs == 1 and legacy.stats.right_hand_sides == loads.n_cases
    assert legacy.grid_xyz() == reference.grid_xyz()


def test_batch_equals_one_by_one(fixture):
    deck, loads, legacy, _ = fixture
    report = [(g, c) for g in sorted(legacy.grid_xyz())[::3] for c in (1, 3, 5)]
    batch = legacy.solve(loads, report).values
    picked = list(range(0, loads.n_cases, 4))  # every fourth case: one run each, kept fast
    single = np.hstack([legacy.solve(loads.select([j]), report).values for j in picked])
    assert _max_rel(batch[:, picked], single) <= SAME_PROGRAM
    assert legacy.stats.runs == 1 + len(picked)


def test_extra_springs_agree_with_reference(fixture):
    deck, loads, legacy, reference = fixture
    rbe2 = next(iter(ReferenceAdapter(deck).deck.rbe2s.values()))
    a, b = rbe2.gn, rbe2.gm[0]
    springs = [ScalarSpring((a, 4), (b, 4), 1.0e3 / 3), ScalarSpring((a, 5), (b, 5), 2.5e4),
               ScalarSpring((b, 6), (a, 6), 7.0e2), ScalarSpring((a, 4), (b, 5), -12.5),
               ScalarSpring((b, 1), None, 1.0e5)]
    report = legacy.dofs()
    got = legacy.with_springs(springs).solve(loads, report).values
    want = reference.with_springs(springs).solve(loads, report).values
    assert _max_rel(got, want) <= AGREE
    plain = legacy.solve(loads, report).values
    assert _max_rel(got, plain) > 1e-6  # the springs did change the answer


CANTILEVER = """\
$ cantilever along x, L = 2 m, steel-like, orientation vector {v}
GRID,1,,0.,0.,0.
GRID,2,,2.,0.,0.
CBAR,1,1,1,2,{v}
PBAR,1,1,3.0E-3,4.0E-6,1.0E-6,2.0E-6
MAT1,1,2.0E11,8.0E10
{spc}
"""


def _cantilever(tmp_path: Path, v: str = "0.,1.,0.", spc: str = "SPC1,1,123456,1") -> Path:
    path = tmp_path / f"cantilever-{len(list(tmp_path.glob('*.bdf')))}.bdf"
    path.write_text(CANTILEVER.format(v=v, spc=spc))
    return path


@pytest.mark.parametrize("v", ["0.,1.,0.", "0.,0.,1."])
def test_cantilever_matches_beam_theory(tmp_path, v):
    """Tip of a cantilever under end loads (Timoshenko & Gere, *Mechanics of Materials*, table of
    beam deflections: w = P L^3 / (3 E I), theta = P L^2 / (2 E I); axial P L / (E A); torsion
    T L / (G J)). Units N, m. Plane 1 (I1 = 4e-6 m^4) contains the orientation vector."""
    L, E, G, A, I1, I2, J = 2.0, 2.0e11, 8.0e10, 3.0e-3, 4.0e-6, 1.0e-6, 2.0e-6
    legacy = LegacyAdapter(_cantilever(tmp_path, v), workdir_root=tmp_path)
    dofs = [(2, c) for c in range(1, 7)]
    u = legacy.solve(LoadMatrix.unit(dofs), dofs).values
    Iy_basic, Iz_basic = (I2, I1) if v == "0.,1.,0." else (I1, I2)  # bending about basic y / z
    expected = {(1, 1): L / (E * A), (2, 2): L**3 / (3 * E * Iz_basic), (3, 3): L**3 / (3 * E * Iy_basic),
                (4, 4): L / (G * J), (5, 5): L / (E * Iy_basic), (6, 6): L / (E * Iz_basic),
                (2, 6): L**2 / (2 * E * Iz_basic), (3, 5): -L**2 / (2 * E * Iy_basic)}
    for (r, c), value in expected.items():
        assert u[r - 1, c - 1] == pytest.approx(value, rel=1e-12)  # 13 printed digits
        assert u[c - 1, r - 1] == pytest.approx(value, rel=1e-12)  # Maxwell-Betti


def test_default_command_and_registry(tmp_path):
    deck = FIXTURES / "cube" / "model.bdf"
    by_dialect = CommandAdapter(deck, dialect=LegacyDialect(), workdir_root=tmp_path)
    by_name = make_adapter("legacy", deck, timeout_s=60)
    loads = read_loads(FIXTURES / "cube" / "loads.csv").select([0, 1])
    report = [(7, 1), (71, 4), (72, 6)]
    np.testing.assert_array_equal(by_dialect.solve(loads, report).values, by_name.solve(loads, report).values)
    assert by_name.name == "legacy" and by_name.timeout_s == 60


# --------------------------------------------------------------------------------------------
# formats
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("x", [0.0, -0.0, 0.1, 1 / 3, -2.0 / 3e-7, 206.85e9, 1e-300, -1.2345678901234567e-305,
                               5e-324, 1.7976931348623157e308, -1.7976931348623157e308, 123456789012345678.0])
def test_real_field_fits_and_keeps_13_digits(x):
    field = real_field(x)
    assert len(field) == 20
    assert float(field) == pytest.approx(x, rel=5e-13, abs=0.0)


@pytest.mark.parametrize("text, value", [
    ("  1.234567890123D-03", 1.234567890123e-3),
    (" -9.876543210987D+12", -9.876543210987e12),
    ("  0.000000000000D+00", 0.0),
    ("  1.000000000000-100", 1e-100),      # Fortran drops the D for 3-digit exponents
    (" -2.500000000000+123", -2.5e123),
])
def test_fortran_real_reads_d_format(text, value):
    assert fortran_real(text) == value


@pytest.mark.parametrize("text", ["", "                 NaN", "*" * 20, "-Infinity", "1.2345Q-03",
                                  "0.123456789012D", "1.0", "9.999999999999+999", "  1.0D-03 junk"])
def test_fortran_real_rejects_the_rest(text):
    with pytest.raises(ValueError):
        fortran_real(text)


def _listing(tmp_path: Path, deck: Path, loads: LoadMatrix, report) -> tuple[Path, str]:
    """Write the run deck and run FRAMESOLVE by hand; the run directory and its listing."""
    work = tmp_path / "run"
    work.mkdir()
    run_deck = LegacyDialect().write_deck(work, BaseDeck(deck, read_deck(deck)), loads, report, ())
    out = subprocess.run([sys.executable, str(FRAMESOLVE), str(run_deck)], cwd=work,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    return run_deck, out.stdout


def _record(work: Path, text: str, returncode: int = 0) -> RunRecord:
    out = work / "listing.stdout"
    out.write_text(text)
    (work / "listing.stderr").write_text("")
    return RunRecord(("framesolve",), returncode, 0.1, 0, text[-2000:], "", work, out,
                     work / "listing.stderr")


def test_listing_pages_and_missing_node(tmp_path):
    deck = FIXTURES / "car" / "model.bdf"
    loads = read_loads(FIXTURES / "car" / "loads.csv").select([0, 1, 2])
    legacy = LegacyAdapter(deck, workdir_root=tmp_path)
    report = legacy.dofs()
    run_deck, text = _listing(tmp_path, deck, loads, report)
    lines = text.splitlines()
    headers = [ln for ln in lines if ln.startswith("1FRAMESOLVE 2.3")]
    assert len(headers) >= 4 and re.search(r"PAGE\s+4$", headers[3])
    assert any("(CONTINUED)" in ln for ln in lines)  # a table runs across a page break
    assert lines[-1] == "0NORMAL TERMINATION"  # carriage control 0: double space
    blocks = parse_listing(text)
    assert sorted(blocks) == [1, 2, 3] and all(len(b) == len(legacy.grid_xyz()) for b in blocks.values())
    dialect = LegacyDialect()
    good = dialect.read_results(run_deck.parent, run_deck, loads, report, _record(run_deck.parent, text))
    assert _max_rel(good, ReferenceAdapter(deck).solve(loads, report).values) <= AGREE
    row = next(i for i, ln in enumerate(lines) if ln[1:11].strip() == "11" and i > lines.index(
        next(ln for ln in lines if ln.startswith("0LOAD CASE     2"))))
    cut = "\n".join(lines[:row] + lines[row + 1:]) + "\n"
    with pytest.raises(SolverRunError, match=r"load case 2 lacks node\(s\) \[11\]"):
        dialect.read_results(run_deck.parent, run_deck, loads, report, _record(run_deck.parent, cut))
    abnormal = text.replace("0NORMAL TERMINATION", "0ABNORMAL TERMINATION")
    with pytest.raises(SolverRunError, match="no NORMAL TERMINATION"):
        dialect.read_results(run_deck.parent, run_deck, loads, report, _record(run_deck.parent, abnormal))
    with pytest.raises(SolverRunError, match="exit code 7"):
        dialect.read_results(run_deck.parent, run_deck, loads, report, _record(run_deck.parent, text, 7))


# --------------------------------------------------------------------------------------------
# failures
# --------------------------------------------------------------------------------------------
def test_singular_model_is_unstable(tmp_path):
    legacy = LegacyAdapter(_cantilever(tmp_path, spc="$ no support"), workdir_root=tmp_path)
    with pytest.raises(UnstableStructureError, match="SINGULAR STIFFNESS AT NODE") as info:
        legacy.solve(LoadMatrix.unit([(2, 3)]), [(2, 3)])
    assert info.value.dofs and all(g in (1, 2) and 1 <= c <= 6 for g, c in info.value.dofs)


def test_crash_gives_returncode_and_tail(tmp_path):
    legacy = LegacyAdapter(FIXTURES / "cube" / "model.bdf", misbehave="crash", workdir_root=tmp_path,
                           trusted=True, keep_failed=True)
    loads = read_loads(FIXTURES / "cube" / "loads.csv")
    with pytest.raises(SolverRunError) as info:
        legacy.solve(loads, [(7, 1)])
    err = info.value
    assert not isinstance(err, SolverTimeoutError)
    assert err.returncode == 139
    assert "SIGSEGV" in err.log_tail and "FRAMESOLVE" in err.log_tail
    assert err.workdir and Path(err.workdir, "run.dat").is_file()  # kept for inspection


@pytest.mark.parametrize("mode, message", [
    ("garbage", "unreadable number"),
    ("nan", r"unreadable number 'NaN'"),
    ("truncate", "no NORMAL TERMINATION"),
    ("wrong_cases", r"has 19 load-case block\(s\)"),
])
def test_bad_listings_never_give_numbers(tmp_path, mode, message):
    legacy = LegacyAdapter(FIXTURES / "cube" / "model.bdf", misbehave=mode, workdir_root=tmp_path, trusted=True)
    loads = read_loads(FIXTURES / "cube" / "loads.csv")
    assert loads.n_cases == 20
    with pytest.raises(SolverRunError, match=message) as info:
        legacy.solve(loads, legacy.dofs())
    assert info.value.returncode == 0 and info.value.log_tail
    assert legacy.stats.right_hand_sides == 0 and not legacy.stats.history[-1]["ok"]


def _framesolve_processes(root: Path) -> list[psutil.Process]:
    """Live framesolve.py processes started under ``root`` (their run directory or deck is there),
    so that runs of other test sessions on the machine are neither counted nor killed."""
    found = []
    for p in psutil.process_iter(["cmdline", "status", "cwd"]):
        try:
            args = p.info["cmdline"] or ()
            mine = str(root) in (p.info["cwd"] or "") or any(str(root) in a for a in args)
            if p.info["status"] != psutil.STATUS_ZOMBIE and mine and any("framesolve.py" in a for a in args):
                found.append(p)
        except psutil.Error:
            pass
    return found


def test_hang_times_out_and_leaves_no_process(tmp_path):
    assert not _framesolve_processes(tmp_path), "a framesolve.py process was running before the test"
    timeout = 2.0
    legacy = LegacyAdapter(FIXTURES / "cube" / "model.bdf", timeout_s=timeout, misbehave="hang",
                           workdir_root=tmp_path, trusted=True)
    t0 = time.perf_counter()
    with pytest.raises(SolverTimeoutError) as info:
        legacy.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
    wall = time.perf_counter() - t0
    assert wall < timeout + 4.0  # the runner's SIGTERM grace is 2 s; a sleeping process needs none
    child = re.search(r"WAITING FOR CHILD PROCESS (\d+)", info.value.log_tail)
    assert child, info.value.log_tail  # the child (own session) was started, so the check means something
    deadline = time.monotonic() + 3.0  # killed orphans are reaped by init shortly after the kill
    while _framesolve_processes(tmp_path) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = _framesolve_processes(tmp_path)
    for p in left:  # do not leave them to the next test run
        p.kill()
    assert not left, [p.info["cmdline"] for p in left]


def test_bad_misbehave_value():
    with pytest.raises(ValueError, match="misbehave must be one of"):
        LegacyAdapter(FIXTURES / "cube" / "model.bdf", misbehave="explode")


# --------------------------------------------------------------------------------------------
# what FRAMESOLVE cannot express is refused, never dropped
# --------------------------------------------------------------------------------------------
CUBE_BAR_1 = "CBAR           1       1       1       2     0.0     0.0     1.0"


@pytest.mark.parametrize("continuation, card, why", [
    # PA PB W1A W2A W3A W1B W2B W3B in fields 2-9 of the continuation
    ("                                         .01                     .01", "CBAR 1", "offsets"),
    ("              56", "CBAR 1", "pin flags"),
])
def test_offsets_and_pin_flags_are_refused_with_the_card_and_exit_2(continuation, card, why, tmp_path, capsys):
    """One CBAR of the cube with 1 cm offsets, or a pin flag, would have been solved without
    them (3-29 %, 33-151 % off the reference): FRAMESOLVE's deck has no field for either."""
    from blackbox.cli import main
    from conftest import copy_fixture

    study = copy_fixture("cube", tmp_path / "cube")
    text = (study / "model.bdf").read_text()
    (study / "model.bdf").write_text(text.replace(CUBE_BAR_1, CUBE_BAR_1 + "\n" + continuation, 1))
    assert main(["solve", str(study), "--adapter", "legacy", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "UnsupportedFeatureError: FRAMESOLVE cannot express 1 feature(s)" in err
    assert f"{card} (" in err and "model.bdf:" in err and why in err
    assert not (tmp_path / "o").exists()


def test_every_feature_it_cannot_express_is_named(tmp_path):
    from solver_adapters import conformance as cf
    from solver_adapters.protocol import UnsupportedFeatureError

    expected = {"offsets": {"CBAR 5", "CBAR 13", "CBAR 14", "CBAR 15", "CBAR 16"},
                "pin_flags": {"CBAR 2", "CBAR 14", "CBAR 16", "CBAR 17"},
                "shear_pin_flags": {"CBAR 10", "CBAR 15"},
                "cd_systems": {"GRID 2", "GRID 6", "GRID 7", "GRID 9", "GRID 12", "GRID 82"},
                "cd_supports": {"GRID 4"}, "rods": {"CROD 30", "CONROD 31"}, "rbe3": {"RBE3 40"}}
    for feature, cards in expected.items():
        deck, _, _ = cf.feature_deck(tmp_path / feature, feature)
        with pytest.raises(UnsupportedFeatureError) as info:
            LegacyAdapter(deck, workdir_root=tmp_path)
        assert set(info.value.cards) == cards, feature
    # and what it can express runs (springs between branch rotations, several cases)
    deck, loads, _ = cf.feature_deck(tmp_path / "springs", "branch_springs")
    a = LegacyAdapter(deck, workdir_root=tmp_path)
    U = a.solve(loads, a.dofs()).values
    R = ReferenceAdapter(deck).solve(loads, a.dofs()).values
    assert _max_rel(U, R) < AGREE
