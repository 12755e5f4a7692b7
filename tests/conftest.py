"""Shared test settings: the two tiers (tiers.py), hypothesis seeded with no deadline (the first
call JIT-compiles), a check after every test module that it left the checkout as it was (every
test writes under its own temporary folder: never results/ or docs/ of the repository), and one
temporary folder for the whole run, removed at its end, so that what engines and Dask leave in the
temporary directory (PhysX's hub lock, Dask's scratch space) does not stay on the machine."""

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

import tiers

ROOT = Path(__file__).resolve().parents[1]


def pytest_addoption(parser):
    parser.addoption("--thorough", action="store_true",
                     help="run the thorough tier: the tests marked thorough, and every property-based "
                          "test at its full count of examples (the fast tier runs without it)")


def pytest_configure(config):
    tiers.THOROUGH = config.getoption("thorough")
    # Before anything reads it: child processes inherit TMPDIR, and libraries read it when they start.
    if "BROADPHASE_TEST_TMPDIR" not in os.environ:
        folder = tempfile.mkdtemp(prefix="broadphase-tests-")
        os.environ["TMPDIR"] = os.environ["BROADPHASE_TEST_TMPDIR"] = folder
        tempfile.tempdir = None  # gettempdir() reads TMPDIR again
        # Removed at exit, after what registered later (multiprocessing removes its own folder there).
        atexit.register(shutil.rmtree, folder, ignore_errors=True)


def pytest_sessionstart(session):
    """Before the test workers start (this runs first, in the process that starts them): our
    kernels compiled into numba's cache by two processes at once, each over half of our
    backends, so that the workers load them rather than each compile every kernel again."""
    workers = getattr(session.config.option, "numprocesses", None)
    if os.environ.get("PYTEST_XDIST_WORKER") or not workers:
        return
    import subprocess
    import sys

    import engines

    ours = [n for n in engines.names() if engines.of_kind(n, "own")]
    # Two halves of about equal compile time (5-6 min each with an empty cache, 2 cores), each
    # holding the backends that share kernels, so that no kernel compiles in both: own.sap_parallel
    # alone (its parallel kernels take about 5 min) with the trees; the rest together.
    first = [n for n in ours if n in ("own.sap_parallel", "own.bvh", "own.quadtree")]
    halves = (first, [n for n in ours if n not in first])
    probes = [subprocess.Popen([sys.executable, str(Path(__file__).with_name("compile_probe.py")), "--every-path",
                                *half], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
              for half in halves]
    for probe in probes:
        _, err = probe.communicate()
        # A failure here shows again, in the tests that reach the same kernel.
        if probe.returncode:
            print(f"warming numba's cache: {(err.strip().splitlines() or ['?'])[-1]}", file=sys.stderr)


settings.register_profile(
    "default", deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("default")


def pytest_collection_modifyitems(config, items):
    """The fast tier leaves out the tests marked thorough; the thorough tier runs those and the
    property-based tests (at their full count), and leaves the rest to the fast tier."""
    def thorough(item):
        return item.get_closest_marker("thorough") is not None

    def property_based(item):
        return getattr(getattr(item, "obj", None), "is_hypothesis_test", False)

    keep = (lambda item: thorough(item) or property_based(item)) if tiers.THOROUGH else \
        (lambda item: not thorough(item))
    config.hook.pytest_deselected(items=[item for item in items if not keep(item)])
    items[:] = [item for item in items if keep(item)]


def checkout_state() -> dict[str, tuple[int, int]]:
    """The repository's top-level entries, those of results/, and every file of docs/ with its
    size and modification time."""
    state = {entry.name: (0, 0) for entry in os.scandir(ROOT)}
    results = ROOT / "results"
    if results.is_dir():
        state.update({f"results/{entry.name}": (0, 0) for entry in os.scandir(results)})
    for path in (ROOT / "docs").rglob("*"):
        if path.is_file():
            stat = path.stat()
            state[str(path.relative_to(ROOT))] = (stat.st_size, stat.st_mtime_ns)
    return state


@pytest.fixture(autouse=True, scope="module")
def leaves_the_checkout_clean():
    before = checkout_state()
    yield
    after = checkout_state()
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    # Caches the interpreter and tools keep are theirs to write.
    changed = [k for k in changed if not k.startswith((".pytest_cache", ".hypothesis", "__pycache__"))]
    assert not changed, f"a test of this module wrote into the checkout: {changed}"
