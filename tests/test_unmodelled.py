"""Decks with elements the reference solver does not model (shells, solids): external adapters run
them, every command works on such a study, the reference adapter refuses it with the reader's
message naming every unsupported card.

The structure of the MYSTRAN tests is a car body frame (floor rails and cross members, A-, B- and
C-pillars, roof rails) with a floor panel of eight CQUAD4 shells (PSHELL, aluminium) and a
flexible joint at the top of the left B-pillar (branches: pillar, front roof rail, rear roof
rail). Two floor grids carry shells only: their drilling rotation has no stiffness, which
AUTOSPC (NASTRAN's SOL 101 default, and MYSTRAN's) constrains.

References and tolerances:

* truth recovery. The measurements are simulated by MYSTRAN on a *truth deck*: the study's deck
  with the joint's springs written into it by hand as CELAS2 between the branch grids' rotations
  (kx12 about x between branches 1 and 2, ...), so MYSTRAN solves the whole structure; the
  identification goes through the black-box condensation of the study's deck by MYSTRAN (one
  run). The noise is 1e-5 relative (so MYSTRAN's 7 printed digits, 5e-7, stay below it): every
  estimate must be within 4 of its standard errors of the truth and within 1e-4 relative (the
  standard errors are ~1e-5 relative here; a missing floor panel gives estimates off by factors,
  measured below). Measured: at most 5.7e-6 relative, 0.76 standard errors.
* pass-through. MYSTRAN on the adapter's run deck (every card re-written in large field) against
  MYSTRAN on the user's bulk data copied verbatim: RTOL_F06 = 1e-6 of each case's largest
  displacement, as in ``tests/test_mystran_decks.py`` (7 printed digits, rounding in the last).
* round trips through our own reader and writer are exact (reals printed with the digits that read
  back) or, for reals the reader computed, within 1e-11 (16-character fields).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from blackbox.cli import main
from blackbox.diagnosis.decks import unmodelled_notes, unsplittable_grids
from blackbox.diagnosis.effects.undeclared_joint import joint_candidate_grids
from blackbox.study import load_study
from solver_adapters.bdf import read_deck, read_deck_text
from solver_adapters.bdf_write import write_deck
from solver_adapters.protocol import DeckFormatError, LoadMatrix, ModelError
from solver_adapters.reference import ReferenceAdapter

from conftest import needs_mystran

DATA = Path(__file__).parent / "data"
RTOL_F06 = 1e-6
pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


# --------------------------------------------------------------------------------------------
# the car body with its floor panel, and a post on an elastic block
# --------------------------------------------------------------------------------------------
CAR_TRUTH = {"kx12": 2.0e4, "ky12": 3.0e4, "kz12": 1.5e4, "kx13": 2.5e4, "ky13": 2.0e4, "kz13": 4.0e4,
             "kx23": 1.0e4, "ky23": 3.5e4, "kz23": 2.2e4}
"""The joint's true simple-model springs, N*m/rad: of the order of the members' own rotational
stiffness at the joint (4 E I / L = 1.7e5 for the 1 m rails), so that every one shows."""
JOINT = (18, 100, 101)          # the B-pillar top (branch 1: the pillar), front rail's end, rear rail's start
PANEL_ONLY = (5, 11)            # floor grids that only the shells reach
FLOOR_JOINTS = {2, 4, 6, 7, 8, 9, 10, 12, 14}   # floor grids where bars meet, under the panel, not supported


def car_body_deck(shells: bool = True) -> str:
    """The car body's bulk data: floor grids 1-15 on a 5 x 3 raster (x = 0, 0.5, ..., 2; y = 0,
    0.5, 1), roof grids 16-21 at z = 0.8 above x = 0, 1, 2 and y = 0, 1, the joint's branch grids
    100, 101 at grid 18, supported at the four floor corners (translations); the floor panel's
    CQUAD4 1001-1008 with ``shells``."""
    L = ["$ car body frame with a floor panel (tests/test_unmodelled.py)", "BEGIN BULK",
         "MAT1,1,2.1+11,,.3", "PBAR,1,1,4.-4,2.-7,2.-7,3.-7"]
    L += ["MAT1,2,7.+10,,.33", "PSHELL,2,2,.002,2,,2"] if shells else ["$", "$"]   # same line numbers
    xs, ys, H = (0.0, 0.5, 1.0, 1.5, 2.0), (0.0, 0.5, 1.0), 0.8
    floor = {(i, j): 3 * i + j + 1 for i in range(5) for j in range(3)}
    roof = {(i, j): 16 + 2 * (i // 2) + j // 2 for i in (0, 2, 4) for j in (0, 2)}
    L += [f"GRID,{g},,{xs[i]!r},{ys[j]!r},0." for (i, j), g in floor.items()]
    L += [f"GRID,{g},,{xs[i]!r},{ys[j]!r},{H!r}" for (i, j), g in roof.items()]
    L += [f"GRID,{g},,1.,0.,{H!r}" for g in JOINT[1:]]
    bars = [(floor[i, j], floor[i + 1, j], "0.,0.,1.") for j in (0, 2) for i in range(4)]       # rails
    bars += [(floor[i, j], floor[i, j + 1], "0.,0.,1.") for i in (0, 2, 4) for j in (0, 1)]      # cross members
    bars += [(floor[i, j], roof[i, j], "1.,0.,0.") for i in (0, 2, 4) for j in (0, 2)]           # pillars
    bars += [(roof[0, j], roof[2, j], "0.,0.,1.") for j in (0, 2)]                               # roof rails
    bars += [(roof[2, j], roof[4, j], "0.,0.,1.") for j in (0, 2)]
    bars += [(roof[i, 0], roof[i, 2], "0.,0.,1.") for i in (0, 4)]                               # roof cross members
    joint = {(roof[0, 0], JOINT[0]): (roof[0, 0], JOINT[1]), (JOINT[0], roof[4, 0]): (JOINT[2], roof[4, 0])}
    for eid, (a, b, v) in enumerate(bars, start=1):
        a, b = joint.get((a, b), (a, b))
        L.append(f"CBAR,{eid},1,{a},{b},{v}")
    L.append(f"RBE2,900,{JOINT[0]},123,{JOINT[1]},{JOINT[2]}")
    L += [f"SPC1,1,123,{floor[i, j]}" for i in (0, 4) for j in (0, 2)]
    if shells:
        L += [f"CQUAD4,{1001 + 2 * i + j},2,{floor[i, j]},{floor[i + 1, j]},{floor[i + 1, j + 1]},{floor[i, j + 1]}"
              for i in range(4) for j in range(2)]
    return "\n".join(L + ["ENDDATA"]) + "\n"


def car_body_study(folder: Path, shells: bool = True, adapter: str = "mystran") -> Path:
    """The car body as a study folder: 12 seeded load cases of three forces or moments at roof,
    pillar and floor grids, the joint ``JB`` (simple model)."""
    folder.mkdir(parents=True)
    (folder / "model.bdf").write_text(car_body_deck(shells))
    rng = np.random.default_rng(3)
    rows = ["case,grid,component,value"]
    for c in range(12):
        for g in rng.choice([16, 17, 19, 20, 21, 8, 4], 3, replace=False):
            comp = int(rng.integers(1, 7))
            rows.append(f"L{c + 1},{g},{comp},{(1000.0 if comp <= 3 else 200.0) * rng.uniform(-1, 1)!r}")
    (folder / "loads.csv").write_text("\n".join(rows) + "\n")
    (folder / "study.toml").write_text(
        f'name = "carbody"\n\n[solver]\nadapter = "{adapter}"\ndeck = "model.bdf"\n\n[[joints]]\nname = "JB"\n'
        f'grids = [{", ".join(map(str, JOINT))}]\nmodel = "simple"\ninitial = 1.0e4\n')
    return folder


def truth_deck(study: Path, folder: Path) -> Path:
    """``truth.toml`` and ``truth.bdf``: the study's deck with the joint's springs of
    :data:`CAR_TRUTH` written by hand (CELAS2 between the branch grids' rotations about each
    axis), measured at every joint DOF with 1e-5 relative noise."""
    lines = [ln for ln in (study / "model.bdf").read_text().splitlines() if ln != "ENDDATA"]
    for eid, (name, k) in enumerate(CAR_TRUTH.items(), start=5001):
        comp, i, j = 4 + "xyz".index(name[1]), int(name[2]), int(name[3])
        lines.append(f"CELAS2,{eid},{k!r},{JOINT[i - 1]},{comp},{JOINT[j - 1]},{comp}")
    (folder / "truth.bdf").write_text("\n".join(lines + ["ENDDATA"]) + "\n")
    (folder / "truth.toml").write_text('seed = 1\ndeck = "truth.bdf"\n\n[noise]\nrelative = 1.0e-5\nfloor = 0.02\n\n'
                                       '[measure]\njoint = true\n')
    return folder / "truth.toml"


SOLID = """$ a post on an elastic block: CHEXA 9 (grids 1-8) held at its bottom face, three bars from
$ its top corners to grid 20 (a block holds translations only, so one bar alone would pivot)
GRID,1,,0.,0.,0.,,123
GRID,2,,.2,0.,0.,,123
GRID,3,,.2,.2,0.,,123
GRID,4,,0.,.2,0.,,123
GRID,5,,0.,0.,.2
GRID,6,,.2,0.,.2
GRID,7,,.2,.2,.2
GRID,8,,0.,.2,.2
GRID,20,,.1,.1,1.2
CBAR,1,7,5,20,1.,0.,0.
CBAR,2,7,6,20,0.,1.,0.
CBAR,3,7,8,20,1.,0.,0.
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3
MAT1,3,3.E9,,.35
"""
SOLID_SMALL = ("CHEXA          9       2       1       2       3       4       5       6+H1\n"
               "+H1            7       8\n"
               "PSOLID         2       3               2\n")
SOLID_LARGE = ("CHEXA*                 9               2               1               2+HX1\n"
               "*HX1                   3               4               5               6+HX2\n"
               "*HX2                   7               8\n"
               "PSOLID*                2               3                               2\n")
SOLID_LOADS = LoadMatrix.from_dense([(20, 1), (20, 2), (20, 3), (20, 6)], np.diag([100.0, 100.0, 1000.0, 10.0]),
                                    ["x", "y", "z", "mz"])
SOLID_REPORT = [(g, c) for g in (5, 6, 20) for c in range(1, 7)]


def _rel(U, R) -> float:
    return float(np.max(np.abs(U - R) / np.max(np.abs(R), axis=0)))


# --------------------------------------------------------------------------------------------
# the reader keeps what it does not model, for an external solver
# --------------------------------------------------------------------------------------------
def test_keep_reads_shells_and_solids_with_their_grids():
    """``unmodelled="keep"``: the shells, solids and their properties are kept apart with their
    fields typed as NASTRAN reads them (the CHEXA's grids 7, 8 come from its continuation, in
    either spelling) and the grids they join; the strict reader refuses the same deck."""
    for solid in (SOLID_SMALL, SOLID_LARGE):
        deck = read_deck_text(SOLID + solid, name="solid.bdf", unmodelled="keep")
        chexa, psolid = deck.unmodelled
        assert (chexa.name, chexa.fields[:10], chexa.grids) == ("CHEXA", (9, 2, 1, 2, 3, 4, 5, 6, 7, 8),
                                                                tuple(range(1, 9)))
        assert (psolid.name, psolid.fields[:4], psolid.grids) == ("PSOLID", (2, 3, None, 2), ())
        assert set(deck.unmodelled_grids()) == set(range(1, 9)) and deck.max_element_id() == 9
        assert "CHEXA x1 (first at solid.bdf:18)" in deck.summary()
    car = read_deck_text(car_body_deck(), unmodelled="keep")
    assert len(car.unmodelled) == 9 and car.unmodelled[1].fields[:6] == (1001, 2, 1, 4, 5, 2)
    assert {g for g, cards in car.unmodelled_grids().items() if cards} == set(range(1, 16))
    with pytest.raises(DeckFormatError, match="CQUAD4 x8"):
        read_deck_text(car_body_deck())


@pytest.mark.parametrize("card, why", [("FORCE,1,3,,1.,1.,0.,0.", "loads are not part of the model")])
def test_keep_still_refuses_what_cannot_be_handed_on(card, why):
    """Load sets (loads come from loads.csv) would change the model if handed on: located
    errors, also when kept."""
    text = car_body_deck().replace("ENDDATA", card + "\nENDDATA")
    with pytest.raises(DeckFormatError, match=why) as info:
        read_deck_text(text, name="car.bdf", unmodelled="keep")
    assert "cannot be handed to an external solver" in str(info.value)
    assert info.value.file == "car.bdf" and info.value.line == text.splitlines().index(card) + 1


def test_kept_elements_are_checked():
    """A kept element's grids must exist, and its EID is one of the deck's element IDs."""
    with pytest.raises(ModelError, match=r"CQUAD4 1009: grid\(s\) 99 does not exist"):
        read_deck_text(car_body_deck().replace("ENDDATA", "CQUAD4,1009,2,1,2,99,4\nENDDATA"), unmodelled="keep")
    with pytest.raises(DeckFormatError, match="duplicate element ID 3"):
        read_deck_text(car_body_deck().replace("ENDDATA", "CQUAD4,3,2,1,2,5,4\nENDDATA"), unmodelled="keep")


def test_reference_refuses_a_kept_deck_with_the_readers_message(tmp_path):
    """The reference adapter given a deck read for an external solver refuses it with exactly
    the reader's message: every unsupported card with its count and first location."""
    path = tmp_path / "car.bdf"
    path.write_text(car_body_deck())
    with pytest.raises(DeckFormatError) as strict:
        read_deck(path)
    with pytest.raises(DeckFormatError) as ref:
        ReferenceAdapter(path, parsed=read_deck(path, unmodelled="keep"))
    assert str(ref.value) == str(strict.value)
    assert (ref.value.line, ref.value.card, ref.value.field) == (6, "PSHELL", 1)
    for text in ("PSHELL x1 (first at", f"CQUAD4 x8 (first at {path}:61)", "an external adapter (mystran"):
        assert text in str(ref.value)


