"""Boxes of any extents through the interface: the exact answer for boxes, our backends that take
them (exact on random and adversarial box scenes, statics and spawning, boxes that change as
bodies rotate), every other backend refusing them in one line, and box trajectories read from
NPZ, CSV and Broadmark's .aabbs files through to the studies."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import engines
from own.brute import brute_pairs
from own.common import swept_boxes
from own.dimension import marker
from own.large_cover import COVER_FROM, pairs_among_covered
from own.reference import box_pairs, narrow_phase
from own.static_boxes import StaticBoxCells
from scenes.broadmark import write_aabbs
from scenes.recorded import TrajectoryFileError, load_trajectory
from strategies import box_scenes, touching_boxes
from structures import pair_keys, same_pairs, structure_pairs
from studies import compare
from tiers import examples

BOX_BACKENDS = [n for n in engines.available() if "boxes" in engines.backend_class(n).shapes]
BALLS_ONLY = [n for n in engines.available() if n not in BOX_BACKENDS]
ENGINES_WITH_BOXES = [n for n in BOX_BACKENDS if not engines.of_kind(n, "own")]
OWN_EXACT_BOXES = [n for n in BOX_BACKENDS if engines.of_kind(n, "own") and engines.backend_class(n).exact]


def as_set(pairs: np.ndarray) -> set[tuple[int, int]]:
    return set(map(tuple, np.asarray(pairs).tolist()))


def touching_exactly(positions, extents) -> bool:
    """Some overlapping pair of boxes only touches: on an axis one's edge is the other's edge."""
    pairs = box_pairs(positions, extents)
    lo, hi = positions - extents, positions + extents
    i, j = pairs[:, 0], pairs[:, 1]
    return bool(((lo[j] == hi[i]) | (lo[i] == hi[j])).any())


def zero_width(positions, extents) -> bool:
    """Some box has no width on an axis (a segment, a point)."""
    return bool((extents == 0).any())


def float32_tight(positions, extents) -> bool:
    """Some pair overlaps by less than float32 resolves at its coordinates, or a value is beyond
    float32's range: an engine that stores poses in float32 may lose it."""
    if not len(positions):
        return False
    if max(np.abs(positions).max(), extents.max()) > np.finfo(np.float32).max / 4:
        return True
    pairs = box_pairs(positions, extents)
    i, j = pairs[:, 0], pairs[:, 1]
    slack = (extents[i] + extents[j] - np.abs(positions[j] - positions[i])).min(axis=1)
    scale = np.maximum(np.abs(positions[i]).max(axis=1), np.abs(positions[j]).max(axis=1)) + extents.max() + 1e-30
    return bool((slack <= 16 * float(np.finfo(np.float32).eps) * scale).any())


# Engine -> box scenes it mishandles, each shown by test_an_engine_misses_boxes_where_its_limits_say.
FLOAT32_ENGINES = ["physx.sap", "physx.mbp", "physx.pabp", "box2d.v2", "box2d.v3", "rapier.bvh"]
BOX_LIMITATIONS = {**{name: [float32_tight] for name in FLOAT32_ENGINES},
                   "bullet.dbvt": [touching_exactly, zero_width], "bullet.simple": [touching_exactly, zero_width],
                   "coal.hash": [touching_exactly], "coal.interval": [touching_exactly],
                   "mujoco.sap": [touching_exactly],
                   **{name: [touching_exactly, float32_tight] for name in ["physx.sap", "physx.mbp", "physx.pabp"]}}
# Engines that miss box pairs on ordinary scenes: out of the never-miss tests, their misses pinned below.
UNRELIABLE_ON_BOXES = {"coal.sap"}


def check_boxes(name: str, positions, extents, static=None, alive=None) -> None:
    """The backend's pairs on these boxes against the reference: no miss, no pair twice, exactly
    the box overlaps for an exact backend (outside the known limits of an engine)."""
    assume(not any(applies(positions, extents) for applies in BOX_LIMITATIONS.get(name, [])))
    backend = engines.create(name)
    try:
        backend.reset(positions, extents=extents, static=static, alive=alive)
    except ValueError as refused:  # an engine's limits (say, a hash's cells per box): refused in one line
        assert not engines.of_kind(name, "own") and "\n" not in str(refused), refused
        backend.close()
        assume(False)
    try:
        got = backend.pairs()
        expected = as_set(box_pairs(positions, extents, alive, static))
        assert len(as_set(got)) == len(got), f"{name}: a pair reported twice"
        assert expected <= as_set(got), f"{name}: missed {sorted(expected - as_set(got))[:5]}"
        if backend.exact:
            assert as_set(got) == expected
        backend.validate()
    finally:
        backend.close()


def test_the_backends_that_take_boxes_are_registered():
    assert {"own.grid", "own.brute", "own.sap", "own.sap_incremental", "own.sap_parallel", "own.bvh", "own.quadtree",
            "own.verlet"} <= set(OWN_EXACT_BOXES)
    assert {"own.grid_incremental", "own.grid_parallel"} <= set(OWN_EXACT_BOXES)
    assert {"chipmunk.bbtree_index", "chipmunk.hash_index", "own.grid_swept", "own.sap_swept"} <= set(BOX_BACKENDS)


def test_every_engine_of_the_issue_takes_boxes_natively_and_the_cutoff_libraries_refuse_them():
    """The physics engines and the box libraries take boxes; what takes points with a cutoff
    (the neighbour-list libraries, Warp's hash grid, scipy's k-d tree) does not."""
    engines_with_boxes = {n for n in engines.names() if "boxes" in engines.backend_class(n).shapes}
    for family in ["chipmunk", "box2d", "bullet", "physx", "rapier", "mujoco", "fcl", "coal", "shapely", "cgal"]:
        members = [n for n in engines.names() if n.startswith(family + ".")]
        assert members and set(members) - {"chipmunk.sweep1d"} <= engines_with_boxes, family
    for family in ["mdanalysis", "freud", "matscipy", "vesin", "sklearn", "warp", "scipy"]:
        assert not any(n.startswith(family + ".") for n in engines_with_boxes), family


