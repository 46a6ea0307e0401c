"""The files of `cpapfit register` and `cpapfit design` (all mm, scan frame), as {name: bytes}."""

import numpy as np

from ..align.nonrigid import Registration
from ..export import stl_bytes, threemf_bytes
from ..pipeline import Design
from ..records import contact_curve_record, design_record
from ..scan import Scan
from ..template import load_template
from .write import json_bytes, ply_bytes


def registration_ply(reg: Registration) -> bytes:
    """The warped template as PLY with residual_mm (-1 where unmatched) and valid vertex properties."""
    residual = np.where(reg.valid, reg.residual, -1.0)
    attributes = {"residual_mm": residual.astype(np.float32), "valid": reg.valid.astype(np.uint8)}
    return ply_bytes(reg.vertices, load_template().faces, attributes)


def design_files(d: Design, scan: Scan) -> dict[str, bytes]:
    """The files of `cpapfit design` (all mm, scan frame), as {name: bytes}."""
    return {
        "registered_template.ply": registration_ply(d.registration),
        "contact_curve.json": json_bytes(contact_curve_record(d)),
        "cushion.stl": stl_bytes(d.solid),
        "cushion.3mf": threemf_bytes(d.solid, "cushion"),
        **{f"{name}.stl": stl_bytes(part) for name, part in d.mould_parts.items()},
        "fit.json": json_bytes(design_record(d, scan)),
    }
