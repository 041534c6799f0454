"""The in-process reference solver against textbook cases and structural identities.

Tolerances: the reference solver is a direct sparse factorization in double precision; on these
small, well-conditioned models the round-off is ~1e-13 relative, so 1e-9 leaves four orders of
margin while still catching any wrong term (a wrong term is O(1) relative).
"""

from __future__ import annotations

import numpy as np
import pytest

from blackbox.joints import ComplexJoint, spring_network
from blackbox.structures import FrameBuilder, cube, star_joint_frame, tube_body
from solver_adapters.bdf import read_deck_text
from solver_adapters.protocol import (LoadMatrix, ScalarSpring, UnknownDofError,
                                      UnstableStructureError, ModelError)
from solver_adapters.reference import ReferenceAdapter

from conftest import adapter_of

RTOL = 1e-9   # see module docstring
E, G_MOD, A, I1, I2, J = 2.0e11, 8.0e10, 1.0e-3, 2.0e-6, 3.0e-6, 1.5e-6


def unit_case(adapter, dof, value=1.0, report=None):
    loads = LoadMatrix.from_dense([dof], np.array([[value]]), ["c"])
    report = report or [dof]
    return adapter.solve(loads, report).values[:, 0]


def cantilever(direction, n_el=4, length=2.0, v=None):
    f = FrameBuilder(E=E, G=G_MOD, A=A, I1=I1, I2=I2, J=J)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    for i in range(n_el + 1):
        f.grid(i + 1, d * length * i / n_el)
    for i in range(n_el):
        f.bar(i + 1, i + 2, v=v)
    f.fix(1)
    return f


def test_cantilever_tip_load_textbook():
    """Gere & Timoshenko, Mechanics of Materials, App. G, case 1 (tip force P: delta = P L^3/3EI,
    theta = P L^2/2EI), case 6 (tip moment M: theta = M L/EI), axial P L/EA, torsion T L/GJ."""
    L, P = 2.0, 1.0e3
    a = adapter_of(cantilever((1, 0, 0), v=(0, 1, 0)))    # plane 1 = x-y: I1 bends in y
    tip = 5
    assert unit_case(a, (tip, 2), P)[0] == pytest.approx(P * L**3 / (3 * E * I1), rel=RTOL)
    assert unit_case(a, (tip, 2), P, [(tip, 6)])[0] == pytest.approx(P * L**2 / (2 * E * I1), rel=RTOL)
    assert unit_case(a, (tip, 3), P)[0] == pytest.approx(P * L**3 / (3 * E * I2), rel=RTOL)
    assert unit_case(a, (tip, 3), P, [(tip, 5)])[0] == pytest.approx(-P * L**2 / (2 * E * I2), rel=RTOL)
    assert unit_case(a, (tip, 6), P)[0] == pytest.approx(P * L / (E * I1), rel=RTOL)
    assert unit_case(a, (tip, 1), P)[0] == pytest.approx(P * L / (E * A), rel=RTOL)
    assert unit_case(a, (tip, 4), P)[0] == pytest.approx(P * L / (G_MOD * J), rel=RTOL)


@pytest.mark.parametrize("direction", [(0, 0, 1), (1, 1, 0), (1, -2, 3)])
def test_cantilever_any_direction(direction):
    """Same textbook tip deflection for a bar in any direction: the load normal to the bar in
    plane 1 (which contains the orientation vector) sees I1; the transformation must be exact."""
    L, P = 2.0, 1.0e3
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    v = np.cross(d, [0.3, 0.5, 0.7])
    f = cantilever(direction, v=tuple(v))
    a = adapter_of(f)
    y = np.cross(np.cross(d, v), d)
    y /= np.linalg.norm(y)
    loads = LoadMatrix.from_dense([(5, 1), (5, 2), (5, 3)], (P * y)[:, None], ["c"])
    u = a.solve(loads, [(5, 1), (5, 2), (5, 3)]).values[:, 0]
    assert u @ y == pytest.approx(P * L**3 / (3 * E * I1), rel=RTOL)
    assert np.linalg.norm(u - (u @ y) * y) < 1e-9 * abs(u @ y)


