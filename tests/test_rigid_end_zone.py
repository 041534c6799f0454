"""Rigid end zones at a joint (``rigid_end_zone``) and the shell-modelled joints they are found on.

References and tolerances:

* the member with a zone against the reference solver's own CBAR with an offset ``WA = e ex``
  (or ``WB = -e ex``) of the same length: both ``K`` come from element runs, whose cantilever
  flexibilities are inverted (``cond(F_bb)`` up to ~1e6), so they agree to ~1e-16 x 1e6; 1e-10
  of the largest entry leaves margin and is still ~1e5 below any modelling difference (a zone
  1 mm longer changes ``K`` by ~1e-2);
* the Jacobian against central differences (``h = 1e-6`` of the parameter's scale: truncation
  ~1e-12, rounding ~1e-10 of the column; 1e-5 leaves margin, as ``tests/test_diagnose.py``); the
  score column (reciprocity, no run of the members' own columns) against the augmented model's
  Jacobian at ``e = 0``: the same quantity two ways, 1e-10;
* the shell box against beam theory: 0.2 % (the issue's requirement); what is left at the
  fixtures' mesh (6 quads across a wall) and L/b = 40 is the end sections' RBE2 (rigid rings)
  and the mesh, 0.08-0.18 % (``fixtures/undeclared/shell_thick/README.md``);
* the thick-walled joint found: the rigid zone is the first effect added and the verdict
  "explained" (reduced chi2 in its 99 % band); its length within 20 mm of half the members'
  depth (50 mm, the engineering rule; measured 39.7 mm).
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from blackbox import diagnosis as dg
from blackbox.commands import diagnose as diagnose_command
from blackbox.diagnosis.effects import RigidEndZone
from blackbox.diagnosis.effects.rigid_end_zone import beam_polynomial, zone_stiffness
from blackbox.diagnosis.runs import element_stiffness
from solver_adapters.bdf import read_deck_text
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran

ROOT = Path(__file__).resolve().parents[1]
UNDECLARED = ROOT / "fixtures" / "undeclared"


def _shells():
    """``fixtures/undeclared/generate_shells.py`` as a module (the mesh and the beam check)."""
    if "generate_shells" not in sys.modules:
        spec = importlib.util.spec_from_file_location("generate_shells", UNDECLARED / "generate_shells.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod            # dataclasses look their module up there
        spec.loader.exec_module(mod)
    return sys.modules["generate_shells"]


# --------------------------------------------------------------------------------------------
# the member with a rigid zone
# --------------------------------------------------------------------------------------------
PBARS = ("PBAR,1,1,4.-3,6.7-6,3.1-6,5.-6",                       # Euler-Bernoulli, I1 != I2
         "PBAR,2,1,4.-3,6.7-6,3.1-6,5.-6,,,\n,,,,,,,,\n,.4167,.35",  # Timoshenko, K1 != K2
         "PBAR,3,1,4.-3,6.7-6,3.1-6,5.-6,,,\n,,,,,,,,\n,,,1.2-6")     # a product of inertia I12


def _members_deck(members) -> tuple[str, dict]:
    """One CBAR per ``(xa, xb, v, pid, wa, wb)``, each on its own two grids, end a clamped."""
    lines = ["BEGIN BULK", "MAT1,1,2.1+11,8.1+10,", *PBARS]
    ends = {}
    for k, (xa, xb, v, pid, wa, wb) in enumerate(members):
        ga, gb = 2 * k + 1, 2 * k + 2
        lines += [f"GRID,{ga},,{xa[0]!r},{xa[1]!r},{xa[2]!r}", f"GRID,{gb},,{xb[0]!r},{xb[1]!r},{xb[2]!r}"]
        f = [k + 1, pid, ga, gb, *map(repr, v), "", "", "",
             *(map(repr, wa) if wa is not None else ["", "", ""]), *(map(repr, wb) if wb is not None else ["", "", ""])]
        f = [str(x) for x in f]
        lines.append(",".join(["CBAR"] + f[:8]) + "\n," + ",".join(f[8:]))
        ends[k + 1] = (ga, gb)
    lines += ["SPC1,1,123456," + ",".join(str(a) for a, _ in ends.values()), "ENDDATA"]
    return "\n".join(lines) + "\n", ends


def _element_K(members) -> dict:
    text, ends = _members_deck(members)
    K, _ = element_stiffness(ReferenceAdapter(read_deck_text(text)), ends, [])
    return K


@pytest.mark.parametrize("end", [0, 1])
def test_zone_is_the_cbar_with_an_offset(end):
    """A member's stiffness with a rigid zone of length e at one end, built from its plain
    black-box ``K_e``, is the reference solver's CBAR with the offset WA = e ex (end a) or
    WB = -e ex (end b): Euler-Bernoulli, Timoshenko (K1, K2) and coupled planes (I12), members
    in random directions and orientations."""
    rng = np.random.default_rng(1)
    plain, offset, lengths = [], [], []
    for k in range(6):
        xa = rng.normal(size=3)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        L = float(rng.uniform(0.3, 1.5))
        e = float(rng.uniform(0.05, 0.4)) * L
        xb = xa + L * d
        v = rng.normal(size=3).tolist()
        pid = 1 + k % 3
        plain.append((xa.tolist(), xb.tolist(), v, pid, None, None))
        w = (e * d).tolist()
        offset.append((xa.tolist(), xb.tolist(), v, pid, w if end == 0 else None,
                       [-x for x in w] if end == 1 else None))
        lengths.append(e)
    K0, K1 = _element_K(plain), _element_K(offset)
    for eid, e in zip(K0, lengths):
        K = zone_stiffness(K0[eid], e, end)
        assert np.max(np.abs(K - K1[eid])) <= 1e-10 * np.max(np.abs(K1[eid])), eid
        assert np.max(np.abs(K0[eid] - K1[eid])) > 1e-3 * np.max(np.abs(K1[eid]))     # the zone matters
        assert np.max(np.abs(zone_stiffness(K0[eid], 0.0, end) - K0[eid])) == 0.0        # nested exactly


def test_members_that_are_no_prismatic_beam_have_no_zone():
    """A member with a sideways offset (5 % of its length) is no prismatic beam between its grids:
    ``beam_polynomial`` says so, and a zone on it is an error."""
    xa, xb, v = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]
    K = _element_K([(xa, xb, v, 1, None, None), (xa, xb, v, 1, [0.0, 0.05, 0.0], None)])
    assert beam_polynomial(K[1])[0] is not None
    poly, why = beam_polynomial(K[2])
    assert poly is None and "no prismatic beam" in why
    with pytest.raises(ValueError, match="no prismatic beam"):
        zone_stiffness(K[2], 0.1)


# --------------------------------------------------------------------------------------------
# in the augmented model
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cube_prepared(tmp_path_factory):
    return diagnose_command.prepare(UNDECLARED / "support_flexibility", tmp_path_factory.mktemp("prep"))


def _model(pr, spec):
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    return (dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, o),
            dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)}))


def test_candidates_at_the_joint_and_where_members_meet(cube_prepared):
    """The cube's declared joint J7 (its three branch members) and every grid where members
    meet that could be an undeclared joint (not the clamped grid 1) are candidates, at the
    simplest variant, bounded by half the shortest member (0.1 m of the 0.2 m edges)."""
    zones = {e.where: e for e in cube_prepared.candidates if isinstance(e, RigidEndZone)}
    assert set(zones) == {("J7",), (2,), (3,), (4,), (5,), (6,), (8,)}
    j7 = zones[("J7",)]
    assert (j7.variant, j7.names, len(j7.members), j7.grid) == ("common", ("e_J7",), 3, 7)
    assert j7.bounds[1][0] == pytest.approx(0.1) and j7.one_sided.all() and j7.nominal[0] == 0.0


def test_score_column_and_jacobian(cube_prepared):
    """The score column at e = 0 (reciprocity, rows of the split run) is the augmented model's
    Jacobian column there; away from the nested point, with the per-member variant and a second
    zone, the Jacobian matches central differences (module docstring)."""
    pr = cube_prepared
    zones = [e for e in pr.candidates if isinstance(e, RigidEndZone)]
    j7, g4 = zones[0], next(e for e in zones if e.where == (4,))
    pr.base.ensure_columns(j7.dofs + g4.dofs, "test")
    spec, x = dg.ModelSpec(tuple(pr.joints)), pr.joints[0].initial_params(2.0e4)
    model, om = _model(pr, spec)
    cols = RigidEndZone.batch_columns(model, model.state(x), x, om, [j7, g4])
    for e, col in zip((j7, g4), cols.T):
        s2, x2 = spec.add(e, x)
        J = _model(pr, s2)[0].jacobian(x2, om)[:, -1]
        assert np.max(np.abs(J - col)) <= 1e-10 * np.max(np.abs(J)), e.label()
    per_member = j7.richer(np.array([0.03]))[0][0]
    assert per_member.variant == "per-member" and per_member.n_params == 3
    spec, x = spec.add(per_member, x)
    spec, x = spec.add(g4, x)
    x[-4:] = [0.02, 0.035, 0.05, 0.03]
    model, om = _model(pr, spec)
    J = model.jacobian(x, om)
    pj = spec.joint_params
    for i in range(len(x)):
        h = 1e-6 * (np.max(np.abs(x[:pj])) if i < pj else 0.05)
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        fd = (model.predict(xp, om) - model.predict(xm, om)) / (2 * h)
        assert np.max(np.abs(J[:, i] - fd)) <= 1e-5 * np.max(np.abs(fd)), spec.names[i]


def test_nested_and_variants_nested(cube_prepared):
    """At e = 0 the model predicts the declared model's values (dK is exactly 0 there; the larger
    block system rounds differently, 1e-12); the per-member variant
    at every length equal to the common one predicts what the common one does; a second zone
    on a member that already has one (grid 3's members include J7's member to grid 3) is not
    offered."""
    pr = cube_prepared
    zones = {e.where: e for e in pr.candidates if isinstance(e, RigidEndZone)}
    j7 = zones[("J7",)]
    pr.base.ensure_columns(j7.dofs, "test")
    spec0, x0 = dg.ModelSpec(tuple(pr.joints)), pr.joints[0].initial_params(2.0e4)
    f0 = _model(pr, spec0)[0].predict(x0, _model(pr, spec0)[1])
    spec, x = spec0.add(j7, x0)
    model, om = _model(pr, spec)
    assert np.max(np.abs(model.predict(x, om) - f0)) <= 1e-12 * np.max(np.abs(f0))
    x[-1] = 0.04
    f_common = model.predict(x, om)
    rich, x_rich = j7.richer(x[-1:])[0]
    spec_r = spec.replace_effect(0, rich)
    f_rich = _model(pr, spec_r)[0].predict(np.concatenate([x[:-1], x_rich]), om)
    assert np.max(np.abs(f_rich - f_common)) <= 1e-12 * np.max(np.abs(f_common))
    shared = next(e for w, e in zones.items() if w != ("J7",) and {m.eid for m in e.members} & {m.eid for m in j7.members})
    assert not shared.applicable(spec) and zones[("J7",)].applicable(spec0)


def test_zone_in_the_grids_displacement_systems(tmp_path, monkeypatch):
    """On ``tests/rich_deck.py`` (grid 14 in a cylindrical CD system, measurements in the grids'
    CD components): a zone of 0.2 m at grid 14 predicts the reference solver's deck in which each
    of its four members has the offset of that length at grid 14 (``WA = e ex`` or ``WB = -e ex``,
    in basic), to 1e-8 of the largest response (as the member factor of
    ``tests/test_edited_decks.py``: ``K_e`` from flexibilities inverted at cond ~1e6). Members
    with offsets or pin flags on their card (grid 15's CBEAM is prismatic; 108 has offsets, 116 a
    pin flag) take no zone."""
    import dataclasses

    from blackbox.structures import TruthDeck
    from rich_deck import write_rich_study

    monkeypatch.chdir(tmp_path)
    pr = diagnose_command.prepare(write_rich_study(tmp_path / "rich"), tmp_path)
    zones = {e.where: e for e in pr.candidates if isinstance(e, RigidEndZone)}
    assert all(m.eid not in (108, 116) for z in zones.values() for m in z.members)
    zone = zones[(14,)]
    assert all(m.frame is not None for m in zone.members)        # every member has a CD'd grid
    pr.base.ensure_columns(zone.refit_columns(), "test")
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(zone, pr.ident.k)
    e = 0.2
    x[-1] = e
    rows = list(dict.fromkeys(pr.study.measurements.all_dofs))
    model = dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, rows)
    om = dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(rows)})
    f = model.predict(x, om)
    truth = TruthDeck(pr.deck)
    for m in zone.members:
        b = truth.deck.cbars[m.eid]
        ex = np.subtract(truth.deck.grids[b.gb].xyz, truth.deck.grids[b.ga].xyz)
        ex = ex / np.linalg.norm(ex)
        w = tuple(float(v) for v in (e * ex if m.zone_end == 0 else -e * ex))
        truth.deck.cbars[m.eid] = dataclasses.replace(b, **({"wa": w} if m.zone_end == 0 else {"wb": w}))
    for j, sl in zip(pr.joints, dg.ModelSpec(tuple(pr.joints)).joint_slices()):
        truth.joint(j.name, j.grids, "simple", pr.ident.k[sl])
    f_true = om.pick(ReferenceAdapter(truth.deck).solve(pr.study.loads, rows).values)
    assert np.max(np.abs(f - f_true)) < 1e-8 * np.max(np.abs(f_true))
    f0 = dg.AugmentedModel(pr.base, dg.ModelSpec(tuple(pr.joints)), pr.boundary, pr.K_deck, rows).predict(
        pr.ident.k, om)
    assert np.max(np.abs(f0 - f_true)) > 1e-3 * np.max(np.abs(f_true))      # the zone matters


# --------------------------------------------------------------------------------------------
# the shell-modelled joints
# --------------------------------------------------------------------------------------------
@needs_mystran
@pytest.mark.parametrize("t", [0.002, 0.010])
def test_shell_box_against_beam_theory(t, tmp_path):
    """The fixtures' shell box (6 quads across a wall), a 4 m cantilever through MYSTRAN, against
    Timoshenko beam theory of its midline section: axial, bending with shear, the bending
    coupling, pure bending and torsion (Bredt plus the walls' own twisting) within 0.2 %; for
    the thick wall Bredt's J alone is 1.3 % off (the walls' t^3 term matters)."""
    shells = _shells()
    check = shells.beam_check(shells.BoxSection(0.1, t), workdir=tmp_path)
    for k in shells.CHECKS:
        assert abs(check[k]) < 2e-3, (k, check[k])
    if t == 0.010:
        assert check["bredt_only"] < -0.01


@pytest.mark.slow
def test_thick_walled_joint_has_rigid_end_zones():
    """The thick-walled joint (a node of 40 mm plates) is stiffer than the frame model's rigid
    joint: declared, the reduced chi2 is about 3 (springs at their rigid limit); diagnose adds
    the rigid end zone at the joint first and ends "explained", the hold-out predicted better;
    the zone's length is near half the members' depth (module docstring)."""
    doc = diagnose_command.run(UNDECLARED / "shell_thick", plots=False).document
    planted = json.loads((UNDECLARED / "shell_thick" / "construction.json").read_text())
    first = doc["added"][0]
    assert (first["effect"], first["where"]) == ("rigid_end_zone", ["JC"])
    assert doc["verdict"] == "explained" and doc["after"]["in_band"]
    assert doc["before"]["reduced_chi2"] > 2.0
    # identify's springs run to 1e14-1e21, where its predictions are rounding: the split deck's
    # nesting is checked with the springs at 100 x the structure's stiffness instead (reference
    # solver: double precision, 1e-3 sigma leaves margin over the 8e-6 measured at the limit)
    assert any("beyond their rigid limit" in w for w in doc["warnings"])
    assert doc["identify_check"]["nesting_error_sigma"] < 1e-3
    assert doc["after"]["holdout_rms"] < doc["before"]["holdout_rms"]
    e = first["parameters"][0]["value"]
    assert abs(e - planted["effects"][0]["half_depth"]["midline"]) < 0.02
    assert all(a["effect"] != "rigid_end_zone" or a["where"] == ["JC"] for a in doc["added"])


@pytest.mark.slow
def test_thin_walled_joint_is_not_taken_for_a_stiff_one():
    """The thin-walled corner (2 mm walls, no diaphragm) is flexible and its walls distort: the
    first effect the diagnosis adds is the coupled joint, not a rigid zone, whose evidence at the
    joint is far weaker (the later rounds, where rigid zones patch a fit still at several times
    the noise, are in the folder's README)."""
    doc = diagnose_command.run(UNDECLARED / "shell_thin", max_steps=1, plots=False).document
    assert doc["before"]["reduced_chi2"] > 3.0
    (first,) = doc["added"]
    assert (first["effect"], first["where"]) == ("joint_coupling", ["JC"])
    zone = next(c for c in doc["steps"][0]["candidates"] if c["effect"] == "rigid_end_zone" and c["where"] == ["JC"])
    coupling = next(c for c in doc["steps"][0]["candidates"] if c["effect"] == "joint_coupling")
    assert zone["delta_bic"] > 0.5 * coupling["delta_bic"]
