"""One registry for adapters and dialects, adapter options, and one errors module per package.

Entry points are faked by monkeypatching ``importlib.metadata.entry_points`` (what the registry
calls at every lookup); a plug-in's module is written to a temporary folder put on ``sys.path``.
"""

from __future__ import annotations

import ast
import importlib
import importlib.metadata
import inspect
import pkgutil
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

import solver_adapters.errors as sa_errors
import solver_adapters.protocol as protocol
from conftest import FIXTURES
from solver_adapters import registry
from solver_adapters.legacy import LegacyAdapter, LegacyDialect
from solver_adapters.nastran import MystranAdapter, NastranDialect
from solver_adapters.protocol import (FactorizationError, LoadMatrix, OptionError, PluginConflictError,
                                      PluginLoadError, RegistryError, SolverError, SolverRunError,
                                      SolverTimeoutError, UnknownPluginError, UnstableStructureError)
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.registry import Registry, adapter_factory, known_adapters, make_adapter
from solver_adapters.subprocess import CommandAdapter, get_dialect, known_dialects

ROOT = Path(__file__).resolve().parents[1]
DECK = FIXTURES / "cube" / "model.bdf"
REAL_ENTRY_POINTS = importlib.metadata.entry_points


def fake_entry_points(monkeypatch, *specs: tuple[str, str, str]) -> None:
    """Installed entry points = the real ones (this package's own) plus ``(group, name, value)``."""
    extra = [EntryPoint(name=n, value=v, group=g) for g, n, v in specs]

    def entry_points(**params):
        group = params.get("group")
        return [*REAL_ENTRY_POINTS(**params), *(ep for ep in extra if ep.group == group)]

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)


