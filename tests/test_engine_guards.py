"""Every backend fed the inputs that crashed, hung or traced back through an engine (extreme and
tiny radii, reaches that overflow a double, everything at one point, statics that move), each in
a forked child with a time limit: the answer is exact (every due pair among the candidates) or a
one-line ValueError naming the backend, raised at the interface, never a crash, a hang, an
exception from inside a library or a silent miss the backend does not declare."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import pytest
from test_engines import LIMITATIONS, UNRELIABLE

import engines
import tiers
from interface.pairs import missing
from own.reference import box_pairs, narrow_phase

TIME_LIMIT_S = 60.0  # a hang; every answer here takes well under a second
RNG = np.random.default_rng(51)
BASE = RNG.uniform(0.0, 100.0, (50, 3))  # 50 centres in a box of 100, r = 3: ordinary pairs among them
TINY = np.nextafter(0.0, 1.0)  # the smallest subnormal double


@dataclass
class Case:
    name: str
    positions: np.ndarray  # (n, 3): the first two columns in 2D
    radii: np.ndarray
    moved: np.ndarray | None = None  # the positions of a second frame (update), where it has one
    static: np.ndarray | None = None


def _with(radius_at_0: float) -> np.ndarray:
    radii = np.full(len(BASE), 3.0)
    radii[0] = radius_at_0
    return radii


CASES = [
    Case("radius 1e-300 among r=3", BASE, _with(1e-300)),
    Case("subnormal radius among r=3", BASE, _with(TINY)),
    Case("every radius 1e-300", BASE * 1e-297, np.full(len(BASE), 1e-300)),
    Case("every radius subnormal", BASE, np.full(len(BASE), TINY)),
    Case("every radius 1e-300, coincident pairs", np.repeat(BASE[:25], 2, axis=0), np.full(len(BASE), 1e-300)),
    Case("radius 1e300 among r=3", BASE, _with(1e300)),
    Case("radii 1e308 and 1", np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 5.0]]), np.array([1e308, 1.0])),
    Case("a radius sum that overflows", np.array([[0.0, 0.0, 0.0], [1e308, 0.0, 0.0], [5.0, 5.0, 5.0]]),
         np.array([1e308, 1e308, 1.0])),
    Case("one object at 1e308", np.vstack([BASE[1:], [1e308, 1e308, 1e308]]), np.full(len(BASE), 3.0)),
    Case("reach overflows a double", np.vstack([BASE[1:], [1.7e308, 1.7e308, 1.7e308]]),
         np.r_[np.full(len(BASE) - 1, 3.0), 1e308]),
    Case("coordinates of 1e308", BASE * 1e306, np.full(len(BASE), 3.0)),
    Case("400 at one point, radius 0", np.zeros((400, 3)), np.zeros(400)),
    Case("two coincident points of radius 1e-300", np.zeros((2, 3)), np.full(2, 1e-300)),
    Case("radius 0 among r=3, moved", BASE, np.where(np.arange(len(BASE)) % 5 == 0, 0.0, 3.0), moved=BASE + 0.5),
    Case("a static that moves", BASE, np.full(len(BASE), 3.0),
         moved=np.vstack([BASE[:1] + 40.0, BASE[1:]]), static=np.arange(len(BASE)) < 10),
]


def run_case(name: str, case: Case, dim: int, conn) -> None:
    """In the child: reset (and update) the backend; send each frame's pairs, or the error."""
    try:
        backend = engines.create(name)
        positions = np.ascontiguousarray(case.positions[:, :dim])
        backend.reset(positions, case.radii, static=case.static)
        found = [backend.pairs().tolist()]
        if case.moved is not None:
            backend.update(np.ascontiguousarray(case.moved[:, :dim]))
            found.append(backend.pairs().tolist())
        backend.close()
        conn.send(["pairs", found, backend.reports])
    except Exception as exc:  # noqa: BLE001 - what it was is the result
        conn.send(["error", type(exc).__name__, str(exc)])
    finally:
        conn.close()


def outcome_of(target, *args) -> list:
    """What `target(*args, conn)` sends from a forked child (["pairs", ...], ["error", type,
    message]), or ["hang"] past the time limit, or ["crash", exit status]."""
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=target, args=(*args, child), daemon=True)
    proc.start()
    child.close()
    if not parent.poll(TIME_LIMIT_S):
        proc.kill()
        proc.join()
        return ["hang"]
    try:
        message = parent.recv()
    except EOFError:
        proc.join()
        return ["crash", proc.exitcode]
    proc.join(timeout=10)
    return message


