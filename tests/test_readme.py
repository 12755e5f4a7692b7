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


def test_ci_runs_the_readme_test_command_then_the_thorough_tier():
    """The README's command is the install and the fast tier; CI runs both, then --thorough."""
    install, tests = readme_commands()[1].rsplit(" && ", 1)
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert install in ci and tests in ci and f"{tests} --thorough" in ci
    assert ci.index(install) < ci.index(tests) < ci.index(f"{tests} --thorough")
