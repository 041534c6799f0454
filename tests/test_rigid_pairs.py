"""Rigid branch pairs (Section 2.2, last paragraph): the pair's rotations move together, the
pair has no parameters, and identification works around it."""


import numpy as np

from blackbox.joints import SimpleJoint
from blackbox.study import load_study
from blackbox.adapters import make_adapter_for
from blackbox.commands import identify
from blackbox.condensation import CondensedModel, condense
from blackbox.declared import declared_model

from conftest import copy_fixture


def test_rigid_pair_equals_very_stiff_springs_and_is_identified(tmp_path):
    study_dir = tmp_path / "cube"
    copy_fixture("cube", study_dir, "*.png")
    toml = study_dir / "study.toml"
    toml.write_text(toml.read_text().replace("deck_stiffness = 0.0", "deck_stiffness = 0.0\nrigid_pairs = [[7, 71]]"))
    study = load_study(study_dir)
    declared = declared_model(study)
    (joint,) = declared.joints
    assert joint.rigid_pairs == ((1, 2),) and joint.n_params == 6       # kx13 ... kz23 remain
    adapter = make_adapter_for(study, cache=False)
    cm = declared.condense(adapter, [])
    k = np.full(6, 1e4)
    U = cm.response(k).U_B
    # reference: the full simple model with the 1-2 springs very stiff (1e12 N*m/rad)
    full = SimpleJoint(joint.name, joint.grids)
    cm_full = CondensedModel(condense(adapter, study.loads, full.dofs, []), [full])    # no tie
    kf = np.array([1e12 if n.endswith("12") else 1e4 for n in full.param_names])
    U_ref = cm_full.response(kf).U_B
    # both are "rigid" to ~1e-6 of the relative rotation: agreement to 1e-5 of the response
    assert np.max(np.abs(U - U_ref)) < 1e-5 * np.max(np.abs(U_ref))
    rot = U[3:].reshape(3, 3, -1)
    assert np.max(np.abs(rot[0] - rot[1])) < 1e-5 * np.max(np.abs(rot))    # branches 1, 2 together
    run = identify.run(study, adapter=adapter)
    assert run.result.converged and run.result.n_params == 6
