"""Sweep and prune in strips: the plain sweep's cost, made local where a scene is dense.

A sweep along one axis tests every pair that overlaps on that axis alone: about
n * (mean width) / (extent) per object, which grows as sqrt(n) on a square scene at fixed density
(229 per object at n = 65536 at the essay's density, a few hundred more in a settled pile). Here
the other axis is cut into strips at least as tall as the tallest box, and each strip is swept
on its own (as PhysX's multi-box pruning sweeps each of its regions): the objects are sorted by
(strip of their lower bound, lower bound on the sweep axis). Two boxes that overlap lie in one
strip or in two adjacent ones, so each object is swept against the later objects of its strip
and, through a cursor that only moves forward, against the objects of the next strip that
overlap it on the sweep axis. Each pair is found once, from the object in the lower strip.

Strips are as tall as the boxes of a typical size, not the largest: where sizes spread (debris
whose longest sides run from 7 to 150), strips sized by the largest box held dozens of objects
across, and the sweep tested 76 pairs per object at n = 4096 for 3.4 found. The boxes larger than
that size (at most LARGE_SHARE of them) are sorted last, in a bucket of their own, and each is
queried against the strips it spans (and the one below, whose boxes reach up into it); among
themselves they are paired through the cells they cover (own/large_cover.py), as the grids' large
bucket is, or swept where they are few.

Exact, like the plain sweep: the strip of a value is floor((v - base) / height), monotone in v,
and a frame whose strip boxes each span at most two strips is checked, not assumed
(`strip_prepare` declines otherwise, and the caller sweeps plain).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import SMALLEST_CELL, emit, gather, half_of
from .dimension import CIRCLES
from .large_cover import COVER_FROM, pairs_among_covered

# Strips pay once the plain sweep would test at least this many pairs per object, and the strips
# cut that at least in half (estimated from the extents and radii).
STRIPS_FROM_WINDOW = 4
# The "auto" axis changes only when the other extent is this much longer.
AXIS_STAYS = 1.25
# A repair of last frame's order gives up past this many swaps per object.
MAX_SWAPS_PER_OBJECT = 8

# Strips are sized so that at most this share of the objects is larger than a strip (those go
# to the large bucket), to the nearest of SIZE_BINS steps of the largest size; and only where
# that at least halves the strips' height (sizes of 4 to 8, as in the recorded circle families,
# keep one strip order: each large object costs a query of three strips or more). On the debris
# at n = 4096 (57 thousand tests a frame for 14 thousand pairs, 311 thousand in strips one widest
# box tall), the pairs took 0.80 ms with a quarter large, 1.16 with an eighth, 1.32
# with a sixteenth, 1.25 with a third.
LARGE_SHARE = 1 / 4
SIZE_BINS = 64
LARGE_FROM_RATIO = 2.0

# Pads each strip's widest box for the next strip's cursor, so that the float sum s_lo + width
# cannot round below the box's upper bound (a correctly rounded difference errs by 2^-53 of itself).
WIDTH_PAD = 1.0 + 1e-12


@nb.njit(cache=True)
def strip_plan(positions, radii, axis_mode, always, last_axis):
    """(axis, base, 1 / height, strips, s0, s1, large): the sweep axis (`axis_mode` 0 x, 1 y, -1
    the longer extent, where `last_axis` stays unless the other extent is AXIS_STAYS longer: a
    square scene would otherwise flip between frames, and each flip costs a sort from scratch),
    strips along the other one, the boxes' extent on the sweep axis, and the half size (the larger
    half-extent) above which a box goes to the large bucket (inf: none does); strips = 0 where
    strips would not pay (unless `always`) or cannot be used (no extent, zero or non-finite sizes,
    more strips than objects)."""
    n = positions.shape[0]
    x0, x1, y0, y1 = np.inf, -np.inf, np.inf, -np.inf
    widest = total = 0.0
    narrowest = np.inf
    for i in range(n):
        rx, ry = half_of(radii, i, 0), half_of(radii, i, 1)
        x0, x1 = min(x0, positions[i, 0] - rx), max(x1, positions[i, 0] + rx)
        y0, y1 = min(y0, positions[i, 1] - ry), max(y1, positions[i, 1] + ry)
        widest = max(widest, rx, ry)  # a strip holds the widest box across, whichever the axis
        narrowest = min(narrowest, max(rx, ry))
        total += max(rx, ry)
    axis = axis_mode
    if axis_mode < 0:
        axis = int(y1 - y0 > x1 - x0)
        longer, shorter = max(x1 - x0, y1 - y0), min(x1 - x0, y1 - y0)
        if last_axis >= 0 and axis != last_axis and longer <= AXIS_STAYS * shorter:
            axis = last_axis
    (s0, s1), (o0, o1) = ((x0, x1), (y0, y1)) if axis == 0 else ((y0, y1), (x0, x1))
    s_extent, o_extent = s1 - s0, o1 - o0
    none = (axis, 0.0, 0.0, 0, s0, s1, np.inf)
    if n < 2 or not (widest > 0 and np.isfinite(widest) and np.isfinite(s_extent) and np.isfinite(o_extent)
                     and s_extent > 0):
        return none
    # Sizes within LARGE_FROM_RATIO of each other (equal radii) cannot leave a large bucket.
    large, reach = _large_size(radii, widest) if LARGE_FROM_RATIO * narrowest <= widest else (np.inf, widest)
    height = max(2.0 * reach * WIDTH_PAD, SMALLEST_CELL)
    strips = int(o_extent / height) + 2  # one spare: the base is rounded down to a whole strip
    if strips < 3 or strips > n:
        return none
    window = n * (2.0 * total / n) / s_extent  # the plain sweep's pairs per object
    # Per object: its strip's window and the next strip's, which reaches a widest box further back.
    strip_window = window * (height / o_extent) * (2.0 + reach * n / total)
    if not always and (window < STRIPS_FROM_WINDOW or strip_window > 0.5 * window):
        return none
    # The base on a multiple of the height, so that strips stay put while the scene's lowest box
    # moves (it does every frame where objects are spawned and removed): last frame's order stays
    # a good start for the repair.
    base = (np.floor(o0 / height) - 1.0) * height
    if not (base <= o0):
        base = o0
    return axis, base, 1.0 / height, strips, s0, s1, large


@nb.njit(cache=True)
def _large_size(radii, widest):
    """large_size over each box's larger half-extent."""
    sizes = np.empty(radii.shape[0])
    for i in range(radii.shape[0]):
        sizes[i] = max(half_of(radii, i, 0), half_of(radii, i, 1))
    return large_size(sizes, widest, LARGE_SHARE)