def lattice_of_touching_boxes(seed: int, dim: int, n: int = 120):
    """Unit boxes on a lattice of unit steps: neighbours share faces, edges and corners exactly."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, 12, (n, dim)).astype(np.float64), np.full((n, dim), 0.5)


# (engine, scene, what it shows): each limit of BOX_LIMITATIONS and UNRELIABLE_ON_BOXES, missed here.
CORNER = (np.array([[0.0, 0.0], [1.0, 1.0]]), np.full((2, 2), 0.5))
SIDE_BY_SIDE = (np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), np.full((2, 3), 0.5))
CORNER_3D = (np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), np.full((2, 3), 0.5))
FLAT_INSIDE = (np.array([[0.0, 0.0], [1.5, -2.3]]), np.array([[0.0, 3.0], [11.4, 6.8]]))
BOX_EVIDENCE = [("bullet.dbvt", CORNER), ("bullet.simple", CORNER), ("bullet.dbvt", FLAT_INSIDE),
                ("bullet.simple", FLAT_INSIDE), ("coal.interval", SIDE_BY_SIDE), ("coal.sap", SIDE_BY_SIDE),
                ("mujoco.sap", CORNER_3D), ("coal.hash", lattice_of_touching_boxes(0, 2)),
                *[(name, lattice_of_touching_boxes(7, 3)) for name in ["physx.sap", "physx.mbp", "physx.pabp"]]]


@pytest.mark.parametrize("name, scene", BOX_EVIDENCE, ids=lambda v: v if isinstance(v, str) else "")
def test_an_engine_misses_boxes_where_its_limits_say(name, scene):
    """Each engine's box limits are real: on this scene it misses a pair (were it fixed, this fails
    and the limit goes); the studies report such misses, they never hide them."""
    if name not in engines.available():
        pytest.skip(f"{name} is not available here")
    positions, extents = scene
    backend = engines.create(name)
    backend.reset(positions, extents=extents)
    missed = as_set(box_pairs(positions, extents)) - as_set(backend.pairs())
    backend.close()
    assert missed
    assert name in UNRELIABLE_ON_BOXES or any(applies(positions, extents) for applies in BOX_LIMITATIONS[name])


@pytest.mark.parametrize("name", BALLS_ONLY)
def test_a_backend_without_boxes_refuses_them_in_one_line(name):
    backend = engines.create(name)
    positions = np.random.default_rng(0).uniform(0, 100, (12, 2))
    with pytest.raises(ValueError, match="does not take boxes") as err:
        backend.reset(positions, extents=np.ones((12, 2)))
    assert "\n" not in str(err.value)
    backend.close()


@pytest.mark.parametrize("extents, words", [
    (np.ones((5, 3)), "extents must have shape (5, 2)"),
    (np.ones(5), "extents must have shape (5, 2)"),
    (np.r_[[[1.0, -1.0]], np.ones((4, 2))], "extents row 0 is negative"),
    (np.r_[np.ones((4, 2)), [[np.nan, 1.0]]], "extents row 4 is not finite"),
])
def test_bad_extents_are_one_line_naming_the_problem(extents, words):
    grid = engines.create("own.grid")
    with pytest.raises(ValueError, match=re.escape(words)):
        grid.reset(np.zeros((5, 2)), extents=extents)


@pytest.mark.parametrize("extents, words", [
    (np.ones((5, 3)), "extents must have shape (5, 2)"),
    (np.ones(5), "extents must have shape (5, 2)"),
    (np.r_[np.ones((2, 2)), [[1.0, -1e-300]], np.ones((2, 2))], "extents row 2 is negative"),
    (np.r_[np.ones((4, 2)), [[np.nan, 1.0]]], "extents row 4 is not finite"),
    (np.r_[np.ones((3, 2)), [[1.0, np.inf]], np.ones((1, 2))], "extents row 3 is not finite"),
    (np.r_[np.ones((3, 2)), [[1.0, -np.inf]], np.ones((1, 2))], "extents row 3 is negative"),
])
def test_bad_extents_in_an_update_are_one_line_naming_the_problem(extents, words):
    """A frame's extents go through one compiled pass (not check_extents): it refuses the same."""
    grid = engines.create("own.grid")
    grid.reset(np.zeros((5, 2)), extents=np.ones((5, 2)), static=np.array([True, False, False, False, True]))
    with pytest.raises(ValueError, match=re.escape(words)):
        grid.update(np.zeros((5, 2)), extents=extents)


def test_radii_or_extents_one_of_them_and_extents_only_for_boxes():
    grid = engines.create("own.grid")
    with pytest.raises(ValueError, match="not both"):
        grid.reset(np.zeros((3, 2)), np.ones(3), extents=np.ones((3, 2)))
    with pytest.raises(ValueError, match="one of them"):
        grid.reset(np.zeros((3, 2)))
    grid.reset(np.zeros((3, 2)), np.ones(3))
    with pytest.raises(ValueError, match="reset with radii"):
        grid.update(np.zeros((3, 2)), extents=np.ones((3, 2)))


@pytest.mark.parametrize("static, changed", [
    ([True, False, False, False], 0),
    ([True, True, False, False], 1),  # the statics one block of rows
    ([False, True, False, True], 3),  # not one block
])
def test_a_static_box_that_changes_its_extents_is_refused(static, changed):
    grid = engines.create("own.grid")
    static = np.array(static)
    grid.reset(np.zeros((4, 2)), extents=np.ones((4, 2)), static=static)
    moved = np.where(static[:, None], 1.0, 2.0) * np.ones((4, 2))
    grid.update(np.zeros((4, 2)), extents=moved)  # movers may
    moved[changed, 1] = 1.5
    with pytest.raises(ValueError, match=f"object {changed} is static but its extents changed"):
        grid.update(np.zeros((4, 2)), extents=moved)


