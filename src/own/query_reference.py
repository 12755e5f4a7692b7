"""The exact answer to the queries a project puts to its structure every frame, by brute force over
every object, in 2D and 3D: rays (the closest hit, or every hit), box overlaps and points.

The tests of one query against one object (`ray_hit`, `box_meets`, `point_inside`) are the ones
every structure of ours applies to the objects it does not prune, so that a structure agrees with
this reference bit for bit wherever it visits the object at all.

The rules, as the interface states them:
- a ray is the segment origin + t * direction, 0 <= t <= length, direction of unit length; it hits
  an object whose shape it meets (a ball's circle or sphere, a box's box, closed), at the least
  such t: 0 where the origin is inside. A ray of length 0 hits what holds its origin.
- the closest hit of a ray is the object of least t; of equal t, the lowest object id.
- a box query meets each object whose box (a ball's: centre -+ radius) overlaps it, closed
  intervals, the rule of the pairs.
- a point query meets each object whose shape holds the point (the boundary counts).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.extending import overload

from .common import half_of

NO_HIT = -1


def ray_hit(origins, directions, lengths, q, positions, sizes, k):
    """The t at which ray q first meets object k's shape, or inf where it misses: compiled apart
    for balls (a vector of radii) and boxes (a matrix of half-extents), as common.half_of is."""


@overload(ray_hit)
def _ray_hit(origins, directions, lengths, q, positions, sizes, k):
    if sizes.ndim == 1:
        return lambda origins, directions, lengths, q, positions, sizes, k: _ray_ball(
            origins, directions, lengths, q, positions, sizes, k)
    return lambda origins, directions, lengths, q, positions, sizes, k: _ray_box(
        origins, directions, lengths, q, positions, sizes, k)


@nb.njit(cache=True, inline="always")
def _ray_ball(origins, directions, lengths, q, positions, radii, k):
    """|o + t u - c| = r, u of unit length: the lesser root, 0 where the origin is inside."""
    b = cc = 0.0
    for a in range(positions.shape[1]):
        oc = origins[q, a] - positions[k, a]
        b += oc * directions[q, a]
        cc += oc * oc
    rr = radii[k] * radii[k]
    if not (cc < np.inf and rr < np.inf and b * b < np.inf):
        return _ray_far_ball(origins, directions, lengths, q, positions, radii, k)
    cc -= rr
    if cc <= 0.0:  # the origin inside (or on) the ball
        return 0.0
    disc = b * b - cc
    if b > 0.0 or not disc >= 0.0:  # heading away, or passing by
        return np.inf
    t = -b - np.sqrt(disc)
    return max(t, 0.0) if t <= lengths[q] else np.inf


@nb.njit(cache=True)
def _ray_far_ball(origins, directions, lengths, q, positions, radii, k):
    """_ray_ball where a square passes the largest double (distances past ~1.3e154): in half
    coordinates (exact, and never overflowing), the ray's distance from the centre taken from its
    perpendicular part, each square divided by the larger of it and the radius first."""
    d = positions.shape[1]
    oc = np.empty(d)
    b = 0.0
    for a in range(d):
        oc[a] = 0.5 * origins[q, a] - 0.5 * positions[k, a]
        b += oc[a] * directions[q, a]
    r = 0.5 * radii[k]
    if _within(oc, r):
        return 0.0
    if b > 0.0:  # heading away
        return np.inf
    for a in range(d):
        oc[a] -= b * directions[q, a]  # the part across the ray
    unit = max(np.abs(oc).max(), r)
    across = 0.0
    for a in range(d):
        across += (oc[a] / unit) ** 2
    if across > (r / unit) ** 2:  # passing by
        return np.inf
    t = 2.0 * max(-b - unit * np.sqrt((r / unit) ** 2 - across), 0.0)
    return t if t <= lengths[q] else np.inf


@nb.njit(cache=True, inline="always")
def _within(offset, r):
    """Whether |offset| <= r, each square divided by the larger of |offset|'s parts and r first."""
    unit = max(np.abs(offset).max(), r)
    if unit == 0.0:
        return True
    s = 0.0
    for a in range(offset.shape[0]):
        s += (offset[a] / unit) ** 2
    return s <= (r / unit) ** 2


@nb.njit(cache=True, inline="always")
def clip_to_slab(lo, hi, o, u, t0, t1):
    """The part t0..t1 of a ray (origin o, direction u along this axis) inside the slab lo..hi
    (closed); t0 > t1 where none is."""
    if u == 0.0:
        return (t0, t1) if lo <= o <= hi else (np.inf, -np.inf)
    s0, s1 = (lo - o) / u, (hi - o) / u
    return max(t0, min(s0, s1)), min(t1, max(s0, s1))