def test_portal_frame_sway_slope_deflection():
    """Fixed-base portal, lateral load H at beam level. Slope-deflection (Hibbeler, Structural
    Analysis, ch. 11) with symmetric joint rotations: a = 2EIc/h, b = 2EIb/L,
    psi = H h / (6 a (2 - 3a/(2a+3b))), sway = psi h. Axial strain made negligible (A huge),
    which the slope-deflection method assumes; 1e-6 covers the remaining axial effect."""
    h, L, H, Ic, Ib = 3.0, 5.0, 1.0e4, 2.0e-5, 5.0e-5
    f = FrameBuilder(E=E, G=G_MOD, A=1.0e3, I1=Ic, I2=Ic, J=J)
    f.grid(1, (0, 0, 0)); f.grid(2, (0, 0, h)); f.grid(3, (L, 0, h)); f.grid(4, (L, 0, 0))
    f.bar(1, 2, v=(1, 0, 0)); f.bar(4, 3, v=(1, 0, 0))
    f.fix(1); f.fix(4)
    beam = FrameBuilder(E=E, G=G_MOD, A=1.0e3, I1=Ib, I2=Ib, J=J)
    text = f.bdf().replace("ENDDATA\n", "")
    text += f"PBAR,2,1,1000.0,{Ib!r},{Ib!r},{J!r}\nCBAR,3,2,2,3,0.0,0.0,1.0\nENDDATA\n"
    del beam
    a = ReferenceAdapter(read_deck_text(text))
    # plane 1 of the columns (v = x) is the x-z frame plane: I1 = Ic; the beam's v = z: I1 = Ib
    sway = unit_case(a, (2, 1), H)[0]
    aa, bb = 2 * E * Ic / h, 2 * E * Ib / L
    psi = H * h / (6 * aa * (2 - 3 * aa / (2 * aa + 3 * bb)))
    assert sway == pytest.approx(psi * h, rel=1e-6)


def test_space_frame_with_torsion_l_shaped_cantilever():
    """L-shaped cantilever in the horizontal plane, vertical tip load P (Roark's Formulas, the
    classic bent-cantilever case): delta = P b^3/3EI + P a^3/3EI + P b^2 a/GJ, member 1 twisted
    by P b."""
    a_len, b_len, P = 1.5, 1.0, 500.0
    f = FrameBuilder(E=E, G=G_MOD, A=A, I1=I2, I2=I2, J=J)
    f.grid(1, (0, 0, 0)); f.grid(2, (a_len, 0, 0)); f.grid(3, (a_len, b_len, 0))
    f.bar(1, 2, v=(0, 0, 1)); f.bar(2, 3, v=(0, 0, 1))
    f.fix(1)
    a = adapter_of(f)
    # vertical load bends in the plane normal to v=z: local y is horizontal -> plane 2 (I2)
    delta = unit_case(a, (3, 3), P)[0]
    expect = P * b_len**3 / (3 * E * I2) + P * a_len**3 / (3 * E * I2) + P * b_len**2 * a_len / (G_MOD * J)
    assert delta == pytest.approx(expect, rel=RTOL)


def test_equilibrium_reactions_balance_loads():
    """Sum of reactions + loads = 0 in force and moment (statics), on a generated body."""
    f = tube_body(6, 8)
    a = adapter_of(f)
    rng = np.random.default_rng(3)
    dofs = [(g, c) for g in rng.choice(sorted(f.grids), 5, replace=False) for c in (1, 2, 3, 4, 5, 6)]
    vals = rng.standard_normal((len(dofs), 1)) * 100
    loads = LoadMatrix.from_dense(dofs, vals, ["c"])
    u = a.solve(loads, a.dofs()).values[:, 0]
    m = a.model
    F = np.zeros(len(a.dofs()))
    F[m.g_index(dofs)] = vals[:, 0]
    R = m.K_gg @ u - F               # reactions at constrained DOFs, zero elsewhere (to round-off)
    total = np.zeros(6)
    xyz = a.grid_xyz()
    for i, (g, c) in enumerate(a.dofs()):
        v = F[i] + R[i]
        e = np.zeros(3); e[(c - 1) % 3] = v
        if c <= 3:
            total[:3] += e
            total[3:] += np.cross(xyz[g], e)
        else:
            total[3:] += e
    scale = np.abs(vals).sum() * 5
    assert np.max(np.abs(total)) < 1e-8 * scale


