"""Verlet neighbour list: candidate pairs found with a skin, then reused while objects stay close.

The list holds every pair whose boxes, each enlarged by half the `skin`, overlap (built with our
exact grid); each frame only its pairs are tested against the current boxes. A pair that was not
in the list can overlap only after the two objects have together closed more than the skin, so
while no object has moved more than skin / 2 (along either axis, since the build) the list holds
every overlap and the result is exact. `every=None` (the default) rebuilds exactly when that rule
requires; `every=k` rebuilds every k frames whatever the motion, as molecular dynamics codes do
(LAMMPS `neigh_modify every`), and misses pairs when objects outrun the skin: a setting that
trades accuracy for speed, measured by the trade-off study. `precision="float32"` rounds the
coordinates and radii to float32 first, as a code that stores them so would. `fat=True` reports
the list itself, the pairs whose fat boxes overlap, as Box2D's broad phase does: no test per
frame, more candidates for the narrow phase, still every overlap under the rule.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from engines.base import BroadPhase
from engines.knobs import Knob, fixed, mean_diameter, sizes
from scenes.scene import shown

from .common import PairCollector, emit
from .grid import UniformGrid
from .statics import StaticsApart

PRECISIONS = ("float64", "float32")
# The default skin adapts to the motion (an explicit `skin` stays as given), after each list from
# how long it lived and how many pairs its skin added to every frame's filter:
# - SHORT_IN_A_ROW lists in a row that lived one frame drop it to zero: no frame's motion fits it,
#   so the list is never reused and only fattens the rebuild (halving it instead spent the first
#   five or so frames of the tumbler on such lists; a single one is often one bounce, on a pile
#   settling). At zero skin every frame is a rebuild, so the skin is tried again after PROBE_AFTER
#   of them, twice as many after each try that failed (each try rebuilds the grid for the fat radii);
# - a list whose skin added a share `excess` to the pairs that overlapped, and that lived `lived`
#   frames, halves it where excess x lived >= SHRINK_GAIN (down to MIN_SHARE of the default):
#   halving saves about excess / 2 of the overlapping pairs' filter every frame, for a rebuild
#   every lived / 2 frames instead of every lived. Where objects are dense the filter costs more
#   than the rebuilds a wide skin saves. A halved list that then lived one frame takes the skin
#   back, and halving stops there;
# - a list that lived LONG_LIVED frames grows it by half, up to LARGEST_SKIN_DIAMETERS.
# Measured over 60 frames at n = 8192 (mean frame; fixed skins of 0.05 / 0.1 / 0.25 diameters, the
# list's pairs over the overlapping ones at 0.25): the essay's motion at r = 25 took 0.41 / 0.47 /
# 0.82 ms (1.54 times), gauss_x 0.29 / 0.26 / 0.40 (1.55), r = 10 0.15 / 0.14 / 0.17 (1.60),
# r = 3 0.13 / 0.090 / 0.077 (1.68, lists of 3 frames), the pile 0.23 / 0.15 / 0.12 (1.22).
SHRINK_BELOW, SHORT_IN_A_ROW, LONG_LIVED, PROBE_AFTER = 2, 2, 8, 16
SHRINK_GAIN, MIN_SHARE = 1.25, 0.125
SKIN_FACTORS = (0.05, 0.1, 0.25, 0.5, 1.0, 2.0)  # the skin, in mean diameters, for a sweep
# The default skin, in mean diameters, where it starts, and the most it grows to.
DEFAULT_SKIN_DIAMETERS, LARGEST_SKIN_DIAMETERS = 0.125, 0.25
# Every trial that tunes the skin spans this many frames (engines.knobs.Knob.trial_frames): the
# sweep's larger skins (a diameter lives about 30 frames of the essay's motion at r = 10) must pay
# for a rebuild inside it, as the default's shorter-lived lists do.
TRIAL_FRAMES = 40


@nb.njit(cache=True)
def filter_pairs(candidates, positions, radii, buf):
    """The candidates whose boxes overlap now (closed intervals), in the list's order."""
    count = 0
    for k in range(candidates.shape[0]):
        i, j = candidates[k, 0], candidates[k, 1]
        reach = radii[i] + radii[j]
        if abs(positions[i, 0] - positions[j, 0]) <= reach and abs(positions[i, 1] - positions[j, 1]) <= reach:
            emit(buf, count, i, j)
            count += 1
    return (count,)


@nb.njit(cache=True)
def largest_step(positions, built):
    """The largest displacement of any object along either axis since the list was built."""
    step = 0.0
    for i in range(positions.shape[0]):
        step = max(step, abs(positions[i, 0] - built[i, 0]), abs(positions[i, 1] - built[i, 1]))
    return step