def outcome(name: str, case: Case, dim: int) -> list:
    """["pairs", pairs per frame, reports], ["error", type, message], ["hang"] or ["crash", exit
    status] of one backend on one case."""
    return outcome_of(run_case, name, case, dim)


def available_in(dim: int) -> list[str]:
    return [n for n in engines.available() if engines.works_in(n, dim)]


def every_outcome(dim: int, names: list[str]) -> dict[str, dict[str, list]]:
    """Case name -> backend -> outcome of the cases `names`, for every backend that works in `dim`."""
    return {case.name: {name: outcome(name, case, dim) for name in available_in(dim)} for case in CASES
            if case.name in names}


# The fast tier's cases, one of each kind of input (sizes below a double's resolution, a reach that
# overflows, a static that moves); the thorough tier runs the others.
FAST_CASES = ["every radius subnormal", "a radius sum that overflows", "a static that moves"]


def tier_cases() -> list[Case]:
    return [c for c in CASES if (c.name in FAST_CASES) != tiers.THOROUGH]


@pytest.fixture(scope="module")
def outcomes() -> dict[int, dict[str, dict[str, list]]]:
    """Every outcome of this tier's cases, from a fresh process per dimension that never runs an
    engine itself: forked from this test process, which has (Rapier's worker threads, TBB's), a
    child could wait forever on a pool whose threads did not come along."""
    found = {}
    names = [c.name for c in tier_cases()]
    for dim in (2, 3):
        run = subprocess.run([sys.executable, __file__, str(dim), *names], capture_output=True, text=True,
                             timeout=TIME_LIMIT_S * 20 + 600)
        assert run.returncode == 0, run.stderr[-3000:]
        found[dim] = json.loads(run.stdout.strip().splitlines()[-1])
    return found


def declared(name: str, positions: np.ndarray, radii: np.ndarray) -> bool:
    """Whether the backend declares that it may miss pairs on this input (test_engines' LIMITATIONS)."""
    return name in UNRELIABLE or any(applies(positions, radii) for applies in LIMITATIONS.get(name, []))


@pytest.mark.parametrize("case", [c if c.name in FAST_CASES else pytest.param(c, marks=pytest.mark.thorough)
                                  for c in CASES], ids=[c.name for c in CASES])
@pytest.mark.parametrize("dim", [2, 3])
def test_every_backend_answers_exactly_or_refuses_in_one_line(outcomes, case, dim):
    problems = []
    assert set(outcomes[dim][case.name]) == set(available_in(dim))
    for name, result in outcomes[dim][case.name].items():
        if result[0] == "hang":
            problems.append(f"{name}: no answer in {TIME_LIMIT_S:g} s")
        elif result[0] == "crash":
            problems.append(f"{name}: crashed (exit status {result[1]})")
        elif result[0] == "error":
            kind, text = result[1:]
            # Our refusals name the backend first (BroadPhase's guards); an engine's own ValueError,
            # raised from inside the adapter's call, does not.
            if kind != "ValueError" or not text.startswith(f"{name}: ") or "\n" in text.strip():
                problems.append(f"{name}: {kind}: {text[:200]}")
        else:
            found, reports = result[1], result[2]
            frames = [case.positions[:, :dim]] + ([case.moved[:, :dim]] if case.moved is not None else [])
            for k, (positions, got) in enumerate(zip(frames, found)):
                due = box_pairs(positions, case.radii, static=case.static)
                if reports == "contacts":
                    due = narrow_phase(positions, case.radii, due)
                lost = missing(due, np.array(got, dtype=np.int64).reshape(-1, 2), len(case.radii))
                if len(lost) and not declared(name, positions, case.radii):
                    problems.append(f"{name}: missed {len(lost)} of {len(due)} pairs in frame {k}")
    assert not problems, "\n".join(problems)


def test_the_cases_are_what_they_say():
    by_name = {c.name: c for c in CASES}
    assert by_name["subnormal radius among r=3"].radii[0] == 5e-324
    with np.errstate(over="ignore"):
        assert not np.isfinite(by_name["reach overflows a double"].positions[-1, 0] + 1e308)
    assert os.cpu_count()


if __name__ == "__main__":  # the fixture's driver: one dimension's outcomes as JSON
    print(json.dumps(every_outcome(int(sys.argv[1]), sys.argv[2:])))