def test_maxwell_betti_and_superposition():
    f = star_joint_frame(4, seed=2)
    a = adapter_of(f)
    rng = np.random.default_rng(0)
    labels = list(a.dofs())
    dofs = [labels[i] for i in rng.choice(len(labels), 10, replace=False)]
    dofs = [d for d in dofs if d[0] < 200]        # base grids are clamped
    Gm = a.solve(LoadMatrix.unit(dofs), dofs).values
    assert np.max(np.abs(Gm - Gm.T)) <= 1e-12 * np.max(np.abs(Gm))
    F = rng.standard_normal((len(dofs), 2))
    both = a.solve(LoadMatrix.from_dense(dofs, F, ["a", "b"]), dofs).values
    summed = a.solve(LoadMatrix.from_dense(dofs, F.sum(1, keepdims=True), ["s"]), dofs).values
    assert np.allclose(both.sum(1, keepdims=True), summed, rtol=1e-10, atol=1e-14 * np.abs(summed).max())
    assert np.allclose(Gm @ F, both, rtol=1e-9, atol=1e-12 * np.abs(both).max())


def test_rigid_body_invariance_free_free_with_springs():
    """A free-free structure with RBE2 ties and a coupled joint (a complex-model spring network,
    cross-component and negative springs included) strains nothing under the six rigid-body
    motions: K_gg r = 0 for u = t + w x X, theta = w."""
    f = star_joint_frame(3, seed=5)
    f.spcs.clear()
    name, g = f.joints[0]
    joint = ComplexJoint(name, g)
    rng = np.random.default_rng(1)
    Q = rng.standard_normal((6, 6))
    f.springs += [(s.a[0], s.a[1], s.b[0], s.b[1], s.k)
                  for s in spring_network(joint, joint.params_from_kc(Q @ Q.T * 1e4))]
    assert any(s[1] != s[3] for s in f.springs) and any(s[4] < 0 for s in f.springs)
    a = adapter_of(f)
    m = a.model
    xyz = a.grid_xyz()
    Kg = m.K_gg
    scale = abs(Kg).max()
    for mode in range(6):
        r = np.zeros(Kg.shape[0])
        for i, (gid, c) in enumerate(m.g_labels):
            X = np.asarray(xyz[gid])
            if mode < 3:
                r[i] = 1.0 if c == mode + 1 else 0.0
            else:
                w = np.zeros(3); w[mode - 3] = 1.0
                r[i] = np.cross(w, X)[c - 1] if c <= 3 else w[c - 4]
        assert np.max(np.abs(Kg @ r)) < 1e-9 * scale
    with pytest.raises(UnstableStructureError) as err:
        a.solve(LoadMatrix.unit([(1, 1)]), [(1, 1)])
    assert len(err.value.dofs) > 0


def test_rbe2_and_celas2_relative_rotation_is_moment_over_k():
    """Two coincident grids tied by RBE2 CM=123, rotational CELAS2 springs between them:
    a moment M on the free grid rotates it by exactly M / k relative to the clamped one."""
    f = FrameBuilder()
    f.grid(1, (0, 0, 0)); f.grid(2, (0, 0, 0)); f.grid(3, (1, 0, 0))
    f.bar(3, 1)            # something on grid 1 so the deck is a frame; 3 is clamped below
    f.fix(1); f.fix(3)
    f.rbe2.append((900, 1, (2,), "123"))
    k = {4: 2.0e4, 5: 3.0e4, 6: 5.0e4}
    f.springs += [(1, c, 2, c, k[c]) for c in (4, 5, 6)]
    a = adapter_of(f)
    for c in (4, 5, 6):
        assert unit_case(a, (2, c), 7.0)[0] == pytest.approx(7.0 / k[c], rel=1e-12)
    assert unit_case(a, (2, 1), 7.0)[0] == 0.0        # tied in translation to a clamped grid


