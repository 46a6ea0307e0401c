"""The cotangent Laplacian of a triangle mesh (membrane energy), robust for obtuse triangles."""

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix

MIN_WEIGHT = 1e-3  # obtuse angles give negative cotangents: clamp so every edge keeps a small stiffness


def cotangent_weights(vertices: np.ndarray, faces: np.ndarray) -> csr_matrix:
    """(N, N) symmetric matrix of edge weights w_ij = (cot a + cot b) / 2, clamped to >= MIN_WEIGHT."""
    n = len(vertices)
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, o = faces[:, (k + 1) % 3], faces[:, (k + 2) % 3], faces[:, k]  # edge (i, j) opposite vertex o
        a, b = vertices[i] - vertices[o], vertices[j] - vertices[o]
        cot = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(np.cross(a, b), axis=1), 1e-12)
        rows += [i, j]
        cols += [j, i]
        vals += [cot / 2.0, cot / 2.0]
    w = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    w.sum_duplicates()
    w.data = np.maximum(w.data, MIN_WEIGHT)
    return w


def laplacian(vertices: np.ndarray, faces: np.ndarray) -> csr_matrix:
    """(N, N) positive semi-definite cotangent Laplacian L: d^T L d = sum over edges w_ij |d_i - d_j|^2."""
    w = cotangent_weights(vertices, faces)
    degree = np.asarray(w.sum(axis=1)).ravel()
    return (csr_matrix((degree, (np.arange(len(degree)), np.arange(len(degree)))), shape=w.shape) - w).tocsr()
