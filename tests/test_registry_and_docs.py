"""The house rules: backend metadata in one place, one option vocabulary, commands that run from
anywhere, and no exact own backend left out of the exactness tests."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pandas as pd
import pytest

import engines
from fakes import register
from own.brute import Brute
from studies import COMMANDS, bench, scenes, tune
from test_own_exact import EXACT

ROOT = Path(__file__).resolve().parents[1]
# The commands that measure and write rows: each offers the whole output vocabulary.
ROW_WRITERS = ["compare", "essay", "stress", "scale", "tune", "recommend", "queries"]


def test_every_backend_belongs_to_a_registered_family():
    for name in engines.names():
        family = engines.family(name)
        assert family.kind in ("own", "essay", "engine", "particle", "library") and family.colour and family.title


def test_every_family_package_is_pinned_in_pyproject_as_the_registry_says():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    for family in engines.FAMILIES.values():
        where = project["optional-dependencies"][family.extra] if family.extra else project["dependencies"]
        for requirement in family.requirements:
            assert requirement in where, (family.name, requirement)
            if family.kind in ("engine", "particle"):
                assert "==" in requirement, f"{family.name}: engine and particle library versions are pinned"
    # The test extra installs every engine, so every adapter is tested.
    extras = {f.extra for f in engines.FAMILIES.values() if f.extra}
    tested = {extra for dep in project["optional-dependencies"]["test"] if "[" in dep
              for extra in re.sub(r".*\[(.*)\].*", r"\1", dep).split(",")}
    assert extras <= tested, f"the test extra leaves out {extras - tested}"


def test_an_unavailable_backend_says_how_to_install_it(monkeypatch):
    from interface import registry

    monkeypatch.setitem(registry.BACKENDS, "chipmunk.missing", registry.Entry("engines.no_such_adapter:Nothing"))
    with pytest.raises(ValueError, match=r"not available here \(ModuleNotFoundError.*install it with: pip install "
                                         r"\"pymunk==7\.3\.1\""):
        engines.create("chipmunk.missing")
    assert "install it with" in engines.unavailable()["chipmunk.missing"]


class Planned(Exception):
    """Raised where a study would start running its plan."""


class OneOfOurs(Brute):
    """A backend of ours the studies have never heard of, but for its registered roles."""

    name = "own.newcomer"


class OursOnEveryCore(Brute):
    name = "own.newcomer_parallel"


def test_a_backend_registered_with_roles_is_in_every_study_that_runs_them(monkeypatch, tmp_path):
    coherence = ({"coherent": False}, {"coherent": True})
    register(monkeypatch, OneOfOurs, roles=engines.Roles(tuned=True, structured=True, bench_row="own.newcomer",
                                                          coherence=coherence))
    register(monkeypatch, OursOnEveryCore, roles=engines.Roles(bench_row="own.newcomer", every_core=True))
    # bench: its row on one thread, its parallel form measured apart, and the coherence table.
    assert bench.bench_rows(2, every_core=False)["own.newcomer"] == ["own.newcomer"]
    assert bench.bench_rows(2, every_core=True)["own.newcomer"] == ["own.newcomer_parallel"]
    assert "own.newcomer" not in bench.bench_rows(2, every_core=True).get("own.grid", [])
    assert bench.coherence_settings()["own.newcomer"] == coherence
    # every core: never set against the engines on one thread.
    assert engines.ours_on_one_thread("own.newcomer") and not engines.ours_on_one_thread("own.newcomer_parallel")
    # scenes: a structured backend over 3x our fastest is named in the verdict.
    table = pd.DataFrame({"total_ms": [1.0, 4.0, 0.5], "broad_ms": [1.0, 4.0, 0.5], "missed_total": [0, 0, 0]},
                         index=["own.grid", "own.newcomer", "own.newcomer_parallel"])
    assert scenes.verdict(table)["slow"] == {"own.newcomer": 4.0}
    # tune: among the backends its scene families run.
    tuned = []

    def planned(runner, scene, backends, args, exact_only=False):
        tuned.extend(backends)
        raise Planned  # the plan is all this test wants: stop before anything runs

    monkeypatch.setattr(tune, "run_tune", planned)
    monkeypatch.setattr(tune, "QUICK_FAMILIES", ("uniform r=10",))
    monkeypatch.setattr(tune, "QUICK_FAMILY_SIZES", (64,))
    with pytest.raises(Planned):
        tune.main(["--families", "--quick", "--out", str(tmp_path / "o"), "--report-dir", str(tmp_path / "r")])
    assert "own.newcomer" in tuned and "own.newcomer_parallel" not in tuned


def test_roles_are_read_from_the_registry_alone():
    assert engines.with_role("every_core") == ["own.grid_parallel", "own.sap_parallel"]
    assert set(engines.with_role("tuned")) == set(engines.with_role("structured"))
    with pytest.raises(ValueError, match="unknown role 'fast'"):
        engines.with_role("fast")


def test_every_registered_exact_own_backend_is_in_the_exactness_tests():
    tested = {name for name, _ in EXACT}
    exact_own = {n for n in engines.names() if engines.of_kind(n, "own") and engines.backend_class(n).exact}
    assert exact_own <= tested, f"not in tests/test_own_exact.py EXACT: {sorted(exact_own - tested)}"


def test_the_readme_and_engines_page_name_every_backend_and_engine_family():
    readme = (ROOT / "README.md").read_text()
    for name in engines.names():
        assert f"`{name}`" in readme or f"`.{name.split('.')[1]}`" in readme, f"README's backend table lacks {name}"
    page = (ROOT / "docs" / "engines.md").read_text()
    for family in engines.FAMILIES.values():
        if family.kind in ("engine", "particle", "library"):
            for package in family.packages:
                assert package in page, f"docs/engines.md says nothing of {package}"


def test_knob_values_are_beside_the_defaults_they_tune():
    for name in engines.available():
        cls = engines.backend_class(name)
        for knob in cls.sweeps:
            assert knob.param in cls.defaults, (name, knob.param)


def options_of(command: str) -> dict[str, str]:
    """Option -> its help text with the default left out, as the command's parser has it."""
    parser = importlib.import_module(f"studies.{command}").parser()
    return {a.option_strings[-1]: re.sub(r"\s*\(default[^)]*\)", "", a.help or "").strip()
            for a in parser._actions if a.option_strings}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_has_help_and_a_docstring(command, capsys):
    module = importlib.import_module(f"studies.{command}")
    assert module.__doc__.startswith(f"`python -m studies.{command}")
    with pytest.raises(SystemExit) as done:
        module.main(["--help"])
    assert done.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: python -m studies.{command}")