def _entities(deck) -> dict:
    """The deck's entities without source locations, positions rounded to 1e-11 relative."""
    out = {}
    for f in dataclasses.fields(deck):
        if f.name in ("files", "no_effect", "autospc_src"):
            continue
        v = getattr(deck, f.name)
        items = v.items() if isinstance(v, dict) else enumerate(v) if isinstance(v, list) else None
        if items is None:
            out[f.name] = v
            continue
        out[f.name] = {k: _plain(e) for k, e in items}
    return out


def _plain(x):
    if dataclasses.is_dataclass(x):
        d = {f.name: _plain(getattr(x, f.name)) for f in dataclasses.fields(x) if f.name not in ("src", "cp", "card")}
        return (type(x).__name__, tuple(sorted(d.items())))
    if isinstance(x, (tuple, list)):
        return tuple(_plain(v) for v in x)
    if isinstance(x, float):
        return float(f"{x:.11e}")
    return x


@pytest.mark.parametrize("name", ["coord_frame.bdf", "rbe3_posts.bdf", "cbush_frame.bdf", "cbar_pins_offsets.bdf",
                                  "coord_cantilever.bdf", "pbarl_angle.bdf", "autospc_truss.bdf", "car_body"])
@pytest.mark.parametrize("fmt", ["large", "free"])
def test_write_deck_writes_the_whole_model(name, fmt, tmp_path):
    """``write_deck`` (diagnose's edited decks) gives back everything the reader holds: grids
    with their CD, coordinate systems, CBAR orientation and offsets in their grids' CD, RBE3,
    CBUSH/PBUSH, the kept shells, PARAM,AUTOSPC,NO. Before, it dropped the CD systems, the
    coordinate systems, RBE3 and CBUSH: diagnose's split deck of such a study was another
    structure."""
    text = car_body_deck() if name == "car_body" else (DATA / name).read_text()
    if name == "autospc_truss.bdf":
        text += "PARAM,AUTOSPC,NO\n"
    deck = read_deck_text(text, base_dir=DATA, unmodelled="keep")
    again = read_deck_text(write_deck(deck, fmt), unmodelled="keep")
    assert _entities(again) == _entities(deck)
    if not deck.unmodelled and deck.autospc:        # the same structure for the reference solver
        ref, back = ReferenceAdapter(deck), ReferenceAdapter(again)
        dofs = [d for d in ref.dofs() if d not in set(ref.autospc_dofs)][::5]
        loads = LoadMatrix.unit(dofs)
        np.testing.assert_allclose(back.solve(loads, dofs).values, ref.solve(loads, dofs).values, rtol=1e-9,
                                   atol=1e-9 * np.abs(ref.solve(loads, dofs).values).max())


