"""The bad-input corpus: every input path's bad cases, generated here, each refused by `cpapfit
design` with one line on stderr, exit code 2, and nothing in the output folder.

A case is a function (folder, subject) -> (argv before --out, words the error line must hold);
it writes its input under `folder`. `subject.ph` is the seed-1 synthetic subject (arrays),
`subject.capture` its capture folder.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from PIL import Image
from scipy.spatial.transform import Rotation

from cpapfit.io.capture import capture_files
from cpapfit.io.write import png_bytes, write_files
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.render import raycast, shade
from cpapfit.rgbd import project
from cpapfit.scan import Intrinsics

CASES = {}
MESH_FORMATS = ("ply", "obj", "stl", "off", "glb")


def case(name):
    def register(make):
        CASES[name] = make
        return make

    return register


def capture(folder: Path, subject) -> Path:
    """A copy of the subject's capture folder (colour, depth, intrinsics)."""
    shutil.copytree(subject.capture, folder, dirs_exist_ok=True, ignore=shutil.ignore_patterns("ground_truth"))
    return folder


def edit_intrinsics(folder: Path, **changes) -> None:
    path = folder / "intrinsics.json"
    path.write_text(json.dumps(json.loads(path.read_text()) | changes))


# --- mesh files ---------------------------------------------------------------------------

def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _truncated(path: Path) -> Path:
    return _write(path, path.read_bytes()[: int(path.stat().st_size * 0.6)])


def mesh_file(path: Path, vertices: np.ndarray, faces: np.ndarray | None = None) -> Path:
    """(N, 3) vertices and (M, 3) faces (none: a point cloud) written as the format of `path`."""
    geom = trimesh.PointCloud(vertices) if faces is None else trimesh.Trimesh(vertices, faces, process=False)
    data = geom.export(file_type=path.suffix[1:])
    return _write(path, data.encode() if isinstance(data, str) else data)


for fmt in MESH_FORMATS:
    case(f"empty {fmt}")(lambda d, s, fmt=fmt: ([_write(d / f"scan.{fmt}", b"")], ["empty"]))
    case(f"garbage {fmt}")(
        lambda d, s, fmt=fmt: ([_write(d / f"scan.{fmt}", np.random.default_rng(9).bytes(4000))], [f"scan.{fmt}"])
    )
    case(f"truncated {fmt}")(
        lambda d, s, fmt=fmt: ([_truncated(mesh_file(d / f"scan.{fmt}", s.ph.surface, s.ph.faces))], [f"scan.{fmt}"])
    )


def with_bad_vertices(value, step: int):
    def make(d, s):
        v = s.ph.surface.copy()
        v[::step, 0] = value
        return [mesh_file(d / "bad.ply", v, s.ph.faces)], ["NaN or infinite"]

    return make


case("NaN vertices")(with_bad_vertices(np.nan, 50))
case("an infinite vertex")(with_bad_vertices(np.inf, 10**6))


@case("a head mesh in inches, its units left to auto")
def _(d, s):
    """Read as centimetres (a head's size in both), the face is 2.54 times too small: the refusal asks after the units."""
    head = ict_head_mesh(1).mesh
    words = ["the template's size (an adult's: x0.7-1.4)", "units: centimetres, decided from the size", "--units in"]
    return [mesh_file(d / "inches.ply", head.vertices / 25.4, head.faces)], words


@case("a head mesh with its vertex colours in BGR order")
def _(d, s):
    head = ict_head_mesh(1).mesh
    colours = head.visual.vertex_colors.copy()
    colours[:, :3] = colours[:, 2::-1]
    data = trimesh.Trimesh(head.vertices, head.faces, vertex_colors=colours, process=False).export(file_type="ply")
    return [_write(d / "bgr.ply", data)], ["blue", "BGR"]


@case("text with a mesh extension")
def _(d, s):
    return [_write(d / "notes.obj", b"these are my notes, not a mesh\n")], ["no mesh"]


