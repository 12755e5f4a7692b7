"""The README's first lines are the two set-up commands, and CI runs exactly the second."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    lines = (ROOT / "README.md").read_text().splitlines()
    start = lines.index("```bash") + 1
    return lines[start:start + 2]


def test_readme_starts_with_the_main_job_and_the_test_command():
    main_job, tests = readme_commands()
    assert main_job.endswith("python -m studies.compare --n 2048")
    assert tests.endswith("python -m pytest")
    assert "```bash" in (ROOT / "README.md").read_text().splitlines()[:4]


def test_ci_runs_the_readme_test_command():
    assert readme_commands()[1] in (ROOT / ".ci" / "run").read_text().splitlines()
