"""Black-box condensation (Sections 3.3-3.5) against full solves with the joint in the deck.

Reference values come from an independent path: the joint put into the full model as scalar
springs (CELAS2-equivalent, ``with_springs``) and the whole structure re-solved. Tolerance 1e-9
relative (the issue's figure): both paths are exact in exact arithmetic; round-off in the
condensed flexibility form is ~1e-13 here.
"""

from __future__ import annotations


import numpy as np
import pytest

from blackbox import sensitivity as S
from blackbox.condensation import CondensedModel, condense
from blackbox.joints import ComplexJoint, SimpleJoint, actual_joint_stub_kc, make_joint
from blackbox.reference_tables import TABLE_3_1
from blackbox.structures import FrameBuilder, cube, random_loads, star_joint_frame
from blackbox.study import load_study
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter

from conftest import FIXTURES, adapter_of, load_matrix, max_rel

REL = 1e-9


def complex_params(joint: ComplexJoint, scale: float, seed: int = 0) -> np.ndarray:
    """A random symmetric positive definite K_C of the given magnitude."""
    rng = np.random.default_rng(seed)
    Q = rng.standard_normal((joint.m, joint.m))
    return joint.params_from_kc(scale * (Q @ Q.T / joint.m + np.eye(joint.m)))


def check_condensed_equals_full(adapter, loads, joints, k, observed=()):
    boundary = [d for j in joints for d in j.dofs]
    c = condense(adapter, loads, boundary, observed)
    assert c.solver_runs == 1 and c.right_hand_sides == len(boundary) + loads.n_cases
    m = CondensedModel(c, joints)
    r = m.response(k)
    report = list(c.boundary) + list(c.observed)
    full = S.full_response(adapter, joints, k, loads, report)
    assert max_rel(np.vstack([r.U_B, r.U_O]), full) < REL
    return m


@pytest.mark.parametrize("fixture,scale", [("cube", 1e4), ("car", 1e5)])
@pytest.mark.parametrize("model", ["simple", "complex"])
def test_condensed_equals_full_on_fixtures(fixture, scale, model):
    study = load_study(FIXTURES / fixture)
    adapter = ReferenceAdapter(study.deck_path)
    jc = study.config.joints[0]
    joint = make_joint(jc.name, jc.grids, model)
    k = np.full(joint.n_params, scale) if model == "simple" else complex_params(joint, scale)
    observed = [d for d in adapter.dofs() if d[0] not in jc.grids][::7]     # away from the joint
    check_condensed_equals_full(adapter, study.loads, [joint], k, observed)


@pytest.mark.parametrize("n", [2, 4, 6])
@pytest.mark.parametrize("model", ["simple", "complex"])
def test_condensed_equals_full_n_branches(n, model):
    f = star_joint_frame(n, seed=n)
    adapter = adapter_of(f)
    joint = make_joint(*f.joints[0], model)
    k = np.linspace(2e4, 9e4, joint.n_params) if model == "simple" else complex_params(joint, 5e4, n)
    loads = load_matrix(random_loads(f, 5, seed=4))
    check_condensed_equals_full(adapter, loads, [joint], k, observed=[(100, 1), (101, 5)])


def two_joint_frame() -> FrameBuilder:
    """A two-bay portal space frame with two flexible joints (3 and 4 branches)."""
    f = FrameBuilder(E=206.85e9, G=82.7e9, A=2.99e-4, I1=77.42e-8, I2=16.65e-8, J=35.40e-8)
    pts = {1: (0, 0, 0), 2: (1, 0, 0), 3: (2, 0, 0), 4: (0, 0, 1), 5: (1, 0, 1), 6: (2, 0, 1),
           7: (0, 1, 0), 8: (1, 1, 0), 9: (2, 1, 0), 10: (0, 1, 1), 11: (1, 1, 1), 12: (2, 1, 1)}
    for g, p in pts.items():
        f.grid(g, p)
    members = [(1, 4), (2, 5), (3, 6), (4, 5), (5, 6), (7, 10), (8, 11), (9, 12), (10, 11), (11, 12),
               (4, 10), (5, 11), (6, 12)]
    for a, b in members:
        f.bar(a, b)
    for g in (1, 2, 3, 7, 8, 9):
        f.fix(g)
    f.flexible_joint("JA", 4, [e for e, a, b, _ in f.bars if 4 in (a, b)], 41)
    f.flexible_joint("JB", 11, [e for e, a, b, _ in f.bars if 11 in (a, b)], 111)
    return f


