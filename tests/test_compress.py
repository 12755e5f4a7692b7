"""own.grid's vector scan (own/compress.py): exact, and never writing past the pair buffer."""

from __future__ import annotations

import numpy as np
import pytest

import engines
from interface.pairs import keys
from own.brute import brute_pairs
from own.compress import SLACK_ROWS
from own.dimension import CIRCLES
from own.grid import grid_pairs
from scenes import generate


def dense_grid(positions, radii):
    """own.grid laid out for the scene, and the arguments of its pair kernel (the buffer last)."""
    grid = engines.create("own.grid")
    grid.reset(positions, radii)
    ids, centres, key, sradii = grid._slots
    return grid, (ids, centres, sradii, sradii, key, grid._start, grid._layout, grid._limit)


@pytest.mark.parametrize("vector", [True, False])
def test_the_pair_kernel_never_writes_past_its_buffer_and_is_exact_where_the_pairs_fit(vector):
    # A clump: scans of tens of slots, whose blocks of 8 store whole vectors past the last pair.
    scene = generate("clusters", 300, seed=1, box=(0.0, 0.0, 300.0, 300.0))
    _, args = dense_grid(scene.positions, scene.radii)
    expected = np.sort(keys(brute_pairs(scene.positions, scene.radii), 300))
    total, _ = grid_pairs(*args, vector, CIRCLES, np.empty((len(expected) + SLACK_ROWS, 2), dtype=np.int64))
    assert total == len(expected)
    for rows in [*range(0, 40), *range(total - 20, total + 3 * SLACK_ROWS)]:
        memory = np.full((rows + 64, 2), -7, dtype=np.int64)
        count, _ = grid_pairs(*args, vector, CIRCLES, memory[:rows])
        assert count == total  # every pair counted, whether it fitted or not
        assert (memory[rows:] == -7).all(), f"wrote past a buffer of {rows} rows"
        if count <= rows:
            np.testing.assert_array_equal(np.sort(keys(memory[:count], 300)), expected)


def test_centres_stored_by_row_take_the_scalar_scan_with_the_same_pairs():
    scene = generate("clusters", 500, seed=2, box=(0.0, 0.0, 400.0, 400.0))
    grid, args = dense_grid(scene.positions, scene.radii)
    by_row = np.ascontiguousarray(args[1])  # the vector scan reads columns; a C array must not reach it
    assert args[1].strides[0] == 8 and by_row.strides[0] == 16
    found = {}
    for name, centres in (("columns", args[1]), ("rows", by_row)):
        buf = np.empty((200000, 2), dtype=np.int64)
        count, _ = grid_pairs(args[0], centres, *args[2:], True, CIRCLES, buf)
        found[name] = np.sort(keys(buf[:count], 500))
    np.testing.assert_array_equal(found["columns"], found["rows"])
    np.testing.assert_array_equal(found["columns"], np.sort(keys(brute_pairs(scene.positions, scene.radii), 500)))


@pytest.mark.parametrize("specialise", [True, False])
def test_the_vector_scan_finds_every_pair_of_one_crowded_cell_in_any_id_order(specialise):
    # Spread over many cells, then all in one: the slots keep last frame's cell order, so ids
    # come in no order and each block holds ids both below and above the scanning object's (the
    # pair's min and max come from either); runs of 0 to 99 slots end mid-block. Coincident
    # centres and boxes that only touch count.
    rng = np.random.default_rng(3)
    radii = np.full(100, 0.6) if specialise else rng.uniform(0.0, 0.6, 100)
    crowded = rng.uniform(0.0, 1.0, (100, 2))
    crowded[:5] = crowded[5]
    crowded[6] = crowded[7] + [radii[6] + radii[7], 0.0]
    grid = engines.create("own.grid", vector=True, specialise=specialise, cell=100.0)
    grid.reset(rng.uniform(0.0, 5000.0, (100, 2)), radii)
    grid.update(crowded)
    ids = grid._slots[0]
    assert grid.stats()["cells"] == 1 and grid.stats()["vector"] == 1
    assert (np.diff(ids) < 0).sum() > 20, "the slots should hold the ids in no order"
    expected = np.sort(keys(brute_pairs(crowded, radii), 100))
    assert 6 * 100 + 7 in expected and len(expected) > 2000
    np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 100)), expected)
