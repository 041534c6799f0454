"""Diagnose's edited decks keep the whole model (``blackbox.diagnosis.decks``).

The study is ``tests/rich_deck.py``: every card of the supported subset as users write them
(CORD2R chained in another CORD2R, CORD1R on grids, CORD2C; GRDSET; CP and CD on grids; PBARL I,
BOX, TUBE; PBEAM with CBEAM; CBAR offsets and a pin flag; CROD, CONROD; RBE2 tie and rigid link;
RBE3; CBUSH; CELAS1 to ground, CELAS2 between grids; CONM2; SPC1 and SPC sets under an SPCADD),
a 4-branch joint whose grids are in a CORD1R, measurements in the grids' CD components.

What is checked:

* the split deck at its rigid state is the declared model: the element and split decks read
  back, and the split structure conditioned on rigid cuts predicts what the study's own deck
  predicts at the declared estimate, through the reference solver and MYSTRAN;
* each effect released in the split deck is the structure it stands for: its prediction equals
  the reference solver's on a truth deck built independently (``blackbox.structures.TruthDeck``:
  a grid split and joined by springs, a support replaced by springs, a joint untied, a member's
  section scaled) -- on grids with cylindrical and chained rectangular CD systems, on a member
  with offsets, on a pinned member and a CBEAM;
* a split deck that does not reproduce the declared model stops the diagnosis (exit 3) naming
  the cards at the grids where it differs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from blackbox import diagnosis as dg
from blackbox.cli import main as cli_main
from blackbox.commands import diagnose as diagnose_command
from blackbox.diagnosis.effects import JointTranslation, MemberStiffness, SupportFlexibility, UndeclaredJoint
from blackbox.errors import EditedDeckError
from blackbox.structures import TruthDeck
from solver_adapters.bdf import read_deck_text
from solver_adapters.reference import ReferenceAdapter

from conftest import MYSTRAN_MARKS
from rich_deck import JOINT_GRIDS, write_rich_study

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


@pytest.fixture(scope="module")
def rich(tmp_path_factory) -> Path:
    return write_rich_study(tmp_path_factory.mktemp("rich") / "rich")


@pytest.fixture(scope="module")
def prepared(rich, tmp_path_factory):
    return diagnose_command.prepare(rich, tmp_path_factory.mktemp("decks"))


def _model(pr, spec):
    o = list(dict.fromkeys(pr.study.measurements.all_dofs))
    model = dg.AugmentedModel(pr.base, spec, pr.boundary, pr.K_deck, o)
    return model, dg.ObsMap.of(pr.fit_obs, {d: i for i, d in enumerate(o)})


@pytest.mark.parametrize("adapter", ["reference", pytest.param("mystran", marks=MYSTRAN_MARKS)])
def test_split_deck_nests_the_declared_model(rich, adapter):
    """Rigid-state nesting on the whole card subset. Reference solver: 1e-6 sigma (double
    precision throughout; cond(S) of the 66 cut pairs ~1e6 costs ~1e-10, margin for the
    conditioning of the declared fit). MYSTRAN: its displacements carry 7 printed digits
    (``shared`` notes: half a unit in the 7th digit, 5e-7 relative); the conditioning on the
    pairs amplifies that by cond ~1e3 here, on displacements of ~50 sigma: 5e-2 sigma. Before
    edited decks kept CD systems this study nested to ~1e3 sigma; the SPCADD alone made the
    split deck unreadable."""
    res = diagnose_command.run(rich, adapter=adapter, max_steps=0, plots=False)
    tol = 1e-6 if adapter == "reference" else 5e-2
    assert res.diagnosis.nesting_error < tol
    assert res.diagnosis.verdict == "adequate"
    for name, text in res.decks:                     # every edited deck reads back as written
        d = read_deck_text(text, name)
        if name == "split.bdf":
            assert set(d.coords) == {1, 2, 3, 4}
            assert {g.cd for g in d.grids.values()} >= {1, 2, 3, 4}
            assert all(set(a.sets) <= {s.sid for s in d.spc1s} for a in d.spcadds.values())
            assert len(d.rods) == 2 and d.rbe3s and d.bushes and d.pelas


def test_member_stiffness_is_the_member_in_its_grids_components(prepared):
    """A member factor alpha = 2 on members with an offset (108: CD 3 at end a, CD 2 at end b),
    a pin flag (116) and a CBEAM (115) predicts the truth deck in which that member's section
    is doubled (A, I1, I2, J: the element matrix doubles exactly), to 1e-8 of the largest
    response (K_e from flexibilities inverted at cond ~1e6, 1e-10 relative, margin)."""
    pr = prepared
    rows = list(dict.fromkeys(pr.study.measurements.all_dofs))
    for eid in (108, 115, 116):
        eff = next(e for e in pr.candidates if isinstance(e, MemberStiffness) and e.where == (eid,))
        pr.base.ensure_columns(eff.refit_columns(), "test")
        spec, x = dg.ModelSpec(tuple(pr.joints)).add(eff, pr.ident.k)
        x[-1] = 2.0
        model, om = _model(pr, spec)
        f = model.predict(x, om)
        truth = TruthDeck(pr.deck)
        b = truth.deck.cbars[eid]
        p = truth.deck.pbars[b.pid]
        pid = max(truth.deck.pbars) + 1
        truth.deck.pbars[pid] = dataclasses.replace(p, pid=pid, a=2 * p.a, i1=2 * p.i1, i2=2 * p.i2,
                                                    i12=2 * p.i12, j=2 * p.j)
        truth.deck.cbars[eid] = dataclasses.replace(b, pid=pid)
        U = _truth_response(pr, truth.deck, rows)
        f_true = om.pick(U)
        assert np.max(np.abs(f - f_true)) < 1e-8 * np.max(np.abs(f_true)), eid


def _truth_response(pr, deck, rows) -> np.ndarray:
    """The declared joint at its estimate plus whatever ``deck`` plants, by the reference solver."""
    truth = TruthDeck(deck)
    for j, sl in zip(pr.joints, dg.ModelSpec(tuple(pr.joints)).joint_slices()):
        truth.joint(j.name, j.grids, "simple", pr.ident.k[sl])
    return ReferenceAdapter(truth.deck).solve(pr.study.loads, rows).values


def _connection_case(pr, kind, where):
    eff = next(e for e in pr.candidates if isinstance(e, kind) and e.where == where)
    return eff.richer(np.zeros(eff.n_params))[0][0] if eff.variant == "equal" else eff


@pytest.mark.parametrize("kind,where", [(UndeclaredJoint, (30,)), (UndeclaredJoint, (14,)),
                                        (SupportFlexibility, (4,)), (JointTranslation, ("J",))],
                         ids=["undeclared-30-CD2-offset", "undeclared-14-CD4-cylindrical",
                              "support-4-CD4-SPCADD", "joint-translation-CD3"])
def test_connection_effects_reproduce_truth_decks(prepared, kind, where):
    """Released at springs ``k_p = k_ref_p / theta_p`` per axis (the "per-axis" variant), a
    connection predicts the truth deck that TruthDeck builds without the diagnosis (the grid
    split into one grid per member with those springs between every pair of branches per
    axis; the support's SPC components replaced by grounded springs; the joint's RBE2 tie
    replaced by translation springs) to 1e-8 of the largest response. The grids are in a
    CORD2R chained in a CORD2R (30), a CORD2C (4, 14) and a CORD1R (J): a cut that bridged the
    basic components instead of the grid's would be off by the springs' misalignment (tens of
    per cent)."""
    pr = prepared
    rows = list(dict.fromkeys(pr.study.measurements.all_dofs))
    eff = _connection_case(pr, kind, where)
    assert eff.variant == "per-axis"
    theta = np.linspace(0.5, 3.0, eff.n_params)
    spec, x = dg.ModelSpec(tuple(pr.joints)).add(eff, pr.ident.k)
    x[spec.joint_params:] = theta
    model, om = _model(pr, spec)
    f = model.predict(x, om)
    k = eff.k_ref / theta
    truth = TruthDeck(pr.deck)
    if kind is UndeclaredJoint:
        g = where[0]
        branches = truth.split_grid(g)
        for p, c in enumerate((4, 5, 6)):
            for i in range(len(branches)):
                for j in range(i + 1, len(branches)):
                    truth.spring(k[p], branches[i], c, branches[j], c)
    elif kind is SupportFlexibility:
        g = where[0]
        comps = truth.unclamp(g)
        ks = dict(zip(comps, k)) if len(k) == len(comps) else None
        assert ks is not None
        for c, kc in ks.items():
            truth.spring(kc, g, int(c))
    else:
        truth.untie_translations(JOINT_GRIDS)
        for p, c in enumerate((1, 2, 3)):
            for i in range(len(JOINT_GRIDS)):
                for j in range(i + 1, len(JOINT_GRIDS)):
                    truth.spring(k[p], JOINT_GRIDS[i], c, JOINT_GRIDS[j], c)
    U = _truth_response(pr, truth.deck, rows)
    f_true = om.pick(U)
    assert np.max(np.abs(f - f_true)) < 1e-8 * np.max(np.abs(f_true))


def test_a_split_deck_that_is_another_structure_stops_the_diagnosis(rich, tmp_path, monkeypatch, capsys):
    """The split deck's new grids made without their CD system (what edited decks did): the
    rigid state is ~1e3 sigma away from the declared model. That is a solver-side failure of the
    edited deck, not a finding: exit 3, the message names the grids where the two differ and
    the cards there (their CD systems among them), and nothing is written."""
    from solver_adapters.deck import Grid

    def new_grid(self, like):
        g = self.next_grid
        self.next_grid += 1
        self.deck.grids[g] = Grid(g, self.deck.grids[like].xyz)
        return g

    monkeypatch.setattr(dg.SplitEditor, "new_grid", new_grid)
    with pytest.raises(EditedDeckError) as exc:
        diagnose_command.run(rich, max_steps=0, plots=False)
    msg = str(exc.value)
    assert "does not reproduce the declared model" in msg and "GRID" in msg and "CD" in msg
    out = tmp_path / "out"
    assert cli_main(["diagnose", str(rich), "--out", str(out)]) == 3
    assert not out.exists()
    assert "does not reproduce the declared model" in capsys.readouterr().err