@case("unknown extension")
def _(d, s):
    return [mesh_file(d / "scan.ply", s.ph.surface, s.ph.faces).rename(d / "scan.xyz")], ["not a mesh file"]


@case("missing file")
def _(d, s):
    return [d / "nowhere.ply"], ["no such file"]


@case("degenerate triangles")
def _(d, s):
    line = np.repeat(s.ph.surface[:, :1], 3, axis=1)  # every point on the line x = y = z: no triangle has area
    return [mesh_file(d / "line.ply", line, s.ph.faces)], ["no area"]


@case("non-manifold")
def _(d, s):
    """The face with fins: two more triangles on each triangle's edges, to a point behind the face."""
    ph, apex = s.ph, len(s.ph.surface)
    fins = [np.column_stack([ph.faces[:, k], ph.faces[:, k + 1], np.full(len(ph.faces), apex)]) for k in (0, 1)]
    vertices = np.vstack([ph.surface, ph.surface.mean(axis=0) + [0, 0, 80]])
    return [mesh_file(d / "fins.off", vertices, np.vstack([ph.faces, *fins]))], ["non-manifold"]


@case("triangle soup")
def _(d, s):
    rng = np.random.default_rng(3)
    return [mesh_file(d / "soup.ply", rng.uniform(0, 180, (3000, 3)), rng.integers(0, 3000, (6000, 3)))], ["do not form a surface"]


@case("every triangle with its own corners, not quite at the same places")
def _(d, s):
    corners = s.ph.surface[s.ph.faces].reshape(-1, 3) + np.random.default_rng(4).normal(0.0, 0.01, (3 * len(s.ph.faces), 3))
    return [mesh_file(d / "split.ply", corners, np.arange(len(corners)).reshape(-1, 3))], ["merge"]


@case("faces pointing nowhere")
def _(d, s):
    faces = s.ph.faces.copy()
    faces[5, 2] = len(s.ph.surface) + 10
    lines = [f"v {x} {y} {z}" for x, y, z in s.ph.surface] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return [_write(d / "bad.obj", ("\n".join(lines) + "\n").encode())], ["bad.obj"]


@case("single point")
def _(d, s):
    return [mesh_file(d / "point.ply", s.ph.surface[:1])], ["only 1 vertices"]


@case("10 million points")
def _(d, s):
    n, path = 10_000_000, d / "huge.ply"
    rng = np.random.default_rng(0)
    with open(path, "wb") as fh:
        fh.write(f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
                 "property float z\nend_header\n".encode())
        for _ in range(10):  # in chunks: the test holds 12 MB, not 120
            (rng.random((n // 10, 3), dtype=np.float32) * 200).tofile(fh)
    return [path], ["10,000,000 vertices"]


@case("metres stated as millimetres")
def _(d, s):
    return [mesh_file(d / "m.ply", s.ph.surface / 1000, s.ph.faces), "--units", "mm"], ["check the unit"]


@case("a size no unit makes a face")
def _(d, s):
    return [mesh_file(d / "big.stl", s.ph.surface * 40, s.ph.faces)], ["none of"]


@case("a scan that is not a face")
def _(d, s):
    egg = trimesh.creation.icosphere(5, radius=1.0).vertices * [75.0, 100.0, 90.0]  # a bald, featureless head
    return [mesh_file(d / "egg.ply", egg)], ["no face found"]  # a point cloud: the landmark-free path


@case("a point cloud of a face too sparse to press a cushion on")
def _(d, s):
    kept = np.unique(np.floor(s.ph.surface / 3.5), axis=0, return_index=True)[1]  # one point per 3.5 mm cube
    return [mesh_file(d / "sparse.ply", s.ph.surface[np.sort(kept)])], ["mm apart, too sparse", "export a denser cloud, or a mesh"]


@case("a scan larger than a head, no face in it")
def _(d, s):
    blob = trimesh.creation.icosphere(4, radius=1.0)  # 900 mm across in mm: a bust's size, read as mm
    return [mesh_file(d / "blob.ply", blob.vertices * [350.0, 450.0, 200.0], blob.faces)], ["no face found", "crop it to the head"]


@case("a room scan in metres with a face in it")
def _(d, s):
    x, y = np.meshgrid(np.linspace(-1.5, 1.5, 150), np.linspace(-1.5, 1.5, 150))
    wall = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 1.0)])  # 3 m of wall behind the head
    points = np.vstack([s.ph.surface / 1000.0 - s.ph.surface.mean(axis=0) / 1000.0, wall])
    return [mesh_file(d / "room.ply", points)], ["none of", "crop a scan of more than head and shoulders"]


