"""The registry and the input checks at the interface boundary."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import engines
from interface.pairs import canonical, is_canonical
from own.brute import brute_pairs
from own.reference import box_pairs, narrow_phase
from scenes import generate
from tiers import examples

OWN = ["own.brute", "own.sap", "own.grid", "own.grid_incremental", "own.quadtree", "own.bvh", "essay.sap", "essay.grid", "essay.quadtree"]


def test_registry_lists_own_backends_as_available():
    assert set(OWN) <= set(engines.names())
    assert set(OWN) <= set(engines.available())
    assert not set(OWN) & set(engines.unavailable())


def test_unknown_backend_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown backend 'own.nope'"):
        engines.create("own.nope")


def test_unknown_parameter_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown parameter.*cells.*known: cell, coherent, p"):
        engines.create("own.grid", cells=3)


@pytest.mark.parametrize(
    ("name", "params", "message"),
    [
        ("own.grid", {"p": 0}, "p must be an integer >= 1"),
        ("own.grid", {"p": 2.5}, "p must be an integer"),
        ("own.grid", {"cell": -1.0}, "cell must be a positive"),
        ("own.grid", {"p": 4, "cell": 1.0}, "not both"),
        ("own.grid", {"vector": "yes"}, "vector must be True, False or None"),
        ("own.quadtree", {"capacity": 0}, "capacity must be an integer >= 1"),
        ("own.quadtree", {"max_depth": 27}, "max_depth must be at most 26"),
        ("own.bvh", {"leaf_size": 0}, "leaf_size must be an integer >= 1"),
        ("own.sap", {"axis": "w"}, "axis must be one of"),
        ("own.sap", {"sweep": "fast"}, "sweep must be one of auto, plain, sparse, got 'fast'"),
        ("own.sap", {"strips": "yes"}, "strips must be one of auto, on, off, got 'yes'"),
        ("own.sap_parallel", {"parallel_from": -1}, "parallel_from must be an integer >= 0"),
        ("own.grid_parallel", {"parallel_from": 1.5}, "parallel_from must be an integer >= 0"),
        ("essay.quadtree", {"capacity": "5"}, "capacity must be an integer"),
    ],
)
def test_bad_parameters(name, params, message):
    with pytest.raises(ValueError, match=message):
        engines.create(name, **params)


def test_patterns_match_globs_and_reject_typos():
    assert engines.match("own.*") == [n for n in engines.names() if n.startswith("own.")]
    assert engines.match("own.grid, essay.sap") == ["own.grid", "essay.sap"]
    with pytest.raises(ValueError, match="'owm.\\*' matches no backend"):
        engines.match("owm.*")


@pytest.mark.parametrize("name", OWN)
@pytest.mark.parametrize(
    ("positions", "radii", "message"),
    [
        ([[0.0, np.nan]], [1.0], "row 0 is not finite"),
        ([[0.0, 0.0], [np.inf, 1.0]], [1.0, 1.0], "row 1 is not finite"),
        ([[0.0, 0.0]], [-1.0], "radius 0 is negative"),
        ([[0.0, 0.0]], [np.nan], "radius 0 is not finite"),
        ([0.0, 0.0, 1.0], [1.0], r"positions must have shape \(n, 2\)"),
        ([[0.0, 0.0, 0.0, 0.0]], [1.0], r"positions must have shape \(n, 2\)"),
        ([[0.0, 0.0]], [1.0, 2.0], r"radii must have shape \(1,\)"),
    ],
)
def test_bad_input_is_rejected_with_a_clear_message(name, positions, radii, message):
    with pytest.raises(ValueError, match=message):
        engines.create(name).reset(positions, radii)


@pytest.mark.parametrize("name", OWN)
def test_update_checks_the_object_count_and_values(name):
    backend = engines.create(name)
    backend.reset([[0.0, 0.0], [1.0, 1.0]], [1.0, 1.0])
    with pytest.raises(ValueError, match="has 3 rows but the scene has 2"):
        backend.update(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="not finite"):
        backend.update([[0.0, 0.0], [np.nan, 0.0]])


def test_describe_names_the_parameters():
    assert engines.create("own.grid", p=16).describe() == \
        "own.grid(cell=None, coherent=True, p=16, specialise=True, vector=None)"
    assert engines.create("own.brute").describe() == "own.brute"


def test_canonical_orders_and_deduplicates():
    got = canonical([3, 1, 2, 1, 5], [1, 3, 2, 3, 0])
    assert got.tolist() == [[0, 5], [1, 3]]
    assert is_canonical(got, 6) is None
    assert "twice" in is_canonical(np.array([[0, 1], [0, 1]]), 2)
    assert "i >= j" in is_canonical(np.array([[1, 0]]), 2)


@examples(200)
@given(st.lists(st.tuples(st.integers(0, 2**40), st.integers(0, 2**40)), max_size=60))
def test_canonical_is_the_sorted_set_of_pairs(rows):
    # Engines' pairs go through it (ids up to 2^40: its keys must not overflow or collide).
    expected = sorted({(min(a, b), max(a, b)) for a, b in rows if a != b})
    got = canonical([a for a, _ in rows], [b for _, b in rows])
    assert got.dtype == np.int64 and got.shape == (len(expected), 2)
    assert [tuple(r) for r in got.tolist()] == expected


def test_narrow_phase_counts_touching_circles():
    pos = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0 + 1e-12], [3.0, 3.0]])
    pairs = brute_pairs(pos, np.ones(4))
    assert narrow_phase(pos, np.ones(4), pairs).tolist() == [[0, 1]]
