"""Shared test settings: hypothesis profiles (seeded, no deadline: the first call JIT-compiles),
a check after every test that it left the checkout as it was (every test writes under its own
temporary folder: never results/ or docs/ of the repository), and one temporary folder for the
whole run, removed at its end, so that what engines and Dask leave in the temporary directory
(PhysX's hub lock, Dask's scratch space) does not stay on the machine."""

import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

ROOT = Path(__file__).resolve().parents[1]

def pytest_configure(config):
    # Before anything reads it: child processes inherit TMPDIR, and libraries read it when they start.
    if "BROADPHASE_TEST_TMPDIR" not in os.environ:
        folder = tempfile.mkdtemp(prefix="broadphase-tests-")
        os.environ["TMPDIR"] = os.environ["BROADPHASE_TEST_TMPDIR"] = folder
        tempfile.tempdir = None  # gettempdir() reads TMPDIR again
        # Removed at exit, after what registered later (multiprocessing removes its own folder there).
        atexit.register(shutil.rmtree, folder, ignore_errors=True)


settings.register_profile(
    "default", deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile(
    "thorough", deadline=None, max_examples=1000, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))


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


@pytest.fixture(autouse=True)
def leaves_the_checkout_clean():
    before = checkout_state()
    yield
    after = checkout_state()
    changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
    # Caches the interpreter and tools keep are theirs to write.
    changed = [k for k in changed if not k.startswith((".pytest_cache", ".hypothesis", "__pycache__"))]
    assert not changed, f"the test wrote into the checkout: {changed}"