def test_rbe2_offset_is_a_rigid_link():
    """A force at the dependent grid of an RBE2 CM=123456 with offset r equals the force plus
    the moment r x F at the independent grid (rigid-body statics)."""
    f = cantilever((1, 0, 0), v=(0, 1, 0))
    f.grid(50, (2.0, 0.3, -0.4))
    f.rbe2.append((900, 5, (50,), "123456"))
    a = adapter_of(f)
    F = np.array([10.0, -20.0, 30.0])
    r = np.array([0.0, 0.3, -0.4])
    u1 = a.solve(LoadMatrix.from_dense([(50, 1), (50, 2), (50, 3)], F[:, None], ["c"]), a.dofs()).values
    M = np.cross(r, F)
    u2 = a.solve(LoadMatrix.from_dense([(5, c) for c in range(1, 7)], np.r_[F, M][:, None], ["c"]),
                 a.dofs()).values
    assert np.allclose(u1, u2, rtol=1e-10, atol=1e-12 * np.abs(u2).max())


def test_with_springs_matches_deck_springs():
    """Springs passed through the protocol equal CELAS2 cards written into the deck."""
    f = cube()
    g = f.joints[0][1]
    springs = [ScalarSpring((g[0], 4), (g[1], 4), 1e4), ScalarSpring((g[1], 6), (g[2], 5), -2e2),
               ScalarSpring((g[2], 6), None, 5e3)]
    a = adapter_of(f).with_springs(springs)
    f.springs += [(s.a[0], s.a[1], s.b[0] if s.b else 0, s.b[1] if s.b else 0, s.k) for s in springs]
    b = adapter_of(f)
    loads = LoadMatrix.from_dense([(5, 6), (6, 6), (8, 6)], np.full((3, 1), 0.5), ["L1"])
    assert np.allclose(a.solve(loads, a.dofs()).values, b.solve(loads, b.dofs()).values, rtol=1e-12, atol=0)


def test_one_factorization_for_many_right_hand_sides():
    a = adapter_of(tube_body(8, 8))
    dofs = [d for d in a.dofs() if d[0] < 20]
    a.solve(LoadMatrix.unit(dofs), dofs)
    a.solve(LoadMatrix.unit(dofs[:3]), dofs)
    assert a.stats.factorizations == 1
    assert a.stats.runs == 2
    assert a.stats.right_hand_sides == len(dofs) + 3


def test_errors_name_what_is_wrong():
    f = cantilever((1, 0, 0), v=(0, 1, 0))
    a = adapter_of(f)
    with pytest.raises(UnknownDofError, match=r"\(99,1\)"):
        a.solve(LoadMatrix.unit([(99, 1)]), [(1, 1)])
    f.spcs.clear()
    f.fix(1, "12345")                  # rotation about z left free: the bar spins in x-y
    with pytest.raises(UnstableStructureError) as err:
        adapter_of(f).solve(LoadMatrix.unit([(5, 1)]), [(5, 1)])
    assert (1, 6) in err.value.dofs or (5, 2) in err.value.dofs
    f.fix(1)
    f.grid(77, (9, 9, 9))              # a grid nothing connects
    # NASTRAN's default AUTOSPC constrains it (a grid-point singularity), and lists it ...
    a = adapter_of(f)
    a.solve(LoadMatrix.unit([(5, 1)]), [(5, 1)])
    assert a.autospc_dofs == [(77, c) for c in range(1, 7)]
    # ... and with PARAM,AUTOSPC,NO it is an error that names it
    with pytest.raises(UnstableStructureError, match="77:T1"):
        ReferenceAdapter(read_deck_text(f.bdf().replace("ENDDATA", "PARAM,AUTOSPC,NO\nENDDATA"))).solve(
            LoadMatrix.unit([(5, 1)]), [(5, 1)])
    g = cantilever((1, 0, 0), v=(1, 0, 0))
    with pytest.raises(ModelError, match="parallel"):
        adapter_of(g).solve(LoadMatrix.unit([(5, 1)]), [(5, 1)])
