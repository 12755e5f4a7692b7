"""The essay's uniform grid: each particle goes into its own cell and the 8 around it, then every
pair inside each cell is tested. The printed code's -1 index (wrapping to the opposite border) is
fixed; the repeated tests of one pair in up to 9 shared cells are the method, and are counted.
`printed_defects=True` keeps the wrap-around, to measure it (`wrapped` inserts in the stats)."""

from __future__ import annotations

import math

from interface.knobs import Knob, fixed

from .particle import EssayBroadPhase, Particle, ordered


def default_p(n: int, span: float, r_max: float) -> int:
    """About the essay's optimum (p = 2 at n = 16, 24 at n = 2048, i.e. sqrt(n) / 2), but never
    cells narrower than the largest diameter, below which the 9-cell scheme misses pairs."""
    p = max(1, round(math.sqrt(n) / 2))
    if r_max > 0:
        cells = span / (2 * r_max)  # infinite for a subnormal radius: then the essay's p stands
        p = min(p, max(1, int(cells))) if math.isfinite(cells) else p
    return p


def _cell(v: float, origin: float, width: float, p_cells: int) -> int:
    return min(int((v - origin) / width), p_cells - 1) if p_cells > 1 else 0


class EssayGrid(EssayBroadPhase):
    """p x p cells over the square around the centres; p defaults to `default_p`."""

    name = "essay.grid"
    method = "grid"
    defaults = {"p": None, "printed_defects": False}
    sweeps = (Knob("p", fixed([4, 8, 16, 24, 32, 48, 64, 96]), "cells per side p"),)

    def __init__(self, **params):
        super().__init__(**params)
        if self.params["p"] is not None:
            self._int_param("p", 1)

    def _find(self, particles: list[Particle]) -> set[tuple[int, int]]:
        if not particles:
            self._stats = {"tests": 0, "duplicate_tests": 0, "p": 0, "wrapped": 0}
            return set()
        x0 = min(p.x for p in particles)
        y0 = min(p.y for p in particles)
        span = max(max(p.x for p in particles) - x0, max(p.y for p in particles) - y0) or 1.0
        if math.isinf(span):  # centres further apart than the largest double: one cell holds all
            span = math.inf
        p_cells = 1 if math.isinf(span) else self.params["p"] or default_p(len(particles), span,
                                                                           max(p.r for p in particles))
        width = span / p_cells
        cells: list[list[list[Particle]]] = [[[] for _ in range(p_cells)] for _ in range(p_cells)]
        # The printed code started the neighbour loops at index -1, which Python reads as the last.
        first = -1 if self.params["printed_defects"] else 0
        wrapped = 0
        for part in particles:
            cx, cy = _cell(part.x, x0, width, p_cells), _cell(part.y, y0, width, p_cells)
            for nx in range(max(cx - 1, first), min(cx + 2, p_cells)):
                for ny in range(max(cy - 1, first), min(cy + 2, p_cells)):
                    cells[nx][ny].append(part)
                    wrapped += nx < 0 or ny < 0
        found: set[tuple[int, int]] = set()
        tests = 0
        for column in cells:
            for cell in column:
                for a in range(len(cell)):
                    for b in range(a + 1, len(cell)):
                        found.add(ordered(cell[a], cell[b]))
                        tests += 1
        self._stats = {"tests": tests, "duplicate_tests": tests - len(found), "p": p_cells, "wrapped": wrapped}
        self._cells, self._home = cells, (x0, y0, width, p_cells)
        return found

    def validate(self):
        """Every particle sits in its own cell and each neighbour inside the grid, and nowhere else."""
        if not getattr(self, "_cells", None):
            return
        x0, y0, width, p_cells = self._home
        wrap = self.params["printed_defects"]
        where: dict[int, set[tuple[int, int]]] = {}
        for cx, column in enumerate(self._cells):
            for cy, cell in enumerate(column):
                for part in cell:
                    assert (cx, cy) not in where.setdefault(part.index, set()), f"particle {part.index} twice in a cell"
                    where[part.index].add((cx, cy))
        for part in self._particles:
            cx, cy = _cell(part.x, x0, width, p_cells), _cell(part.y, y0, width, p_cells)
            expected = {(nx % p_cells, ny % p_cells) if wrap else (nx, ny)
                        for nx in range(cx - 1, cx + 2) for ny in range(cy - 1, cy + 2)
                        if (wrap or 0 <= nx) and (wrap or 0 <= ny) and nx < p_cells and ny < p_cells}
            assert where.get(part.index) == expected, f"particle {part.index} is in the wrong cells"