PLUGIN = '''
from solver_adapters.reference import ReferenceAdapter


class ToyAdapter(ReferenceAdapter):
    """A plug-in adapter with options of its own."""

    name = "toy"

    def __init__(self, deck_path, *, scale=1.0, label="toy"):
        super().__init__(deck_path)
        self.scale, self.label = scale, label


def declared_factory(deck_path, **kw):
    """Takes any keyword, but declares the ones it understands."""
    return ToyAdapter(deck_path, **kw)


declared_factory.options = {"scale": "multiplies nothing", "label": "a name"}


def open_factory(deck_path, **kw):
    return ("open", deck_path, kw)


def needs_key(deck_path, key, colour="red"):
    return (deck_path, key, colour)


class ToyDialect(object):
    name = "toy"

    def __init__(self, digits=7):
        self.digits = digits
'''


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A plug-in package ``toy_plugin_bb`` importable for this test only."""
    (tmp_path / "toy_plugin_bb.py").write_text(PLUGIN)
    (tmp_path / "broken_plugin_bb.py").write_text("raise RuntimeError('the plug-in is broken')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "toy_plugin_bb"
    for name in ("toy_plugin_bb", "broken_plugin_bb"):
        sys.modules.pop(name, None)


# --------------------------------------------------------------------------------------------
# built-ins and the package's own entry points
# --------------------------------------------------------------------------------------------
def test_builtins_are_registered_and_our_own_entry_points_do_not_clash():
    assert {"reference", "mystran", "command", "legacy", "opensees"} <= set(known_adapters())
    # pyproject.toml declares reference/mystran/command/opensees as entry points: the same objects
    assert adapter_factory("reference") is ReferenceAdapter
    assert adapter_factory("mystran") is MystranAdapter
    assert adapter_factory("command") is CommandAdapter
    assert adapter_factory("legacy") is LegacyAdapter
    from solver_adapters.opensees import OpenSeesAdapter, OpenSeesDialect
    assert adapter_factory("opensees") is OpenSeesAdapter
    assert registry.DIALECTS.get("nastran") is NastranDialect
    assert registry.DIALECTS.get("legacy") is LegacyDialect
    assert registry.DIALECTS.get("opensees") is OpenSeesDialect
    assert known_dialects()["nastran"] == "solver_adapters.nastran:NastranDialect"


def test_entry_point_to_the_same_object_by_another_path_is_not_a_clash(monkeypatch):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "reference",
                                    "solver_adapters.reference.adapter:ReferenceAdapter"),
                      ("blackbox.dialects", "nastran", "solver_adapters.nastran:NastranDialect"))
    assert adapter_factory("reference") is ReferenceAdapter
    assert isinstance(get_dialect("nastran"), NastranDialect)


# --------------------------------------------------------------------------------------------
# clashes are never silent
# --------------------------------------------------------------------------------------------
def test_user_entry_point_with_a_builtin_name_is_an_error_naming_both(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "reference", f"{plugin}:ToyAdapter"))
    with pytest.raises(PluginConflictError) as info:
        make_adapter("reference", DECK)
    msg = str(info.value)
    assert "adapter name 'reference'" in msg
    assert "solver_adapters.reference:ReferenceAdapter (built-in)" in msg
    assert f"{plugin}:ToyAdapter (entry point 'reference' in group 'blackbox.adapters'" in msg
    assert isinstance(info.value, SolverError) and isinstance(info.value, ValueError)
    # the clash concerns that name only: the other adapters are still found
    assert adapter_factory("legacy") is LegacyAdapter


def test_user_dialect_with_a_builtin_name_is_an_error_naming_both(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.dialects", "nastran", f"{plugin}:ToyDialect"))
    with pytest.raises(PluginConflictError, match=rf"solver_adapters.nastran:NastranDialect \(built-in\) "
                                                  rf"and {plugin}:ToyDialect"):
        get_dialect("nastran")
    with pytest.raises(PluginConflictError):   # a CommandAdapter naming the dialect hits it too
        CommandAdapter(DECK, command=["true"], dialect="nastran")
    assert "solver_adapters.nastran:NastranDialect | toy_plugin_bb:ToyDialect" == known_dialects()["nastran"]


def test_two_packages_with_one_name_clash(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "toy", f"{plugin}:ToyAdapter"),
                      ("blackbox.adapters", "toy", f"{plugin}:open_factory"))
    with pytest.raises(PluginConflictError, match="ToyAdapter .* and .*open_factory"):
        adapter_factory("toy")


def test_programmatic_registration_follows_the_same_rules():
    reg = Registry("widget", "blackbox.test-widgets", call="factory()")
    reg.register("a", "solver_adapters.legacy:LegacyDialect")
    reg.register("a", "solver_adapters.legacy:LegacyDialect")          # the same again: fine
    reg.register("b", NastranDialect)                                  # an object
    with pytest.raises(PluginConflictError, match="already registered to solver_adapters.legacy:LegacyDialect"):
        reg.register("a", "solver_adapters.nastran:NastranDialect")
    assert reg.names() == ["a", "b"] and reg.get("a") is LegacyDialect and reg.get("b") is NastranDialect
    assert isinstance(reg.create("b", epsilon_tol=1e-3), NastranDialect)
    with pytest.raises(ValueError, match="module:object"):
        reg.register("c", "no_colon")


# --------------------------------------------------------------------------------------------
# unknown names and broken entry points
# --------------------------------------------------------------------------------------------
def test_unknown_name_lists_the_known_ones(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "toy", f"{plugin}:ToyAdapter"))
    with pytest.raises(UnknownPluginError) as info:
        make_adapter("abaqus", DECK)
    msg = str(info.value)
    assert "unknown adapter 'abaqus'; known: command, legacy, mystran, opensees, reference, toy." in msg
    assert "'blackbox.adapters'" in msg
    assert isinstance(info.value, ValueError) and isinstance(info.value, registry.AdapterNotFound)
    with pytest.raises(UnknownPluginError, match="unknown solver dialect 'abaqus'; known: legacy, nastran"):
        get_dialect("abaqus")


def test_entry_point_that_fails_to_import_is_named_with_its_error(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "gone", "no_such_module_bb:Adapter"),
                      ("blackbox.adapters", "broken", "broken_plugin_bb:Adapter"),
                      ("blackbox.dialects", "nodialect", f"{plugin}:NoSuchClass"))
    with pytest.raises(PluginLoadError) as info:
        make_adapter("gone", DECK)
    msg = str(info.value)
    assert "adapter 'gone' cannot be loaded from no_such_module_bb:Adapter (entry point 'gone' in group " \
           "'blackbox.adapters'" in msg
    assert "ModuleNotFoundError: No module named 'no_such_module_bb'" in msg
    with pytest.raises(PluginLoadError, match="broken_plugin_bb:Adapter .*RuntimeError: the plug-in is broken"):
        adapter_factory("broken")
    with pytest.raises(PluginLoadError, match="AttributeError.*NoSuchClass"):
        get_dialect("nodialect")


def test_broken_entry_point_with_a_builtin_name_is_reported_not_skipped(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "legacy", "no_such_module_bb:Adapter"))
    with pytest.raises(PluginLoadError, match="entry point 'legacy'"):
        adapter_factory("legacy")


def test_missing_optional_package_gives_the_install_hint():
    reg = Registry("adapter", "blackbox.test-adapters", call="factory(deck_path, **options)")
    reg.register("fancy", "no_such_fancy_solver_bb:Adapter", install_hint="pip install fancy-solver")
    with pytest.raises(PluginLoadError, match="adapter 'fancy' cannot be loaded from no_such_fancy_solver_bb:"
                                              "Adapter \\(built-in\\).*Install what it needs with: pip install "
                                              "fancy-solver"):
        reg.get("fancy")


# --------------------------------------------------------------------------------------------
# options
# --------------------------------------------------------------------------------------------
def test_builtin_adapter_options_are_checked_against_the_constructor():
    a = make_adapter("reference", DECK, backend="superlu")
    assert isinstance(a, ReferenceAdapter) and a.backend == "superlu"
    with pytest.raises(OptionError) as info:
        make_adapter("reference", DECK, backnd="superlu")
    assert str(info.value) == ("adapter 'reference' has no option 'backnd'; "
                               "accepted options: backend, extra_springs, parsed")
    assert isinstance(info.value, ValueError)


def test_options_passed_on_through_kwargs_are_accepted_and_others_named():
    # LegacyAdapter(**kw) -> CommandAdapter: both constructors' options count
    spec = registry.adapter_options("legacy")
    assert {"timeout_s", "misbehave", "program", "workdir_root", "keep_failed", "command"} <= set(spec.names)
    assert not spec.open
    a = make_adapter("legacy", DECK, timeout_s=60, keep_failed=False)
    assert a.timeout_s == 60 and a.keep_failed is False
    # MystranAdapter: checked before it is built, so this needs no MYSTRAN
    assert {"epsilon_tol", "autospc", "binary", "workdir_root"} <= set(registry.adapter_options("mystran").names)
    with pytest.raises(OptionError, match=r"adapter 'mystran' has no options 'epsilon', 'spc'; accepted "
                                          r"options: timeout_s, binary, epsilon_tol"):
        make_adapter("mystran", DECK, epsilon=1e-3, spc=True)


def test_none_options_are_left_out_before_the_check():
    # None is an unset field (the CLI passes timeout_s=None to every adapter): the default applies
    assert make_adapter("reference", DECK, backend=None).backend == "auto"
    assert isinstance(make_adapter("reference", DECK, timeout_s=None), ReferenceAdapter)
    with pytest.raises(OptionError, match="no option 'timeout_s'"):
        make_adapter("reference", DECK, timeout_s=60)


def test_make_adapter_call_signature_keeps_working():
    # blackbox.adapters.make_adapter_for: make_adapter(name, deck, **opts) with these option sets
    for name, opts in [("reference", {"backend": "auto", "parsed": None}),
                       ("command", {"command": ["true", "{deck}"], "dialect": "nastran", "timeout_s": 5.0,
                                    "trusted": True}),
                       ("legacy", {"timeout_s": 600.0})]:
        assert make_adapter(name, DECK, **opts).name == name


def test_legacy_runs_its_own_program_whatever_trusted_says(tmp_path, monkeypatch):
    # blackbox's adapter wiring passes trusted=<--trust-command> to every adapter that takes it;
    # the shipped FRAMESOLVE is this package's own program and needs no consent, another does
    monkeypatch.setenv("BLACKBOX_CONFIG_DIR", str(tmp_path / "config"))
    a = make_adapter("legacy", DECK, trusted=False, misbehave="crash", workdir_root=tmp_path)
    with pytest.raises(SolverRunError):
        a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
    with pytest.raises(sa_errors.ConsentError):
        make_adapter("legacy", DECK, command=[sys.executable, str(tmp_path / "other.py"), "{deck}"])


def test_plugin_adapter_gets_its_options(monkeypatch, plugin):
    fake_entry_points(monkeypatch, ("blackbox.adapters", "toy", f"{plugin}:ToyAdapter"),
                      ("blackbox.adapters", "toy-declared", f"{plugin}:declared_factory"),
                      ("blackbox.adapters", "toy-open", f"{plugin}:open_factory"),
                      ("blackbox.adapters", "toy-key", f"{plugin}:needs_key"))
    a = make_adapter("toy", DECK, scale=2.5, label="mine")      # as from [solver.options]
    assert type(a).__name__ == "ToyAdapter" and (a.scale, a.label) == (2.5, "mine")
    loads = LoadMatrix.unit([(7, 4)])
    assert a.solve(loads, [(7, 4)]).values.shape == (1, 1)
    with pytest.raises(OptionError, match="adapter 'toy' has no option 'colour'; accepted options: scale, label$"):
        make_adapter("toy", DECK, colour="red")
    # an explicit declaration wins over a **kwargs signature
    assert make_adapter("toy-declared", DECK, scale=3.0).scale == 3.0
    with pytest.raises(OptionError, match="adapter 'toy-declared' has no option 'colour'; accepted options: "
                                          "scale, label"):
        make_adapter("toy-declared", DECK, colour="red")
    assert registry.adapter_options("toy-declared").declared
    # a bare **kwargs function cannot be checked: everything is handed on
    assert make_adapter("toy-open", DECK, anything=1) == ("open", DECK, {"anything": 1})
    assert registry.adapter_options("toy-open").open
    # a required option must be given (None counts as not given)
    assert make_adapter("toy-key", DECK, key="k") == (DECK, "k", "red")
    with pytest.raises(OptionError, match="adapter 'toy-key' needs option\\(s\\) 'key' \\(accepted options: "
                                          "key, colour\\)"):
        make_adapter("toy-key", DECK, key=None)


def test_dialect_options_are_checked(monkeypatch, plugin):
    assert get_dialect("nastran", epsilon_tol=1e-3, strict_cards=False).epsilon_tol == 1e-3
    with pytest.raises(OptionError, match="solver dialect 'nastran' has no option 'eps'; accepted options: "
                                          "epsilon_tol, max_cases_per_run, autospc, strict_cards"):
        get_dialect("nastran", eps=1e-3)
    with pytest.raises(OptionError, match="solver dialect 'legacy' has no option 'digits'; accepted options: none"):
        get_dialect("legacy", digits=3)
    fake_entry_points(monkeypatch, ("blackbox.dialects", "toy", f"{plugin}:ToyDialect"))
    assert get_dialect("toy", digits=3).digits == 3
    with pytest.raises(OptionError, match="'precision'.*accepted options: digits"):
        get_dialect("toy", precision=3)


# --------------------------------------------------------------------------------------------
# one errors module per package
# --------------------------------------------------------------------------------------------
def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            out.add("." * node.level + (node.module or ""))
    return out


def test_solver_adapters_errors_imports_nothing_of_the_project():
    imported = _imports(ROOT / "solver_adapters" / "errors.py")
    assert not [m for m in imported if m.startswith((".", "solver_adapters", "blackbox"))], imported


def test_blackbox_errors_imports_only_the_protocol():
    imported = _imports(ROOT / "blackbox" / "errors.py")
    assert [m for m in imported if m.startswith((".", "solver_adapters", "blackbox"))] == ["solver_adapters.protocol"]


def _exception_classes(package) -> dict[str, list[str]]:
    """Module -> exception classes defined there, for every importable module of ``package``
    (``_guard`` is excluded: a standalone script run with ``python -I -S``, it cannot import
    the package)."""
    found = {}
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        if info.name.endswith("._guard"):
            continue
        module = importlib.import_module(info.name)
        classes = [n for n, obj in vars(module).items()
                   if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == info.name]
        if classes:
            found[info.name] = sorted(classes)
    return found


@pytest.mark.parametrize("package, errors_module", [("solver_adapters", "solver_adapters.errors"),
                                                    ("blackbox", "blackbox.errors")])
def test_every_error_class_is_defined_in_the_errors_module(package, errors_module):
    found = _exception_classes(importlib.import_module(package))
    elsewhere = {m: c for m, c in found.items() if m != errors_module}
    assert not elsewhere, f"error classes outside {errors_module}: {elsewhere}"


def test_protocol_re_exports_every_error_and_old_import_paths_work():
    public = [n for n in sa_errors.__all__ if n != "NumberFieldError"]
    for name in public:
        assert getattr(protocol, name) is getattr(sa_errors, name), name
    from blackbox.errors import SolverRunError as bb_run
    from solver_adapters.protocol import SolverRunError as p_run
    assert bb_run is p_run is sa_errors.SolverRunError
    assert registry.AdapterNotFound is RegistryError


def test_solver_failures_are_solver_errors_and_other_errors_are_not():
    for cls in (sa_errors.DeckFormatError, sa_errors.ModelError, UnstableStructureError,
                sa_errors.UnknownDofError, SolverRunError, SolverTimeoutError, FactorizationError,
                RegistryError, UnknownPluginError, PluginLoadError, PluginConflictError, OptionError):
        assert issubclass(cls, SolverError), cls
    assert issubclass(SolverTimeoutError, SolverRunError)
    for cls in (sa_errors.CorruptEntry, sa_errors.UnauthenticEntry, sa_errors.CheckFailure, sa_errors.TableFormatError,
                sa_errors.InsecureFileError, sa_errors.ConsentError):
        assert not issubclass(cls, SolverError), cls


def test_blackbox_errors_share_one_base():
    import blackbox.errors as bb
    from blackbox.comparison import ComparisonError
    from blackbox.joints import JointModelError

    assert JointModelError is bb.JointModelError and ComparisonError is bb.ComparisonError
    for cls in (bb.StudyError, bb.IdentificationError, bb.JointModelError, bb.ComparisonError, bb.DiagnosisError):
        assert issubclass(cls, bb.BlackboxError) and not issubclass(cls, SolverError)
    for cls in (bb.JointModelError, bb.ComparisonError, bb.DiagnosisError):
        assert issubclass(cls, ValueError)                  # callers catching ValueError keep working
    err = bb.StudyError("bad value", file="study.toml", line=3, column="k")
    assert str(err) == "study.toml:3 column 'k': bad value" and (err.file, err.line, err.column) == ("study.toml", 3, "k")
    for name in ("SolverError", "SolverRunError", "UnstableStructureError", "OptionError"):
        assert getattr(bb, name) is getattr(protocol, name)


# --------------------------------------------------------------------------------------------
# a solver failure is a solver error wherever it happens
# --------------------------------------------------------------------------------------------
class GarbageDialect:
    """Writes an empty deck; its reader fails the way a dialect meeting garbage output might."""

    name = "garbage"

    def __init__(self, exc: BaseException):
        self.exc = exc

    def command(self, deck_path):
        return None

    def write_deck(self, workdir, base, loads, report, springs):
        deck = Path(workdir) / "run.txt"
        deck.write_text("")
        return deck

    def read_results(self, workdir, deck_path, loads, report, record):
        raise self.exc


@pytest.mark.parametrize("exc", [ValueError("could not convert string to float: '****'"),
                                 KeyError(7), IndexError("list index out of range")])
def test_a_dialect_failing_on_garbage_output_is_a_solver_run_error(tmp_path, exc):
    a = CommandAdapter(DECK, command=[sys.executable, "-c", "print('garbage')"], dialect=GarbageDialect(exc),
                       workdir_root=tmp_path, keep_failed=True, trusted=True)
    with pytest.raises(SolverRunError) as info:
        a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
    err = info.value
    assert f"dialect 'garbage' could not read the solver's output: {type(exc).__name__}" in str(err)
    assert err.returncode == 0 and "garbage" in err.log_tail
    assert err.workdir and Path(err.workdir).is_dir()          # kept for inspection
    assert err.__cause__ is exc


def test_a_dialect_solver_error_passes_through_unchanged(tmp_path):
    exc = UnstableStructureError("singular", [(7, 1)])
    a = CommandAdapter(DECK, command=[sys.executable, "-c", "pass"], dialect=GarbageDialect(exc),
                       workdir_root=tmp_path, trusted=True)
    with pytest.raises(UnstableStructureError) as info:
        a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
    assert info.value is exc


@pytest.mark.parametrize("switch", ["crash", "garbage", "nan"])
def test_legacy_misbehaviour_is_a_solver_run_error(tmp_path, switch):
    a = LegacyAdapter(DECK, timeout_s=60, misbehave=switch, workdir_root=tmp_path)
    with pytest.raises(SolverRunError):
        a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])


def test_reference_non_finite_result_is_an_unstable_structure_error(monkeypatch):
    a = ReferenceAdapter(DECK)
    fact = a.factorization()
    monkeypatch.setattr(fact, "solve", lambda F: np.full_like(F, np.nan))
    with pytest.raises(UnstableStructureError, match=r"non-finite displacements.*\[grid:component 7:T1\]"):
        a.solve(LoadMatrix.unit([(7, 1)]), [(7, 1)])
    assert a.stats.runs == 0


def test_reference_factorization_library_errors_are_solver_errors():
    from solver_adapters.reference import model

    err = model._pardiso_error(-2, 22)
    assert isinstance(err, FactorizationError) and isinstance(err, SolverError)
    assert (err.code, err.phase) == (-2, 22) and "not enough memory" in str(err)


def test_mystran_that_cannot_run_is_a_solver_run_error(tmp_path):
    from solver_adapters.nastran import mystran_version

    with pytest.raises(SolverRunError, match="cannot run MYSTRAN"):
        mystran_version(str(tmp_path / "no-such-mystran"))


def test_make_adapter_signature_is_name_deck_options():
    params = inspect.signature(make_adapter).parameters
    assert list(params) == ["name", "deck_path", "options"]
    assert params["options"].kind is inspect.Parameter.VAR_KEYWORD
