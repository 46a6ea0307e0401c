"""The files of `cpapfit register` and `cpapfit design` (all mm, scan frame), as {name: bytes}."""

import numpy as np

from .. import __version__
from ..align.nonrigid import Registration
from ..export import stl_bytes, threemf_bytes
from ..pipeline import NOT_BUILT_PARTS, Design
from ..quality import assess_design
from ..scan import Scan
from ..template import load_template
from .write import json_bytes, ply_bytes


def registration_ply(reg: Registration) -> bytes:
    """The warped template as PLY with residual_mm (-1 where unmatched) and valid vertex properties."""
    residual = np.where(reg.valid, reg.residual, -1.0)
    attributes = {"residual_mm": residual.astype(np.float32), "valid": reg.valid.astype(np.uint8)}
    return ply_bytes(reg.vertices, load_template().faces, attributes)


def mask_dimensions(d: Design) -> dict:
    """Width (across the face), height (along the head) and depth (along the mask axis) in mm."""
    axis, up = d.cushion.axis, d.cushion.up
    side = np.cross(up, axis)
    v = d.solid.vertices
    return {f"{k}_mm": round(float(np.ptp(v @ a)), 2) for k, a in (("width", side), ("height", up), ("depth", axis))}


def design_files(d: Design, scan: Scan) -> dict[str, bytes]:
    """The files of `cpapfit design` (all mm, scan frame), as {name: bytes}."""
    reg = d.registration
    fit = {
        "cpapfit_version": __version__, "units": "mm", "source": scan.source, "scan_units": scan.units,
        "mask": d.contact.mask,
        **assess_design(d, scan).record(),  # rescan_advised, warnings, quality
        "landmarks": {"path": d.alignment.landmarks.path, "count": len(d.alignment.landmarks.points)},
        "registration": {"iterations": len(reg.log), "matched_vertices": int(reg.valid.sum()),
                         "residual_median_mm": float(np.median(reg.residual[reg.valid]))},
        "seal_on_scan_fraction": float(d.contact.on_scan.mean()),
        "cushion": {**mask_dimensions(d), **d.checks},
        "fit_before_compression": d.rim.summary(),
        "seated_along_mask_axis": {
            "about": "each cushion, rigid, pushed along the mask axis until its rim first touches the skin; "
                     "gap = rim to skin along the axis (mm); generic = the same design on the template, placed by the similarity",
            **{name: s.summary() for name, s in d.seated.items()},
        },
        "parameters": dict(vars(d.cushion.params)),
        "not_built_yet": list(NOT_BUILT_PARTS),
    }
    return {
        "registered_template.ply": registration_ply(reg),
        "contact_curve.json": json_bytes({"units": "mm", "mask": d.contact.mask, "points": np.round(d.contact.curve, 4).tolist()}),
        "cushion.stl": stl_bytes(d.solid),
        "cushion.3mf": threemf_bytes(d.solid, "cushion"),
        **{f"{name}.stl": stl_bytes(part) for name, part in d.mould_parts.items()},
        "fit.json": json_bytes(fit),
    }
