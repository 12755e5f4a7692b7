"""Small scenes take one compiled call per frame (own/small.py): exact like the structures, and
the structure back the moment the scene grows past the threshold."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import engines
from interface.pairs import is_canonical, keys
from own.brute import brute_pairs
from own.small import SMALL_SCENE_N, SmallScenes, small_sweep
from scenes import generate
from scenes.motion import simulate
from strategies import any_scene

STRUCTURED = ["own.grid", "own.grid_incremental", "own.grid_parallel", "own.sap", "own.sap_incremental",
              "own.sap_parallel", "own.quadtree", "own.bvh"]


def same_pairs(got: np.ndarray, positions: np.ndarray, radii: np.ndarray) -> None:
    n = len(positions)
    assert is_canonical(got, n) is None, is_canonical(got, n)
    assert np.array_equal(np.sort(keys(got, n)), np.sort(keys(brute_pairs(positions, radii), n)))


@given(scene=any_scene, seed=st.integers(0, 2**32 - 1))
def test_the_one_call_sweep_is_exact_from_any_order(scene, seed):
    positions, radii = scene
    positions, radii = positions[:SMALL_SCENE_N], radii[:SMALL_SCENE_N]
    order = np.random.default_rng(seed).permutation(len(positions)).astype(np.int64)
    same_pairs(small_sweep(positions, radii, order, np.empty(len(positions))), positions, radii)
    assert np.array_equal(np.sort(order), np.arange(len(positions)))  # still a permutation


@pytest.mark.parametrize("name", STRUCTURED)
@given(scene=any_scene, steps=st.lists(st.floats(0.0, 30.0), min_size=1, max_size=4), seed=st.integers(0, 2**32 - 1))
def test_a_small_scene_is_exact_across_frames_without_a_structure(name, scene, steps, seed):
    positions, radii = (a[:SMALL_SCENE_N] for a in scene)
    backend = engines.create(name)
    backend.reset(positions, radii)
    assert backend.stats() == {"small_scene": 1} and backend.structure() == {}
    backend.validate()
    rng = np.random.default_rng(seed)
    for step in [0.0, *steps]:
        positions = positions + rng.uniform(-step, step, positions.shape)
        backend.update(positions)
        same_pairs(backend.pairs(), positions, radii)


@pytest.mark.parametrize("name", STRUCTURED)
def test_the_structure_comes_back_when_the_scene_grows_past_the_threshold(name):
    backend = engines.create(name)
    for n in (SMALL_SCENE_N, SMALL_SCENE_N + 1, 2048, SMALL_SCENE_N, 3):
        traj = simulate(generate("clusters", n, seed=n), 4)
        backend.reset(traj.positions[0], traj.scene.radii)
        assert ("small_scene" in backend.stats()) == (n <= SMALL_SCENE_N), (n, backend.stats())
        for f in range(1, traj.frames):
            backend.update(traj.positions[f])
            same_pairs(backend.pairs(), traj.positions[f], traj.scene.radii)
        backend.validate()


def test_bad_input_is_refused_on_the_small_path_as_on_the_structures():
    backend = engines.create("own.grid")
    with pytest.raises(RuntimeError, match="call reset"):
        backend.update(np.zeros((3, 2)))
    backend.reset(np.zeros((3, 2)), np.ones(3))
    with pytest.raises(ValueError, match="3 objects"):
        backend.update(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="not finite"):
        backend.update(np.array([[0.0, 0.0], [np.nan, 1.0], [2.0, 2.0]]))
    with pytest.raises(ValueError, match="radius 1 is negative"):
        backend.reset(np.zeros((3, 2)), np.array([1.0, -1.0, 1.0]))


def test_the_threshold_can_be_set_to_always_build_the_structure(monkeypatch):
    monkeypatch.setattr(SmallScenes, "small_scene_n", 0)
    backend = engines.create("own.grid")
    backend.reset(np.zeros((3, 2)), np.ones(3))
    assert "cells" in backend.stats()
