"""Directions across a direction (a tangent plane's basis): one kernel for every stage."""

import numpy as np


def across(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two (K, 3) unit directions across (K, 3) unit axes, square to each other and to them: each
    axis crossed with x, or with y where it lies within 26 degrees of x."""
    side = np.cross(axes, np.where(np.abs(axes[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    return side, np.cross(axes, side)


def plane_across(axis: np.ndarray) -> np.ndarray:
    """(2, 3) unit directions across one unit `axis` (3,), square to each other: the axis crossed
    with the coordinate axis it is least along."""
    side = np.cross(axis, np.eye(3)[np.argmin(np.abs(axis))])
    side /= np.linalg.norm(side)
    return np.stack([side, np.cross(axis, side)])
