"""Fuzzing the loaders (hypothesis): thousands of generated and mutated scans, capture folders and
landmark files; each either loads or raises the project's own error, never anything else.

Derandomised (the same examples on every run) and without an example database, so CI is
deterministic and writes nothing.
"""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpapfit.errors import CpapfitError
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.landmarks import read_landmarks
from cpapfit.io.write import write_files
from cpapfit.scan import Intrinsics
from cpapfit.template import canonical_face

pytestmark = pytest.mark.filterwarnings("ignore")  # parsers' deprecation warnings on broken files
FUZZ = settings(derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck))


def fuzz(examples: int) -> settings:
    return settings(FUZZ, max_examples=examples)
FORMATS = ("ply", "obj", "stl", "off", "glb")
N_TEMPLATE = 28881


def loads_or_refuses(read, *args) -> None:
    """Call a loader; our own errors are the expected refusals, anything else fails the test."""
    try:
        read(*args)
    except CpapfitError:
        pass


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def valid_mesh_bytes() -> dict[str, bytes]:
    """The canonical face (468 vertices, mm) in each format; PLY both binary and ASCII."""
    v, f = canonical_face()
    mesh = trimesh.Trimesh(v, f, process=False, vertex_colors=np.tile([200, 150, 120, 255], (len(v), 1)))
    out = {fmt: mesh.export(file_type=fmt) for fmt in FORMATS}
    out["ascii.ply"] = mesh.export(file_type="ply", encoding="ascii")
    return {k: (d.encode() if isinstance(d, str) else d) for k, d in out.items()}


VALID = valid_mesh_bytes()
edits = st.lists(st.tuples(st.floats(0, 1), st.binary(min_size=0, max_size=8), st.integers(0, 8)), max_size=4)


def mutate(data: bytes, cut: float, changes: list) -> bytes:
    """`data` cut to a fraction, then at each (position, new bytes, n) n bytes replaced by the new ones."""
    out = bytearray(data[: max(1, int(len(data) * cut))])
    for where, new, n in changes:
        i = int(where * len(out))
        out[i:i + n] = new
    return bytes(out)


def write(folder: Path, name: str, data: bytes) -> Path:
    path = folder / name
    path.write_bytes(data)
    return path


@fuzz(400)
@given(fmt=st.sampled_from(FORMATS), data=st.binary(max_size=3000))
def test_random_bytes_with_a_mesh_extension(folder, fmt, data):
    loads_or_refuses(load_scan, write(folder, f"random.{fmt}", data))


@fuzz(700)
@given(name=st.sampled_from(sorted(VALID)), cut=st.one_of(st.just(1.0), st.floats(0, 1)), changes=edits)
def test_mutated_mesh_files(folder, name, cut, changes):
    suffix = name.rsplit(".", 1)[-1]
    loads_or_refuses(load_scan, write(folder, f"mutated.{suffix}", mutate(VALID[name], cut, changes)))


numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**6, 10**6), st.text(max_size=3), st.none())


@fuzz(250)
@given(
    meta=st.fixed_dictionaries({
        "width": st.one_of(st.just(64), numbers), "height": st.one_of(st.just(48), numbers),
        "intrinsic_matrix": st.one_of(st.just([60, 0, 0, 0, 60, 0, 32, 24, 1]), st.lists(numbers, max_size=10)),
    }, optional={"depth_scale": numbers}),
    part=st.sampled_from(["depth.png", "color.png", "intrinsics.json", None]),
    cut=st.floats(0, 1),
    changes=edits,
)
def test_mutated_capture_folders(folder, meta, part, cut, changes):
    """A small 64x48 capture of a bump at 500 mm, with generated intrinsics and one file mutated."""
    capture = folder / "capture"
    shutil.rmtree(capture, ignore_errors=True)
    u, v = np.meshgrid(np.arange(64) - 32, np.arange(48) - 24)
    depth = np.round((500 - 30 * np.exp(-(u**2 + v**2) / 200.0)) * 10).astype(np.uint16)
    image = np.full((48, 64, 3), 180, np.uint8)
    files = capture_files(image, depth, Intrinsics(64, 48, 60, 60, 32, 24), 10000.0)
    files["intrinsics.json"] = json.dumps(meta).encode()
    if part:
        files[part] = mutate(files[part], cut, changes)
    write_files(capture, files)
    loads_or_refuses(load_scan, capture)


json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.floats(), st.integers(-2**70, 2**70), st.text(max_size=5)),
    lambda inner: st.one_of(st.lists(inner, max_size=6), st.dictionaries(st.text(max_size=5), inner, max_size=4)),
    max_leaves=30,
)
landmark_like = st.fixed_dictionaries({
    "points": st.one_of(json_values, st.lists(st.lists(numbers, min_size=2, max_size=4), max_size=12)),
    "template_index": st.one_of(json_values, st.lists(st.one_of(st.integers(-5, 40000), numbers), max_size=12)),
})


@fuzz(500)
@given(content=st.one_of(json_values, landmark_like), units=st.sampled_from(["mm", "cm", "m"]))
def test_generated_landmark_files(folder, content, units):
    text = json.dumps(content)  # Python's JSON: NaN and Infinity included, as some writers emit them
    loads_or_refuses(read_landmarks, write(folder, "landmarks.json", text.encode()), units, N_TEMPLATE)


@fuzz(300)
@given(cut=st.floats(0, 1), changes=edits)
def test_mutated_landmark_files(folder, cut, changes):
    valid = json.dumps({"points": canonical_face()[0][:20].tolist(), "template_index": list(range(20))}).encode()
    loads_or_refuses(read_landmarks, write(folder, "landmarks.json", mutate(valid, cut, changes)), "mm", N_TEMPLATE)


def test_the_fuzzers_see_valid_files_load(folder):
    """The seeds of the mutations are valid: each format loads (so the mutations start from a real file)."""
    for name, data in VALID.items():
        assert len(load_scan(write(folder, f"valid.{name.rsplit('.', 1)[-1]}", data)).vertices) == 468
