"""docs/plugin.md, followed literally: the plug-in package written from the page's text, installed
with pip into a fresh virtual environment, checked with ``blackbox conformance`` and used by
``blackbox identify``; what the commands print must be what the page shows (timings aside).

The fresh environment sees this checkout's packages (a ``.pth`` line that adds this environment's
site-packages, as a user's environment has blackbox installed) and gets the plug-in by
``pip install -e``, as the page says (``--no-deps``: its one dependency, blackbox, is there).
Building the editable wheel needs setuptools >= 68 and wheel: taken from this environment when it
has them, else pip fetches them as for any build (``pip install -e ".[test]"`` needs the same).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from conftest import FIXTURES, ROOT, printed_lines_match

PAGE = ROOT / "docs" / "plugin.md"


def page_parts() -> tuple[list[str], dict[str, str], list[str], dict[str, str]]:
    """From the page's worked example: the shell lines that make the package folder, the files
    (path -> text), the shell lines that install and use it, and what each ``$ command`` prints."""
    text = PAGE.read_text().split("## A complete plug-in, step by step", 1)[1].split("\n## ", 1)[0]
    blocks, current, before = [], None, ""          # (info string, text, the line before the fence)
    for line in text.splitlines():
        if line.startswith("```"):
            if current is None:
                current = (line[3:].strip(), [], before)
            else:
                blocks.append((current[0], "\n".join(current[1]) + "\n", current[2]))
                current = None
        elif current is not None:
            current[1].append(line)
        elif line.strip():
            before = line
    files = {re.match(r"File `([^`]+)`:", b)[1]: t for info, t, b in blocks if b.startswith("File `")}
    shell = [t for info, t, b in blocks if not info and not b.startswith("File `")]
    setup, use, shown = shell[0].strip().splitlines(), shell[1].strip().splitlines(), shell[2]
    printed = {}
    for block in re.split(r"^\$ ", shown, flags=re.M)[1:]:
        command, _, out = block.partition("\n")
        printed[command.strip()] = out
    return setup, files, use, printed


def _build_isolation_flag() -> list[str]:
    try:
        import setuptools
        ok = int(setuptools.__version__.split(".")[0]) >= 68 and importlib.util.find_spec("wheel") is not None
    except ImportError:
        ok = False
    return ["--no-build-isolation"] if ok else []


def fresh_environment(folder: Path) -> Path:
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(folder)], check=True, capture_output=True)
    python = folder / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()
    ours = sysconfig.get_paths()["purelib"]
    Path(site, "blackbox_here.pth").write_text(f"import site; site.addsitedir({ours!r})\n")
    return python


@pytest.mark.slow
def test_the_plugin_page_works_as_written(tmp_path):
    setup, files, use, printed = page_parts()
    assert set(files) == {"framesolve-blackbox/pyproject.toml", "framesolve-blackbox/framesolve_blackbox/__init__.py"}
    assert [c.split()[0] for c in use] == ["pip", "blackbox", "blackbox"]
    work = tmp_path / "checkout"                   # the page's commands run from a checkout's root
    for name in ("cube", "legacy_solver"):
        shutil.copytree(FIXTURES / name, work / "fixtures" / name, ignore=shutil.ignore_patterns(".blackbox_cache"))
    for line in setup:
        words = shlex.split(line)
        if words[:2] == ["mkdir", "-p"]:
            (work / words[2]).mkdir(parents=True)
        else:
            assert words[0] == "cp", line
            shutil.copy(work / words[1], work / words[2])
    for path, text in files.items():
        (work / path).write_text(text)
    python = fresh_environment(tmp_path / "env")
    outputs = {}
    env = {**os.environ, "PYTHONNOUSERSITE": "1"}
    for line in use:
        words = shlex.split(line)
        if words[0] == "pip":
            assert words[1:3] == ["install", "-e"]
            run = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q",
                                  "--no-deps", *_build_isolation_flag(), "-e", words[3]],
                                 cwd=work, capture_output=True, text=True, env=env)
            assert run.returncode == 0, run.stdout + run.stderr
            continue
        run = subprocess.run([str(python), "-m", "blackbox.cli", *words[1:]], cwd=work, capture_output=True,
                             text=True, env=env, timeout=600)
        assert run.returncode == 0, run.stdout + run.stderr
        outputs[line] = run.stdout.replace(str(work) + os.sep, "")
    assert set(printed) == set(outputs)
    for command, shown in printed.items():
        assert not printed_lines_match(shown, outputs[command])
    # the page's claim: the same estimate as with the reference solver
    import json

    import blackbox
    got = json.loads((work / "out" / "cube-framesolve" / "result.json").read_text())
    ref = blackbox.identify(FIXTURES / "cube", profile=False).result
    assert got["solver"]["adapter"] == "framesolve"
    assert abs(got["fit"]["reduced_chi2"] - ref.reduced_chi2) < 1e-8 * ref.reduced_chi2


def test_the_page_counts_its_lines_right():
    _, files, _, _ = page_parts()
    toml = files["framesolve-blackbox/pyproject.toml"]
    code = files["framesolve-blackbox/framesolve_blackbox/__init__.py"]
    count = lambda t: sum(1 for line in t.splitlines() if line.strip())      # noqa: E731
    assert f"{count(toml)} lines of `pyproject.toml` and {count(code)} lines of Python" in PAGE.read_text()
