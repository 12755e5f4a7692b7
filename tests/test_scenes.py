"""Scene generators, the essay's motion, and scene files."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from interface.checks import check_positions
from scenes import DISTRIBUTIONS, ESSAY_BOX, ESSAY_COVERAGE, Scene, generate
from scenes.io import SceneFileError, load_scene, save_scene
from scenes.motion import kinetic_energy, momentum, simulate
from strategies import BAD_SCENE_FILES
from tiers import examples


@pytest.mark.parametrize("dist", DISTRIBUTIONS)
def test_generators_are_seeded_inside_the_box_and_at_the_essay_speed(dist):
    a, b = generate(dist, 500, seed=7), generate(dist, 500, seed=7)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, generate(dist, 500, seed=8).positions)
    assert a.box == ESSAY_BOX and a.positions.shape == (500, 2) and a.positions.dtype == np.float64
    assert (a.positions - a.radii[:, None] >= 0).all() and (a.positions + a.radii[:, None] <= 2000).all()
    np.testing.assert_allclose(np.hypot(*a.velocities.T), 10.0)
    assert (a.radii == 10.0).all()


def test_gaussian_x_clumps_along_x_only():
    s = generate("gauss_x", 20000, seed=1)
    assert abs(s.positions[:, 0].std() - 200.0) < 10 and abs(s.positions[:, 0].mean() - 1000.0) < 10
    assert abs(s.positions[:, 1].std() - 2000 / np.sqrt(12)) < 20
    t = generate("gauss_y", 20000, seed=1)
    assert abs(t.positions[:, 1].std() - 200.0) < 10


def test_mixed_sizes_are_log_uniform_between_the_bounds():
    s = generate("uniform", 20000, radii=(1.0, 100.0), seed=2)
    assert 1.0 <= s.radii.min() and s.radii.max() <= 100.0
    logs = np.log10(s.radii)
    assert abs(np.mean(logs < 1.0) - 0.5) < 0.02  # half the radii below the geometric middle


def test_circles_larger_than_the_box_sit_in_its_middle():
    s = generate("uniform", 10, radius=5000.0, seed=0)
    assert (s.positions == 1000.0).all()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"dist": "gauss_z"}, "unknown distribution 'gauss_z'"),
        ({"n": -1}, "n must be a non-negative integer"),
        ({"radius": -1.0}, "radius must be finite and non-negative"),
        ({"radii": (5.0, 1.0)}, "radii bounds"),
        ({"radius": 1.0, "radii": (1.0, 2.0)}, "either radius or radii"),
        ({"speed": np.nan}, "speed must be finite"),
        ({"box": (0, 0, -1, 5)}, "box must be finite"),
    ],
)
def test_generator_rejects_bad_values(kwargs, message):
    with pytest.raises(ValueError, match=message):
        generate(**{"n": 10, **kwargs})


def test_same_seed_same_trajectory():
    a = simulate(generate("clusters", 300, seed=3, speed=500.0), 40)
    b = simulate(generate("clusters", 300, seed=3, speed=500.0), 40)
    np.testing.assert_array_equal(a.positions, b.positions)


def test_nobody_leaves_the_box_and_energy_is_conserved():
    scene = generate("clusters", 400, radii=(2.0, 20.0), seed=4, speed=3000.0)
    traj = simulate(scene, 120)
    lo = traj.positions - scene.radii[None, :, None]
    hi = traj.positions + scene.radii[None, :, None]
    assert (lo >= -1e-9).all() and (hi <= 2000 + 1e-9).all()
    assert sum(len(c) for c in traj.contacts) > 100  # collisions did happen
    e0 = kinetic_energy(traj.velocities[0], scene.radii)
    for v in traj.velocities:
        assert kinetic_energy(v, scene.radii) == pytest.approx(e0, rel=1e-9)


def test_momentum_is_conserved_without_walls():
    scene = generate("clusters", 400, radii=(2.0, 20.0), seed=5, speed=3000.0, walls=False)
    traj = simulate(scene, 60)
    p0 = momentum(traj.velocities[0], scene.radii)
    assert sum(len(c) for c in traj.contacts) > 50
    scale = np.abs(scene.radii**2 * 3000.0).sum()
    for v in traj.velocities:
        np.testing.assert_allclose(momentum(v, scene.radii), p0, atol=1e-9 * scale)


def test_static_and_unresponsive_scenes_do_only_what_they_ask():
    scene = generate("uniform", 200, seed=6, speed=1000.0, moves=False)
    traj = simulate(scene, 5)
    assert (traj.positions == scene.positions).all()
    ghost = simulate(generate("clusters", 200, seed=6, speed=1000.0, responds=False, walls=False), 5)
    np.testing.assert_allclose(ghost.positions[4], ghost.positions[0] + 4 * ghost.velocities[0] / 60.0)


def test_each_frame_records_its_exact_pairs():
    traj = simulate(generate("clusters", 300, seed=9, speed=800.0), 10)
    from own.brute import brute_pairs

    for f in range(traj.frames):
        np.testing.assert_array_equal(traj.box_pairs[f], brute_pairs(traj.positions[f], traj.scene.radii))


def test_renumbered_trajectory_is_the_same_motion_with_every_pair_mapped():
    from own.brute import brute_pairs
    from own.reference import narrow_phase

    traj = simulate(generate("clusters", 300, seed=9, speed=800.0), 4)
    order = np.random.default_rng(1).permutation(300)
    again = traj.renumbered(order)
    np.testing.assert_array_equal(again.scene.radii, traj.scene.radii[order])
    for f in range(traj.frames):
        np.testing.assert_array_equal(again.positions[f], traj.positions[f][order])
        pairs = brute_pairs(again.positions[f], again.scene.radii)
        np.testing.assert_array_equal(again.box_pairs[f], pairs)
        np.testing.assert_array_equal(again.contacts[f], narrow_phase(again.positions[f], again.scene.radii, pairs))
    assert sum(len(p) for p in again.contacts) > 0  # the scene does touch
    with pytest.raises(ValueError, match="permutation"):
        traj.renumbered(np.zeros(300, dtype=np.int64))
    with pytest.raises(ValueError, match="permutation"):
        traj.renumbered(order.astype(float))


def test_scene_validates_its_arrays():
    with pytest.raises(ValueError, match="radius 1 is negative"):
        Scene(np.zeros((2, 2)), np.array([1.0, -1.0]), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="velocities has 1 rows"):
        Scene(np.zeros((2, 2)), np.ones(2), np.zeros((1, 2)))


# --- scene files -------------------------------------------------------------------------


def test_save_and_load_round_trip_exactly(tmp_path):
    scene = generate("gauss_x", 100, radii=(0.1, 30.0), seed=1)
    path = save_scene(scene, tmp_path / "s.csv")
    back = load_scene(path)
    np.testing.assert_array_equal(back.positions, scene.positions)
    np.testing.assert_array_equal(back.radii, scene.radii)
    np.testing.assert_array_equal(back.velocities, scene.velocities)
    assert back.box == scene.box and back.name == "s"


def test_a_minimal_user_file_gets_zero_velocities_and_a_bounding_box(tmp_path):
    path = tmp_path / "mine.csv"
    path.write_text("x,y,r\n0,0,1\n10,5,2\n\n")
    scene = load_scene(path)
    assert scene.n == 2 and (scene.velocities == 0).all()
    assert scene.box == (-1.0, -1.0, 12.0, 7.0)


@pytest.mark.parametrize(("text", "message"), BAD_SCENE_FILES)
def test_bad_scene_files_name_the_line_and_the_problem(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(SceneFileError, match=message) as err:
        load_scene(path)
    assert str(path) in str(err.value)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(SceneFileError, match="no such file"):
        load_scene(tmp_path / "nope.csv")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00x")
    with pytest.raises(SceneFileError, match="cannot be read"):
        load_scene(tmp_path / "bin.csv")


COORDINATES = st.sampled_from([0.0, -1.5, 3e5, 1e154, -1e300, 1.7e308, -1.7e308, np.inf, -np.inf, np.nan])


@examples(200)
@given(st.lists(st.tuples(COORDINATES, COORDINATES), min_size=1, max_size=20))
def test_positions_are_rejected_exactly_when_a_value_is_not_finite(rows):
    positions = np.array(rows)
    if np.isfinite(positions).all():  # huge finite values overflow the quick sum: checked one by one
        assert np.array_equal(check_positions(positions), positions)
    else:
        row = int(np.flatnonzero(~np.isfinite(positions).all(axis=1))[0])
        with pytest.raises(ValueError, match=f"row {row} is not finite"):
            check_positions(positions)


# --- spheres -------------------------------------------------------------------------------


@pytest.mark.parametrize("dist", DISTRIBUTIONS)
def test_sphere_scenes_keep_the_essays_coverage_of_the_volume(dist):
    from scenes import coverage
    from scenes.generate import at_essay_density

    for n in (512, 4096):
        scene = at_essay_density(dist, n, seed=2, dim=3)
        assert scene.dim == 3 and scene.positions.shape == (n, 3) and len(scene.box) == 6
        assert coverage(scene.radii, scene.box) == pytest.approx(ESSAY_COVERAGE)
        low, high = np.array(scene.box[:3]), np.array(scene.box[3:])
        assert ((scene.positions - 10.0 >= low) & (scene.positions + 10.0 <= high)).all()
        speeds = np.linalg.norm(scene.velocities, axis=1)
        np.testing.assert_allclose(speeds, 10.0)
        assert np.abs(scene.velocities[:, 2]).mean() > 2.0  # directions fill the sphere, not the plane
    # The gauss_ kinds spread less along their axis than along the others.
    spread = at_essay_density("gauss_y", 4096, dim=3).positions.std(axis=0)
    assert spread[1] < 0.5 * spread[0] and spread[1] < 0.5 * spread[2]


@pytest.mark.parametrize(("dist", "digest", "velocities"), [
    ("uniform", "9dcb0fb3ffbf7854", "2744349f1ecc6c6d"), ("gauss_x", "29cd7826d141d99e", "e6b97b4ddc311f20"),
    ("gauss_y", "2c59be074976b122", "7b9be254a0be7748"), ("clusters", "90f4e43cedbea16f", "9d4d8141ec27ecc2")])
def test_circle_scenes_are_bit_for_bit_what_they_were_before_spheres(dist, digest, velocities):
    """Positions and radii bit for bit; velocities to 9 decimals, since numpy's cos and sin round
    their last bit by the CPU's vector instructions (AVX-512 or not)."""
    import hashlib

    scene = generate(dist, 300, seed=7, radii=(1.0, 9.0), speed=33.0)
    assert scene.dim == 2 and scene.box == ESSAY_BOX
    assert hashlib.sha1(scene.positions.tobytes() + scene.radii.tobytes()).hexdigest()[:16] == digest
    assert hashlib.sha1(np.round(scene.velocities, 9).tobytes()).hexdigest()[:16] == velocities


