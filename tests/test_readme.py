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
    assert "pytest" in tests and "mystran" in tests and "lint-imports" in tests
    ci = (ROOT / ".ci" / "run").read_text()
    assert tests in ci
