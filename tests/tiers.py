"""The two tiers of the suite. `pytest` runs the fast tier: every backend against the exact answer
on small scenes, each property-based test at a modest share of its examples, each study once.
`pytest --thorough` runs what the fast tier leaves out: the tests marked `thorough` (large n,
long recordings, fresh interpreters, subprocess and cluster runs) and every property-based test
again at its full count of examples."""

from __future__ import annotations

from hypothesis import settings

# Set by conftest.py from the command line before any test module is imported.
THOROUGH = False
# The fast tier's share of a property-based test's examples, and the fewest it runs.
FAST_SHARE = 0.1
FEWEST = 4


def examples(full: int) -> settings:
    """Hypothesis settings of `full` examples in the thorough tier, a share of them in the fast one."""
    return settings(max_examples=full if THOROUGH else max(FEWEST, round(full * FAST_SHARE)))
