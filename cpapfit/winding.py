"""Winding: turn the triangles of a mesh that are wound against their neighbours.

Two triangles sharing an edge agree when they run along it in opposite directions. A breadth-first
tree over the triangles (scipy's csgraph, one root joining every connected piece) carries the
agreement from each piece's first triangle to the rest; each triangle's turn is the parity of the
disagreements on its path to the root, summed by pointer jumping. Edges shared by more than two
triangles are not followed.
"""

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from .rims import pair_keys


def wound_against(faces: np.ndarray) -> np.ndarray:
    """(M,) bool: the triangles of (M, 3) `faces` (vertex indices; vertices at one position as one
    index) to turn so that every triangle agrees with its neighbours; the way most of the triangles
    were wound is kept."""
    first, second, turned = _neighbours(faces)
    if not turned.any():
        return np.zeros(len(faces), dtype=bool)
    m = len(faces)
    graph = csr_matrix((np.ones(len(first)), (first, second)), shape=(m + 1, m + 1))
    _, piece = connected_components(graph[:m, :m], directed=False)
    starts = np.unique(piece, return_index=True)[1]
    graph = graph + csr_matrix((np.ones(len(starts)), (np.full(len(starts), m), starts)), shape=(m + 1, m + 1))
    _, parent = breadth_first_order(graph, m, directed=False, return_predecessors=True)
    parent[m] = m
    flip = _disagrees(first, second, turned, np.arange(m + 1), parent, m)
    while (parent != m).any():  # pointer jumping: each triangle's parity to the root
        flip, parent = flip ^ flip[parent], parent[parent]
    flip = flip[:m]
    return flip if flip.mean() <= 0.5 else ~flip


def _neighbours(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(first, second, turned): the triangles sharing each edge used by exactly two, and whether
    they run along it the same way (one of them is turned)."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    owner = np.tile(np.arange(len(faces)), 3)
    n = int(faces.max()) + 1
    key = pair_keys(directed[:, 0], directed[:, 1], n)
    order = np.argsort(key, kind="stable")
    key = key[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    length = np.diff(np.r_[start, len(key)])
    a, b = order[start[length == 2]], order[start[length == 2] + 1]
    return owner[a], owner[b], directed[a, 0] == directed[b, 0]


def _disagrees(first, second, turned, child, parent, root) -> np.ndarray:
    """(len(child),) bool: whether each triangle and its parent in the tree disagree (not at the root)."""
    m1 = root + 1
    keys = pair_keys(first, second, m1)
    order = np.argsort(keys, kind="stable")
    query = pair_keys(child, parent, m1)
    at = np.clip(np.searchsorted(keys[order], query), 0, len(order) - 1)
    found = keys[order][at] == query
    return found & turned[order][at] & (parent != root)
