"""The exact answer every backend is checked against (own/reference.py): equal to brute force on
random, clumped, lattice, touching and extreme scenes, in 2D and 3D, balls and boxes, at every size
the studies use it, and sharing no code with the structures it checks."""

from __future__ import annotations

import ast
import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from interface.pairs import keys
from own.brute import brute_pairs
from own.reference import box_pairs
from scenes import generate
from strategies import any_scene, box_scenes, sphere_scenes, touching_boxes
from tiers import examples

REFERENCE = Path(__file__).resolve().parents[1] / "src" / "own" / "reference.py"


def loop_pairs(positions, sizes):
    """The rule pair by pair: closed intervals on the float64 bounds c - h, c + h on every axis."""
    half = sizes[:, None] if sizes.ndim == 1 else sizes
    lo, hi = positions - half, positions + half
    return [(i, j) for i, j in itertools.combinations(range(len(positions)), 2)
            if ((lo[i] <= hi[j]) & (lo[j] <= hi[i])).all()]


def assert_reference_is_brute_force(positions, sizes):
    got = box_pairs(positions, sizes)
    np.testing.assert_array_equal(got, brute_pairs(positions, sizes))
    assert got.dtype == np.int64 and got.shape[1:] == (2,)


def test_the_reference_imports_no_structure_of_ours():
    imported = set()
    for node in ast.walk(ast.parse(REFERENCE.read_text())):
        if isinstance(node, ast.ImportFrom):
            imported.add(("." * node.level) + (node.module or ""))
        elif isinstance(node, ast.Import):
            imported.update(alias.name for alias in node.names)
    # numpy and numba, the pair array's type, and the dimensions' markers (tuples of zeros).
    assert imported <= {"__future__", "numba", "numpy", "interface.base", ".dimension"}, imported


@given(scene=any_scene)
@examples(60)
def test_equal_to_brute_force_on_random_and_adversarial_circles(scene):
    assert_reference_is_brute_force(*scene)


@given(scene=sphere_scenes())
@examples(60)
def test_equal_to_brute_force_on_spheres(scene):
    assert_reference_is_brute_force(*scene)


@pytest.mark.parametrize("dim", [2, 3])
@given(data=st.data())
@examples(60)
def test_equal_to_brute_force_on_boxes_touching_and_extreme(dim, data):
    scene = data.draw(st.one_of(box_scenes(dim), touching_boxes(dim)))
    assert_reference_is_brute_force(*scene)


def test_equal_to_the_rule_pair_by_pair_on_touching_tiles():
    # A 10 x 10 tile map of side 0.1 (centres 0.05 + 0.1 k): every neighbour, side or corner, touches.
    k = np.arange(10)
    centres = np.array([(0.05 + 0.1 * i, 0.05 + 0.1 * j) for i in k for j in k])
    extents = np.full((100, 2), 0.05)
    got = box_pairs(centres, extents)
    assert sorted(map(tuple, got.tolist())) == loop_pairs(centres, extents)
    assert len(got) == 238


@pytest.mark.parametrize("dim", [2, 3])
def test_equal_to_brute_force_past_a_few_thousand_objects(dim):
    """Clumped gas, long boxes across it and equal spheres: sizes the studies check at 4096 and on."""
    rng = np.random.default_rng(dim)
    n = 3500
    positions = rng.uniform(0, 400 if dim == 2 else 60, (n, dim))
    positions[: n // 3] = rng.normal(200 if dim == 2 else 30, 15, (n // 3, dim))
    extents = rng.uniform(0, 2, (n, dim))
    extents[:40, 0] = rng.uniform(50, 300, 40)
    assert_reference_is_brute_force(positions, extents)
    assert_reference_is_brute_force(positions, np.exp(rng.uniform(0.0, np.log(6.0), n)))
    scene = generate("clusters", n, seed=8)
    assert_reference_is_brute_force(scene.positions, scene.radii)


def test_pairs_are_sorted_unique_and_every_object_at_one_point_pairs_with_every_other():
    n = 300
    got = box_pairs(np.full((n, 3), 7.0), np.zeros(n))
    assert len(got) == n * (n - 1) // 2
    assert np.array_equal(np.sort(keys(got, n)), keys(got, n)) and len(np.unique(keys(got, n))) == len(got)


def test_empty_and_single_scenes_have_no_pairs():
    for n in (0, 1):
        assert box_pairs(np.zeros((n, 2)), np.ones(n)).shape == (0, 2)


def test_alive_and_static_pick_the_pairs_among_the_living_and_never_two_statics():
    rng = np.random.default_rng(0)
    positions, radii = rng.uniform(0, 30, (200, 2)), rng.uniform(0.5, 3, 200)
    alive, static = rng.random(200) < 0.8, rng.random(200) < 0.3
    expected = [(i, j) for i, j in map(tuple, brute_pairs(positions, radii).tolist())
                if alive[i] and alive[j] and not (static[i] and static[j])]
    assert list(map(tuple, box_pairs(positions, radii, alive, static).tolist())) == expected
