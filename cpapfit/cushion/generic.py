"""The generic cushion: the same design on the un-warped template, placed on the patient by the
similarity transform (scaled to the face); and the template's seal on any face of its topology."""

from functools import lru_cache

import numpy as np
import trimesh

from ..similarity import Similarity
from .contact import Contact, template_curve
from ..template import load_template
from .nurbs import Cushion, CushionParams, design_cushion

NOSE_TIP = 4
AXIS, UP = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])  # the template frame's mask axis and up


@lru_cache(maxsize=4)
def template_cushion(mask: str, params: CushionParams = CushionParams()) -> Cushion:
    """The cushion designed on the template itself (template frame: axis +z, up +y)."""
    template = load_template()
    return design_cushion(contact_on(mask, template.mesh()), AXIS, UP, template.vertices[NOSE_TIP], params)


def contact_on(mask: str, skin: trimesh.Trimesh) -> Contact:
    """The template's seal curve and band of `mask` on a face of the template's topology (`skin`, mm)."""
    tri, bary = template_curve(mask)
    corners = skin.faces[tri]
    curve = np.einsum("kj,kjc->kc", bary, skin.vertices[corners])
    normals = np.einsum("kj,kjc->kc", bary, np.asarray(skin.vertex_normals)[corners])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return Contact(mask, curve, normals, np.ones(len(curve), dtype=bool), skin.vertices[load_template().regions[mask].band])


def place(cushion: Cushion, similarity: Similarity) -> Cushion:
    """The template cushion carried onto the patient by the similarity (an ideally sized stock mask)."""
    control = similarity.apply(cushion.control.reshape(-1, 3)).reshape(cushion.control.shape)
    return Cushion(cushion.mask, control, similarity.rotation[:, 2], similarity.rotation[:, 1], cushion.params)
