"""Verlet neighbour list: candidate pairs found with a skin, then reused while objects stay close.

The list holds every pair whose boxes, each enlarged by half the `skin`, overlap (built with our
exact grid); each frame only its pairs are tested against the current boxes. A pair that was not
in the list can overlap only after the two objects have together closed more than the skin, so
while no object has moved more than skin / 2 (along any axis, since the build) the list holds
every overlap and the result is exact. `every=None` (the default) rebuilds exactly when that rule
requires; `every=k` rebuilds every k frames whatever the motion, as molecular dynamics codes do
(LAMMPS `neigh_modify every`), and misses pairs when objects outrun the skin: a setting that
trades accuracy for speed, measured by the trade-off study. `precision="float32"` rounds the
coordinates and radii to float32 first, as a code that stores them so would. `fat=True` reports
the list itself, the pairs whose fat boxes overlap, as Box2D's broad phase does: no test per
frame, more candidates for the narrow phase, still every overlap under the rule. The default skin
adapts to the motion and the density (own/skin.py).
"""

from __future__ import annotations

import math

import numpy as np

from interface.base import BroadPhase, size_keyword
from interface.checks import shown
from interface.knobs import Knob, fixed, mean_diameter, sizes

from .common import PairCollector
from .dimension import marker
from .grid import UniformGrid
from .grid_query import CellQueries
from .skin import SkinSchedule, filter_pairs, skin_used
from .statics import StaticsApart

PRECISIONS = ("float64", "float32")
SKIN_FACTORS = (0.05, 0.1, 0.25, 0.5, 1.0, 2.0)  # the skin, in mean diameters, for a sweep
# The default skin, in mean diameters: where it starts, and the most it grows to.
DEFAULT_SKIN_DIAMETERS, LARGEST_SKIN_DIAMETERS = 0.25, 1.0
# Every trial that tunes the skin spans this many frames (interface.knobs.Knob.trial_frames): the
# sweep's larger skins (a diameter lives about 30 frames of the essay's motion at r = 10) must pay
# for a rebuild inside it, as the default's shorter-lived lists do.
TRIAL_FRAMES = 40


class VerletList(StaticsApart, CellQueries, BroadPhase):
    """Verlet neighbour list over our exact grid; `skin` (default a quarter of a mean diameter, adapting), `every`
    (None: rebuild when an object has moved skin / 2, exact; k: every k frames, approximate),
    `precision` ("float64", or "float32": inputs rounded first, approximate), `fat` (True: the
    fat-box pairs, untested). Queries go through the list's grid, whose cells hold the fat boxes
    as they were at the build: they hold the shapes now while the rule holds (with `every`, a
    query misses what outran the skin, as the pairs do)."""

    name, method = "own.verlet", "grid"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    resizes = True  # new extents: the list is kept until a box outgrows the skin (skin_used)
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
        self._dim = marker(self.dim)
        self._sizes, self._radii = radii, self._rounded(radii)
        positive = self._radii[self._radii > 0]
        default = DEFAULT_SKIN_DIAMETERS * 2.0 * float(positive.mean()) if len(positive) else 1.0
        self._adapts = self.params["skin"] is None and self.params["every"] is None
        if self._built and self._adapts:
            # Built anew in a run, for the objects that appeared or went: the last list lived until
            # now, and the skin goes on adapting (where objects come and go every frame, a list is
            # never reused, and the skin drops to zero).
            self._skin = self._schedule.next(self._since + 1)
        else:
            self._skin = float(self.params["skin"]) if self.params["skin"] is not None else default
            self._default_skin = self._skin
            self._schedule = SkinSchedule(self._skin, LARGEST_SKIN_DIAMETERS / DEFAULT_SKIN_DIAMETERS * self._skin)
        self._overlapping = None  # the pairs that overlapped in the last frame asked for them
        self._largest_radius = float(self._radii.max()) if len(self._radii) else 0.0
        if not isinstance(getattr(self, "_grid", None), UniformGrid):
            self._grid = UniformGrid()  # kept across resets, with its pair buffers (rain resets every frame)
        self._built_skin = None
        self._build(self._rounded(positions))
        self._frame = 0
        self._stats = {"rebuilds": 0}

    def _build(self, positions: np.ndarray) -> None:
        # The grid is moved, not built again, while the fat radii stay (its counting sort keeps
        # last frame's order): at zero skin on the tumbler, 0.306 to 0.2 ms a frame at n = 4096.
        if not math.isfinite(self._largest_radius + 0.5 * self._skin):
            self._skin = 0.0  # radii near the largest double leave no room for a skin (exact without one)
        if self._built_skin == self._skin and self._grid_sizes is self._radii:
            self._grid.update(positions)
        elif self._built_skin == self._skin and self._radii.ndim == 2:
            # Boxes that turned: the grid takes their fat boxes in place, its cells kept (built
            # anew each frame, the debris at n = 4096 took 2.0 ms a frame, own.grid's 1.4).
            self._grid.update(positions, extents=self._radii + 0.5 * self._skin)
            self._grid_sizes = self._radii
        else:
            self._grid.reset(positions, **size_keyword(self._radii + 0.5 * self._skin))
            self._built_skin, self._grid_sizes = self._skin, self._radii
        self._list = self._grid.pairs()
        self._anchor, self._anchor_sizes = positions.copy(), self._radii  # where and how large, at the build
        self._positions = positions
        self._since = 0

    def _update(self, positions):
        positions = self._rounded(positions)
        if self.radii is not self._sizes:  # boxes took new extents (`resizes`): kept until they outgrow the skin
            self._sizes, self._radii = self.radii, self._rounded(self.radii)
            self._largest_radius = float(self._radii.max()) if len(self._radii) else 0.0
        self._since += 1
        every = self.params["every"]
        due = (self._since >= every) if every is not None \
            else skin_used(positions, self._anchor, self._radii, self._anchor_sizes, self._dim) > 0.5 * self._skin
        if due:
            if self._adapts:
                self._skin = self._schedule.next(self._since, len(self._list), self._overlapping, len(positions))
            self._build(positions)
            self._stats["rebuilds"] += 1
            self._stats["skin"] = self._skin
        self._positions = positions

    def _pairs(self):
        self._stats["listed"] = len(self._list)
        if self.params["fat"] or (self._skin == 0.0 and self._since == 0):  # the list is this frame's pairs
            self._overlapping = len(self._list)
            return self._list.copy()
        out, _ = self._collect(filter_pairs, self._list, self._positions, self._radii, self._dim)
        self._overlapping = len(out)
        return out

    def _query_cells(self):
        grid = self._grid
        cells = None if grid._small is not None else grid._query_cells()[2]
        return self._positions, self._radii, cells

    def validate(self):
        """While the rule holds, the list holds every current overlap."""
        if self.params["every"] is None:
            step = skin_used(self._positions, self._anchor, self._radii, self._anchor_sizes, self._dim)
            assert step <= 0.5 * self._skin, "an object outran the skin"
