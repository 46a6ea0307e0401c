"""Rebuild cpapfit/template/data/canonical_face.json from the npm package @mediapipe/face_mesh.

MediaPipe's canonical face model (Apache-2.0) is not inside the mediapipe Python wheel. The npm
package carries it as geometry_pipeline_metadata_landmarks.binarypb packed into
face_mesh_solution_packed_assets.data; the package's loader .js lists each packed file's byte
range. mediapipe 0.10.21's geometry_pipeline_metadata_pb2 parses it.

Usage (needs npm and the project venv):
    python tools/build_template_data.py [--package DIR]
Without --package the script runs `npm pack @mediapipe/face_mesh` in a temporary folder. The
refined template is made from it: run `tools/build_refined_template.py` after this.
"""

import argparse
import json
import re
import subprocess
import tarfile
import tempfile
from pathlib import Path

import numpy as np
from mediapipe.python.solutions import face_mesh_connections as fmc
from mediapipe.tasks.cc.vision.face_geometry.proto import geometry_pipeline_metadata_pb2

OUT = Path(__file__).resolve().parents[1] / "cpapfit" / "template" / "data" / "canonical_face.json"
ASSET = "geometry_pipeline_metadata_landmarks.binarypb"
FEATURES = {
    "lips": fmc.FACEMESH_LIPS,
    "left_eye": fmc.FACEMESH_LEFT_EYE,
    "right_eye": fmc.FACEMESH_RIGHT_EYE,
    "left_eyebrow": fmc.FACEMESH_LEFT_EYEBROW,
    "right_eyebrow": fmc.FACEMESH_RIGHT_EYEBROW,
}


def fetch_package(tmp: Path) -> Path:
    """npm-pack @mediapipe/face_mesh into tmp and return the unpacked package folder."""
    subprocess.run(["npm", "pack", "@mediapipe/face_mesh"], cwd=tmp, check=True, capture_output=True)
    (tgz,) = tmp.glob("*.tgz")
    with tarfile.open(tgz) as tar:
        tar.extractall(tmp, filter="data")
    return tmp / "package"


def packed_asset(package: Path, name: str) -> bytes:
    """Bytes of one file packed into face_mesh_solution_packed_assets.data."""
    loader = (package / "face_mesh_solution_packed_assets_loader.js").read_text()
    m = re.search(r'"filename":\s*"[^"]*' + re.escape(name) + r'",\s*"start":\s*(\d+),\s*"end":\s*(\d+)', loader)
    start, end = int(m.group(1)), int(m.group(2))
    return (package / "face_mesh_solution_packed_assets.data").read_bytes()[start:end]


def canonical_face(blob: bytes) -> dict:
    """Vertices (cm), uv and triangles of the canonical mesh in the metadata protobuf."""
    meta = geometry_pipeline_metadata_pb2.GeometryPipelineMetadata()
    meta.ParseFromString(blob)
    buf = np.array(meta.canonical_mesh.vertex_buffer, dtype=np.float64).reshape(-1, 5)
    tri = np.array(meta.canonical_mesh.index_buffer, dtype=np.int64).reshape(-1, 3)
    return {
        "vertices_cm": np.round(buf[:, :3], 6).tolist(),
        "uv": np.round(buf[:, 3:], 6).tolist(),
        "faces": tri.tolist(),
    }


def feature_loops() -> dict:
    """Landmark edges [i, j] of lips, eyes and eyebrows (for shading synthetic subjects)."""
    return {k: sorted([min(e), max(e)] for e in v) for k, v in FEATURES.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--package", type=Path, help="an unpacked @mediapipe/face_mesh package folder")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        package = args.package or fetch_package(Path(tmp))
        version = json.loads((package / "package.json").read_text())["version"]
        data = {
            "source": f"@mediapipe/face_mesh {version} (npm), {ASSET}; canonical face model",
            "license": "Apache-2.0, Copyright The MediaPipe Authors; see LICENSE-mediapipe.txt",
            "units": "cm",
            "frame": "x to the subject's left (image right), y up, z out of the face",
            **canonical_face(packed_asset(package, ASSET)),
            "features": feature_loops(),
        }
    OUT.write_text(json.dumps(data, separators=(",", ":")) + "\n")
    print(f"wrote {OUT} ({len(data['vertices_cm'])} vertices, {len(data['faces'])} triangles)")


if __name__ == "__main__":
    main()
