"""The essay-method Python backends: supersets of the box overlaps, with their work counted."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given

import engines
from interface.pairs import is_canonical, keys
from own.brute import brute_pairs
from scenes import generate
from strategies import generated_scenes, lattice_scenes
from tiers import examples

ESSAY = ["essay.sap", "essay.grid", "essay.quadtree"]


def assert_superset(name, positions, radii, **params):
    backend = engines.create(name, **params)
    backend.reset(positions, radii)
    got = backend.pairs()
    backend.validate()
    n = len(positions)
    assert is_canonical(got, n) is None, is_canonical(got, n)
    missed = np.setdiff1d(keys(brute_pairs(positions, radii), n), keys(got, n))
    assert missed.size == 0, f"{name} missed {missed.size} overlapping pair(s)"
    return backend, got


@pytest.mark.parametrize("name", ESSAY)
@examples(40)
@given(scene=generated_scenes(max_n=80) | lattice_scenes(max_n=60))
def test_essay_backends_never_miss(name, scene):
    assert_superset(name, *scene)


def test_essay_sap_reports_exactly_the_x_overlaps():
    scene = generate("uniform", 300, seed=1)
    lo, hi = scene.positions[:, 0] - scene.radii, scene.positions[:, 0] + scene.radii
    i, j = np.triu_indices(300, 1)
    x_overlaps = ((lo[j] <= hi[i]) & (lo[i] <= hi[j])).sum()
    _, got = assert_superset("essay.sap", scene.positions, scene.radii)
    assert len(got) == x_overlaps > len(brute_pairs(scene.positions, scene.radii))


def test_essay_grid_counts_the_duplicate_tests_of_nine_cell_insertion():
    # Two close circles in one cell are both inserted into its 3 x 3 neighbourhood, so the
    # pair is tested once in every cell they share.
    pos = np.array([[0.0, 0.0], [30.0, 30.0], [15.0, 15.0], [15.5, 15.0]])
    backend, got = assert_superset("essay.grid", pos, np.full(4, 0.5), p=3)
    stats = backend.stats()
    assert stats["tests"] == stats["duplicate_tests"] + len(got)
    assert stats["duplicate_tests"] > 0


def test_essay_grid_does_not_wrap_around_the_border():
    # The printed code's index -1 put border particles into the opposite border's cells too.
    pos = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    backend, got = assert_superset("essay.grid", pos, np.full(4, 1.0), p=5)
    assert len(got) == 0 and backend.stats()["tests"] == 0


def test_essay_quadtree_keeps_every_particle():
    scene = generate("uniform", 1024, seed=0)
    backend, _ = assert_superset("essay.quadtree", scene.positions, scene.radii)
    assert backend.stats()["inserted"] == 1024


def test_essay_quadtree_is_exact_for_equal_radii_on_the_essay_scene():
    scene = generate("uniform", 1024, seed=2)
    _, got = assert_superset("essay.quadtree", scene.positions, scene.radii)
    assert len(got) == len(brute_pairs(scene.positions, scene.radii))
