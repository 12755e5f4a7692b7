"""The essay's quadtree: insert every centre, then query a square around each particle.

The printed containment test compared y the wrong way round, so most particles were dropped
once a node filled; here containment is the closed box on both axes. The query square's
half-width is r_i + r_max (the essay's 2r when all radii are equal), so no overlap is missed.

`printed_defects=True` reproduces our reading of the printed code, to measure what it did: the
root fills without a containment test, and a child accepts a point only when it lies above it
(y <= the child's top edge, screen coordinates), in inserts and queries alike. Dropped
particles are counted (`inserted` in the stats).
"""

from __future__ import annotations

from interface.knobs import Knob, fixed

from .particle import EssayBroadPhase, Particle, ordered


class _Node:
    __slots__ = ("x0", "y0", "x1", "y1", "depth", "points", "children")

    def __init__(self, x0: float, y0: float, x1: float, y1: float, depth: int) -> None:
        self.x0, self.y0, self.x1, self.y1, self.depth = x0, y0, x1, y1, depth
        self.points: list[Particle] = []
        self.children: list[_Node] = []

    def contains(self, p: Particle, printed: bool) -> bool:
        if printed:
            return self.x0 <= p.x <= self.x1 and p.y <= self.y0
        return self.x0 <= p.x <= self.x1 and self.y0 <= p.y <= self.y1

    def insert(self, p: Particle, capacity: int, max_depth: int, printed: bool) -> bool:
        # The root holds every point (it is the square around them), so only children test.
        if self.depth > 0 and not self.contains(p, printed):
            return False
        if len(self.points) < capacity or self.depth >= max_depth:
            self.points.append(p)
            return True
        if not self.children:
            mx, my, d = 0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1), self.depth + 1
            self.children = [
                _Node(self.x0, self.y0, mx, my, d), _Node(mx, self.y0, self.x1, my, d),
                _Node(self.x0, my, mx, self.y1, d), _Node(mx, my, self.x1, self.y1, d),
            ]
        return any(child.insert(p, capacity, max_depth, printed) for child in self.children)

    def query(self, x0: float, y0: float, x1: float, y1: float, out: list[Particle], printed: bool) -> int:
        """Append the points inside the closed square; returns the number of nodes visited."""
        if x0 > self.x1 or x1 < self.x0 or y0 > self.y1 or y1 < self.y0:
            return 1
        if printed:
            out.extend(p for p in self.points if x0 <= p.x <= x1 and p.y <= y0)
        else:
            out.extend(p for p in self.points if x0 <= p.x <= x1 and y0 <= p.y <= y1)
        return 1 + sum(child.query(x0, y0, x1, y1, out, printed) for child in self.children)


class EssayQuadtree(EssayBroadPhase):
    """Point quadtree with `capacity` points per node (the essay's kappa, best at 4-5)."""

    name = "essay.quadtree"
    method = "tree"
    defaults = {"capacity": 5, "max_depth": 32, "printed_defects": False}
    sweeps = (Knob("capacity", fixed([1, 2, 3, 5, 8, 12, 20]), "capacity (objects per leaf)"),)

    def __init__(self, **params):
        super().__init__(**params)
        self._capacity = self._int_param("capacity", 1)
        self._max_depth = self._int_param("max_depth", 0)

    def _find(self, particles: list[Particle]) -> set[tuple[int, int]]:
        found: set[tuple[int, int]] = set()
        if not particles:
            self._stats = {"visited": 0, "inserted": 0}
            return found
        x0 = min(p.x for p in particles)
        y0 = min(p.y for p in particles)
        side = max(max(p.x for p in particles) - x0, max(p.y for p in particles) - y0)
        root = _Node(x0, y0, x0 + side, y0 + side, 0)
        printed = bool(self.params["printed_defects"])
        inserted = sum(root.insert(p, self._capacity, self._max_depth, printed) for p in particles)
        r_max = max(p.r for p in particles)
        visited = 0
        for p in particles:
            near: list[Particle] = []
            reach = p.r + r_max
            visited += root.query(p.x - reach, p.y - reach, p.x + reach, p.y + reach, near, printed)
            found.update(ordered(p, q) for q in near if q is not p)
        self._stats = {"visited": visited, "inserted": inserted}
        self._root = root
        return found

    def validate(self):
        """Each stored point lies in its node, nodes respect capacity, and (fixed code) none is lost."""
        root = getattr(self, "_root", None)
        if root is None:
            return
        stored, stack = 0, [root]
        while stack:
            node = stack.pop()
            stored += len(node.points)
            assert len(node.points) <= self._capacity or node.depth >= self._max_depth, "node over capacity"
            assert node.depth == 0 or all(node.contains(p, bool(self.params["printed_defects"])) for p in node.points), \
                "a point outside its node"
            assert not node.children or len(node.children) == 4, "a node with a partial split"
            stack += node.children
        assert stored == self._stats["inserted"], "inserted count does not match the tree"
        if not self.params["printed_defects"]:
            assert stored == len(self._particles), f"{len(self._particles) - stored} particles were dropped"

