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


def test_the_readme_bench_figures_are_those_of_docs_bench():
    """README's Performance paragraph quotes docs/bench/bench.json (one run of `blackbox bench`):
    run counts and wall-time ratios of the finite differences, per adapter."""
    import json

    rows = json.loads((ROOT / "docs" / "bench" / "bench.json").read_text())
    text = " ".join((ROOT / "README.md").read_text().split())

    def span(adapter, method, key, digits=False):
        vals = [r[key] for r in rows if r["adapter"] == adapter and r["method"] == method]
        lo, hi = min(vals), max(vals)
        return (f"{lo}-{hi}" if not digits else f"{round(lo)}-{round(hi)}")

    assert (f"forward differences {span('reference', 'forward', 'solver_runs')} runs and "
            f"{span('reference', 'forward', 'ratio_to_blackbox', True)} times the wall time") in text
    assert (f"central differences {span('reference', 'central', 'solver_runs')} runs and "
            f"{span('reference', 'central', 'ratio_to_blackbox', True)} times") in text
    mys = [r["ratio_to_blackbox"] for r in rows if r["adapter"] == "mystran" and r["method"] != "blackbox"]
    assert f"the factors are {round(min(mys))}-{round(max(mys))}" in text
