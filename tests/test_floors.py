"""The floors of the house: every package imports only from its own floor's package or from
lower floors, and no module imports, directly or through others, one that imports it back.

    studies                  the commands
    engines   scenes         the engines' adapters; scenes, motion and recordings
    own                      our algorithms, the exact reference and narrow phase
    interface                BroadPhase, the registry, the knobs, the pair format, the checks

Every import is counted, those inside functions too: a lazy import still makes the lower floor
depend on the higher one. The registry names its backends' modules as text and imports them on
request, which is what lets it stay on the ground floor.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLOORS = {"interface": 0, "own": 1, "engines": 2, "scenes": 2, "studies": 3}
PACKAGE_DIRS = {"interface": ROOT / "src", "own": ROOT / "src", "engines": ROOT / "src", "scenes": ROOT / "src",
                "studies": ROOT}


def modules() -> dict[str, Path]:
    """Every module of the project's packages, by dotted name."""
    found = {}
    for package, base in PACKAGE_DIRS.items():
        for path in (base / package).rglob("*.py"):
            parts = list(path.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def imported(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The project's modules that `name` imports, resolved to the longest known module name."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            candidates = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = ".".join(package[:len(package) - node.level + 1] + [node.module or ""]).strip(".") \
                if node.level else node.module
            candidates = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        for candidate in candidates:
            while candidate and candidate not in known:
                candidate = candidate.rpartition(".")[0]
            # A package the module lies in is loaded before it anyway ("from . import sibling"
            # names it): no edge of its own.
            if candidate and candidate != name and not name.startswith(candidate + "."):
                targets.add(candidate)
    return targets


def import_graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imported(name, path, known) for name, path in known.items()}


def floor(module: str) -> int:
    return FLOORS[module.split(".")[0]]


def test_every_package_of_the_project_has_a_floor():
    tops = {p.parent.name for p in (ROOT / "src").glob("*/__init__.py")} | {"studies"}
    assert tops == set(FLOORS), f"packages without a floor, or floors without a package: {tops ^ set(FLOORS)}"


def test_no_package_imports_from_a_higher_floor_or_from_a_package_beside_it():
    wrong = [f"{a} -> {b}" for a, targets in import_graph().items() for b in targets
             if a.split(".")[0] != b.split(".")[0] and floor(b) >= floor(a)]
    assert not wrong, "imports that climb or cross a floor:\n" + "\n".join(sorted(wrong))


def test_no_module_imports_itself_back_through_others():
    graph = import_graph()
    state: dict[str, int] = {}  # 1: being walked, 2: done
    cycles = []

    def walk(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(trail[trail.index(nxt):] + [nxt]))
            elif nxt not in state:
                walk(nxt, trail + [nxt])
        state[node] = 2

    for start in sorted(graph):
        if start not in state:
            walk(start, [start])
    assert not cycles, "import circles:\n" + "\n".join(cycles)


def test_the_walk_sees_a_climbing_import_and_a_circle(tmp_path):
    """The checks above can fail: on a made-up pair of modules they find what they look for."""
    low, high = tmp_path / "low.py", tmp_path / "high.py"
    low.write_text("def f():\n    from own import high\n")
    high.write_text("from interface import low\n")
    known = {"interface.low": low, "own.high": high}
    graph = {name: imported(name, path, known) for name, path in known.items()}
    assert graph == {"interface.low": {"own.high"}, "own.high": {"interface.low"}}
    assert floor("own.high") > floor("interface.low")


def test_a_kernel_of_ours_loads_without_the_floors_above_it():
    """Importing one of our structures pulls in the interface and our own modules only: no scene
    family, no engine binding, no progress bar."""
    code = ("import sys, own.grid, own.sap, own.tree, own.reference; "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'scenes', 'engines', 'studies', 'tqdm', 'pymunk'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
