"""Contact regions on the template: a closed centre curve through anchor landmarks, and a band around it."""

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from ..frozen import freeze_arrays


@dataclass(frozen=True)
class ContactRegion:
    """Where a mask touches the template face.

    curve: (K,) int64 template vertex indices in order around the closed seal (last joins first).
    band: (B,) int64 sorted template vertex indices within half_width_mm of the curve.
    distance: (B,) float64 geodesic distance (mm, along mesh edges) of each band vertex to the curve.
    """

    name: str
    curve: np.ndarray
    band: np.ndarray
    distance: np.ndarray
    half_width_mm: float

    def __post_init__(self):
        freeze_arrays(self)


def edge_graph(vertices: np.ndarray, faces: np.ndarray):
    """Sparse (N, N) matrix of mesh edge lengths (mm), symmetric."""
    edges = trimesh.Trimesh(vertices, faces, process=False).edges_unique
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)
    n = len(vertices)
    graph = coo_matrix((length, (edges[:, 0], edges[:, 1])), shape=(n, n))
    return (graph + graph.T).tocsr()


def closed_path(graph, anchors: list[int]) -> np.ndarray:
    """Vertex indices of the closed shortest edge path through `anchors` in order."""
    _, pred = dijkstra(graph, indices=anchors, return_predecessors=True)
    path = []
    for k, start in enumerate(anchors):
        stop = anchors[(k + 1) % len(anchors)]
        leg = [stop]
        while leg[-1] != start:
            leg.append(pred[k, leg[-1]])
        path.extend(reversed(leg[1:]))
    return np.asarray(path, dtype=np.int64)


def contact_region(name: str, vertices: np.ndarray, faces: np.ndarray, anchors: list[int], half_width_mm: float) -> ContactRegion:
    """The contact region through `anchors` (landmark indices, kept by refinement) on a template mesh."""
    graph = edge_graph(vertices, faces)
    curve = closed_path(graph, list(anchors))
    dist = dijkstra(graph, indices=curve, min_only=True, limit=half_width_mm)
    band = np.flatnonzero(np.isfinite(dist))
    return ContactRegion(name=name, curve=curve, band=band, distance=dist[band], half_width_mm=float(half_width_mm))
