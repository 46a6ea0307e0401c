"""The generic cushion: the same design on the un-warped template (the stock mask a patient
would otherwise get), placed on the patient by the similarity transform."""

from functools import lru_cache

import numpy as np

from ..align.similarity import Similarity
from ..contact import Contact, template_curve
from ..template import load_template
from .nurbs import Cushion, CushionParams, design_cushion

NOSE_TIP = 4


@lru_cache(maxsize=4)
def template_cushion(mask: str, params: CushionParams = CushionParams()) -> Cushion:
    """The cushion designed on the template itself (template frame: axis +z, up +y)."""
    template = load_template()
    tri, bary = template_curve(mask)
    mesh = template.mesh()
    corners = template.faces[tri]
    curve = np.einsum("kj,kjc->kc", bary, template.vertices[corners])
    normals = np.einsum("kj,kjc->kc", bary, np.asarray(mesh.vertex_normals)[corners])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    contact = Contact(mask, curve, normals, np.ones(len(curve), dtype=bool), template.vertices[template.regions[mask].band])
    return design_cushion(contact, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), template.vertices[NOSE_TIP], params)


def place(cushion: Cushion, similarity: Similarity) -> Cushion:
    """The template cushion carried onto the patient by the similarity (an ideally sized stock mask)."""
    control = similarity.apply(cushion.control.reshape(-1, 3)).reshape(cushion.control.shape)
    return Cushion(cushion.mask, control, similarity.rotation[:, 2], similarity.rotation[:, 1], cushion.params)
