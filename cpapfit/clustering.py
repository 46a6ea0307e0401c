"""Vertex clustering: a dense mesh thinned by merging the vertices in each cube of a grid into their
mean (off a surface of radius R by at most about cube^2 / (8 R): 6 um at 0.5 mm on a 5 mm curve),
for the 3-D view and for looking at a scan far denser than the fit reads the skin (`Scan.seen`,
`pipeline.face_for`). Sheets of the mesh nearer each other than a cube (the lips closed on each
other) are merged where they share one."""

import numpy as np
import trimesh


def median_edge(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The median length (mm) of the first edge of each of the (F, 3) `faces` over (N, 3) `vertices`."""
    return float(np.median(np.linalg.norm(vertices[faces[:, 0]] - vertices[faces[:, 1]], axis=1)))


def clustered(vertices: np.ndarray, faces: np.ndarray, cube_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """((M, 3) mm vertices, (T, 3) int64 triangles): the mesh of (N, 3) mm `vertices` and (F, 3)
    `faces` with the vertices of its triangles in each cube_mm cube merged into their mean (those
    in no triangle dropped); triangles left with fewer than three corners, turned over (facing
    against the triangle they came from), and repeats, dropped."""
    return clusters(vertices, faces, cube_mm)[2:]


def clusters(vertices: np.ndarray, faces: np.ndarray, cube_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`clustered`, with what it merged: ((U,) the vertices in some triangle, (U,) the merged vertex
    each became, (M, 3) mm merged vertices, (T, 3) int64 triangles)."""
    used = np.unique(faces)
    inverse, count = cubes(vertices[used], cube_mm)
    kept = cube_means(vertices[used], inverse, count)
    merged = inverse[np.searchsorted(used, faces)]
    whole = (merged[:, 0] != merged[:, 1]) & (merged[:, 1] != merged[:, 2]) & (merged[:, 2] != merged[:, 0])
    merged, faces = merged[whole], faces[whole]
    upright = np.einsum("ij,ij->i", trimesh.triangles.cross(kept[merged]), trimesh.triangles.cross(vertices[faces])) > 0
    merged = merged[upright]
    return used, inverse, kept, merged[np.sort(trimesh.grouping.unique_rows(np.sort(merged, axis=1))[0])]


def cubes(points: np.ndarray, cube_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """((N,) the cube_mm cube each of (N, 3) mm points lies in, the cubes numbered in lexicographic
    order of their (x, y, z) grid indices; (K,) how many points each holds)."""
    grid = np.floor(points / cube_mm)
    grid -= grid.min(axis=0)
    span = grid.max(axis=0) + 1.0
    if np.prod(span) < 2.0**62:  # one int64 key a cube, ordered as the rows
        grid, span = grid.astype(np.int64), span.astype(np.int64)
        _, inverse, count = np.unique((grid[:, 0] * span[1] + grid[:, 1]) * span[2] + grid[:, 2], return_inverse=True, return_counts=True)
    else:  # a stray point far off: by rows
        _, inverse, count = np.unique(grid, axis=0, return_inverse=True, return_counts=True)
    return inverse.reshape(-1), count


def cube_means(values: np.ndarray, inverse: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(K, C) the mean of the (N, C) `values` in each cube (`cubes`: (N,) `inverse`, (K,) `count`)."""
    return np.stack([np.bincount(inverse, weights=values[:, c], minlength=len(count)) for c in range(values.shape[1])], axis=1) / count[:, None]


def thinned(surface: trimesh.Trimesh | trimesh.PointCloud, cube_mm: float) -> trimesh.Trimesh | trimesh.PointCloud:
    """A mesh whose `median_edge` is shorter than cube_mm `clustered` in cubes that size; a coarser
    mesh, or a point cloud, as it is."""
    if not isinstance(surface, trimesh.Trimesh) or not len(surface.faces):
        return surface
    vertices, faces = np.asarray(surface.vertices), np.asarray(surface.faces)
    if median_edge(vertices, faces) >= cube_mm:
        return surface
    return trimesh.Trimesh(*clustered(vertices, faces, cube_mm), process=False)