@pytest.mark.parametrize("name", ["own.grid", "own.sap", "chipmunk.bbtree"])
def test_extents_changed_in_place_and_handed_back_are_a_change(name):
    """A caller that grows its own array of extents and hands the same array to update: the
    backend kept a copy, so it sees the change (it compared the array with itself before)."""
    positions = np.array([[0.0, 0.0], [10.0, 0.0]])
    extents = np.ones((2, 2))
    backend = engines.create(name)
    backend.reset(positions, extents=extents)
    assert len(backend.pairs()) == 0
    extents[0, 0] = 9.5
    backend.update(positions, extents=extents)
    assert backend.pairs().tolist() == [[0, 1]]


def test_the_narrow_phase_of_boxes_is_their_overlap():
    rng = np.random.default_rng(4)
    positions, extents = rng.uniform(0, 50, (300, 2)), rng.uniform(0, 3, (300, 2))
    everything = np.array([(i, j) for i in range(300) for j in range(i + 1, 300)])
    assert as_set(narrow_phase(positions, extents, everything)) == as_set(brute_pairs(positions, extents))
    # Boxes that touch along an edge overlap (closed intervals), as everywhere.
    assert len(narrow_phase(np.array([[0.0, 0.0], [2.0, 0.5]]), np.ones((2, 2)), np.array([[0, 1]]))) == 1


@pytest.mark.parametrize("dim", [2, 3])
def test_own_grid_is_exact_on_a_few_thousand_boxes_long_and_small(dim):
    rng = np.random.default_rng(dim)
    n = 3500
    positions = rng.uniform(0, 400 if dim == 2 else 60, (n, dim))
    extents = rng.uniform(0, 2, (n, dim))
    extents[:40, 0] = rng.uniform(50, 300, 40)  # long boxes, in the grid's large bucket
    assert as_set(structure_pairs("own.grid", positions, extents)) == as_set(brute_pairs(positions, extents))


@st.composite
def spread_sizes(draw, dim: int):
    """Boxes (or balls) whose sizes spread over two decades, as debris of aspect 1 to 20 does:
    many too large for a grid's cells, some on a lattice (shared edges), some of zero width."""
    n = draw(st.integers(0, 500))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    positions = rng.uniform(0, draw(st.sampled_from([100.0, 600.0, 3000.0])), (n, dim))
    sizes = rng.uniform(1, 4, (n, dim)) * np.exp(rng.uniform(0, np.log(40), (n, 1)))
    if draw(st.booleans()):
        positions = np.round(positions / 8.0) * 8.0
        sizes = np.round(sizes)
    sizes[rng.random((n, dim)) < 0.05] = 0.0
    return positions + draw(st.sampled_from([0.0, -1e4])), sizes if draw(st.booleans()) else sizes[:, 0]