def test_each_shared_option_means_the_same_in_every_command():
    seen: dict[str, dict[str, str]] = {}
    for command in COMMANDS:
        for option, text in options_of(command).items():
            seen.setdefault(option, {})[command] = text
    for option in ("--frames", "--repeat", "--budget", "--timeout", "--memory", "--out", "--resume", "--report-only",
                   "--n", "--dist", "--radius", "--radii", "--speed", "--seed", "--scene", "--quick"):
        meanings = set(seen.get(option, {}).values())
        if option in ("--frames", "--quick", "--out"):  # the words differ where the study's own part does
            first = {t.split(":")[0].split(" (")[0].split(",")[0] for t in meanings}
            assert len(first) == 1 or option == "--quick", f"{option}: {seen[option]}"
            continue
        assert len(meanings) == 1, f"{option} means different things: {seen[option]}"
    assert all("as globs" in t for t in seen["--backends"].values()), seen["--backends"]
    for command in ROW_WRITERS:
        for option in ("--out", "--resume", "--report-only", "--frames", "--repeat", "--budget", "--timeout",
                       "--memory"):
            assert command in seen[option], f"{command} lacks {option}"


@pytest.mark.thorough
def test_python_m_studies_lists_the_commands_and_the_console_script_runs_from_anywhere(tmp_path):
    listed = subprocess.run([sys.executable, "-m", "studies"], cwd=tmp_path, capture_output=True, text=True)
    assert listed.returncode == 0 and all(name in listed.stdout for name in COMMANDS)
    script = Path(sys.executable).with_name("broadphase")
    assert script.exists(), "the console script is installed with the package"
    done = subprocess.run([str(script), "compare", "--n", "32", "--quick", "--backends", "own.grid", "--out",
                           str(tmp_path / "o")], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "o" / "results.csv").exists()
    unknown = subprocess.run([str(script), "nope"], cwd=tmp_path, capture_output=True, text=True)
    assert unknown.returncode == 2 and "unknown command 'nope'" in unknown.stderr


def test_the_architecture_page_is_linked_and_names_every_command():
    assert "docs/ARCHITECTURE.md" in (ROOT / "README.md").read_text()
    page = (ROOT / "docs" / "ARCHITECTURE.md").read_text()
    for command in COMMANDS:
        assert f"studies/{command}.py" in page
    assert "## Add a backend" in page and "## Add a study" in page
