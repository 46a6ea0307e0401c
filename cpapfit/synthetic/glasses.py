"""A pair of glasses for a synthetic subject: a thin frame the depth camera sees in front of the face.

Lens rims 50 × 34 mm, 14 mm in front of the eye corners; a bridge over the nose 6 mm in front of
the nasion; nose pads (8 mm discs) resting on the sides of the nose 10 mm below it, on arms to the
rims; temples running back past the face. Tubes of 1.2 mm radius (pad arms 0.6 mm). Not skin:
the subject's truth is the face under them.
"""

import numpy as np
import trimesh

from ..template import Template

RIM_MM = (25.0, 17.0)  # half width, half height
RIM_DROP_MM = 3.0  # the rims' middle below the eye corners' level
LENS_FORWARD_MM = 14.0
TUBE_MM = 1.2
PAD_RADIUS_MM, PAD_THICK_MM, PAD_BELOW_NASION_MM, PAD_BESIDE_MM = 4.0, 1.5, 10.0, 8.0
EYES = ((33, 133), (263, 362))  # outer and inner eye corners (Face Mesh), right then left
NASION = 168
FRAME = np.array([0.08, 0.07, 0.07])  # a glasses frame's albedo


def glasses_mesh(face: np.ndarray, template: Template) -> trimesh.Trimesh:
    """The frame (mm, template frame) worn on `face`, the (N, 3) template vertices of a subject."""
    normals = np.asarray(trimesh.Trimesh(face, template.faces, process=False).vertex_normals)
    centres = [_lens_centre(face, *corners) for corners in EYES]
    inner = [c - [np.sign(c[0]) * RIM_MM[0], RIM_DROP_MM, 0.0] for c in centres]  # each rim's inner edge
    parts = [_rim(c) for c in centres]
    parts.append(_tube(np.array([inner[0], face[NASION] + [0.0, 2.0, 6.0], inner[1]])))
    for side, rim in zip((-1.0, 1.0), inner):
        parts += _pad(face, normals, side, rim)
    for c in centres:
        hinge = c + [np.sign(c[0]) * RIM_MM[0], -RIM_DROP_MM, 0.0]
        parts.append(_tube(hinge + np.array([[0.0, 0.0, 0.0], [5.0, 0.0, -40.0], [8.0, 0.0, -100.0]]) * [np.sign(c[0]), 1, 1]))
    return trimesh.util.concatenate(parts)


def _lens_centre(face: np.ndarray, outer: int, inner: int) -> np.ndarray:
    centre = 0.5 * (face[outer] + face[inner])
    centre[2] = max(face[outer, 2], face[inner, 2]) + LENS_FORWARD_MM
    return centre


def _rim(centre: np.ndarray) -> trimesh.Trimesh:
    """A lens rim: an ellipse about `centre` (RIM_DROP_MM lower), its outer side swept 3 mm back round the face."""
    t = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    outward = np.clip(np.cos(t) * np.sign(centre[0]), 0.0, None)  # 1 at the outer edge, 0 over the inner half
    ring = np.stack([RIM_MM[0] * np.cos(t), RIM_MM[1] * np.sin(t) - RIM_DROP_MM, -3.0 * outward**2], axis=1)
    return _tube(np.vstack([centre + ring, centre + ring[:1]]))


def _pad(face: np.ndarray, normals: np.ndarray, side: float, rim: np.ndarray) -> list[trimesh.Trimesh]:
    """A nose pad on the side `side` (-1 right, +1 left) of the nose, resting on the skin, and its arm to the rim."""
    target = face[NASION] + [side * PAD_BESIDE_MM, -PAD_BELOW_NASION_MM, 0.0]
    near = np.flatnonzero((np.abs(face[:, 0] - target[0]) < 3.0) & (np.abs(face[:, 1] - target[1]) < 3.0))
    k = near[np.argmax(face[near, 2])]  # the skin there, not the back of the head
    n = normals[k] / np.linalg.norm(normals[k])
    pad = trimesh.creation.cylinder(radius=PAD_RADIUS_MM, height=PAD_THICK_MM, sections=12)
    pad.apply_transform(trimesh.geometry.align_vectors([0.0, 0.0, 1.0], n))
    pad.apply_translation(face[k] + 0.5 * PAD_THICK_MM * n)
    return [pad, _tube(np.array([face[k] + PAD_THICK_MM * n, rim + [-side * 3.0, -3.0, 0.0]]), radius=0.5 * TUBE_MM)]


def _tube(points: np.ndarray, radius: float = TUBE_MM) -> trimesh.Trimesh:
    """Cylinders along a (K, 3) polyline, with spheres at its corners."""
    parts = [trimesh.creation.cylinder(radius=radius, segment=[a, b], sections=8) for a, b in zip(points[:-1], points[1:])]
    parts += [trimesh.creation.icosphere(1, radius=radius).apply_translation(p) for p in points]
    return trimesh.util.concatenate(parts)
