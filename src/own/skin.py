"""A skin that adapts to the motion: how far our structures that are kept over frames (the Verlet
list, the trees, the sweeps and the pairs they found) let each object move before they are built again.

A structure built with a skin holds every pair whose boxes, each enlarged by half the skin, overlap;
it is reused, exactly, while no object has moved more than skin / 2 since it was built. A wider skin
lives longer but holds more pairs to test every frame; one that no frame's motion fits is never
reused and only fattens the build. `largest_step` is the rule (`largest_reach` for boxes whose
extents change: a side that moved out by growing counts as moved), `filter_pairs` tests a kept list
against the boxes of this frame, and `SkinSchedule` picks the skin for the next build from how long
the last one lived and how many pairs its skin added.
"""

from __future__ import annotations

import numba as nb

from .common import emit, half_of

# The rule, after each build (`lived` frames, its skin adding `extra` pairs per object to those
# that overlapped):
# - SHORT_IN_A_ROW builds in a row that lived one frame drop the skin to zero: no frame's motion
#   fits it (halving it instead spent the first five or so frames of the tumbler on such lists; a
#   single one is often one bounce, on a pile settling). At zero skin every frame is a build, so a
#   skin is tried again after PROBE_AFTER of them, twice as many after each try that failed (each
#   try builds for the fat radii anew);
# - where extra x lived >= SHRINK_GAIN the skin is halved (down to MIN_SHARE of the start):
#   halving saves about half the extra pairs' tests every frame, for a build every lived / 2
#   frames instead of every lived, and a build costs about what testing SHRINK_GAIN / 2 pairs per
#   object does; where objects are dense the tests cost more than the builds a wide skin saves. A
#   halved skin whose build then lived one frame is taken back, and halving stops there;
# - where extra x lived x GROW_MARGIN < SHRINK_GAIN the skin is doubled, up to `largest`: where
#   objects are sparse or slow its pairs cost little and a wider one saves builds (doubling it
#   adds about GROW_MARGIN times the product, so it is not halved again at once).
# Measured on the Verlet list over 60 frames at n = 8192 (mean frame; fixed skins of 0.05 / 0.1 /
# 0.25 mean diameters; extra pairs per object x frames lived at 0.25): the essay's motion at r = 25
# took 0.41 / 0.47 / 0.82 ms (55), gauss_x 0.29 / 0.26 / 0.40 (12), r = 10 0.15 / 0.14 / 0.17 (7),
# r = 3 0.13 / 0.090 / 0.077 (0.2), the pile 0.23 / 0.15 / 0.12 (3). A rule on the share of pairs
# the skin adds instead halved the skin on sparse scenes, where a build costs more than the few
# pairs it saves (up to 2.6x slower at n = 1024 in the tuning study); there a skin of a diameter
# was fastest (r = 3: 0.059 ms against 0.075 at a quarter diameter, n = 8192).
SHRINK_BELOW, SHORT_IN_A_ROW, PROBE_AFTER = 2, 2, 16
SHRINK_GAIN, GROW_MARGIN, MIN_SHARE = 10.0, 6.0, 0.125


@nb.njit(cache=True)
def largest_step(positions, built, dim):
    """The largest displacement of any object along any axis since `built` (`dim`: the
    dimension's marker, own/dimension.py)."""
    step = 0.0
    for i in range(positions.shape[0]):
        for a in range(len(dim)):
            step = max(step, abs(positions[i, a] - built[i, a]))
    return step


@nb.njit(cache=True)
def largest_reach(positions, built, sizes, built_sizes, dim):
    """Boxes whose extents change: the farthest any box's side has gone out since `built`, its
    centre's displacement plus its half-extent's growth along any axis (`built_sizes`, the
    half-extents then). A structure built over boxes grown by half the skin holds every box whose
    reach is at most skin / 2: a box that grew is a box whose side moved."""
    reach = 0.0
    for i in range(positions.shape[0]):
        for a in range(len(dim)):
            reach = max(reach, abs(positions[i, a] - built[i, a]) + half_of(sizes, i, a) - half_of(built_sizes, i, a))
    return reach


def skin_used(positions, built, sizes, built_sizes, dim) -> float:
    """How much of the skin the objects have used since the build (against skin / 2): the largest
    step, or for boxes whose extents changed since, the largest reach."""
    if sizes is built_sizes or sizes.ndim == 1:  # balls keep their radii: the kernel over balls as it was
        return largest_step(positions, built, dim)
    return largest_reach(positions, built, sizes, built_sizes, dim)


@nb.njit(cache=True)
def filter_pairs(candidates, positions, radii, dim, buf):
    """The candidates whose boxes overlap now (closed intervals), in the list's order; `radii`: the
    balls' radii or the boxes' half-extents (common.half_of)."""
    count = 0
    for k in range(candidates.shape[0]):
        i, j = candidates[k, 0], candidates[k, 1]
        meet = True
        for a in range(len(dim)):
            r, s = half_of(radii, i, a), half_of(radii, j, a)
            # The rule on the bounds themselves: a centre distance against r + s rounds otherwise.
            meet &= (positions[j, a] - s <= positions[i, a] + r) & (positions[i, a] - r <= positions[j, a] + s)
        if meet:
            emit(buf, count, i, j)
            count += 1
    return (count,)


class SkinSchedule:
    """The skin for each build, from `start`, grown to `largest` at most (see the rule above)."""

    def __init__(self, start: float, largest: float) -> None:
        self.skin, self.start, self.largest = start, start, largest
        self.floor = MIN_SHARE * start  # no halving goes below it
        self._bare = 0  # builds in a row at zero skin
        self._probe_after, self._probing = PROBE_AFTER, False  # when a skin is tried again; being tried
        self._short = 0  # builds in a row that lived one frame
        self._halved_from = 0.0  # the skin the last build was halved from (0: it was not)

    def next(self, lived: int, kept: int | None = None, overlapping: int | None = None, n: int = 1) -> float:
        """The skin for the next build, after one that lived `lived` frames and kept `kept` pairs
        for its `n` objects, of which `overlapping` overlapped in the last frame asked for them
        (None where none was asked: no pairs beyond them counted)."""
        extra = (kept - overlapping) / max(n, 1) if kept is not None and overlapping is not None else 0.0
        self._short = self._short + 1 if lived < SHRINK_BELOW else 0
        halved_from, self._halved_from = self._halved_from, 0.0
        if self.skin == 0.0:
            self._bare += 1
            if self._bare >= self._probe_after:
                self.skin, self._bare, self._probing = self.start, 0, True
        elif self._short and halved_from:  # halved too far: back, and no lower again
            self.skin = self.floor = halved_from
        elif self._short >= SHORT_IN_A_ROW:
            if self._probing:  # a try after zero skin failed: the next waits twice as long
                self._probe_after *= 2
            self.skin, self._probing = 0.0, False
        elif self._short:
            pass  # one short build: wait for another
        elif extra * lived >= SHRINK_GAIN and 0.5 * self.skin >= self.floor:
            self._halved_from, self.skin = self.skin, 0.5 * self.skin
        elif extra * lived * GROW_MARGIN < SHRINK_GAIN:
            self.skin = min(2.0 * self.skin, self.largest)
        if not self._short:  # a build that lived: a skin is worth trying soon again
            self._probe_after, self._probing = PROBE_AFTER, False
        return self.skin

    @property
    def probe_after(self) -> int:
        return self._probe_after