@nb.njit(cache=True, inline="always")
def _ray_box(origins, directions, lengths, q, positions, extents, k):
    """The slabs, closed: the largest entering t over the axes, if no exit comes before it."""
    t0, t1 = 0.0, lengths[q]
    for a in range(positions.shape[1]):
        t0, t1 = clip_to_slab(positions[k, a] - extents[k, a], positions[k, a] + extents[k, a], origins[q, a],
                              directions[q, a], t0, t1)
        if t0 > t1:
            return np.inf
    return t0


@nb.njit(cache=True, inline="always")
def box_meets(lo, hi, q, positions, sizes, k):
    """Whether object k's box overlaps query box q (closed intervals)."""
    hit = True
    for a in range(positions.shape[1]):
        h = half_of(sizes, k, a)
        hit &= (positions[k, a] - h <= hi[q, a]) & (lo[q, a] <= positions[k, a] + h)
    return hit


def point_inside(points, q, positions, sizes, k):
    """Whether object k's shape holds point q (its boundary too)."""


@overload(point_inside)
def _point_inside(points, q, positions, sizes, k):
    if sizes.ndim == 1:
        return lambda points, q, positions, sizes, k: _point_in_ball(points, q, positions, sizes, k)
    return lambda points, q, positions, sizes, k: _point_in_box(points, q, positions, sizes, k)


@nb.njit(cache=True, inline="always")
def _point_in_ball(points, q, positions, radii, k):
    s = 0.0
    for a in range(positions.shape[1]):
        s += (points[q, a] - positions[k, a]) ** 2
    rr = radii[k] * radii[k]
    if s < np.inf and rr < np.inf:
        return s <= rr
    offset = np.empty(positions.shape[1])  # squares past a double: in half coordinates, scaled
    for a in range(positions.shape[1]):
        offset[a] = 0.5 * points[q, a] - 0.5 * positions[k, a]
    return _within(offset, 0.5 * radii[k])


@nb.njit(cache=True, inline="always")
def _point_in_box(points, q, positions, extents, k):
    inside = True
    for a in range(positions.shape[1]):
        inside &= (positions[k, a] - extents[k, a] <= points[q, a]) & (points[q, a] <= positions[k, a] + extents[k, a])
    return inside


@nb.njit(cache=True)
def closest_hits(origins, directions, lengths, positions, sizes):
    """(object, t) of each ray's closest hit over every object: NO_HIT and inf where it hits none."""
    m = origins.shape[0]
    hit, at = np.full(m, NO_HIT, dtype=np.int64), np.full(m, np.inf)
    for q in range(m):
        for k in range(positions.shape[0]):
            t = ray_hit(origins, directions, lengths, q, positions, sizes, k)
            if t < at[q]:  # ascending k: of equal t, the lowest id stays
                hit[q], at[q] = k, t
    return hit, at


@nb.njit(cache=True, inline="always")
def query_meets(kind, a0, a1, a2, q, positions, sizes, k):
    """Whether query q meets object k: kind 0 rays (a0..a2: origins, directions, lengths), 1 boxes
    (a0, a1: lo, hi), 2 points (a0)."""
    if kind == 0:
        return ray_hit(a0, a1, a2, q, positions, sizes, k) < np.inf
    if kind == 1:
        return box_meets(a0, a1, q, positions, sizes, k)
    return point_inside(a0, q, positions, sizes, k)


@nb.njit(cache=True)
def _all_meeting(kind, a0, a1, a2, positions, sizes):
    """Every (query, object) the queries meet (query_meets), by query then object."""
    m, n = a0.shape[0], positions.shape[0]
    out = np.empty((16, 2), dtype=np.int64)
    count = 0
    for q in range(m):
        for k in range(n):
            if query_meets(kind, a0, a1, a2, q, positions, sizes, k):
                if count == out.shape[0]:
                    grown = np.empty((2 * count, 2), dtype=np.int64)
                    grown[:count] = out
                    out = grown
                out[count, 0], out[count, 1] = q, k
                count += 1
    return out[:count].copy()


def every_ray_hit(origins, directions, lengths, positions, sizes) -> np.ndarray:
    """Every (ray, object) whose segment meets the object's shape, (m, 2), sorted."""
    return _all_meeting(0, origins, directions, lengths, positions, sizes)


def boxes_meeting(lo, hi, positions, sizes) -> np.ndarray:
    """Every (query, object) whose boxes overlap, (m, 2), sorted."""
    return _all_meeting(1, lo, hi, np.empty(0), positions, sizes)


def points_inside(points, positions, sizes) -> np.ndarray:
    """Every (query, object) whose shape holds the point, (m, 2), sorted."""
    return _all_meeting(2, points, points, np.empty(0), positions, sizes)


def closer_hits(hit: np.ndarray, at: np.ndarray, other: np.ndarray, other_at: np.ndarray):
    """Two answers' closest hits merged (object ids, -1 and inf for none): the closer of each ray's,
    of equal t the lower id, as the reference's rule."""
    nearer = (other_at < at) | ((other_at == at) & (other >= 0) & ((hit < 0) | (other < hit)))
    return np.where(nearer, other, hit), np.where(nearer, other_at, at)
