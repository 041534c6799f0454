"""Rigid branch pairs (Section 2.2, last paragraph): the pair's rotations move together, the
pair has no parameters, and identification works around it."""

import shutil
from pathlib import Path

import numpy as np

from blackbox.joints import SimpleJoint
from blackbox.study import load_study
from blackbox.workflows import condensed_for_study, identify_study, make_adapter_for, study_joints

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"


def test_rigid_pair_equals_very_stiff_springs_and_is_identified(tmp_path):
    study_dir = tmp_path / "cube"
    shutil.copytree(FIXTURES / "cube", study_dir, ignore=shutil.ignore_patterns(".blackbox_cache", "*.png"))
    toml = study_dir / "study.toml"
    toml.write_text(toml.read_text().replace("deck_stiffness = 0.0", "deck_stiffness = 0.0\nrigid_pairs = [[7, 71]]"))
    study = load_study(study_dir)
    (joint,) = study_joints(study)
    assert joint.rigid_pairs == ((1, 2),) and joint.n_params == 6       # kx13 ... kz23 remain
    adapter = make_adapter_for(study, cache=False)
    cm = condensed_for_study(study, adapter, [joint], [])
    k = np.full(6, 1e4)
    U = cm.response(k).U_B
    # reference: the full simple model with the 1-2 springs very stiff (1e12 N*m/rad)
    full = SimpleJoint(joint.name, joint.grids)
    cm_full = condensed_for_study(study, adapter, [full], [])
    kf = np.array([1e12 if n.endswith("12") else 1e4 for n in full.param_names])
    U_ref = cm_full.response(kf).U_B
    # both are "rigid" to ~1e-6 of the relative rotation: agreement to 1e-5 of the response
    assert np.max(np.abs(U - U_ref)) < 1e-5 * np.max(np.abs(U_ref))
    rot = U[3:].reshape(3, 3, -1)
    assert np.max(np.abs(rot[0] - rot[1])) < 1e-5 * np.max(np.abs(rot))    # branches 1, 2 together
    run = identify_study(study, adapter)
    assert run.result.converged and run.result.n_params == 6
