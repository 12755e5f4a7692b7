"""scikit-learn's trees (`sklearn.neighbors`): `KDTree` and `BallTree` through `NearestNeighbors`.

The tree is fitted on the centres every frame (`update`), and `radius_neighbors_graph` returns
every pair within the cutoff as one sparse matrix (each pair both ways, no point paired with
itself), so no Python runs per object (`pairs`). float64, Euclidean distance.
"""

from __future__ import annotations

from sklearn.neighbors import NearestNeighbors

from .cutoff import CutoffSearch


class _SklearnTree(CutoffSearch):
    both_ways = True
    algorithm = ""

    def _build(self, positions):
        self._fitted = NearestNeighbors(radius=self._cutoff, algorithm=self.algorithm).fit(positions)

    def _query(self):
        graph = self._fitted.radius_neighbors_graph(mode="connectivity").tocoo()
        return graph.row, graph.col


class SklearnKDTree(_SklearnTree):
    """scikit-learn's KDTree, fitted on the centres every frame, every pair within the cutoff."""

    name, method, algorithm = "sklearn.kdtree", "kdtree", "kd_tree"


class SklearnBallTree(_SklearnTree):
    """scikit-learn's BallTree, fitted on the centres every frame, every pair within the cutoff."""

    name, method, algorithm = "sklearn.balltree", "tree", "ball_tree"
