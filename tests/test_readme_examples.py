"""The README's worked examples are what the commands print: each ``$ blackbox ...`` block is run
(from a folder holding fresh copies of the fixtures it names, so nothing is cached) and its
printed lines compared with the README's, only timings allowed to differ."""

from __future__ import annotations

import re
import shlex
import shutil

import pytest

from blackbox.cli import main

from conftest import FIXTURES, ROOT, printed_lines_match


def worked_examples() -> list[tuple[str, str]]:
    """``(command, printed lines)`` of every README block that starts with ``$ blackbox``."""
    text = (ROOT / "README.md").read_text()
    out = []
    for block in re.findall(r"```\n(\$ blackbox .*?)```", text, re.S):
        command, _, printed = block.partition("\n")
        out.append((command[2:].strip(), printed))
    return out


def test_the_readme_has_its_worked_examples():
    commands = [c for c, _ in worked_examples()]
    assert commands == ["blackbox identify fixtures/cube --out out/cube",
                        "blackbox diagnose fixtures/undeclared/support_flexibility --out out/diag"]


@pytest.mark.parametrize("command, printed", worked_examples(), ids=lambda v: v.split()[1] if " " in v else None)
def test_a_worked_example_prints_what_the_readme_shows(command, printed, tmp_path, monkeypatch, capsys):
    words = shlex.split(command)[1:]
    study = words[1]
    shutil.copytree(FIXTURES.parent / study, tmp_path / study, ignore=shutil.ignore_patterns(".blackbox_cache"))
    monkeypatch.chdir(tmp_path)
    assert main(words) == 0
    got = capsys.readouterr().out.replace(str(tmp_path) + "/", "")
    assert not printed_lines_match(printed, got)
    if words[0] == "identify":          # "(A second run says `0 solver run(s) + 1 batch(es) from the cache`.)"
        shutil.rmtree(tmp_path / "out")
        assert main(words) == 0
        assert "0 solver run(s) + 1 batch(es) from the cache" in capsys.readouterr().out
        assert "(A second run says `0 solver run(s) + 1 batch(es) from the cache`.)" in (ROOT / "README.md").read_text()