@nb.njit(cache=True)
def large_size(sizes, widest, share):
    """(large, reach): the half size above which a box is large, and the largest half size of the
    others, which the strips (own.sap's columns in 3D) hold, from each box's half size across them
    (`sizes`, at most `widest`). The smallest of SIZE_BINS steps of `widest` that at most `share`
    of the boxes exceed; where none is large (equal sizes: every circle scene), inf
    and `widest`, the strips as before."""
    n = sizes.shape[0]
    counts = np.zeros(SIZE_BINS + 1, dtype=np.int64)
    scale = SIZE_BINS / widest
    for i in range(n):
        counts[int(sizes[i] * scale)] += 1  # bin SIZE_BINS: widest
    above, b = 0, SIZE_BINS
    while b > 0 and above + counts[b] <= share * n:  # bin b can go to the large bucket
        above += counts[b]
        b -= 1
    large = (b + 1) / scale
    if above == 0 or LARGE_FROM_RATIO * large > widest:
        return np.inf, widest
    return large, large


@nb.njit(cache=True, inline="always")
def _strip(v, base, inv_height, last):
    return min(int((v - base) * inv_height), last)


@nb.njit(cache=True)
def strip_prepare(positions, radii, plan, last_order, incremental, order, work, sorted_bounds,
                  strip_start, strip_width, strip_of):
    """Sort for this frame's strip sweep into `order`, `sorted_bounds` (s_lo, s_hi, o_lo, o_hi),
    `strip_start` (first slot of each strip, then of the large bucket, then n: strips + 2 entries)
    and `strip_width` (each strip's widest box on the sweep axis, padded; strips + 1 entries, the
    large bucket's last); `strip_of` (n) is scratch. Returns the swaps of the repair, -1 after a
    full sort, or -2 when a box spans more than two strips (nothing usable: the caller sweeps plain).

    With `incremental`, last frame's strip order (`last_order`, its axis + 2 in its last entry) is
    repaired by an insertion sort on (strip, lower bound), which costs O(n) while few objects change
    strip or pass each other; otherwise, and when the repair gives up, the objects are radix-sorted
    by lower bound and then grouped by strip with a stable counting sort.
    """
    n = positions.shape[0]
    axis, base, inv_height, strips, s0, s1, large = plan
    other = 1 - axis
    last = strips - 1
    xy, sr, keys, perm = work
    swaps = -1
    if incremental and last_order[n] == axis + 2:
        gather(positions, radii, last_order[:n], xy, sr, CIRCLES)
        if not _slot_strips(xy, sr, axis, base, inv_height, last, large, strip_of, keys, perm):
            return -2
        swaps = _repair(strip_of, keys, perm, MAX_SWAPS_PER_OBJECT * n + 64)
        if swaps >= 0:
            for a in range(n):
                order[a] = last_order[perm[a]]
    if swaps < 0:
        # Sorted on (strip, lower bound quantised) by a counting sort, on about one bucket per
        # object (at most one per strip height along the sweep axis). The quantising is monotone,
        # so only objects sharing a bucket can be out of order, and the insertion sort below puts
        # them right, exactly.
        cols = max(1, min(int((s1 - s0) * inv_height) + 1, n // strips))
        scale, top = cols / (s1 - s0), float(cols - 1)
        quant = perm.view(np.uint64)  # borrowed: the sort keys
        for i in range(n):
            k = _strip_or_large(positions, radii, i, other, base, inv_height, last, large)
            q = min((positions[i, axis] - half_of(radii, i, axis) - s0) * scale, top)
            quant[i] = np.uint64(k) * np.uint64(cols) + np.uint64(q)
        source = counting_argsort(quant, (strips + 1) * cols)
        gather(positions, radii, source, xy, sr, CIRCLES)
        if not _slot_strips(xy, sr, axis, base, inv_height, last, large, strip_of, keys, perm):
            return -2
        _repair(strip_of, keys, perm, n * n + 64)
        for a in range(n):
            order[a] = source[perm[a]]
    s_lo, s_hi, o_lo, o_hi = sorted_bounds
    strip_width[:] = 0.0
    k_last, widest = -1, 0.0  # the strip of the slots before, and its widest box so far
    for a in range(n):  # perm is almost the identity: near-sequential reads
        j = perm[a]
        r, ro = half_of(sr, j, axis), half_of(sr, j, other)
        s_lo[a], s_hi[a] = xy[j, axis] - r, xy[j, axis] + r
        o_lo[a], o_hi[a] = xy[j, other] - ro, xy[j, other] + ro
        k = strip_of[a]
        if k != k_last:  # slots come strip by strip: a branch taken once per strip
            if k_last >= 0:
                strip_width[k_last] = widest * WIDTH_PAD
            strip_start[k_last + 1:k + 1] = a
            k_last, widest = k, 0.0
        widest = max(widest, s_hi[a] - s_lo[a])
    if k_last >= 0:
        strip_width[k_last] = widest * WIDTH_PAD
    strip_start[k_last + 1:] = n
    order[n] = axis + 2  # a strip order, on this axis
    return swaps


@nb.njit(cache=True)
def counting_argsort(keys, buckets):
    """Stable argsort of integer keys below `buckets`."""
    start = np.zeros(buckets + 1, dtype=np.int64)
    for i in range(keys.shape[0]):
        start[keys[i] + 1] += 1
    for b in range(buckets):
        start[b + 1] += start[b]
    order = np.empty(keys.shape[0], dtype=np.int64)
    for i in range(keys.shape[0]):
        b = keys[i]
        order[start[b]] = i
        start[b] += 1
    return order


@nb.njit(cache=True, inline="always")
def _strip_or_large(xy, sr, a, other, base, inv_height, last, large):
    """The strip of row a's lower bound on the other axis, or last + 1 (the large bucket) where its
    larger half-extent is at least `large`."""
    if max(half_of(sr, a, 0), half_of(sr, a, 1)) >= large:
        return last + 1
    return _strip(xy[a, other] - half_of(sr, a, other), base, inv_height, last)


@nb.njit(cache=True)
def _slot_strips(xy, sr, axis, base, inv_height, last, large, strip_of, keys, perm):
    """Each row's strip (last + 1: the large bucket) into strip_of, its lower bound on the sweep
    axis into keys, and perm the identity; False if a box of the strips spans more than two."""
    other = 1 - axis
    spans = 0
    for a in range(xy.shape[0]):
        k = _strip_or_large(xy, sr, a, other, base, inv_height, last, large)
        if k <= last:
            spans = max(spans, _strip(xy[a, other] + half_of(sr, a, other), base, inv_height, last) - k)
        strip_of[a] = k
        keys[a] = xy[a, axis] - half_of(sr, a, axis)
        perm[a] = a
    return spans <= 1


@nb.njit(cache=True)
def _repair(strips, keys, perm, max_swaps):
    """Insertion sort of the rows by (strip, key), all three permuted together; the swaps made, or
    -1 once past max_swaps (the rows then part-sorted)."""
    swaps = 0
    for a in range(1, keys.shape[0]):
        k, key, p = strips[a], keys[a], perm[a]
        b = a - 1
        while b >= 0 and (strips[b] > k or (strips[b] == k and keys[b] > key)):
            strips[b + 1], keys[b + 1], perm[b + 1] = strips[b], keys[b], perm[b]
            b -= 1
            swaps += 1
        if swaps > max_swaps:
            return -1
        strips[b + 1], keys[b + 1], perm[b + 1] = k, key, p
    return swaps


@nb.njit(cache=True)
def strip_sweep(order, s_lo, s_hi, o_lo, o_hi, strip_start, strip_width, a0, a1, buf):
    """Box-overlap pairs of the objects in sorted slots a0..a1-1 with the later ones of their strip
    and the overlapping ones of the next strip, into buf; returns (pairs found, pairs tested).

    Windows hold a few objects (that is what the strips are for): plain loops, each candidate
    written at row `count` and kept only by a hit, with no branch on the test."""
    strips = strip_start.shape[0] - 1
    count = tested = 0
    lo, hi = 0, strips - 1  # the strip of slot a0: the last one starting at or before it
    while lo < hi:
        mid = (lo + hi + 1) >> 1
        if strip_start[mid] <= a0:
            lo = mid
        else:
            hi = mid - 1
    k = lo
    own_end = strip_start[k + 1]
    next_end = strip_start[k + 2] if k + 1 < strips else own_end
    reach = strip_width[k + 1] if k + 1 < strips else 0.0
    cursor = own_end  # in strip k + 1: no slot before it can overlap what is left of strip k
    for a in range(a0, a1):
        while own_end <= a:
            k += 1
            own_end = cursor = strip_start[k + 1]
            next_end = strip_start[k + 2] if k + 1 < strips else own_end
            reach = strip_width[k + 1] if k + 1 < strips else 0.0
        top, bottom, lo_a, hi_a, i = s_hi[a], s_lo[a], o_lo[a], o_hi[a], order[a]
        b = a + 1
        while b < own_end and s_lo[b] <= top:
            emit(buf, count, i, order[b])
            count += (o_lo[b] <= hi_a) & (o_hi[b] >= lo_a)
            b += 1
        tested += b - a - 1
        while cursor < next_end and s_lo[cursor] + reach < bottom:
            cursor += 1
        b = cursor
        while b < next_end and s_lo[b] <= top:
            emit(buf, count, i, order[b])
            count += (o_lo[b] <= hi_a) & (o_hi[b] >= lo_a) & (s_hi[b] >= bottom)
            b += 1
        tested += b - cursor
    return count, tested


@nb.njit(cache=True)
def large_against_strips(order, s_lo, s_hi, o_lo, o_hi, strip_start, strip_width, base, inv_height, a0, a1,
                         buf, count, tested):
    """Pairs of the large bucket's slots a0..a1-1 with the objects of the strips, into buf from row
    `count`; returns (pairs found, pairs tested), counting on from the given ones.

    A strip object that meets a large box lies in a strip the box spans or in the one below (it
    spans at most two), and on the sweep axis starts at most its strip's widest box before the
    large box: each such strip is bisected to there and scanned to the large box's end. Each pair
    is met once, in the strip of the small object's lower bound."""
    strips = strip_start.shape[0] - 2
    last = strips - 1
    for a in range(a0, a1):
        bottom, top, lo_a, hi_a, i = s_lo[a], s_hi[a], o_lo[a], o_hi[a], order[a]
        k0 = max(_strip(lo_a, base, inv_height, last) - 1, 0)
        for k in range(k0, _strip(hi_a, base, inv_height, last) + 1):
            lo, end = strip_start[k], strip_start[k + 1]
            lo += np.searchsorted(s_lo[lo:end], bottom - strip_width[k])  # the first that can reach it
            b = lo
            while b < end and s_lo[b] <= top:
                emit(buf, count, i, order[b])
                count += (o_lo[b] <= hi_a) & (o_hi[b] >= lo_a) & (s_hi[b] >= bottom)
                b += 1
            tested += b - lo
    return count, tested


@nb.njit(cache=True)
def large_among_themselves(order, s_lo, s_hi, o_lo, o_hi, a0, a1, positions, radii, buf, count, tested):
    """Pairs among the large bucket's slots a0..a1-1 (sorted by lower bound on the sweep axis),
    into buf from row `count`: through the cells they cover from COVER_FROM of them, else swept.
    Returns (pairs found, pairs tested), counting on from the given ones."""
    if a1 - a0 >= COVER_FROM:
        ids = order[a0:a1]  # their centres and sizes as the strips' bounds were made from them
        found, tested_covered = pairs_among_covered(positions[ids], radii[ids], ids, buf, count, tested, CIRCLES)
        if found >= 0:
            return found, tested_covered
    for a in range(a0, a1):
        top, lo_a, hi_a, i = s_hi[a], o_lo[a], o_hi[a], order[a]
        b = a + 1
        while b < a1 and s_lo[b] <= top:
            emit(buf, count, i, order[b])
            count += (o_lo[b] <= hi_a) & (o_hi[b] >= lo_a)
            b += 1
        tested += b - a - 1
    return count, tested


@nb.njit(cache=True)
def strip_pairs(order, s_lo, s_hi, o_lo, o_hi, strip_start, strip_width, base, inv_height, positions, radii, buf):
    """Every pair of a strip order (strip_prepare's): the strips swept, the large bucket against
    them and among itself; returns (pairs found, pairs tested)."""
    strips = strip_start.shape[0] - 2
    first_large, n = strip_start[strips], strip_start[strips + 1]
    count, tested = strip_sweep(order, s_lo, s_hi, o_lo, o_hi, strip_start[:strips + 1], strip_width[:strips],
                                0, first_large, buf)
    count, tested = large_against_strips(order, s_lo, s_hi, o_lo, o_hi, strip_start, strip_width, base, inv_height,
                                         first_large, n, buf, count, tested)
    return large_among_themselves(order, s_lo, s_hi, o_lo, o_hi, first_large, n, positions, radii, buf, count,
                                  tested)


@nb.njit(cache=True, parallel=True)
def strip_pairs_parallel(order, s_lo, s_hi, o_lo, o_hi, strip_start, strip_width, base, inv_height, positions,
                         radii, bufs):
    """strip_pairs with the strips' slots and the large bucket's each split into one chunk per row
    of bufs, swept and queried in parallel; the pairs among the large objects in the first chunk.
    Returns (pairs per chunk, pairs tested per chunk)."""
    chunks = bufs.shape[0]
    strips = strip_start.shape[0] - 2
    first_large, n = strip_start[strips], strip_start[strips + 1]
    counts, tested = np.zeros((2, chunks), dtype=np.int64)
    for c in nb.prange(chunks):
        count, t = strip_sweep(order, s_lo, s_hi, o_lo, o_hi, strip_start[:strips + 1], strip_width[:strips],
                               c * first_large // chunks, (c + 1) * first_large // chunks, bufs[c])
        m = n - first_large
        count, t = large_against_strips(order, s_lo, s_hi, o_lo, o_hi, strip_start, strip_width, base, inv_height,
                                        first_large + c * m // chunks, first_large + (c + 1) * m // chunks,
                                        bufs[c], count, t)
        if c == 0:
            count, t = large_among_themselves(order, s_lo, s_hi, o_lo, o_hi, first_large, n, positions, radii,
                                              bufs[c], count, t)
        counts[c], tested[c] = count, t
    return counts, tested