# --- RGB-D captures -----------------------------------------------------------------------

def save_png(path: Path, image: np.ndarray) -> None:
    path.write_bytes(png_bytes(image))


@case("empty folder")
def _(d, s):
    (d / "capture").mkdir()
    return [d / "capture"], ["intrinsics.json"]


@case("depth all zero")
def _(d, s):
    save_png(capture(d, s) / "depth.png", np.zeros_like(s.ph.depth_raw))
    return [d], ["valid"]


@case("half the depth pixels dropped at random")
def _(d, s):
    depth = s.ph.depth_raw.copy()
    depth[np.random.default_rng(0).random(depth.shape) < 0.5] = 0  # too few whole triangles for the face check's probes
    save_png(capture(d, s) / "depth.png", depth)
    return [d], ["face's pixels", "holes"]


@case("depth in the wrong depth_scale")
def _(d, s):
    edit_intrinsics(capture(d, s), depth_scale=10.0)  # 10 units per metre: the face 350 m away
    return [d], ["depth_scale"]


@case("intrinsics with a focal length twice too long")
def _(d, s):
    folder = capture(d, s)
    k = json.loads((folder / "intrinsics.json").read_text())["intrinsic_matrix"]
    edit_intrinsics(folder, intrinsic_matrix=[2 * k[0], *k[1:4], 2 * k[4], *k[5:]])  # the face half as wide and high
    return [d], ["face_size", "intrinsics (fx, fy)"]


@case("colour with its channels in BGR order")
def _(d, s):
    save_png(capture(d, s) / "color.png", s.ph.image[..., ::-1])
    return [d], ["blue", "BGR"]


@case("depth and colour of different sizes")
def _(d, s):
    save_png(capture(d, s) / "color.png", s.ph.image[::2, ::2])
    return [d], ["register"]