def test_several_joints_at_once_and_mixed_models():
    f = two_joint_frame()
    adapter = adapter_of(f)
    ja = make_joint(*f.joints[0], "simple")
    jb = make_joint(*f.joints[1], "complex")
    assert (ja.n_branches, jb.n_branches) == (3, 4)
    k = np.r_[np.full(ja.n_params, 3e4), complex_params(jb, 6e4)]
    loads = load_matrix(random_loads(f, 4, seed=4))
    m = check_condensed_equals_full(adapter, loads, [ja, jb], k, observed=[(5, 3), (12, 1)])
    dofs = list(m.c.boundary) + list(m.c.observed)
    d = S.direct(m, k, dofs)
    c = S.finite_difference(adapter, [ja, jb], k, loads, dofs, "central", rel_step=1e-4)
    assert max_rel(d, c) < 1e-6   # central differences: O(h^2) truncation ~1e-8, round-off ~1e-12/h


@pytest.mark.parametrize("model", ["simple", "complex"])
def test_direct_equals_central_differences_cube(model):
    """Eq. 18 (no solver run) against eq. 7 on the full model (2 n solver runs)."""
    f = cube()
    adapter = adapter_of(f)
    joint = make_joint(*f.joints[0], model)
    k = np.full(joint.n_params, 1e4) if model == "simple" else complex_params(joint, 1e4)
    loads = LoadMatrix.from_dense([(5, 6), (6, 6), (8, 6)], np.full((3, 1), 0.5), ["L1"])
    m = CondensedModel(condense(adapter, loads, joint.dofs), [joint])
    d = S.direct(m, k, list(joint.dofs))
    runs0 = adapter.stats.runs
    c = S.finite_difference(adapter, [joint], k, loads, list(joint.dofs), "central", rel_step=1e-4)
    assert adapter.stats.runs - runs0 == 2 * joint.n_params
    # relative step 1e-4: truncation (h^2 u''') ~1e-8 of the derivative, plus round-off
    assert max_rel(d, c) < 1e-6
    fwd = S.finite_difference(adapter, [joint], k, loads, list(joint.dofs), "forward", rel_step=1e-6)
    assert max_rel(d, fwd) < 1e-4   # forward: O(h) truncation with h = 1e-6 relative
    semi = S.semi_analytic(m, k, list(joint.dofs))
    assert max_rel(d, semi) < 1e-8  # K_J is linear in k: the matrix difference is exact to round-off


def test_deck_stiffness_is_subtracted():
    """A deck that already couples the branches with simple-model springs k0 (deck_stiffness)
    gives the same joint response once K_deck is subtracted."""
    f = cube()
    joint = SimpleJoint(*f.joints[0])
    k0 = 2.5e3
    plain = adapter_of(f)
    from blackbox.joints import spring_network
    f.springs += [(s.a[0], s.a[1], s.b[0], s.b[1], s.k) for s in spring_network(joint, np.full(9, k0))]
    coupled = adapter_of(f)
    loads = LoadMatrix.from_dense([(5, 6), (6, 6), (8, 6)], np.full((3, 1), 0.5), ["L1"])
    k = np.linspace(5e3, 2e4, 9)
    m_plain = CondensedModel(condense(plain, loads, joint.dofs), [joint])
    m_coupled = CondensedModel(condense(coupled, loads, joint.dofs), [joint],
                               K_deck=joint.matrix(np.full(9, k0)))
    assert max_rel(m_coupled.response(k).U_B, m_plain.response(k).U_B) < REL


def test_recovery_of_whole_field_by_superposition():
    """Every grid's displacement from the same single call, without enlarging B."""
    f = cube()
    adapter = adapter_of(f)
    joint = make_joint(*f.joints[0], "complex")
    k = complex_params(joint, 2e4, 3)
    loads = LoadMatrix.from_dense([(5, 6), (6, 6), (8, 6)], np.full((3, 1), 0.5), ["L1"])
    c = condense(adapter, loads, joint.dofs, observed=adapter.dofs())
    assert len(c.boundary) == 12 and c.solver_runs == 1
    m = CondensedModel(c, [joint])
    full = S.full_response(adapter, [joint], k, loads, list(c.observed))
    assert max_rel(m.response(k).U_O, full) < REL


def test_stub_joint_is_a_valid_complex_truth():
    """The stub K_C of Section 5.4.1 gives a positive definite, condensable joint."""
    f = cube()
    joint = ComplexJoint(*f.joints[0])
    dirs = [(0, 0, -1), (-1, 0, 0), (0, -1, 0)]          # towards nodes 3, 8, 6
    K_C = actual_joint_stub_kc(dirs, 0.01, **TABLE_3_1)
    assert np.all(np.linalg.eigvalsh(K_C) > 0)
    adapter = adapter_of(f)
    loads = LoadMatrix.from_dense([(5, 6), (6, 6), (8, 6)], np.full((3, 1), 0.5), ["L1"])
    check_condensed_equals_full(adapter, loads, [joint], joint.params_from_kc(K_C))
