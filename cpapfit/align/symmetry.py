"""A face's plane of symmetry and the mirror term that holds the registered template symmetric about it.

The registration's data terms pin the template to the scan along the skin's normal but hardly along
the skin, where the membrane alone decides (bench/RESULTS.md: the "slide"). A face is nearly
symmetric, and its plane of symmetry can be read off the scan: mirrored across it, the scan lies on
itself (`symmetry_plane`, a point-to-plane ICP over the plane's three degrees of freedom). The mirror
term (`mirror_term`) then asks each template vertex, mirrored across that plane, to lie on its mirror
pair: the template's midline is put on the face's, and a part of the face the camera did not see
takes the shape of the side it did.
"""

from typing import NamedTuple

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix

from ..nearest import NearestPoints

PAIR_MM = (5.0, 2.0)  # the mirror ICP's pair gate, from its first iteration's to its last's
NORMAL_COS = np.cos(np.radians(30.0))  # a point's mirrored normal and its pair's: at most 30 deg apart
TRIM = 0.5  # share of the closest pairs kept each iteration (0.8 let one synthetic subject with holes settle 1.7 mm off)
MAX_POINTS = 20_000  # the scan points mirrored (every k-th), all of them searched


class Plane(NamedTuple):
    """The points p with normal . p = offset (unit normal, offset in mm)."""

    normal: np.ndarray
    offset: float

    def reflect(self, points: np.ndarray) -> np.ndarray:
        """(K, 3) points (mm) mirrored across the plane."""
        return points - 2.0 * (points @ self.normal - self.offset)[:, None] * self.normal

    def reflect_directions(self, vectors: np.ndarray) -> np.ndarray:
        """(K, 3) direction vectors mirrored."""
        return vectors - 2.0 * (vectors @ self.normal)[:, None] * self.normal


class MirrorTerm(NamedTuple):
    """sum over pairs (i, j) of |reflect(p_i) - p_j|^2 at unit weight, written in the plane's frame
    (rows of `frame`: the normal, then two directions in the plane): across the plane it is
    u^T across u - 2 u . across_rhs + const (u: the (n,) coordinates along the normal), along it
    v^T along v for each of the two in-plane coordinates v; across, along: (n, n) sparse."""

    frame: np.ndarray
    across: csr_matrix
    across_rhs: np.ndarray
    along: csr_matrix


def plane_of_pairs(points: np.ndarray, mirror: np.ndarray) -> Plane:
    """The plane that best swaps each of the (n, 3) points (mm) with its mirror pair (`mirror`: (n,)
    indices): its normal along their differences, through their midpoints."""
    d = points - points[mirror]
    normal = np.linalg.eigh(d.T @ d)[1][:, -1]
    return Plane(normal, float(np.mean((points + points[mirror]) @ normal) / 2.0))


def symmetry_plane(points: np.ndarray, normals: np.ndarray, rims: np.ndarray, start: Plane, iterations: int = 20) -> Plane:
    """The plane across which the (K, 3) surface points (mm; unit `normals`) mirror onto themselves,
    from `start` (a few mm and degrees off): each mirrored point is paired with its nearest point,
    pairs gated by distance and normal, and trimmed, and the plane moved to bring them together. A
    point whose pair lies on the surface's rims ((K,) bool: its edge, a hole's edge) mirrors off the
    surface, or into a hole, and is left out."""
    tree, plane = NearestPoints(points), start
    step = max(1, len(points) // MAX_POINTS)
    q, qn = points[::step], normals[::step]
    for gate in np.geomspace(*PAIR_MM, iterations):
        dist, idx = tree.query(plane.reflect(q), gate)
        ok = np.isfinite(dist)
        idx = np.where(ok, idx, 0)
        ok &= ~rims[idx] & (np.einsum("ij,ij->i", plane.reflect_directions(qn), normals[idx]) > NORMAL_COS)
        if ok.sum() < 50:
            break
        ok &= dist <= np.quantile(dist[ok], TRIM)
        plane = _gauss_newton(plane, q[ok], points[idx[ok]], normals[idx[ok]])
    return plane


def _gauss_newton(plane: Plane, q: np.ndarray, s: np.ndarray, m: np.ndarray) -> Plane:
    """One step on sum(((reflect(q) - s) . m)^2) over the normal (tilted along two directions in the
    plane) and the offset; q, s: (K, 3) pairs (mm), m: (K, 3) unit normals at s."""
    n, c = plane
    e1, e2 = _in_plane(n)
    h = q @ n - c
    r = np.einsum("ij,ij->i", q - 2.0 * h[:, None] * n - s, m)
    nm = m @ n
    jac = np.column_stack([-2.0 * ((q @ e) * nm + h * (m @ e)) for e in (e1, e2)] + [2.0 * nm])
    a, b, dc = np.linalg.lstsq(jac, -r, rcond=None)[0]
    normal = n + a * e1 + b * e2
    return Plane(normal / np.linalg.norm(normal), c + dc)


def _in_plane(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit directions in the plane, at right angles."""
    e1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


class MirrorPairs(NamedTuple):
    """The template's mirror pairs: mirror (n,) each vertex's pair, and as matrices over the n vertices
    plus (P, n) the sum of each pair's coordinates (each pair once), across = plus^T plus and along
    (n, n) the squared differences summed (`MirrorTerm`)."""

    mirror: np.ndarray
    plus: csr_matrix
    across: csr_matrix
    along: csr_matrix


def mirror_pairs(mirror: np.ndarray) -> MirrorPairs:
    """The matrices of the (n,) mirror pairs: each pair once, a vertex on the midline (its own pair)
    held on the plane."""
    i = np.flatnonzero(np.arange(len(mirror)) <= mirror)
    j = mirror[i]
    rows = np.arange(len(i))
    shape = (len(i), len(mirror))
    plus = coo_matrix((np.ones(2 * len(i)), (np.r_[rows, rows], np.r_[i, j])), shape=shape).tocsr()  # u_i + u_j - 2c
    pair = i != j
    minus = coo_matrix((np.r_[np.ones(pair.sum()), -np.ones(pair.sum())], (np.r_[rows[pair], rows[pair]], np.r_[i[pair], j[pair]])),
                       shape=shape).tocsr()  # v_i - v_j
    return MirrorPairs(mirror, plus, (plus.T @ plus).tocsr(), (minus.T @ minus).tocsr())


def mirror_term(pairs: MirrorPairs, plane: Plane) -> MirrorTerm:
    """The mirror term of the template's mirror pairs about `plane`."""
    frame = np.vstack([plane.normal, *_in_plane(plane.normal)])
    return MirrorTerm(frame, pairs.across, pairs.plus.T @ np.full(pairs.plus.shape[0], 2.0 * plane.offset), pairs.along)