@pytest.mark.parametrize("dim", [2, 3])
@examples(60)
@given(data=st.data())
def test_many_large_objects_pair_through_the_cells_they_cover(dim, data):
    """The grids' large bucket where it holds many (large_cover.py): its pairs exactly, each once."""
    positions, sizes = data.draw(spread_sizes(dim))
    ids = np.arange(len(positions)) * 3 + 7  # objects' ids are not their rows
    buf = np.empty((len(positions) ** 2 // 2 + 8, 2), dtype=np.int64)
    found, tests = pairs_among_covered(positions, sizes, ids, buf, 0, 0, marker(dim))
    if found < 0:  # no cells to lay: the grids sweep these instead
        assert not sizes.any()
        return
    assert tests >= found
    assert len(as_set(buf[:found])) == found
    assert as_set(buf[:found]) == as_set(ids[brute_pairs(positions, sizes)])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("sizes", ["boxes", "balls"])
@pytest.mark.parametrize("params", [{"strips": "on"}, {"strips": "on", "incremental": True, "axis": "y"},
                                    {"strips": "on", "parallel": True, "parallel_from": 0}])
@examples(40)
@given(data=st.data())
def test_the_sweeps_strips_take_spread_sizes_with_a_large_bucket(dim, sizes, params, data):
    """The 2D sweep's strips and the 3D sweep's columns sized by a typical box, the larger boxes
    queried against them and paired among themselves (strips.py, columns.py): exact over frames
    where the boxes change."""
    positions, extents = data.draw(spread_sizes(dim))
    extents = extents if extents.ndim == 1 else extents[:, 0] if sizes == "balls" else extents
    rng = np.random.default_rng(len(positions))
    backend = engines.create("own.sap", skin=0, **params)
    backend.reset(positions, **({"extents": extents} if extents.ndim == 2 else {"radii": extents}))
    for _ in range(2):
        positions = positions + rng.normal(0, 2, positions.shape)
        if extents.ndim == 2:
            extents = extents * rng.uniform(0.8, 1.2, extents.shape)
            backend.update(positions, extents=extents)
        else:
            backend.update(positions)
        backend.validate()
        got = backend.pairs()
        assert same_pairs(got, brute_pairs(positions, extents))


@pytest.mark.parametrize("name", ["own.grid", "own.grid_incremental", "own.grid_parallel", "own.verlet", "own.sap",
                                  "own.sap_incremental", "own.sap_parallel"])
@pytest.mark.thorough
@pytest.mark.parametrize("dim", [2, 3])
def test_the_grids_and_sweeps_take_many_large_boxes_apart(name, dim):
    rng = np.random.default_rng(dim)
    n = 3000
    positions = rng.uniform(0, 1500 if dim == 2 else 200, (n, dim))
    extents = rng.uniform(1, 4, (n, dim)) * np.exp(rng.uniform(0, np.log(30), (n, 1)))
    backend = engines.create(name, **({"parallel_from": 0} if name == "own.sap_parallel" else {}))
    backend.reset(positions, extents=extents)
    for frame in range(3):
        positions = positions + rng.normal(0, 1, (n, dim))
        extents = extents * rng.uniform(0.9, 1.1, (n, dim))
        backend.update(positions, extents=extents)
        got = backend.pairs()
        assert same_pairs(got, box_pairs(positions, extents)), f"frame {frame}"
    if name == "own.grid" or (name.startswith("own.sap") and dim == 2):
        # The cells, not the sweep, paired them; the sweep's strips are sized by a typical box.
        assert backend.stats()["large"] >= COVER_FROM


@pytest.mark.parametrize("name", ["own.sap", "own.sap_incremental", "own.sap_swept"])
@pytest.mark.parametrize("huge", [10, 100])
def test_the_3d_sweeps_columns_hold_a_few_huge_boxes_apart(name, huge):
    """A few boxes across the scene among many small ones (crates put back at the top of the beams,
    swept over both places): the columns sized by the small ones, the huge ones in a bucket of
    their own, paired with the columns they span and among themselves (swept where they are few,
    through the cells they cover where many): exact, each pair once."""
    rng = np.random.default_rng(huge)
    n = 3000
    positions = rng.uniform(0, 300, (n, 3))
    extents = rng.uniform(1, 3, (n, 3))
    # Each long on one or two axes, short on the rest: their lower corners lie among the small
    # boxes' on the short axes, where a small box in the column below can meet them.
    long = rng.random((huge, 3)) < 0.4
    long[np.arange(huge), rng.integers(0, 3, huge)] = True
    extents[:huge] *= np.where(long, 50.0, 1.0)
    backend = engines.create(name, strips="on")
    backend.reset(positions, extents=extents)
    for frame in range(3):
        before = positions, extents
        positions = positions + rng.normal(0, 1, (n, 3))
        extents = extents * rng.uniform(0.9, 1.1, (n, 3))
        backend.update(positions, extents=extents)
        backend.validate()
        got = backend.pairs()
        # The swept form's answer: the pairs of the boxes swept over both frames.
        boxes = swept_boxes(before[0], positions, before[1], extents) if name == "own.sap_swept" else \
            (positions, extents)
        assert same_pairs(got, box_pairs(*boxes)), f"frame {frame}"
    if name != "own.sap_swept":  # the swept boxes are grown by the motion: their sizes are not these
        assert backend.stats()["columns"] > 0 and 0 < backend.stats()["large"] <= 2 * huge


@pytest.mark.parametrize("vector", [True, False])
@examples(40)
@given(data=st.data())
def test_own_grid_scans_boxes_eight_at_a_time_or_one_at_a_time_exactly(vector, data):
    """own.grid's vector scan takes the boxes' half-extents by column (own/compress.py): forced
    (on any CPU) and off, exact on random and adversarial boxes, with statics and objects not
    alive, before and after every box takes new extents (the slots gather them in place)."""
    positions, extents = data.draw(box_scenes(dim=2))
    n = len(positions)
    rng = np.random.default_rng(n)
    static, alive = rng.random(n) < 0.3, rng.random(n) < 0.8
    grid = engines.create("own.grid", vector=vector)
    grid.small_scene_n = 0  # the structure, however small the scene
    grid.reset(positions, extents=extents, static=static, alive=alive)
    turned = np.where(static[:, None], extents, extents[:, ::-1])  # a quarter turn of every mover
    for sizes in (extents, turned):
        grid.update(positions, extents=sizes)
        got = grid.pairs()
        assert same_pairs(got, box_pairs(positions, sizes, alive, static))
        grid.validate()
    assert grid.stats()["vector"] == int(vector)


@pytest.mark.parametrize("vector", [True, False])
def test_own_grid_scans_long_runs_of_boxes_eight_at_a_time_exactly(vector):
    """Dozens of boxes a cell (runs of many blocks of 8, and a last block part full), boxes large
    and small, turning each frame: the vector scan, and the scalar one, against the exact answer."""
    rng = np.random.default_rng(5)
    n = 3000
    positions = rng.uniform(0, 250, (n, 2))
    extents = rng.uniform(1, 4, (n, 2)) * rng.uniform(1, 6, (n, 1))
    grid = engines.create("own.grid", vector=vector)
    grid.reset(positions, extents=extents)
    for frame in range(3):
        positions = positions + rng.normal(0, 1, (n, 2))
        extents = extents * rng.uniform(0.9, 1.1, (n, 2))
        grid.update(positions, extents=extents)
        got = grid.pairs()
        assert same_pairs(got, box_pairs(positions, extents)), f"frame {frame}"
        grid.validate()
    assert grid.stats()["tests"] > 16 * n and grid.stats()["large"] > 0 and grid.stats()["vector"] == int(vector)


RELIABLE_ON_BOXES = [n for n in BOX_BACKENDS if n not in UNRELIABLE_ON_BOXES]


def never_misses_on_random_and_adversarial_boxes(name, dim, scene):
    if dim not in engines.backend_class(name).dims:
        pytest.skip(f"{name} works in 2D only")
    positions, extents = scene.draw(box_scenes(dim=dim))
    rng = np.random.default_rng(len(positions))
    check_boxes(name, positions, extents)
    check_boxes(name, positions, extents, static=rng.random(len(positions)) < 0.3,
                alive=rng.random(len(positions)) < 0.8)


@pytest.mark.parametrize("name", [n for n in RELIABLE_ON_BOXES if n not in ENGINES_WITH_BOXES])
@pytest.mark.parametrize("dim", [2, 3])
@examples(40)
@given(scene=st.data())
def test_a_box_backend_never_misses_on_random_and_adversarial_boxes(name, dim, scene):
    never_misses_on_random_and_adversarial_boxes(name, dim, scene)


# Engines build a world per example (PhysX a stage: 0.2 s): fewer examples, the same strategy.
@pytest.mark.parametrize("name", [n for n in RELIABLE_ON_BOXES if n in ENGINES_WITH_BOXES])
@pytest.mark.parametrize("dim", [2, 3])
@examples(15)
@given(scene=st.data())
def test_an_engine_never_misses_on_random_and_adversarial_boxes(name, dim, scene):
    never_misses_on_random_and_adversarial_boxes(name, dim, scene)


# The settings that take our backends down their other paths, besides every box backend as it comes.
OTHER_PATHS = [("own.grid_parallel", {"parallel_from": 0}),
               ("own.grid_parallel", {"parallel_from": 0, "candidates": "kept"}),
               ("own.grid_incremental", {"candidates": "kept"}), ("own.sap", {"strips": "on"}),
               ("own.sap", {"sweep": "sparse"}), ("own.sap", {"skin": 0.5}), ("own.bvh", {"coherent": False}),
               ("own.quadtree", {"coherent": False}), ("own.verlet", {"skin": 0})]


@pytest.mark.parametrize("name, params", [(n, {}) for n in BOX_BACKENDS if engines.of_kind(n, "own")] + OTHER_PATHS)
@pytest.mark.parametrize("dim", [2, 3])
@examples(60)
@given(scene=st.data())
def test_our_backends_report_every_pair_of_boxes_that_only_touch(name, params, dim, scene):
    """Tile maps of sides float64 cannot represent, points on corners, -0.0, subnormal and 1e-300
    sizes: the rule on the bounds c - h, c + h, exactly, as the structure is built and on a frame
    after (where a kept list of candidates is filtered)."""
    if dim not in engines.backend_class(name).dims:
        pytest.skip(f"{name} works in 2D only")
    positions, extents = scene.draw(touching_boxes(dim))
    backend = engines.create(name, **params)
    backend.small_scene_n = 0  # the structure however small the scene
    backend.reset(positions, extents=extents)
    for frame in range(2):
        got = backend.pairs()
        expected = box_pairs(positions, extents)
        assert same_pairs(got, expected) if backend.exact else same_pairs(got, got) and \
            np.isin(pair_keys(expected), pair_keys(np.sort(got, axis=1))).all(), f"frame {frame}"
        backend.validate()
        backend.update(positions, extents=extents)


@pytest.mark.parametrize("name, params", [(n, {}) for n in RELIABLE_ON_BOXES] + OTHER_PATHS)
@pytest.mark.parametrize("dim", [2, 3])
def test_a_box_backend_follows_boxes_that_move_rotate_spawn_and_go(name, params, dim):
    """Frames of movers whose extents change every frame (a rotating body's box), among static
    walls, with objects appearing and going: every frame exact."""
    if dim not in engines.backend_class(name).dims:
        pytest.skip(f"{name} works in 2D only")
    rng = np.random.default_rng(dim)
    n = 400
    positions = rng.uniform(0, 300, (n, dim))
    extents = rng.uniform(1, 4, (n, dim))
    static = np.zeros(n, dtype=bool)
    static[:30] = True
    extents[:30] = 2.0
    extents[:30, 0] = rng.uniform(40, 150, 30)  # walls
    alive = rng.random(n) < 0.9
    backend = engines.create(name, **params)
    backend.reset(positions, extents=extents, static=static, alive=alive)
    for frame in range(9):
        positions = positions.copy()
        positions[~static] += rng.normal(0, 2, (n - 30, dim))
        if frame % 3:  # two frames in three the bodies rotate, the third they only move
            extents = extents.copy()
            extents[~static] = np.clip(extents[~static] * rng.uniform(0.8, 1.25, (n - 30, dim)), 0, 12)
        if frame % 2:
            alive = alive ^ (rng.random(n) < 0.05)
        backend.update(positions, alive, extents=extents)
        got = backend.pairs()
        expected = as_set(box_pairs(positions, extents, alive, static))
        assert as_set(got) == expected if backend.exact else expected <= as_set(got), f"frame {frame}"
        assert len(as_set(got)) == len(got)
    backend.validate()


RESIZING = [n for n in OWN_EXACT_BOXES if engines.backend_class(n).resizes]
# The grids take new extents in place too: own.grid's slots take them (a box grown past a cell
# changes bucket), and the grids that keep candidates search as own.grid does while boxes turn.
# own.grid_parallel with parallel_from 0: split over the cores however small, where it takes the plain search too.
# The sweeps take new bounds from the radii each frame and keep their order (with a skin, sweep anew).
IN_PLACE = [*[(n, {}) for n in [*RESIZING, "own.grid", "own.grid_incremental", "own.grid_parallel", "own.sap",
                                "own.sap_incremental", "own.sap_parallel"]],
            ("own.grid_parallel", {"parallel_from": 0}), ("own.sap", {"skin": 0.5})]


@pytest.mark.parametrize(("name", "params"), IN_PLACE)
@pytest.mark.parametrize("dim", [2, 3])
def test_boxes_that_turn_a_little_are_taken_in_place_and_stay_exact(name, params, dim):
    """A structure kept with a skin takes new extents like a move (a side that grew moved out),
    a grid in its slots: boxes turning a little every frame, as a settling stack's do, are not
    built anew each frame, and every frame stays exact."""
    assert {"own.verlet", "own.bvh", "own.quadtree"} <= set(RESIZING)
    rng = np.random.default_rng(dim)
    n = 600
    positions = rng.uniform(0, 200, (n, dim))
    extents = rng.uniform(1, 4, (n, dim))
    static = np.arange(n) < 40
    backend = engines.create(name, **params)
    backend.reset(positions, extents=extents, static=static)
    resets, reset = [], backend._reset
    backend._reset = lambda *args: (resets.append(1), reset(*args))  # a build from scratch
    frames = 12
    for _ in range(frames):
        positions = positions.copy()
        positions[~static] += rng.normal(0, 0.01, (n - 40, dim))
        extents = extents.copy()
        extents[~static] *= rng.uniform(0.995, 1.005, (n - 40, dim))
        backend.update(positions, extents=extents)
        assert as_set(backend.pairs()) == as_set(box_pairs(positions, extents, None, static))
        backend.validate()
    assert not resets, "built from scratch for new extents"


def walls_scene(seed: int = 0):
    """The walls scene of the issue, smaller: movers of aspect 1 to 4 among long static walls."""
    rng = np.random.default_rng(seed)
    n, walls = 1500, 120
    positions = rng.uniform(0, 2500, (n, 2))
    extents = rng.uniform(2, 8, (n, 2)) * np.c_[rng.uniform(1, 4, n), np.ones(n)]
    extents[:walls] = np.c_[rng.uniform(100, 750, walls), np.full(walls, 5.0)]
    extents[:walls:2] = extents[:walls:2, ::-1]
    static = np.arange(n) < walls
    return positions, extents, static


@pytest.mark.parametrize("name", OWN_EXACT_BOXES)
def test_walls_as_boxes_cost_few_candidates_and_as_circles_many(name):
    positions, extents, static = walls_scene()
    backend = engines.create(name)
    backend.reset(positions, extents=extents, static=static)
    truth = box_pairs(positions, extents, None, static)
    got = backend.pairs()
    assert as_set(truth) <= as_set(got) and len(got) <= 1.5 * len(truth)
    circles = np.sqrt((extents ** 2).sum(axis=1))  # what the circle model hands a backend
    assert len(box_pairs(positions, circles, None, static)) > 5 * len(truth)


def test_static_boxes_are_filed_in_every_cell_they_cover_and_each_pair_found_once():
    positions, extents, static = walls_scene(1)
    ids = np.flatnonzero(static)
    cells = StaticBoxCells(positions, extents, ids, cell=20.0)
    cells.validate(static)
    movers = np.flatnonzero(~static)
    found, _ = cells.pairs_with(movers, positions[movers], extents[movers], len(movers))
    expected = box_pairs(positions, extents)
    expected = expected[static[expected[:, 0]] != static[expected[:, 1]]]
    assert len(found) == len(as_set(found)) and as_set(np.sort(found, axis=1)) == as_set(expected)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("static_share", [0.15, 0.85])
def test_own_grid_pairs_static_boxes_with_movers_each_way_exactly(dim, static_share):
    """own.grid tests the static boxes against its movers from the statics' side (each static
    walking the movers' rows of cells) where they are at most as many as the movers (0.15), from
    the movers' side otherwise (0.85). Both on statics touching the movers' extent exactly from
    outside it (a mover at the lowest and highest centre, a static's side on its side), statics
    far away, long walls, movers of one cell and of several, and large movers, every frame exact."""
    rng = np.random.default_rng(dim + int(100 * static_share))
    n = 700
    positions = rng.uniform(0, 200, (n, dim))
    extents = rng.uniform(0.5, 3, (n, dim))
    static = rng.random(n) < static_share
    movers = np.flatnonzero(~static)
    extents[movers[:len(movers) // 8]] *= 8  # large movers, in the grid's large bucket
    walls = np.flatnonzero(static)[:10]
    extents[walls, 0] = rng.uniform(50, 150, len(walls))
    far = np.flatnonzero(static)[10:20]
    positions[far] += 1e4
    # Movers at the extent's ends on every axis, and statics whose sides lie on theirs, outside.
    low, high, s_low, s_high = movers[-2], movers[-1], *np.flatnonzero(static)[20:22]
    positions[low], positions[high] = -50.0, 260.0
    extents[[low, high, s_low, s_high]] = 1.0
    positions[s_low], positions[s_high] = positions[low] - 2.0, positions[high] + 2.0
    backend = engines.create("own.grid")
    backend.reset(positions, extents=extents, static=static)
    large = []
    for frame in range(4):
        expected = box_pairs(positions, extents, None, static)
        assert {(min(low, s_low), max(low, s_low)), (min(high, s_high), max(high, s_high))} <= as_set(expected)
        got = backend.pairs()
        assert same_pairs(got, expected), f"frame {frame}"
        large.append(backend.stats()["large"])
        positions, extents = positions.copy(), extents.copy()
        moving = movers[:-2]
        positions[moving] += rng.normal(0, 1.5, (len(moving), dim))
        extents[moving] *= rng.uniform(0.8, 1.25, (len(moving), dim))
        backend.update(positions, extents=extents)
    backend.validate()
    assert max(large) > 0


def rotating_boxes(frames: int = 6, n: int = 60, dim: int = 2, seed: int = 0):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0, 100, (n, dim)) + np.arange(frames)[:, None, None] * rng.normal(0, 1, (n, dim))
    extents = rng.uniform(0.5, 4, (n, dim)) * rng.uniform(0.7, 1.3, (frames, n, dim))
    return positions, extents


def test_npz_csv_and_broadmark_files_of_boxes_give_the_same_frames_and_pairs(tmp_path):
    positions, extents = rotating_boxes(dim=3)
    npz = tmp_path / "boxes.npz"
    np.savez(npz, positions=positions, extents=extents)
    frames, n, _ = positions.shape
    table = pd.DataFrame({"frame": np.repeat(np.arange(frames), n), "id": np.tile(np.arange(n), frames),
                          **{axis: positions[..., a].ravel() for a, axis in enumerate("xyz")},
                          **{f"h{axis}": extents[..., a].ravel() for a, axis in enumerate("xyz")}})
    csv = tmp_path / "boxes.csv"
    table.to_csv(csv, index=False)
    lo, hi = (positions - extents).astype(np.float32), (positions + extents).astype(np.float32)
    aabbs = write_aabbs(tmp_path / "boxes.aabbs", lo, hi, name="falling boxes", kind="Cubes")
    scenes = [load_trajectory(p) for p in (npz, csv)]
    from_broadmark = load_trajectory(aabbs)
    assert from_broadmark.name == "falling boxes" and from_broadmark.meta["broadmark_objects"] == "Cubes"
    for scene in scenes:
        assert scene.shape == "boxes" and np.array_equal(scene.motion.extents, extents)
        assert np.array_equal(scene.motion.positions, positions)
    # Broadmark's float32 bounds come back exactly: centre +- half-extent is the recorded box.
    record = from_broadmark.motion
    assert np.array_equal(record.positions - record.extents, lo)
    assert np.array_equal(record.positions + record.extents, hi)
    from scenes.motion import simulate

    a, b = simulate(scenes[0], frames), simulate(scenes[1], frames)
    for f in range(frames):
        assert np.array_equal(a.box_pairs[f], b.box_pairs[f])
        assert np.array_equal(a.box_pairs[f], box_pairs(positions[f], extents[f]))


def test_a_broadmark_recording_holds_its_initial_block_and_one_a_step(tmp_path):
    """As Broadmark's recorder writes: the header counts F steps, the file holds 1 + F blocks (the
    bodies as placed, then one a step); every block is a frame here, the initial one first, and a
    file with more whole blocks than its header says is read to its end, as Broadmark's reader does."""
    from scenes.broadmark import BOX_DTYPE, HEADER_BYTES

    positions, extents = rotating_boxes(dim=3)
    blocks, n, _ = positions.shape
    lo, hi = (positions - extents).astype(np.float32), (positions + extents).astype(np.float32)
    path = write_aabbs(tmp_path / "free fall.aabbs", lo, hi)
    raw = path.read_bytes()
    assert len(raw) == HEADER_BYTES + blocks * n * BOX_DTYPE.itemsize
    assert np.frombuffer(raw, "<i4", 2, 256).tolist() == [n, blocks - 1]  # objects, steps
    record = load_trajectory(path).motion
    assert record.positions.shape == (blocks, n, 3)
    assert np.array_equal(record.positions - record.extents, lo) and np.array_equal(record.positions + record.extents, hi)
    # Two more whole blocks than the header says: read to the end of the file.
    longer = tmp_path / "longer.aabbs"
    longer.write_bytes(raw + raw[HEADER_BYTES:HEADER_BYTES + 2 * n * BOX_DTYPE.itemsize])
    assert load_trajectory(longer).motion.positions.shape == (blocks + 2, n, 3)
    # Ours written out reads back identically, every frame.
    again = write_aabbs(tmp_path / "again.aabbs", record.positions - record.extents, record.positions + record.extents)
    assert again.read_bytes()[256:] == raw[256:]


def test_a_broadmark_file_cut_inside_a_block_names_where(tmp_path):
    positions, extents = rotating_boxes(dim=3)
    blocks, n, _ = positions.shape
    raw = write_aabbs(tmp_path / "good.aabbs", positions - extents, positions + extents).read_bytes()
    cut = tmp_path / "cut.aabbs"
    cut.write_bytes(raw[:304 + 2 * n * 32 + 100])
    with pytest.raises(TrajectoryFileError, match=re.escape(f"cut 100 bytes into block 3 of {n} boxes")) as err:
        load_trajectory(cut)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("damage, words", [
    (lambda raw: raw[:200], "shorter than the 304-byte header"),
    (lambda raw: raw[:-8], "a truncated or foreign file"),
    (lambda raw: raw[:264] + np.array([7], "<i4").tobytes() + raw[268:], "two zeros belong"),
])
def test_a_malformed_aabbs_file_is_one_line(tmp_path, damage, words):
    positions, extents = rotating_boxes(dim=3)
    good = write_aabbs(tmp_path / "good.aabbs", positions - extents, positions + extents)
    bad = tmp_path / "bad.aabbs"
    bad.write_bytes(damage(good.read_bytes()))
    with pytest.raises(TrajectoryFileError, match=re.escape(words)) as err:
        load_trajectory(bad)
    assert "\n" not in str(err.value) and str(err.value).startswith(str(bad))


def test_a_box_whose_max_is_below_its_min_is_refused(tmp_path):
    positions, extents = rotating_boxes(dim=3)
    lo, hi = positions - extents, positions + extents
    lo[2, 5, 1] = hi[2, 5, 1] + 1
    path = write_aabbs(tmp_path / "inverted.aabbs", lo, hi)
    with pytest.raises(TrajectoryFileError, match="box 5 of frame 2 has a max below its min"):
        load_trajectory(path)


@pytest.mark.parametrize("arrays, words", [
    ({"extents": -np.ones((6, 60, 2))}, "frame 0: extents row 0 is negative"),
    ({"extents": np.ones((6, 60, 3))}, "extents must have shape (60, 2) or (6, 60, 2)"),
    ({"extents": np.ones((60, 2)), "radii": np.ones(60)}, "unknown extents"),
])
def test_a_bad_box_npz_is_one_line(tmp_path, arrays, words):
    positions, _ = rotating_boxes()
    path = tmp_path / "bad.npz"
    np.savez(path, positions=positions, **arrays)
    with pytest.raises(TrajectoryFileError, match=re.escape(words)) as err:
        load_trajectory(path)
    assert "\n" not in str(err.value)


def test_compare_measures_box_trajectories_and_names_the_backends_without_boxes(tmp_path, capsys):
    positions, extents = rotating_boxes(frames=5, n=300)
    static = np.zeros(300, dtype=bool)
    static[:10] = True
    positions[:, :10] = positions[0, :10]
    extents[:, :10] = extents[0, :10]
    npz = tmp_path / "rotating.npz"
    np.savez(npz, positions=positions, extents=extents, static=static)
    out = tmp_path / "out"
    assert compare.main(["--trajectory", str(npz), "--quick", "--backends", "own.grid,own.sap,chipmunk.sweep1d",
                         "--out", str(out), "--check"]) == 0
    printed = capsys.readouterr().out
    assert "not run on boxes, they take circles and spheres only: chipmunk.sweep1d" in printed
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.backend) == {"own.grid", "own.sap"} and (rows.status == "ok").all()
    assert (rows.missed == 0).all() and (rows.candidates == rows.true_pairs).all() and (rows["shape"] == "boxes").all()


@pytest.mark.parametrize("dim", [2, 3])
def test_a_scene_file_of_boxes_is_read_back_the_same_and_a_bad_one_is_one_line(tmp_path, dim):
    from scenes.io import SceneFileError, load_scene, save_scene
    from scenes.scene import Scene

    rng = np.random.default_rng(dim)
    scene = Scene(rng.uniform(0, 10, (6, dim)), None, rng.normal(0, 1, (6, dim)), box=(0.0,) * dim + (10.0,) * dim,
                  extents=rng.uniform(0, 1, (6, dim)))
    again = load_scene(save_scene(scene, tmp_path / "boxes.csv"))
    assert again.shape == "boxes" and np.array_equal(again.extents, scene.extents)
    assert np.array_equal(again.positions, scene.positions) and again.box == scene.box
    (tmp_path / "bad.csv").write_text("x,y,hx,hy\n1,2,0.5,3\n1,2,-1,3\n")
    with pytest.raises(SceneFileError, match="line 3: half-extent hx is negative"):
        load_scene(tmp_path / "bad.csv")


@pytest.mark.parametrize("name", ["own.grid_swept", "own.sap_swept"])
@pytest.mark.parametrize("dim", [2, 3])
def test_swept_boxes_cover_both_frames_boxes_at_both_frames_extents(name, dim):
    """A rotating body's swept box covers its box at the last frame and at this one: every pair
    whose two such unions overlap is a candidate (movers among themselves: the statics are tested
    at this frame's boxes, as for balls)."""
    rng = np.random.default_rng(dim)
    n = 300
    positions, extents = rng.uniform(0, 100 if dim == 2 else 30, (n, dim)), rng.uniform(0.5, 3, (n, dim))
    backend = engines.create(name)
    backend.reset(positions, extents=extents)
    for frame in range(4):
        moved = positions + rng.normal(0, 2, (n, dim))
        turned = extents * rng.uniform(0.8, 1.2, (n, dim)) if frame % 2 == 0 else extents
        backend.update(moved, extents=turned)
        lo, hi = np.minimum(positions - extents, moved - turned), np.maximum(positions + extents, moved + turned)
        assert as_set(box_pairs(0.5 * (lo + hi), 0.5 * (hi - lo))) <= as_set(backend.pairs()), f"frame {frame}"
        positions, extents = moved, turned


def test_show_draws_boxes_as_boxes(tmp_path, capsys):
    from studies import show

    positions, extents = rotating_boxes(frames=3, n=40)
    npz = tmp_path / "few.npz"
    np.savez(npz, positions=positions, extents=extents)
    assert show.main(["--trajectory", str(npz), "--backends", "own.grid", "--out", str(tmp_path / "show")]) == 0
    printed = capsys.readouterr().out
    assert "40 boxes" in printed and "0 missed" in printed


def test_the_readme_boxes_example_runs():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    at = text.index('extents = rng.uniform(2, 8, (4000, 2))')
    code = text[text.rindex("```python", 0, at) + len("```python"):text.index("```", at)]
    scope: dict = {}
    exec(code, scope)  # noqa: S102 - the README's own example
    pairs, positions, static = scope["pairs"], scope["positions"], scope["static"]
    assert as_set(pairs) == as_set(box_pairs(positions, scope["turned"], None, static))


def test_the_3d_sweeps_columns_take_points_beside_a_few_boxes():
    """Only points fit under the large bucket's size, and every lower corner is at one place: the
    columns stay as wide as the widest box (a width of zero would divide by zero)."""
    positions, extents = np.zeros((200, 3)), np.zeros((200, 3))
    positions[:5], extents[:5] = 10.0, 10.0  # their lower corners at the points
    for strips in ("on", "auto"):
        backend = engines.create("own.sap", strips=strips, skin=0)
        backend.reset(positions, extents=extents)
        backend.validate()
        assert as_set(backend.pairs()) == as_set(box_pairs(positions, extents))


@pytest.mark.parametrize("offset", [0.0, 1000.0, -12345.6])
def test_the_3d_sweeps_columns_hold_equal_spheres_all(offset):
    """Equal sizes leave no large bucket: a sphere's width from its bounds, (c + r) - (c - r),
    rounds a few ulps either side of 2 r, and must not read as wider than a column."""
    rng = np.random.default_rng(1)
    positions = rng.uniform(0, 400, (4096, 3)) + offset
    radii = np.full(4096, 10.0 / 3.0)
    backend = engines.create("own.sap", strips="on")
    backend.reset(positions, radii)
    for _ in range(2):
        positions = positions + rng.normal(0, 0.5, positions.shape)
        backend.update(positions)
        backend.validate()
        assert as_set(backend.pairs()) == as_set(brute_pairs(positions, radii))
        assert backend.stats()["columns"] > 0 and backend.stats()["large"] == 0


def _tumbling(dim: int, n: int, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """(positions, half-extents per frame) of unit cubes (squares) on a lattice, all aligned at
    frame 0, turning about random axes: their boxes grow up to sqrt(d)."""
    from scenes.box_families import turned_halves_2d, turned_halves_3d

    rng = np.random.default_rng(5)
    side = int(np.ceil(n ** (1 / dim)))
    k = np.arange(n)
    lattice = np.stack([(k // side ** a) % side for a in range(dim)], axis=1) * 2.5
    spin = rng.normal(0, 0.3, (n, 3 if dim == 3 else 1))
    positions, extents = [], []
    for f in range(frames):
        positions.append(lattice + 0.01 * f)
        if dim == 2:
            extents.append(turned_halves_2d(np.ones((n, 2)), spin[:, 0] * f))
        else:
            angle = np.linalg.norm(spin * f, axis=1)
            axis = spin / np.maximum(np.linalg.norm(spin, axis=1), 1e-12)[:, None]
            extents.append(turned_halves_3d(np.ones((n, 3)), np.column_stack([axis * np.sin(angle / 2)[:, None],
                                                                               np.cos(angle / 2)])))
    return np.array(positions), np.array(extents)


@pytest.mark.parametrize("dim", [2, 3])
def test_our_grid_sizes_its_cells_anew_as_aligned_boxes_turn(dim):
    """Cells sized for the aligned cubes of frame 0 put nearly every turned cube in the large
    bucket (3589 to 3896 of 4000); own.grid lays its cells out again, exact throughout."""
    n = 600
    positions, extents = _tumbling(dim, n, 6)
    grid = engines.create("own.grid")
    grid.reset(positions[0], extents=extents[0])
    first_cell = grid.stats()["cell"]
    for f in range(1, len(positions)):
        grid.update(positions[f], extents=extents[f])
        assert same_pairs(grid.pairs(), box_pairs(positions[f], extents[f])), f"frame {f}"
        grid.validate()
    assert grid.stats()["cell"] > 1.2 * first_cell
    assert grid.stats()["large"] < n // 4, "the turned cubes were left in the large bucket"
