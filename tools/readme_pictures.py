"""Regenerate the README's pictures under docs/: the template's contact regions, a synthetic
subject, and the registration residual on the shared real scans.

Usage: .venv/bin/python tools/readme_pictures.py
"""

from pathlib import Path

import numpy as np

from cpapfit.io import load_scan
from cpapfit.io.write import png_bytes, write_bytes
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.pipeline import align, register_template
from cpapfit.report.pictures import residual_picture, template_regions_picture
from cpapfit.template import load_template

DOCS = Path(__file__).resolve().parents[1] / "docs"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def depth_picture(depth_raw: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 grey depth picture: near is bright, invalid is black."""
    valid = depth_raw > 0
    d = depth_raw.astype(np.float64)
    lo, hi = np.percentile(d[valid], [1, 99])
    grey = np.where(valid, 255 - 200 * np.clip((d - lo) / (hi - lo), 0, 1), 0).astype(np.uint8)
    return np.repeat(grey[..., None], 3, axis=2)


def residual_pictures() -> None:
    """Registration residual on the shared real scans (skipped without ../shared/data)."""
    for name, path in (("fran", SHARED / "fran_cyberware" / "fran.obj"), ("truedepth", SHARED / "rgbd_truedepth_mannequin")):
        if not path.exists():
            print(f"skipped {name}: {path} not found")
            continue
        scan = load_scan(path)
        al = align(scan)
        reg = register_template(scan, al)
        res = reg.residual[reg.valid]
        title = f"{name}: residual median {np.median(res):.2f} mm, p95 {np.percentile(res, 95):.2f} mm"
        write_bytes(DOCS / f"residual_{name}.png", residual_picture(reg.vertices, load_template().faces, reg.residual, al.similarity, title))


def main() -> None:
    write_bytes(DOCS / "template_regions.png", png_bytes(template_regions_picture(load_template())))
    ph = make_phantom(1)
    write_bytes(DOCS / "phantom_seed1.png", png_bytes(np.concatenate([ph.image, depth_picture(ph.depth_raw)], axis=1)))
    residual_pictures()
    print(f"wrote pictures in {DOCS}")


if __name__ == "__main__":
    main()
