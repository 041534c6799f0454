"""One declared model for every command (blackbox.declared).

Every command builds its condensed model through :func:`blackbox.declared.declared_model`, so a
study with rigid branch pairs gives the same declared response at the same parameters in
identify, compare, diagnose and simulate. The reference is the full model solved with the joint's
springs in the deck (the condensation is exact, ``tests/test_condensation.py``).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from blackbox.adapters import make_adapter_for
from blackbox.commands import compare, identify, simulate
from blackbox.declared import SolverCost, declared_model
from blackbox.study import load_study

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"

SAME_RESPONSE_RTOL = 1e-9
"""Two routes through the same condensation and the same joint matrices: only round-off differs."""


@pytest.fixture(scope="module")
def rigid_study(tmp_path_factory) -> Path:
    """The cube study with branches 7 and 71 of joint J7 declared rigid (Sec. 2.2)."""
    dst = tmp_path_factory.mktemp("declared") / "cube_rigid"
    shutil.copytree(FIXTURES / "cube", dst, ignore=shutil.ignore_patterns(".blackbox_cache"))
    toml = dst / "study.toml"
    toml.write_text(toml.read_text().replace("deck_stiffness = 0.0", "deck_stiffness = 0.0\nrigid_pairs = [[7, 71]]"))
    return dst


def _k(n: int) -> np.ndarray:
    return np.linspace(4e3, 2e4, n)


def test_identify_compare_simulate_share_the_declared_response(rigid_study, tmp_path):
    study = load_study(rigid_study, need_measurements=True)
    declared = declared_model(study)
    assert [len(j.param_names) for j in declared.joints] == [6]        # the rigid pair's 3 springs are gone
    k = _k(6)

    ident = identify.run(study, adapter="reference", profile=False)
    ref = ident.model.response(k).U_B
    ref_scale = np.max(np.abs(ref))

    cmp_res = compare.run(study, adapter="reference")
    via_compare = cmp_res.first.fits.simple_model.response(k).U_B
    assert np.max(np.abs(via_compare - ref)) <= SAME_RESPONSE_RTOL * ref_scale

    # the tie acts: the two rigid branches rotate together (to the penalty's 1e-6), unlike without it
    rot = {d: i for i, d in enumerate(ident.model.c.boundary)}
    r7 = ref[[rot[(7, c)] for c in (4, 5, 6)]]
    r71 = ref[[rot[(71, c)] for c in (4, 5, 6)]]
    assert np.max(np.abs(r7 - r71)) <= 1e-5 * np.max(np.abs(r7))

    # simulate: a noise-free truth equal to the declared joint at k reproduces the same response
    truth = tmp_path / "truth.toml"
    values = ", ".join(f"{n} = {float(v)!r}" for n, v in zip(declared.joints[0].param_names, k))
    truth.write_text("seed = 3\n[noise]\nrelative = 0.0\nabsolute = 1e-30\nfloor = 0.0\n"
                     "[measure]\njoint = true\n"
                     f"[[joints]]\nname = \"J7\"\nmodel = \"simple\"\nvalues = {{ {values} }}\n")
    sim = simulate.run(study, truth, adapter="reference")
    got = {(c, (g, comp)): v for c, g, comp, v, _, _ in sim.rows}
    cases = list(ident.model.c.cases)
    for (case, dof), v in got.items():
        want = ref[list(ident.model.c.boundary).index(dof), cases.index(case)]
        assert abs(v - want) <= SAME_RESPONSE_RTOL * ref_scale + 1e-28


def test_complex_model_keeps_the_rigid_tie(rigid_study):
    """A complex model fitted to a study with rigid pairs keeps the tie (the structure's property)."""
    study = load_study(rigid_study, need_measurements=True)
    cx = declared_model(study, "complex")
    cm = cx.condense(make_adapter_for(study, "reference"))
    U = cm.response(cx.k0).U_B
    idx = {d: i for i, d in enumerate(cm.c.boundary)}
    r7, r71 = U[[idx[(7, c)] for c in (4, 5, 6)]], U[[idx[(71, c)] for c in (4, 5, 6)]]
    assert np.max(np.abs(r7 - r71)) <= 1e-5 * np.max(np.abs(r7))


def test_solver_cost_counts_one_batch(rigid_study):
    study = load_study(rigid_study, need_measurements=True)
    res = identify.run(study, adapter="reference", profile=False)
    assert res.solver == SolverCost("reference", 1, res.model.c.right_hand_sides, res.solver.wall_s, 0)
    assert res.solver.right_hand_sides == len(res.model.c.boundary) + study.loads.n_cases
    total = res.solver + SolverCost("mystran", 2, 10, 1.0, 1)
    assert (total.adapter, total.runs, total.right_hand_sides, total.cached_batches) == ("reference+mystran", 3,
                                                                                        res.solver.right_hand_sides + 10, 1)


@pytest.mark.slow
def test_diagnose_uses_the_same_declared_model(rigid_study):
    """diagnose builds its declared model (joints, start, rigid-pair penalty) through the same
    builder: the same parameters and the same K_deck as identify, so its declared fit on the
    study's deck is identify's (tests/test_diagnose.py checks the fit and the split deck's
    nesting)."""
    from blackbox.commands import diagnose

    study = load_study(rigid_study, need_measurements=True)
    ident = identify.run(study, adapter="reference", profile=False)
    d = diagnose.run(study, adapter="reference", effects=["load_scale"], plots=False)
    pr = d.prepared
    assert [j.param_names for j in pr.declared.joints] == [j.param_names for j in ident.declared.joints]
    np.testing.assert_array_equal(pr.declared.k0, ident.declared.k0)
    # the rigid-pair penalty in K_deck: the same matrix (same condensation, same formula)
    np.testing.assert_allclose(pr.K_deck, ident.model.K_deck, rtol=SAME_RESPONSE_RTOL,
                               atol=SAME_RESPONSE_RTOL * np.abs(ident.model.K_deck).max())
    k = _k(6)
    r_diag = pr.declared.condensed_model(ident.model.c).response(k).U_B
    np.testing.assert_allclose(r_diag, ident.model.response(k).U_B, rtol=0, atol=SAME_RESPONSE_RTOL *
                               np.abs(ident.model.response(k).U_B).max())


def test_a_joint_dof_autospc_removed_is_an_error(cube, tmp_path, capsys):
    """AUTOSPC (NASTRAN's default, the reference solver's now) constrains a component no
    element of the deck holds. A branch member pinned at the joint (CBAR 7's end at branch grid
    71 released in 456) leaves branch 71's rotations held by nothing but the joint's springs,
    which the deck alone does not have: AUTOSPC fixes them, and the condensation would take
    them as fixed. Every command that condenses stops with an error naming the DOFs instead
    (before, the same deck failed as a mechanism); the deck's own SPC on a joint DOF passes."""
    deck = cube / "model.bdf"
    text = deck.read_text()
    pinned = "CBAR           7       1      71       8     0.0     0.0     1.0\n             456"
    deck.write_text(text.replace("CBAR           7       1      71       8     0.0     0.0     1.0", pinned))
    study = load_study(cube)
    assert study.deck.cbars[7].pa == "456"
    from blackbox.errors import StudyError
    with pytest.raises(StudyError, match=r"joint 'J7': DOF\(s\) \[\(71, 4\), \(71, 5\), \(71, 6\)\].*AUTOSPC"), \
            pytest.warns(RuntimeWarning, match="AUTOSPC constrained"):
        declared_model(study).condense(make_adapter_for(study, cache=False))
    with pytest.warns(RuntimeWarning, match="AUTOSPC constrained"):
        assert identify_main(cube, tmp_path) == 2
    assert "do not move under a load there although the deck does not constrain them" in capsys.readouterr().err
    # the same joint DOFs constrained by the deck itself: fixed on purpose, no error
    deck.write_text(text.replace("ENDDATA", "CBAR,7,1,71,8,0.,0.,1.\n,456\nSPC1,1,456,71\nENDDATA")
                    .replace("CBAR           7       1      71       8     0.0     0.0     1.0\n", ""))
    study = load_study(cube)
    declared_model(study).condense(make_adapter_for(study, cache=False))


def identify_main(study: Path, tmp_path: Path) -> int:
    from blackbox.cli import main
    return main(["identify", str(study), "--out", str(tmp_path / "id"), "--no-cache"])