class VerletList(StaticsApart, BroadPhase):
    """Verlet neighbour list over our exact grid; `skin` (default a quarter of a mean diameter, adapting), `every`
    (None: rebuild when an object has moved skin / 2, exact; k: every k frames, approximate),
    `precision` ("float64", or "float32": inputs rounded first, approximate), `fat` (True: the
    fat-box pairs, untested)."""

    name, method = "own.verlet", "grid"
    defaults = {"skin": None, "every": None, "precision": "float64", "fat": False}
    sweeps = (Knob("skin", sizes(mean_diameter, SKIN_FACTORS), "skin", trial_frames=TRIAL_FRAMES),
              Knob("every", fixed([2, 5, 10, 20]), "rebuild every k frames", period=True),
              Knob("precision", fixed(list(PRECISIONS)), "coordinates"),
              Knob("fat", fixed([True]), "fat-box pairs reported untested"))

    def __init__(self, **params):
        super().__init__(**params)
        skin, every = self.params["skin"], self.params["every"]
        if skin is not None and not (isinstance(skin, (int, float)) and np.isfinite(skin) and skin >= 0):
            raise ValueError(f"{self.name}: skin must be a distance >= 0, got {shown(skin)}")
        if every is not None:
            self._int_param("every", 1)
        if self.params["precision"] not in PRECISIONS:
            raise ValueError(f"{self.name}: precision must be one of {', '.join(PRECISIONS)}, "
                             f"got {self.params['precision']!r}")
        if not isinstance(self.params["fat"], (bool, np.bool_)):
            raise ValueError(f"{self.name}: fat must be True or False, got {self.params['fat']!r}")
        self._collect = PairCollector()

    def _rounded(self, values: np.ndarray) -> np.ndarray:
        if self.params["precision"] == "float32":
            return values.astype(np.float32).astype(np.float64)
        return values

    def _reset(self, positions, radii):
        self._radii = self._rounded(radii)
        positive = self._radii[self._radii > 0]
        default = DEFAULT_SKIN_DIAMETERS * 2.0 * float(positive.mean()) if len(positive) else 1.0
        self._skin = float(self.params["skin"]) if self.params["skin"] is not None else default
        self._default_skin, self._adapts = self._skin, self.params["skin"] is None and self.params["every"] is None
        self._bare_rebuilds = 0  # rebuilds in a row at zero skin
        self._probe_after, self._probing = PROBE_AFTER, False  # when a skin is tried again; being tried
        self._short = 0  # lists in a row that lived one frame
        # The skin the last list was halved from (0: it was not), and the skin no halving goes below.
        self._halved_from, self._floor = 0.0, MIN_SHARE * self._default_skin
        self._overlapping = None  # the pairs that overlapped in the last frame asked for them
        if not isinstance(getattr(self, "_grid", None), UniformGrid):
            self._grid = UniformGrid()  # kept across resets, with its pair buffers (rain resets every frame)
        self._built_skin = None
        self._build(self._rounded(positions))
        self._frame = 0
        self._stats = {"rebuilds": 0}

    def _build(self, positions: np.ndarray) -> None:
        # The grid is moved, not built again, while the fat radii stay (its counting sort keeps
        # last frame's order): at zero skin on the tumbler, 0.306 to 0.2 ms a frame at n = 4096.
        if self._built_skin == self._skin:
            self._grid.update(positions)
        else:
            self._grid.reset(positions, self._radii + 0.5 * self._skin)
            self._built_skin = self._skin
        self._list = self._grid.pairs()
        self._anchor = positions.copy()  # where the list was built
        self._positions = positions
        self._since = 0

    def _update(self, positions):
        positions = self._rounded(positions)
        self._since += 1
        every = self.params["every"]
        due = (self._since >= every) if every is not None else largest_step(positions, self._anchor) > 0.5 * self._skin
        if due:
            if self._adapts:
                self._adapt_skin(self._since)
            self._build(positions)
            self._stats["rebuilds"] += 1
            self._stats["skin"] = self._skin
        self._positions = positions

    def _adapt_skin(self, lived: int) -> None:
        """The skin for the next list, from how many frames the last one lived and how many pairs
        it listed for each that overlapped in its last frame (see SHRINK_BELOW)."""
        excess = 0.0 if self._overlapping is None else len(self._list) / max(self._overlapping, 1) - 1.0
        self._short = self._short + 1 if lived < SHRINK_BELOW else 0
        halved_from, self._halved_from = self._halved_from, 0.0
        if self._skin == 0.0:
            self._bare_rebuilds += 1
            if self._bare_rebuilds >= self._probe_after:
                self._skin, self._bare_rebuilds, self._probing = self._default_skin, 0, True
        elif self._short and halved_from:  # halved too far: back, and no lower again
            self._skin = self._floor = halved_from
        elif self._short >= SHORT_IN_A_ROW:
            if self._probing:  # a try after zero skin failed: the next waits twice as long
                self._probe_after *= 2
            self._skin, self._probing = 0.0, False
        elif self._short:
            pass  # one short list: wait for another
        elif excess * lived >= SHRINK_GAIN and 0.5 * self._skin >= self._floor:
            self._halved_from, self._skin = self._skin, 0.5 * self._skin
        elif lived >= LONG_LIVED:
            self._skin = min(1.5 * self._skin, LARGEST_SKIN_DIAMETERS / DEFAULT_SKIN_DIAMETERS * self._default_skin)
        if not self._short:  # a list that lived: a skin is worth trying soon again
            self._probe_after, self._probing = PROBE_AFTER, False

    def _pairs(self):
        self._stats["listed"] = len(self._list)
        if self.params["fat"] or (self._skin == 0.0 and self._since == 0):  # the list is this frame's pairs
            self._overlapping = len(self._list)
            return self._list.copy()
        out, _ = self._collect(filter_pairs, self._list, self._positions, self._radii)
        self._overlapping = len(out)
        return out

    def validate(self):
        """While the rule holds, the list holds every current overlap."""
        if self.params["every"] is None:
            assert largest_step(self._positions, self._anchor) <= 0.5 * self._skin, "an object outran the skin"