# --------------------------------------------------------------------------------------------
# the study and the adapter actually used
# --------------------------------------------------------------------------------------------
def test_the_adapter_used_decides(tmp_path, capsys):
    """A study with shells loads (no solver needed); the reference adapter, chosen in study.toml
    or by --adapter, refuses it with the located message naming every unsupported card (exit 2,
    before any work); FRAMESOLVE, whose dialect writes its decks from the modelled cards alone,
    refuses it too, saying why."""
    from blackbox.adapters import make_adapter_for
    study = car_body_study(tmp_path / "car", adapter="reference")
    s = load_study(study)
    assert [u.name for u in s.deck.unmodelled] == ["PSHELL"] + ["CQUAD4"] * 8
    with pytest.raises(DeckFormatError, match=r"(?s)CQUAD4 x8 \(first at .*model.bdf:61\).*external adapter"):
        make_adapter_for(s)
    assert main(["solve", str(study), "--out", str(tmp_path / "o"), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "PSHELL x1 (first at" in err and "CQUAD4 x8 (first at" in err and "model.bdf:6" in err
    with pytest.raises(DeckFormatError, match="'legacy' dialect writes its decks from the modelled cards alone"):
        make_adapter_for(s, "legacy")


def test_diagnosis_leaves_shell_grids_uncut_and_says_so():
    """No undeclared-joint cut at a grid where bars meet a shell (the cut would split the bars
    but not the shell); the grids are named in the diagnosis's notes, with the rule that
    member_stiffness acts on CBARs only."""
    deck = read_deck_text(car_body_deck(), unmodelled="keep")
    bare = read_deck_text(car_body_deck(shells=False))
    declared = set(JOINT)
    skipped = unsplittable_grids(deck)
    # the floor grids between the supports where rails, cross members and pillars meet the panel
    assert set(skipped) == FLOOR_JOINTS and skipped[7] == ["CQUAD4 1003", "CQUAD4 1005"]
    assert set(joint_candidate_grids(bare, declared)) - set(joint_candidate_grids(deck, declared)) == FLOOR_JOINTS
    notes = unmodelled_notes(deck)
    assert "member_stiffness candidates are the CBAR and rod members only" in notes[0]
    assert ("undeclared_joint: 9 grid(s) where bars meet CQUAD4 elements are not candidates "
            "(2, 4, 6, 7, 8, 9, 10, 12, 14)") in notes[1]
    assert unmodelled_notes(bare) == []


# --------------------------------------------------------------------------------------------
# through MYSTRAN
# --------------------------------------------------------------------------------------------
@needs_mystran
def test_car_body_identified_through_mystran(tmp_path, capsys):
    """Simulate through MYSTRAN on the truth deck, identify through MYSTRAN: the joint's nine
    springs come back (module docstring for the tolerances). Without the floor panel in the
    study's deck the same measurements cannot be fitted at all: the shells reach MYSTRAN."""
    study = car_body_study(tmp_path / "car")
    sim = tmp_path / "sim"
    assert main(["simulate", str(study), "--truth", str(truth_deck(study, tmp_path)), "--out", str(sim)]) == 0
    assert main(["identify", str(sim), "--out", str(tmp_path / "id"), "--no-cache"]) == 0
    res = json.loads((tmp_path / "id" / "result.json").read_text())
    assert res["solver"]["runs"] == 1 and 0.5 < res["fit"]["reduced_chi2"] < 1.5
    for p in res["parameters"]:
        truth = CAR_TRUTH[p["name"]]
        assert abs(p["value"] - truth) <= 4 * p["std"], p
        assert abs(p["value"] - truth) <= 1e-4 * truth, p
    # --adapter reference on the same study: refused before any work, every card named
    assert main(["identify", str(sim), "--adapter", "reference", "--out", str(tmp_path / "r")]) == 2
    assert "CQUAD4 x8" in capsys.readouterr().err
    # the floor panel matters: the bare frame cannot explain the measurements
    (sim / "model.bdf").write_text(car_body_deck(shells=False))
    main(["identify", str(sim), "--out", str(tmp_path / "bare"), "--no-cache"])
    assert json.loads((tmp_path / "bare" / "result.json").read_text())["fit"]["reduced_chi2"] > 1e3


@needs_mystran
def test_car_body_every_command_through_mystran(tmp_path):
    """compare, diagnose, design, batch, solve and conformance --study run on the shell study
    through MYSTRAN (exit 0). Diagnose keeps the CQUAD4 in its split deck, cuts no grid that
    carries one and says so; the study's adapter may also be a command running MYSTRAN with the
    nastran dialect (the same displacements)."""
    from solver_adapters.nastran import mystran_binary
    study = car_body_study(tmp_path / "car")
    sim = tmp_path / "sim"
    assert main(["simulate", str(study), "--truth", str(truth_deck(study, tmp_path)), "--out", str(sim)]) == 0
    # the truth deck lies beside the simulated study: its folder is allowed for the MDSE re-simulation
    assert main(["compare", str(sim), "--out", str(tmp_path / "cmp"), "--no-cache",
                 "--allow-outside", str(tmp_path)]) == 0
    assert json.loads((tmp_path / "cmp" / "comparison.json").read_text())["with_mdse"]["available"]
    assert main(["diagnose", str(sim), "--out", str(tmp_path / "dg"), "--no-cache"]) == 0
    doc = json.loads((tmp_path / "dg" / "diagnosis.json").read_text())
    assert doc["verdict"] == "adequate" and any("(2, 4, 6, 7, 8, 9, 10, 12, 14)" in n for n in doc["notes"])
    split = (tmp_path / "dg" / "decks" / "split.bdf").read_text()
    assert split.count("CQUAD4*") == 8 and split.count("PSHELL*") == 1
    assert "## Notes" in (tmp_path / "dg" / "report.md").read_text()
    cands = tmp_path / "cands.csv"
    cands.write_text("kind,grid,component,value,sigma\n" + "".join(f"load,{g},{c},1000.,\n" for g, c in
                     ((4, 3), (7, 2), (16, 1), (17, 3), (19, 2), (5, 3)))
                     + "".join(f"sensor,{g},{c},,\n" for g in JOINT for c in (4, 5, 6)))
    assert main(["design", str(sim), "--candidates", str(cands), "--loads", "3", "--out", str(tmp_path / "ds")]) == 0
    assert main(["batch", str(sim), "--out", str(tmp_path / "bt"), "--no-cache"]) == 0
    assert "ok" in (tmp_path / "bt" / "summary.csv").read_text()
    assert main(["conformance", "mystran", "--study", str(sim), "--no-misbehaviour"]) == 0
    # study.toml says reference, --adapter mystran overrides it: the adapter used decides
    toml = (sim / "study.toml").read_text()
    (sim / "study.toml").write_text(toml.replace('adapter = "mystran"', 'adapter = "reference"'))
    assert main(["solve", str(sim), "--adapter", "mystran", "--out", str(tmp_path / "s0"), "--no-cache"]) == 0
    (sim / "study.toml").write_text(toml)
    # the same study through a command adapter that runs MYSTRAN with the nastran dialect
    assert main(["solve", str(sim), "--out", str(tmp_path / "s1"), "--no-cache"]) == 0
    toml = (sim / "study.toml").read_text().replace(
        'adapter = "mystran"', f'adapter = "command"\ncommand = ["{mystran_binary()}", "{{deck_name}}"]')
    (sim / "study.toml").write_text(toml)
    assert main(["solve", str(sim), "--out", str(tmp_path / "s2"), "--no-cache", "--trust-command"]) == 0
    assert (tmp_path / "s1" / "displacements.csv").read_text() == (tmp_path / "s2" / "displacements.csv").read_text()


@needs_mystran
def test_car_body_needs_autospc(tmp_path):
    """The shell-only floor grids have no stiffness about the panel's normal (MYSTRAN's CQUAD4
    has no drilling stiffness): AUTOSPC, on by default as in NASTRAN, constrains them; with
    PARAM,AUTOSPC,NO MYSTRAN cannot factor the matrix (SuperLU names the pivot where its
    elimination stopped, not necessarily a shell grid)."""
    from solver_adapters.nastran import MystranAdapter
    from solver_adapters.protocol import UnstableStructureError
    path = tmp_path / "car.bdf"
    path.write_text(car_body_deck())
    load, report = LoadMatrix.unit([(19, 1)]), [(19, 1), *((g, 6) for g in PANEL_ONLY)]
    u = MystranAdapter(path, unmodelled="pass").solve(load, report).values
    assert u[0, 0] > 0 and not u[1:].any()          # the drilling rotations constrained, exactly 0
    path.write_text(car_body_deck().replace("ENDDATA", "PARAM,AUTOSPC,NO\nENDDATA"))
    with pytest.raises(UnstableStructureError, match=r"(?s)mechanism.*PARAM,AUTOSPC,NO.*ERROR   981"):
        MystranAdapter(path, unmodelled="pass").solve(load, report)


def _raw_run(folder: Path, bulk: str, loads: LoadMatrix, report) -> np.ndarray:
    """The bulk data copied verbatim into a run deck, run by MYSTRAN (its default AUTOSPC)."""
    from solver_adapters.nastran import NastranDialect, case_control, load_cards, mystran_binary
    from solver_adapters.subprocess import run_solver
    folder.mkdir(parents=True, exist_ok=True)
    deck = folder / "raw.bdf"
    deck.write_text("\n".join(case_control(loads.n_cases, sorted({g for g, _ in report}), None)) + "\nBEGIN BULK\n"
                    + bulk + "".join(load_cards(loads, 1, idle_grid=20)) + "ENDDATA\n")
    rec = run_solver([mystran_binary(), deck.name], folder, timeout_s=60)
    return NastranDialect().read_results(folder, deck, loads, list(report), rec)


@needs_mystran
def test_solid_passes_through_with_its_continuations(tmp_path, capsys):
    """A CHEXA (its last two grids on continuation lines) and its PSOLID reach MYSTRAN re-written
    from the reader's split of the card: the same answer as MYSTRAN on the small-field deck
    copied verbatim, also when the solid is spelt in large field with ``+HX1``/``*HX1`` markers,
    which MYSTRAN itself misreads (copied verbatim: ``*ERROR 1021``, G3-G6 read as 0). The
    block's flexibility matters (ten times stiffer, the post moves far less). As a study,
    `blackbox solve` runs it through MYSTRAN and refuses it with the reference adapter."""
    from solver_adapters.nastran import MystranAdapter
    from solver_adapters.protocol import SolverRunError
    V = _raw_run(tmp_path / "raw", SOLID + SOLID_SMALL, SOLID_LOADS, SOLID_REPORT)
    path = tmp_path / "solid.bdf"
    for solid in (SOLID_SMALL, SOLID_LARGE):
        path.write_text(SOLID + solid)
        U = MystranAdapter(path, unmodelled="pass").solve(SOLID_LOADS, SOLID_REPORT).values
        assert _rel(U, V) <= RTOL_F06
    with pytest.raises(SolverRunError, match="ERROR  1021: CHEXA"):
        _raw_run(tmp_path / "raw_large", SOLID + SOLID_LARGE, SOLID_LOADS, SOLID_REPORT)
    path.write_text(SOLID.replace("MAT1,3,3.E9", "MAT1,3,3.E10") + SOLID_SMALL)
    assert _rel(U, MystranAdapter(path, unmodelled="pass").solve(SOLID_LOADS, SOLID_REPORT).values) > 0.1
    study = tmp_path / "block"
    study.mkdir()
    (study / "model.bdf").write_text(SOLID + SOLID_LARGE)
    (study / "loads.csv").write_text("case,grid,component,value\nx,20,1,100.\nz,20,3,1000.\n")
    (study / "study.toml").write_text('name = "block"\n\n[solver]\nadapter = "mystran"\n')
    assert main(["solve", str(study), "--out", str(tmp_path / "s"), "--no-cache"]) == 0
    assert main(["solve", str(study), "--adapter", "reference", "--out", str(tmp_path / "r")]) == 2
    assert "CHEXA x1 (first at" in capsys.readouterr().err


UNUSED_BASE = """GRID,1,,0.,0.,0.,,123456
GRID,2,,1.,0.,0.
GRID,3,,0.,1.,0.,,123456
GRID,4,,1.,1.,0.,,123456
CBAR,1,7,1,2,0.,1.,0.
PBAR,7,1,1.E-3,2.E-6,3.E-6,4.E-6
MAT1,1,2.1E11,,.3
"""
UNUSED_SECTIONS = "PSHELL,7,8,.01,8\nPCOMP,9,,,,,,,,+P\n+P,8,.002,0.,YES\nMAT8,8,1.E11,1.E10,.3,5.E9\n"


def test_sections_no_element_uses_have_no_effect():
    """A pre-processor exports every property of its model: a frame deck with a PSHELL (sharing
    the PBAR's PID), a PCOMP and their MAT8 but no shell is the frame itself, read with and
    without an external solver in mind (no effect, a note; never a reason for the mystran
    adapter); its solution is the frame's without them, bit for bit. With a CQUAD4 using the
    PSHELL, the PSHELL and its MAT8 are kept (the PCOMP, used by nothing, is not), and the
    reference solver refuses the shell as before."""
    from solver_adapters.reference import ReferenceAdapter

    def tip(deck):
        loads = LoadMatrix.from_dense([(2, 2)], np.array([[1e3]]), ["1"])
        return ReferenceAdapter(deck).solve(loads, [(2, c) for c in range(1, 7)]).values

    plain = read_deck_text(UNUSED_BASE)
    for mode in ("error", "keep"):
        deck = read_deck_text(UNUSED_BASE + UNUSED_SECTIONS, unmodelled=mode)
        assert not deck.unmodelled and set(deck.no_effect) == {"PSHELL", "PCOMP", "MAT8"}
        assert any("no element of the deck uses" in n for n in deck.notes)
        np.testing.assert_array_equal(tip(deck), tip(plain))
    shell = UNUSED_BASE + UNUSED_SECTIONS + "CQUAD4,9,7,1,2,4,3\n"
    kept = read_deck_text(shell, unmodelled="keep")
    assert [u.name for u in kept.unmodelled] == ["PSHELL", "MAT8", "CQUAD4"]
    assert set(kept.no_effect) == {"PCOMP"}
    with pytest.raises(DeckFormatError, match="PSHELL x1"):
        read_deck_text(shell)