@case("8-bit depth")
def _(d, s):
    Image.fromarray((s.ph.depth_raw // 256).astype(np.uint8)).save(capture(d, s) / "depth.png")
    return [d], ["16-bit"]


@case("truncated depth")
def _(d, s):
    _truncated(capture(d, s) / "depth.png")
    return [d], ["depth.png"]


@case("depth claiming a gigapixel")
def _(d, s):
    data = bytearray((capture(d, s) / "depth.png").read_bytes())
    data[16:24] = (100_000).to_bytes(4, "big") * 2  # IHDR width and height: a decompression bomb
    (d / "depth.png").write_bytes(bytes(data))
    return [d], ["depth.png"]


@case("intrinsics written row-major")
def _(d, s):
    path = capture(d, s) / "intrinsics.json"
    data = json.loads(path.read_text())
    path.write_text(json.dumps(data | {"intrinsic_matrix": np.reshape(data["intrinsic_matrix"], (3, 3)).T.ravel().tolist()}))
    return [d], ["row-major"]


@case("intrinsics missing")
def _(d, s):
    (capture(d, s) / "intrinsics.json").unlink()
    return [d], ["intrinsics.json"]


for label, text in {
    "intrinsics not JSON": "width: 640",
    "intrinsics of another size": '{"width": 1280, "height": 720, "intrinsic_matrix": [600,0,0,0,600,0,640,360,1]}',
    "intrinsics with a negative focal length": '{"width": 640, "height": 480, "intrinsic_matrix": [-600,0,0,0,600,0,320,240,1]}',
    "intrinsics with NaN": '{"width": 640, "height": 480, "intrinsic_matrix": [NaN,0,0,0,600,0,320,240,1]}',
}.items():
    def _intrinsics(d, s, text=text):
        (capture(d, s) / "intrinsics.json").write_text(text)
        return [d], ["intrinsics"]

    case(label)(_intrinsics)


@case("units stated for a capture")
def _(d, s):
    return [capture(d, s), "--units", "m"], ["drop --units"]


@case("an image with no face")
def _(d, s):
    """A ball 100 mm across in front of a wall, photographed."""
    rng = np.random.default_rng(0)
    intr = Intrinsics(320, 240, 300.0, 300.0, 159.5, 119.5)
    u, v = np.meshgrid(np.arange(320) - 159.5, np.arange(240) - 119.5)
    r2 = (2 * u) ** 2 + (2 * v) ** 2  # squared distance from the optical axis at 600 mm (1 px = 2 mm there), mm^2
    depth = np.where(r2 < 100.0**2, 600.0 - np.sqrt(np.clip(100.0**2 - r2, 0, None)), 900.0) + rng.normal(0, 0.3, u.shape)
    image = np.clip(150 + 60 * (depth < 800)[..., None] + rng.normal(0, 10, (240, 320, 3)), 0, 255).astype(np.uint8)
    write_files(d, capture_files(image, np.round(depth * 10).astype(np.uint16), intr, 10000.0))
    return [d], ["no face found"]


@case("two faces")
def _(d, s):
    a, b = make_phantom(6), make_phantom(7)
    image = np.concatenate([a.image[:, 160:480], b.image[:, 160:480]], axis=1)
    depth = np.concatenate([a.depth_raw[:, 160:480], b.depth_raw[:, 160:480]], axis=1)
    write_files(d, capture_files(image, depth, a.intrinsics, a.sensor.depth_scale))
    return [d], ["two faces"]


@case("a face seen from behind")
def _(d, s):
    """The subject's face turned 180 degrees about its vertical axis: the camera sees its inside."""
    ph, k = s.ph, s.ph.intrinsics
    half = Intrinsics(k.width // 2, k.height // 2, k.fx / 2, k.fy / 2, k.cx / 2, k.cy / 2)  # a 320x240 camera
    centre = ph.surface.mean(axis=0)
    surface = (ph.surface - centre) @ Rotation.from_euler("y", 180, degrees=True).as_matrix().T + centre
    hits = raycast(surface, ph.faces, half)
    image = shade(hits, surface, ph.faces, np.tile([0.8, 0.6, 0.5], (len(surface), 1)))
    depth = np.where(hits.hit, np.round(np.nan_to_num(hits.depth) * 10), 0).astype(np.uint16)
    write_files(d, capture_files(image, depth, half, 10000.0))
    return [d], ["no face found"]


@case("a partial face that misses the mask region")
def _(d, s):
    """The capture cut off at the upper lip: an oronasal mask's seal around the mouth is not in it."""
    depth = s.ph.depth_raw.copy()
    depth[int(project(s.ph.landmarks[[0]], s.ph.intrinsics)[0, 1]):] = 0  # rows below the top of the upper lip
    save_png(capture(d, s) / "depth.png", depth)
    return [d, "--mask", "oronasal"], ["rescan", "hole"]


# --- landmark files -----------------------------------------------------------------------

def landmarks_case(content, *words: str):
    """A case: the subject's capture with a landmarks file of `content` (JSON-able, or bytes)."""

    def make(d, s):
        path = d / "landmarks.json"
        path.write_bytes(content if isinstance(content, bytes) else json.dumps(content).encode())
        return [s.capture, "--landmarks", path], list(words)

    return make


for label, content, words in (
    ("landmarks with an index the template lacks", {"points": [[0, 0, 500]] * 5, "template_index": [1, 2, 3, 4, 99999]}, ["does not exist"]),
    ("landmarks with negative indices", {"points": [[0, 0, 500]] * 5, "template_index": [1, 2, 3, 4, -1]}, ["does not exist"]),
    ("landmarks with fractional indices", {"points": [[0, 0, 500]] * 4, "template_index": [1.5, 2, 3, 4]}, ["whole numbers"]),
    ("landmarks with a repeated index", {"points": [[0, 0, 500]] * 4, "template_index": [1, 1, 2, 3]}, ["twice"]),
    ("too few landmarks", {"points": [[0, 0, 500]] * 3, "template_index": [1, 2, 3]}, ["at least 4"]),
    ("landmarks with NaN", {"points": [[0, 0, float("nan")]] * 4, "template_index": [1, 2, 3, 4]}, ["NaN"]),
    ("landmarks as a list", [[0, 0, 500]], ["not a landmarks file"]),
    ("landmarks of binary garbage", np.random.default_rng(1).bytes(500), ["not a landmarks file"]),
    ("landmarks nested a million deep", b"[" * 1_000_000 + b"]" * 1_000_000, ["not a landmarks file"]),
):
    case(label)(landmarks_case(content, *words))
case("landmarks file missing")(lambda d, s: ([s.capture, "--landmarks", d / "none.json"], ["no such landmarks file"]))

FEATURES = np.array([1, 4, 10, 33, 61, 133, 152, 168, 234, 263, 291, 362, 454])  # nose, eyes, mouth, chin, brow, cheeks


@case("landmarks of the wrong vertices")
def _(d, s):
    """Real positions on the face, each tied to another landmark's template index."""
    content = {"points": s.ph.surface[FEATURES].tolist(), "template_index": np.roll(FEATURES, 3).tolist()}
    return landmarks_case(content)(d, s)[0], ["face"]


@case("landmarks far from the scan")
def _(d, s):
    """The right landmarks, 40 mm in front of the face (another session's coordinates)."""
    content = {"points": (s.ph.surface[FEATURES] - [0, 0, 40]).tolist(), "template_index": FEATURES.tolist()}
    return landmarks_case(content)(d, s)[0], ["landmarks"]


def assert_refused(code: int, err: str, out: Path, words: list) -> None:
    """Exit code 2, exactly one non-empty stderr line naming the problem, no traceback, no files."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("cpapfit: error: "), err
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], lines[0]
    assert not out.exists() or not any(out.rglob("*")), list(out.rglob("*"))


def test_the_corpus_has_every_input_path():
    assert len(CASES) >= 30
    names = " ".join(CASES)
    for kind in ("ply", "obj", "stl", "off", "glb", "depth", "intrinsics", "landmarks", "face"):
        assert kind in names


@pytest.fixture(scope="module")
def subject(phantom1, phantom1_dir):
    return SimpleNamespace(ph=phantom1, capture=phantom1_dir)


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input_is_refused_with_one_line(name, tmp_path, subject, cli):
    argv, words = CASES[name](tmp_path, subject)
    out = tmp_path / "out"
    code, _, err = cli("design", *argv, "--out", out, "--quiet")
    assert_refused(code, err, out, words)


@pytest.mark.parametrize("name", ["garbage glb", "landmarks nested a million deep"])
def test_a_separate_process_exits_2_without_a_traceback(name, tmp_path, subject):
    argv, words = CASES[name](tmp_path, subject)
    out = tmp_path / "out"
    res = subprocess.run([sys.executable, "-m", "cpapfit", "design", *map(str, argv), "--out", str(out), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert_refused(res.returncode, res.stderr, out, words)
