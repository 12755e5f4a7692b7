"""Hypothesis strategies for scenes that try to break broad phases, and hand-made boundary cases.

Besides the generators, they draw adversarial layouts: circles on a small integer lattice with
radii that make many boxes touch exactly, duplicated positions, everything on one line, radii
from zero to larger than the box, and scenes far from the origin.
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from scenes import DISTRIBUTIONS, generate


@st.composite
def generated_scenes(draw, max_n: int = 200):
    """A generator scene with random n, seed and radii (equal, mixed, tiny or huge)."""
    n = draw(st.integers(0, max_n))
    dist = draw(st.sampled_from(DISTRIBUTIONS))
    seed = draw(st.integers(0, 2**31 - 1))
    sizes = draw(st.sampled_from(["essay", "mixed", "tiny", "huge", "wide_mix"]))
    kw = {
        "essay": {"radius": 10.0},
        "mixed": {"radii": (1.0, 100.0)},
        "tiny": {"radius": 1e-6},
        "huge": {"radius": 3000.0},  # larger than the box: everything overlaps
        "wide_mix": {"radii": (1e-3, 1e3)},
    }[sizes]
    scene = generate(dist, n, seed=seed, **kw)
    return scene.positions, scene.radii


@st.composite
def lattice_scenes(draw, max_n: int = 120):
    """Integer and half-integer positions with radii in {0, 0.25, 0.5, 1}: exact ties everywhere."""
    n = draw(st.integers(0, max_n))
    coords = st.integers(0, 12).map(lambda v: v * 0.5)
    pos = draw(st.lists(st.tuples(coords, coords), min_size=n, max_size=n))
    radii = draw(st.lists(st.sampled_from([0.0, 0.25, 0.5, 1.0]), min_size=n, max_size=n))
    # Exact in float64 for these values; from 1e9 on, not in float32 (own.sap's sparse sweep
    # tallies in float32), and 1e300 absorbs the offsets altogether (every object at one point).
    shift = draw(st.sampled_from([0.0, -1000.0, 1e6, -1e9, 1e300]))
    positions = np.array(pos, dtype=np.float64).reshape(-1, 2) + shift
    return positions, np.array(radii, dtype=np.float64)


@st.composite
def degenerate_scenes(draw, max_n: int = 150):
    """Duplicated points, one vertical or horizontal line, or all at one point."""
    n = draw(st.integers(0, max_n))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kind = draw(st.sampled_from(["duplicates", "vline", "hline", "point"]))
    r = draw(st.sampled_from([0.0, 0.5, 5.0]))
    if kind == "duplicates":
        base = rng.uniform(0, 100, (max(1, n // 4), 2))
        positions = base[rng.integers(0, len(base), n)]
    elif kind == "point":
        positions = np.full((n, 2), 42.0)
    else:
        t = rng.uniform(0, 1000, n)
        positions = np.column_stack([np.full(n, 7.0), t] if kind == "vline" else [t, np.full(n, 7.0)])
    return positions.reshape(-1, 2), np.full(n, r)


any_scene = st.one_of(generated_scenes(), lattice_scenes(), degenerate_scenes())


# The boundary rule, pinned by hand (closed intervals, as Bullet and Chipmunk define it).
BOUNDARY = {
    # centres 2 apart, radii 1: boxes touch exactly on x -> overlap
    "touching boxes overlap": ([[0.0, 0.0], [2.0, 0.0]], [1.0, 1.0], [(0, 1)]),
    "touching corners overlap": ([[0.0, 0.0], [2.0, 2.0]], [1.0, 1.0], [(0, 1)]),
    "1e-12 apart do not": ([[0.0, 0.0], [2.0 + 1e-12, 0.0]], [1.0, 1.0], []),
    "1e-12 apart on y do not": ([[0.0, 0.0], [0.0, 2.0 + 1e-12]], [1.0, 1.0], []),
    "coincident circles do": ([[5.0, 5.0], [5.0, 5.0]], [1.0, 1.0], [(0, 1)]),
    "coincident points of radius zero do": ([[5.0, 5.0], [5.0, 5.0]], [0.0, 0.0], [(0, 1)]),
    "a point on a box edge": ([[0.0, 0.0], [1.0, 0.5]], [1.0, 0.0], [(0, 1)]),
    "one inside another": ([[0.0, 0.0], [0.1, 0.1]], [100.0, 0.01], [(0, 1)]),
    "no objects": (np.zeros((0, 2)), [], []),
    "one object": ([[1.0, 1.0]], [1.0], []),
    "a chain of touching boxes, ends apart": ([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]], [1.0, 1.0, 1.0], [(0, 1), (1, 2)]),
    "the chain broken by 1e-9": ([[0.0, 0.0], [2.0, 0.0], [4.0 + 1e-9, 0.0]], [1.0, 1.0, 1.0], [(0, 1)]),
}


# Scene files that must be refused, with the words the error has to contain.
BAD_SCENE_FILES = [
    ("", "empty file"),
    ("x,y\n1,2\n", "line 1: header must be x,y,r.*missing r"),
    ("x,y,r,w\n1,2,3,4\n", "line 1: .*unknown w"),
    ("x,y,z,r,vx,vy\n1,2,3,4,0,0\n", "line 1: spheres with velocities need vz"),
    ("x,y,r,vz\n1,2,3,4\n", "line 1: vz needs a z column"),
    ("# box: 0,0,1,1\nx,y,z,r\n1,1,1,1\n", "line 1: bad box line .*6 numbers"),
    ("x,y,r,vx\n1,2,3,4\n", "line 1: give both vx and vy"),
    ("x,y,r\n1,2,3\n1,2\n", "line 3: expected 3 columns"),
    ("x,y,r\n1,2,3\n1,2,3,4\n", "line 3: expected 3 columns"),
    ("x,y,r\n1,abc,3\n", "line 2: column y is not a number: 'abc'"),
    ("x,y,r\n1,2,3\nnan,2,3\n", "line 3: column x is not finite"),
    ("x,y,r\n1,2,3\n1,2,inf\n", "line 3: column r is not finite"),
    ("x,y,r\n1,2,-3\n", "line 2: radius is negative"),
    ("x,y,r\n", "no circles"),
    ("# box: 0,0,oops,1\nx,y,r\n1,1,1\n", "line 1: bad box line"),
    ("# box: 0,0,1,1\nx,y,r\n1,1,1\n2,2,x\n", "line 4: column r is not a number"),
]


@st.composite
def sphere_scenes(draw, max_n: int = 150):
    """Spheres (positions (n, 3)): uniform in a cube with equal, mixed, tiny or huge radii; on a
    half-integer lattice with radii that make boxes touch exactly; duplicated points, a flat layer
    (z = 0) or a line; far from the origin."""
    n = draw(st.integers(0, max_n))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kind = draw(st.sampled_from(["uniform", "lattice", "duplicates", "layer", "line"]))
    if kind == "lattice":
        positions = rng.integers(0, 13, (n, 3)) * 0.5
        radii = rng.choice([0.0, 0.25, 0.5, 1.0], n)
    else:
        positions = rng.uniform(0, 300, (n, 3))
        if kind == "duplicates":
            positions = positions[rng.integers(0, max(1, n // 4), n)] if n else positions
        elif kind == "layer":
            positions[:, 2] = 0.0
        elif kind == "line":
            positions[:, 1:] = 7.0
        sizes = draw(st.sampled_from([10.0, 1e-6, 3000.0, 0.0, "mixed"]))
        radii = np.exp(rng.uniform(np.log(0.5), np.log(60.0), n)) if sizes == "mixed" else np.full(n, sizes)
    shift = draw(st.sampled_from([0.0, -1000.0, 1e6, 1e300]))
    return positions + shift, radii


@st.composite
def box_scenes(draw, dim: int = 2, max_n: int = 150):
    """Axis-aligned boxes (positions, half-extents (n, d)) that try to break a broad phase: boxes
    of mixed aspect, long walls across the world, boxes of zero width on an axis, aspect up to
    1:1e6, and boxes on a lattice whose edges are shared exactly (closed intervals touch)."""
    n = draw(st.integers(0, max_n))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kind = draw(st.sampled_from(["mixed", "walls", "zero_width", "aspect", "shared_edges"]))
    positions = rng.uniform(0, 1000, (n, dim))
    extents = rng.uniform(2, 8, (n, dim)) * rng.uniform(1, 4, (n, 1)) ** (np.arange(dim) == 0)
    if kind == "walls":  # a few boxes as long as the world along one axis, thin along the others
        walls = rng.random(n) < 0.1
        axis = rng.integers(0, dim, n)
        extents[walls] = 5.0
        extents[walls, axis[walls]] = rng.uniform(200, 1500, walls.sum())
    elif kind == "zero_width":
        extents[rng.random((n, dim)) < 0.3] = 0.0
    elif kind == "aspect":
        extents[:, 0] = rng.uniform(1e-4, 1e-3, n)
        extents[:, 1] = extents[:, 0] * 1e6
    elif kind == "shared_edges":  # unit boxes on a lattice of unit steps: every neighbour touches
        positions = rng.integers(0, 12, (n, dim)).astype(np.float64)
        extents = np.full((n, dim), 0.5)
    shift = draw(st.sampled_from([0.0, -1e4, 1e6]))
    return positions + shift, extents


@st.composite
def touching_boxes(draw, dim: int = 2, max_n: int = 120):
    """Boxes whose bounds are equal to other boxes' bounds, where a test other than the rule (a
    centre distance against a sum of half-extents) rounds differently from comparing c - h with
    c + h: tile maps of sides that float64 cannot represent (0.1, 1/3), shared edges and corners,
    zero extents on another box's corner, -0.0, subnormal and 1e-300 sizes."""
    n = draw(st.integers(0, max_n))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    kind = draw(st.sampled_from(["tiles", "corners", "negative_zero", "subnormal", "tiny"]))
    if kind in ("tiles", "tiny", "subnormal"):
        step = {"tiles": draw(st.sampled_from([0.1, 1 / 3, 0.7, 0.3, 1e5 / 3])),
                "tiny": 1e-300, "subnormal": 5e-324}[kind]
        cells = rng.integers(0, 6 if kind == "subnormal" else 10, (n, dim))
        # Centres at step/2 + step k, the tile map's way; subnormals at k * step, a box a step wide.
        centres = cells * step + (0.0 if kind == "subnormal" else step / 2)
        extents = np.full((n, dim), step if kind == "subnormal" else step / 2)
        extents[rng.random(n) < 0.2] = 0.0  # points on the tiles' edges and corners too
        return centres, extents
    if kind == "corners":  # boxes of side 0.1, and points at their corners
        centres = rng.integers(0, 8, (n, dim)) * 0.1 + 0.05
        extents = np.full((n, dim), 0.05)
        points = rng.random(n) < 0.4
        signs = rng.choice([-1.0, 1.0], (n, dim))
        centres[points] = centres[points] + signs[points] * 0.05
        extents[points] = 0.0
        return centres, extents
    # -0.0 and 0.0 as centres and extents: equal under the rule.
    centres = rng.choice([-0.0, 0.0, 1.0, -1.0], (n, dim))
    extents = rng.choice([-0.0, 0.0, 0.5, 1.0], (n, dim))
    return centres, extents
