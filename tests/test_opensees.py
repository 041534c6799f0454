"""The ``opensees`` adapter: OpenSees (openseespy 3.8) run as a subprocess on a deck written from
the parsed model (``solver_adapters/opensees.py``, runner ``solver_adapters/_opensees_run.py``).

Reference values are the in-process reference solver's (an independent implementation of the
same NASTRAN element conventions). OpenSees solves in double precision and the runner hands over
``repr`` digits, so displacements agree to the solvers' rounding (measured 2.3e-13 cube,
8.7e-13 car, normwise per case); the tolerances below say what identification and diagnosis
add on top.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import blackbox
from blackbox.cli import main
from solver_adapters import conformance as cf
from solver_adapters.bdf import read_deck
from solver_adapters.protocol import LoadMatrix, ScalarSpring, UnsupportedFeatureError
from solver_adapters.reference import ReferenceAdapter

from conftest import FIXTURES, HAVE_OPENSEES, copy_fixture

pytestmark = [pytest.mark.opensees, pytest.mark.skipif(not HAVE_OPENSEES, reason="openseespy not installed"),
              pytest.mark.usefixtures("runs_under_tmp_path")]

if HAVE_OPENSEES:
    from solver_adapters.opensees import RUNNER, OpenSeesAdapter, OpenSeesDialect
    from solver_adapters.subprocess import CommandAdapter


def normwise(U, R) -> float:
    return float(np.max(np.max(np.abs(U - R), axis=0) / np.max(np.abs(R), axis=0)))


@pytest.mark.parametrize("fixture, tol", [("cube", 1e-11), ("car", 1e-11)])
def test_agrees_with_the_reference_solver(fixture, tol):
    """Both in double precision, exact to rounding (measured 2.3e-13 and 8.7e-13): 1e-11."""
    deck = FIXTURES / fixture / "model.bdf"
    loads = cf.read_loads_csv(FIXTURES / fixture / "loads.csv")
    a = OpenSeesAdapter(deck)
    U = a.solve(loads, a.dofs()).values
    R = ReferenceAdapter(deck).solve(loads, a.dofs()).values
    assert normwise(U, R) < tol
    assert (a.stats.runs, a.stats.right_hand_sides) == (1, loads.n_cases)   # one run for the batch


def test_cli_conformance_passes(tmp_path, capsys):
    """Every check passes; the features OpenSees cannot express are refused, with the card."""
    assert main(["conformance", "opensees", "--out", str(tmp_path / "o")]) == 0
    printed = capsys.readouterr().out
    rep = json.loads((tmp_path / "o" / "conformance.json").read_text())
    assert rep["passed"] and rep["rtol"] == 1e-9
    checks = {c["name"]: c for c in rep["checks"]}
    refused = {n for n, c in checks.items() if c["refused"]}
    assert refused == {"feature[shear_pin_flags]", "feature[cd_supports]", "feature[rbe3]"}
    assert "naming RBE3 40" in checks["feature[rbe3]"]["detail"]
    for name in ("feature[offsets]", "feature[pin_flags]", "feature[cd_systems]", "feature[rods]",
                 "feature[branch_springs]", "feature[spring_cases]", "grounded_springs", "with_springs"):
        assert checks[name]["passed"] and not checks[name]["refused"], checks[name]
    assert "UnstableStructureError" in checks["mechanism"]["detail"]
    for switch in cf.COMMAND_SWITCHES:      # the generic misbehaviours of a command
        assert checks[f"misbehaviour[{switch}]"]["passed"]
    assert "3 refused with a typed error" in printed


@pytest.mark.parametrize("fixture, tol", [("cube", 1e-9), ("car", 1e-9), ("cube_complex", 1e-5)])
def test_identify_agrees_with_the_reference(fixture, tol):
    """Same estimates, intervals and chi2 as with the reference solver. Measured: estimates
    7e-12 (cube), 7e-11 (car), 2e-7 (cube_complex: 21 parameters of a joint stiff enough that
    several are barely bounded, so the solvers' 1e-13 differences are amplified by the
    estimation's conditioning); interval bounds 5e-7 at most (the profile refits stop at a
    relative step of 1e-6, hence 1e-5 for them); chi2 to 1e-12."""
    ref = blackbox.identify(FIXTURES / fixture, adapter="reference").result
    got = blackbox.identify(FIXTURES / fixture, adapter="opensees")
    assert got.solver.adapter == "opensees" and got.solver.runs == 1
    r = got.result
    assert list(r.identifiable) == list(ref.identifiable)
    ok = ref.identifiable
    # relative to each parameter's size (an estimate or a bound may be 0; a bound the profile
    # does not close is infinite, in both or in neither)
    finite = lambda v: np.where(np.isfinite(v), np.abs(v), 0.0)       # noqa: E731
    size = np.maximum(np.abs(ref.k[ok]), np.maximum(finite(ref.ci_low[ok]), finite(ref.ci_high[ok])))
    assert np.max(np.abs(r.k[ok] - ref.k[ok]) / size) < tol
    for mine, theirs in ((r.ci_low[ok], ref.ci_low[ok]), (r.ci_high[ok], ref.ci_high[ok])):
        assert np.array_equal(np.isfinite(mine), np.isfinite(theirs))
        both = np.isfinite(theirs)
        assert np.max(np.abs(mine[both] - theirs[both]) / size[both]) < 1e-5
    assert abs(r.chi2 - ref.chi2) < 1e-10 * ref.chi2


def test_diagnose_agrees_with_the_reference():
    """Same verdict, same effect at the same place, same fit before and after. Measured: reduced
    chi2 33.18 -> 1.0005 both ways, support stiffnesses within 1e-9."""
    a = blackbox.diagnose(FIXTURES / "undeclared" / "support_flexibility", adapter="reference", plots=False).document
    res = blackbox.diagnose(FIXTURES / "undeclared" / "support_flexibility", adapter="opensees", plots=False)
    b = res.document
    assert res.solver.adapter == "opensees" and res.solver.runs >= 2      # split deck and edited decks too
    assert b["verdict"] == a["verdict"] == "explained"
    assert [(e["effect"], e["where"]) for e in b["added"]] == [(e["effect"], e["where"]) for e in a["added"]]
    for key in ("before", "after"):
        assert abs(b[key]["reduced_chi2"] - a[key]["reduced_chi2"]) < 1e-8 * a[key]["reduced_chi2"]
    pa = [p["value"] for e in a["added"] for p in e["parameters"]]
    pb = [p["value"] for e in b["added"] for p in e["parameters"]]
    assert np.allclose(pb, pa, rtol=1e-8, atol=0)


# ---- refused before running ------------------------------------------------------------------
def _with_card_edit(tmp_path, old: str, new: str):
    study = copy_fixture("cube", tmp_path / "cube")
    text = (study / "model.bdf").read_text()
    assert old in text
    (study / "model.bdf").write_text(text.replace(old, new, 1))
    return study


def test_a_shear_pin_flag_is_refused_with_its_card_and_exit_2(tmp_path, capsys):
    # CBAR 1 with PA = 2 (a shear release at end A): continuation line with PA PB
    study = _with_card_edit(tmp_path, "CBAR           1       1       1       2     0.0     0.0     1.0",
                            "CBAR           1       1       1       2     0.0     0.0     1.0\n"
                            "                       2")
    assert main(["solve", str(study), "--adapter", "opensees", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "UnsupportedFeatureError" in err and "CBAR 1 (" in err and "model.bdf:" in err
    assert "pin flag(s) 2" in err and not (tmp_path / "o" / "displacements.csv").exists()


def test_every_refused_feature_is_named_at_once(tmp_path):
    from solver_adapters.bdf_write import format_card
    deck, _, _ = cf.feature_deck(tmp_path, "rbe3")
    pbar = format_card("PBAR", [17, 1, 1.0e-4, 1.0e-8, 1.0e-8, 2.0e-8] + [None] * 12 + [1.0e-9], "free")
    text = deck.read_text().replace("ENDDATA", pbar + "CBAR,77,17,9,11,0.0,0.0,1.0\nENDDATA")
    deck.write_text(text)
    with pytest.raises(UnsupportedFeatureError) as info:
        OpenSeesAdapter(deck)
    assert set(info.value.cards) == {"RBE3 40", "PBAR 17"} and "I12" in str(info.value)


def test_springs_it_cannot_express_are_refused_before_a_run():
    a = OpenSeesAdapter(FIXTURES / "cube" / "model.bdf")
    with pytest.raises(UnsupportedFeatureError, match="a translation .* and a rotation"):
        a.with_springs([ScalarSpring((5, 1), (6, 5), 1e3)])
    assert a.stats.runs == 0


# ---- what OpenSees does not report ----------------------------------------------------------
def test_a_mechanism_is_an_unstable_structure_not_1e8_displacements(tmp_path, capsys):
    """The cube without its support: OpenSees's factorization meets rounding-size pivots and
    returns huge displacements with ``analyze`` = 0; the runner's equilibrium check stops it."""
    study = _with_card_edit(tmp_path, "SPC1           1  123456       1", "$ support removed")
    assert main(["solve", str(study), "--adapter", "opensees", "--out", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err
    assert "UnstableStructureError" in err and "SINGULAR STIFFNESS" in err


def _run_runner(tmp_path, deck_text: str, patch: str = "") -> subprocess.CompletedProcess:
    """The runner on a deck, optionally with its source edited (``old=>new``) to break it."""
    source = RUNNER.read_text()
    if patch:
        old, new = patch.split("=>")
        assert old in source
        source = source.replace(old, new)
    script = tmp_path / "runner.py"
    script.write_text(source)
    deck = tmp_path / "run.tcl"
    deck.write_text(deck_text)
    return subprocess.run([sys.executable, str(script), str(deck)], capture_output=True, text=True,
                          cwd=tmp_path)


def _branch_spring_deck(tmp_path):
    deck, loads, _ = cf.feature_deck(tmp_path / "d", "branch_springs")
    tr = OpenSeesDialect().translation(read_deck(deck))
    return tr.run_deck(loads, ReferenceAdapter(deck).dofs(), ())


def test_the_equilibrium_check_catches_what_opensees_gets_wrong_silently(tmp_path):
    """Springs between branch rotations of a joint whose branches are tied to its first grid
    make chained ties (a spring's auxiliary node follows a tied branch). OpenSees's
    Transformation handler does not follow the chain and answers with exit code 0; the runner
    picks Lagrange multipliers for such a model, and with the handler forced back the
    equilibrium residual (0.008 of the load, against 1e-14) stops the run."""
    text = _branch_spring_deck(tmp_path)
    good = _run_runner(tmp_path, text)
    assert good.returncode == 0 and "constraint handler Lagrange" in good.stdout
    worst = max(float(line.split("residual ")[1].split()[0]) for line in good.stdout.splitlines()
                if "equilibrium residual" in line)
    assert worst < 1e-12
    bad = _run_runner(tmp_path, text, 'ops.constraints(handler)=>ops.constraints("Transformation")')
    assert bad.returncode == 3 and "*** SINGULAR STIFFNESS AT NODE" in bad.stdout


def test_load_cases_that_accumulate_fail_the_conformance_checks(tmp_path):
    """A runner whose load patterns stay active after their case (a Linear time series instead
    of one that is 1 only at its case's step) gives each case the sum of the cases before it:
    exactly the kind of state carried between cases that ``feature[spring_cases]`` and
    ``batch_equals_one_by_one`` must catch."""
    broken = tmp_path / "broken_runner.py"
    source = RUNNER.read_text()
    old = 'ops.timeSeries("Path", j, "-time", j - 1.0, float(j), j + 1.0, "-values", 0.0, 1.0, 0.0)'
    assert old in source
    broken.write_text(source.replace(old, 'ops.timeSeries("Linear", j)'))

    def factory(deck):
        return CommandAdapter(deck, command=[sys.executable, str(broken), "{deck}"], dialect=OpenSeesDialect(),
                              name="opensees", trusted=True)

    suite = cf.Suite(factory, FIXTURES / "cube" / "model.bdf", cf.read_loads_csv(FIXTURES / "cube" / "loads.csv"))
    with pytest.raises(cf.CheckFailure):
        cf.check_feature(suite, "spring_cases")
    with pytest.raises(cf.CheckFailure, match="one-by-one vs batch"):
        cf.check_batch_equals_one_by_one(suite)


def test_cases_in_one_run_with_springs_equal_each_case_alone():
    """OpenSees keeps element and spring forces in the model between analyses; the runner resets
    the model before each case, so with springs in the deck and added ones every case solved in
    a batch equals the case solved alone (to rounding, here bit for bit or 1e-14)."""
    deck = FIXTURES / "cube" / "model.bdf"
    loads = cf.read_loads_csv(FIXTURES / "cube" / "loads.csv").select(range(6))
    a = OpenSeesAdapter(deck).with_springs([ScalarSpring((71, 4), (72, 4), 2.0e3),
                                            ScalarSpring((7, 5), (72, 6), -4.0e2), ScalarSpring((3, 2), None, 1e5)])
    report = a.dofs()
    U = a.solve(loads, report).values
    singles = np.column_stack([a.solve(loads.select([j]), report).values[:, 0] for j in range(loads.n_cases)])
    assert normwise(U, singles) < 1e-12
    R = ReferenceAdapter(deck).with_springs(a.springs).solve(loads, report).values
    assert normwise(U, R) < 1e-11


def test_missing_openseespy_is_named_with_the_install_command(tmp_path):
    """The base interpreter of this virtual environment (no openseespy there) as the runner's
    Python: exit code 5 of the runner becomes a SolverRunError saying how to install it."""
    base = getattr(sys, "_base_executable", None)
    probe = subprocess.run([base, "-c", "import openseespy"], capture_output=True) if base else None
    if probe is None or probe.returncode == 0:
        pytest.skip("no interpreter without openseespy at hand")
    a = OpenSeesAdapter(FIXTURES / "cube" / "model.bdf", python=base, trusted=True)
    with pytest.raises(Exception, match="--ignore-requires-python --no-deps openseespy openseespylinux"):
        a.solve(LoadMatrix.unit([(5, 1)]), [(5, 1)])


def test_another_python_needs_consent():
    from solver_adapters.errors import ConsentError
    with pytest.raises(ConsentError):
        OpenSeesAdapter(FIXTURES / "cube" / "model.bdf", python="/usr/bin/python3")
    assert isinstance(OpenSeesAdapter(FIXTURES / "cube" / "model.bdf", python=sys.executable), OpenSeesAdapter)


def test_a_neutral_axis_offset_is_refused_by_opensees_and_framesolve(tmp_path):
    """A PBEAM with N1/N2 (the neutral axis off the shear centre, modelled by the reference
    solver since the deck tail): neither OpenSees's elastic beam nor FRAMESOLVE's can say it, so
    both refuse the card before any run instead of solving another structure."""
    from solver_adapters.legacy import unsupported_features
    deck, _, _ = cf.feature_deck(tmp_path, "rods")
    pbeam = ("PBEAM   18      1       1.-4    1.-8    1.-8    0.      2.-8\n"
             "        0.      0.      0.      0.      0.      0.      0.      0.\n"
             "        YESA    1.\n"
             "        0.      0.\n"
             "                                        .01     0.      .01     0.\n"
             "CBEAM   78      18      9       11      0.      0.      1.\n")
    text = deck.read_text().replace("ENDDATA", pbeam + "ENDDATA")
    deck.write_text(text)
    from solver_adapters.bdf import read_deck
    model = read_deck(deck)
    assert model.pbars[18].n1 == 0.01
    with pytest.raises(UnsupportedFeatureError) as info:
        OpenSeesAdapter(deck)
    assert "PBEAM 18" in info.value.cards and "neutral axis" in str(info.value)
    assert any(c == "PBEAM 18" and "neutral axis" in why for c, _, why in unsupported_features(model))
