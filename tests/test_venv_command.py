"""A command whose program is a virtual environment's ``python`` runs inside that environment.

A venv's ``bin/python`` is a symbolic link to the base interpreter; Python finds its environment
from the path it was started by (``pyvenv.cfg`` beside it), so a command that runs the link's
target instead runs outside the venv and cannot import what is installed there. The command
adapter must run the program as the user named it (by its absolute path, links kept), while
consent and the cache key still name the file that is executed in the end.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from solver_adapters.legacy import FRAMESOLVE, LegacyDialect
from solver_adapters.protocol import LoadMatrix
from solver_adapters.reference import ReferenceAdapter
from solver_adapters.subprocess import CommandAdapter, locate_program, program_files, resolve_program

from conftest import FIXTURES, HAVE_OPENSEES

pytestmark = pytest.mark.usefixtures("runs_under_tmp_path")

MODULE = "blackbox_only_in_this_venv"


def make_venv(folder: Path, *extra_paths: str) -> Path:
    """A real virtual environment (``python -m venv --system-site-packages``, no pip) whose
    site-packages holds a module no other environment has, and ``.pth`` lines for
    ``extra_paths``. Returns its ``bin/python``."""
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(folder)],
                   check=True, capture_output=True)
    python = folder / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()
    Path(site, f"{MODULE}.py").write_text("MARK = 'imported from the venv'\n")
    if extra_paths:
        Path(site, "blackbox_extra.pth").write_text("\n".join(extra_paths) + "\n")
    return python


@pytest.fixture
def venv_python(tmp_path) -> Path:
    python = make_venv(tmp_path / "venv")
    assert python.is_symlink() or os.path.realpath(python) != str(python)
    base = resolve_program(str(python))
    probe = subprocess.run([str(base), "-c", f"import {MODULE}"], capture_output=True)
    assert probe.returncode != 0          # the base interpreter does not see the venv's module
    return python


def test_locate_keeps_the_link_resolve_follows_it(venv_python):
    assert locate_program(str(venv_python)) == venv_python
    assert resolve_program(str(venv_python)) == Path(os.path.realpath(venv_python))
    assert program_files([str(venv_python)])[0] == Path(os.path.realpath(venv_python))   # cache key: the file run


def test_a_runner_that_imports_from_its_venv_runs(venv_python, tmp_path):
    """FRAMESOLVE behind a runner script that needs a module installed only in the venv."""
    runner = tmp_path / "runner.py"
    runner.write_text(f"import runpy, sys\nimport {MODULE}\nprint({MODULE}.MARK, file=sys.stderr)\n"
                      f"sys.argv = [{str(FRAMESOLVE)!r}, *sys.argv[1:]]\n"
                      f"runpy.run_path({str(FRAMESOLVE)!r}, run_name='__main__')\n")
    deck = FIXTURES / "cube" / "model.bdf"
    a = CommandAdapter(deck, command=[str(venv_python), str(runner), "{deck}"], dialect=LegacyDialect(),
                       trusted=True, name="venv")
    loads = LoadMatrix.unit([(5, 1), (8, 6)])
    U = a.solve(loads, a.dofs()).values
    R = ReferenceAdapter(deck).solve(loads, a.dofs()).values
    assert np.max(np.abs(U - R)) <= 1e-9 * np.max(np.abs(R))     # FRAMESOLVE's 13 printed digits
    assert a._command_for(Path("/x/run.dat"))[0] == str(venv_python)


def test_a_relative_program_still_runs_from_the_run_folder(venv_python, tmp_path, monkeypatch):
    """The program is made absolute (the run folder is the working directory), links kept."""
    monkeypatch.chdir(tmp_path)
    a = CommandAdapter(FIXTURES / "cube" / "model.bdf", command=["venv/bin/python", str(FRAMESOLVE), "{deck}"],
                       dialect=LegacyDialect(), trusted=True)
    assert a._command_for(Path("/x/run.dat"))[0] == str(tmp_path / "venv" / "bin" / "python")
    assert a.solve(LoadMatrix.unit([(5, 1)]), [(5, 1)]).values[0, 0] > 0


@pytest.mark.skipif(not HAVE_OPENSEES, reason="openseespy not installed")
def test_opensees_from_a_venv_of_its_own(tmp_path):
    """OpenSees installed only in another environment (here made visible to it alone through a
    ``.pth`` line): ``python = ".../venv/bin/python"`` runs the runner in that environment."""
    import openseespy

    from solver_adapters.opensees import OpenSeesAdapter
    python = make_venv(tmp_path / "osvenv", str(Path(openseespy.__file__).parents[1]))
    base = resolve_program(str(python))
    if subprocess.run([str(base), "-c", "import openseespy"], capture_output=True).returncode == 0:
        pytest.skip("the base interpreter has openseespy itself")
    deck = FIXTURES / "cube" / "model.bdf"
    a = OpenSeesAdapter(deck, python=python, trusted=True)
    loads = LoadMatrix.unit([(5, 1), (8, 6)])
    U = a.solve(loads, a.dofs()).values
    R = ReferenceAdapter(deck).solve(loads, a.dofs()).values
    assert np.max(np.abs(U - R)) <= 1e-11 * np.max(np.abs(R))
    assert sysconfig.get_paths()["purelib"] not in str(python)