def test_the_essays_motion_in_a_cube_keeps_energy_and_momentum_and_the_walls():
    scene = generate("uniform", 400, radii=(4.0, 20.0), seed=5, speed=900.0, box=(0, 0, 0, 300, 300, 300), dim=3)
    traj = simulate(scene, 60)
    assert traj.positions.shape == (60, 400, 3)
    assert sum(len(c) for c in traj.contacts) > 100  # they collide
    r = scene.radii[:, None]
    assert ((traj.positions >= r - 1e-9) & (traj.positions <= 300 - r + 1e-9)).all()
    drift = traj.drift()
    assert abs(drift["energy_drift"]) < 1e-9 and drift["momentum_drift"] < 0.5  # walls take momentum, not energy
    free = simulate(scene.with_(walls=False), 30)
    p0, p1 = momentum(free.velocities[0], scene.radii), momentum(free.velocities[-1], scene.radii)
    np.testing.assert_allclose(p1, p0, atol=1e-6 * np.abs(p0).sum())
    np.testing.assert_allclose(kinetic_energy(free.velocities[-1], scene.radii),
                               kinetic_energy(free.velocities[0], scene.radii), rtol=1e-9)


def test_a_sphere_scene_file_round_trips_and_takes_its_box(tmp_path):
    scene = generate("gauss_x", 80, radii=(0.5, 9.0), seed=1, dim=3)
    back = load_scene(save_scene(scene, tmp_path / "balls.csv"))
    assert back.dim == 3 and back.box == scene.box
    np.testing.assert_array_equal(back.positions, scene.positions)
    np.testing.assert_array_equal(back.velocities, scene.velocities)
    plain = tmp_path / "plain.csv"
    plain.write_text("x,y,z,r\n0,0,0,1\n4,2,9,2\n")
    loaded = load_scene(plain)
    assert loaded.box == (-1.0, -1.0, -1.0, 6.0, 4.0, 11.0) and (loaded.velocities == 0).all()


def test_a_sphere_scene_refuses_a_box_of_the_wrong_dimension():
    with pytest.raises(ValueError, match=r"box must be 6 numbers \(xmin, ymin, zmin, xmax, ymax, zmax\)"):
        Scene(np.zeros((2, 3)), np.ones(2), np.zeros((2, 3)), box=ESSAY_BOX)
    with pytest.raises(ValueError, match=r"velocities must have shape \(n, 3\)"):
        Scene(np.zeros((2, 3)), np.ones(2), np.zeros((2, 2)), box=(0, 0, 0, 1, 1, 1))
    with pytest.raises(ValueError, match="dim must be 2"):
        generate(dim=4)
