"""Mesh scans in: every supported format, units, appearance, point clouds, and the real fran scan."""

import numpy as np
import pytest
import trimesh
from PIL import Image

from cpapfit.io import load_scan


@pytest.fixture(scope="module")
def face_m(phantom1):
    """The seed-1 subject's surface in metres, centred (as a scanner might export it)."""
    v = (phantom1.surface - phantom1.surface.mean(axis=0)) / 1000.0
    return trimesh.Trimesh(v, phantom1.faces, process=False)


@pytest.mark.parametrize("suffix", [".ply", ".stl", ".off", ".obj", ".glb"])
def test_formats_load_in_mm(tmp_path, face_m, suffix):
    path = tmp_path / f"face{suffix}"
    face_m.export(path)
    scan = load_scan(path)
    assert scan.units == "m"
    assert np.ptp(scan.vertices, axis=0).max() == pytest.approx(np.ptp(face_m.vertices, axis=0).max() * 1000, rel=1e-5)
    assert len(scan.faces) == len(face_m.faces)
    assert np.allclose(np.linalg.norm(scan.normals, axis=1), 1.0)


def test_stated_units_override(tmp_path, face_m):
    path = tmp_path / "face_cm.ply"
    trimesh.Trimesh(face_m.vertices * 100, face_m.faces).export(path)
    assert load_scan(path, units="cm").units == "cm"
    assert load_scan(path).units == "cm"


def test_obj_texture_and_vertex_colours(tmp_path, face_m):
    uv = (face_m.vertices[:, :2] - face_m.vertices[:, :2].min(0)) / np.ptp(face_m.vertices[:, :2], axis=0)
    tex = Image.fromarray(np.full((16, 16, 3), [200, 150, 120], dtype=np.uint8))
    textured = trimesh.Trimesh(face_m.vertices, face_m.faces, visual=trimesh.visual.TextureVisuals(uv=uv, image=tex), process=False)
    textured.export(tmp_path / "tex.obj")
    scan = load_scan(tmp_path / "tex.obj")
    assert scan.texture is not None and scan.texture.shape == (16, 16, 3) and scan.uv.shape == (len(scan.vertices), 2)

    coloured = trimesh.Trimesh(face_m.vertices, face_m.faces, vertex_colors=[10, 200, 30, 255], process=False)
    coloured.export(tmp_path / "col.ply")
    scan = load_scan(tmp_path / "col.ply")
    assert scan.colors is not None and (scan.colors == [10, 200, 30]).all()


def test_a_textured_obj_of_quads_keeps_its_texture(tmp_path):
    """Scanners export quads ("f 1/1 2/2 3/3 4/4"): their texture coordinates are read (trimesh
    before 4.6.11 dropped them, and the face was rendered without its colours)."""
    n = 20
    x, y = np.meshgrid(np.linspace(-50, 50, n), np.linspace(-60, 60, n))
    z = 40 * np.exp(-(x**2 + y**2) / 2000)
    uv = np.column_stack([(x.ravel() + 50) / 100, (y.ravel() + 60) / 120])
    Image.fromarray(np.full((8, 8, 3), [200, 150, 120], dtype=np.uint8)).save(tmp_path / "skin.png")
    (tmp_path / "face.mtl").write_text("newmtl skin\nmap_Kd skin.png\n")
    quads = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j) for i in range(n - 1) for j in range(n - 1)]
    lines = ["mtllib face.mtl", "usemtl skin"] + [f"v {a:.4f} {b:.4f} {c:.4f}" for a, b, c in zip(x.ravel(), y.ravel(), z.ravel())]
    lines += [f"vt {u:.5f} {v:.5f}" for u, v in uv] + ["f " + " ".join(f"{k + 1}/{k + 1}" for k in q) for q in quads]
    (tmp_path / "face.obj").write_text("\n".join(lines) + "\n")
    scan = load_scan(tmp_path / "face.obj", units="mm")
    assert len(scan.faces) == 2 * len(quads) and scan.texture is not None and scan.texture.shape == (8, 8, 3)
    at = np.round((scan.vertices[:, :2] + [50, 60]) / [100 / (n - 1), 120 / (n - 1)]).astype(int)  # grid (column, row)
    assert np.abs(scan.uv - uv[at[:, 1] * n + at[:, 0]]).max() < 1e-4


def test_ply_face_colours_are_read_as_vertex_colours(tmp_path, face_m):
    """Colour per triangle (red on the left half, green on the right): each vertex gets its
    triangles' mean, so the colour renders the landmarks are found on keep it."""
    left = face_m.triangles_center[:, 0] < 0
    colours = np.where(left[:, None], [220, 20, 20, 255], [20, 220, 20, 255]).astype(np.uint8)
    trimesh.Trimesh(face_m.vertices, face_m.faces, face_colors=colours, process=False).export(tmp_path / "faces.ply")
    scan = load_scan(tmp_path / "faces.ply")
    x = scan.vertices[:, 0] / 1000
    assert scan.colors is not None
    assert (scan.colors[x < -0.01] == [220, 20, 20]).all() and (scan.colors[x > 0.01] == [20, 220, 20]).all()


def test_every_triangle_with_its_own_corners_is_joined_into_a_surface(tmp_path, face_m):
    """A triangle soup (each triangle's corners stored apart, as some exporters write), coloured by
    height: read as the surface it is, every corner at one place one vertex, colours kept; a
    textured soup's colours come from its texture."""
    corners = face_m.vertices[face_m.faces].reshape(-1, 3)
    shade = np.round(255 * (corners[:, 1] - corners[:, 1].min()) / np.ptp(corners[:, 1])).astype(np.uint8)
    colours = np.column_stack([shade, 255 - shade, np.full_like(shade, 30), np.full_like(shade, 255)])
    trimesh.Trimesh(corners, np.arange(len(corners)).reshape(-1, 3), vertex_colors=colours, process=False).export(tmp_path / "soup.ply")
    scan = load_scan(tmp_path / "soup.ply")
    assert len(scan.vertices) == len(face_m.vertices) and len(scan.faces) == len(face_m.faces)
    assert np.abs(scan.vertices[scan.faces] - 1000 * face_m.vertices[face_m.faces]).max() < 1e-4  # PLY stores float32
    height = np.round(255 * (scan.vertices[:, 1] / 1000 - corners[:, 1].min()) / np.ptp(corners[:, 1]))
    assert np.abs(scan.colors[:, 0].astype(float) - height).max() <= 1 and (scan.colors[:, 2] == 30).all()

    tex = Image.fromarray(np.full((16, 16, 3), [200, 150, 120], dtype=np.uint8))
    uv = np.full((len(corners), 2), 0.5)
    textured = trimesh.Trimesh(corners, np.arange(len(corners)).reshape(-1, 3), visual=trimesh.visual.TextureVisuals(uv=uv, image=tex), process=False)
    textured.export(tmp_path / "soup.obj")
    scan = load_scan(tmp_path / "soup.obj")
    assert len(scan.vertices) == len(face_m.vertices) and (scan.colors == [200, 150, 120]).all()


def test_a_texture_seam_across_the_face_is_no_rim_and_does_not_bend_the_normals(tmp_path, face_m):
    """A textured OBJ whose texture map is cut down the middle of the face (each vertex on the cut
    written twice, once per side, with its own texture coordinates, as texture atlases do): the cut
    is no rim of the surface, and both copies of a vertex have the normal the uncut surface has."""
    right = face_m.triangles_center[:, 0] > 0
    seam = np.intersect1d(face_m.faces[right], face_m.faces[~right])
    copy = np.arange(len(face_m.vertices))
    copy[seam] = len(face_m.vertices) + np.arange(len(seam))
    faces = np.where(right[:, None], copy[face_m.faces], face_m.faces)
    vertices = np.vstack([face_m.vertices, face_m.vertices[seam]])
    uv = np.column_stack([0.5 * (vertices[:, 0] > 0) + 0.1 * (np.arange(len(vertices)) >= len(face_m.vertices)), np.full(len(vertices), 0.5)])
    tex = Image.fromarray(np.full((16, 16, 3), [200, 150, 120], dtype=np.uint8))
    trimesh.Trimesh(vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv, image=tex), process=False).export(tmp_path / "seam.obj")
    scan = load_scan(tmp_path / "seam.obj")
    face_m.export(tmp_path / "whole.obj")
    whole = load_scan(tmp_path / "whole.obj")
    assert len(scan.vertices) == len(whole.vertices) + len(seam) and scan.texture is not None
    at = {tuple(v): i for i, v in enumerate(whole.vertices)}
    same = np.array([at[tuple(v)] for v in scan.vertices])
    assert len(seam) > 20 and np.array_equal(scan.rims, whole.rims[same])
    assert np.abs(scan.normals - whole.normals[same]).max() < 1e-9


def test_a_mesh_wound_one_way_on_one_side_and_the_other_way_on_the_other_is_wound_alike(tmp_path, face_m, phantom1):
    """The triangles left of the middle written the other way round: the scan's normals agree with
    the file wound alike, up to one sign for all (they pointed into the face on one side), and the
    template registers within 0.6 mm of the truth over the mask region (0.85 mm before, with half of
    it dropped by the normal gate)."""
    from cpapfit.pipeline import align, register_template
    from cpapfit.template import load_template, mask_region

    face_m.export(tmp_path / "alike.ply")
    faces = face_m.faces.copy()
    left = face_m.triangles_center[:, 0] < np.median(face_m.triangles_center[:, 0])
    faces[left] = faces[left][:, ::-1]
    trimesh.Trimesh(face_m.vertices, faces, process=False).export(tmp_path / "two_ways.ply")
    scan, alike = load_scan(tmp_path / "two_ways.ply"), load_scan(tmp_path / "alike.ply")
    assert trimesh.Trimesh(scan.vertices, scan.faces, process=False).is_winding_consistent
    agree = np.einsum("ij,ij->i", scan.normals, alike.normals)
    agree *= np.sign(np.median(agree))  # half and half: which way is the file's is a toss-up, and either will do
    assert np.degrees(np.arccos(np.clip(agree, -1, 1))).max() < 1.0
    region = mask_region(load_template())
    truth = (phantom1.surface - phantom1.surface.mean(axis=0))[region]
    registered = register_template(scan, align(scan)).vertices[region]
    assert np.linalg.norm(registered - truth, axis=1).mean() <= 0.6


def test_point_cloud_gets_outward_normals(tmp_path, face_m):
    """PCA normals are the surface's, and 99 % point out of the face, as the subject's surface
    does, also beside the nose, under it and in the eye sockets. Pointed away from the centroid
    instead, 15 % of them pointed into the head."""
    trimesh.PointCloud(face_m.vertices).export(tmp_path / "cloud.ply")
    scan = load_scan(tmp_path / "cloud.ply")
    assert scan.is_point_cloud
    agree = np.einsum("ij,ij->i", scan.normals, np.asarray(face_m.vertex_normals))
    assert np.median(np.abs(agree)) > 0.95
    assert (agree > 0).mean() >= 0.99


def test_a_point_cloud_written_twice_over_is_read_once(tmp_path, face_m):
    """Every point of a coloured cloud twice, the copies in different colours: one point a
    position, in the file's order, its colour the two's mean, and the same normals as the cloud
    written once. Kept twice, 14 % of the inside of a cloud was taken for rim and 22 % of its rim was not."""
    points = np.asarray(face_m.vertices)
    colours = np.tile([[10, 200, 30]], (len(points), 1)).astype(np.uint8)
    trimesh.PointCloud(np.vstack([points, points]), colors=np.vstack([colours, colours + 20])).export(tmp_path / "twice.ply")
    trimesh.PointCloud(points).export(tmp_path / "once.ply")
    twice, once = load_scan(tmp_path / "twice.ply"), load_scan(tmp_path / "once.ply")
    assert np.array_equal(twice.vertices, once.vertices)
    assert (twice.colors == [20, 210, 40]).all()
    assert np.allclose(twice.normals, once.normals)


def test_point_cloud_parts_each_get_outward_normals(tmp_path, face_m):
    """A cloud in two parts (the face and, 300 mm away, a 40 mm sphere): each part is oriented on
    its own, the face out of the face and the sphere outwards."""
    theta = np.arccos(np.linspace(-1, 1, 800))
    phi = np.arange(800) * np.pi * (3 - np.sqrt(5))
    unit = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    sphere = 0.3 + 0.02 * unit  # metres, as the face
    trimesh.PointCloud(np.vstack([face_m.vertices, sphere])).export(tmp_path / "two.ply")
    normals = load_scan(tmp_path / "two.ply").normals
    n_face = len(face_m.vertices)
    assert (np.einsum("ij,ij->i", normals[:n_face], np.asarray(face_m.vertex_normals)) > 0).mean() >= 0.99
    assert (np.einsum("ij,ij->i", normals[n_face:], unit) > 0.9).all()


@pytest.mark.shared
def test_fran_is_detected_as_metres_and_read_in_mm(shared_data):
    scan = load_scan(shared_data / "fran_cyberware" / "fran.obj")
    assert scan.units == "m" and "metres" in scan.units_note
    extent = np.ptp(scan.vertices, axis=0)
    assert 100 < extent.max() < 200  # mm
    assert scan.texture is not None and scan.uv is not None


@pytest.mark.shared
def test_truedepth_capture_loads_with_its_validity_mask(shared_data):
    scan = load_scan(shared_data / "rgbd_truedepth_mannequin")
    assert scan.valid.shape == (240, 320) and scan.image.shape == (240, 320, 3)
    assert 0.3 < scan.valid.mean() < 0.95  # zeros and far background are invalid
    assert len(scan.vertices) == scan.valid.sum()
    assert np.isnan(scan.depth[~scan.valid]).all() and np.isfinite(scan.depth[scan.valid]).all()
    assert (scan.pixel_vertex[scan.valid] == np.arange(len(scan.vertices))).all()
    head = scan.vertices[scan.vertices[:, 2] < 600]
    assert len(head) > 5000 and 150 < np.ptp(head[:, 1]) < 400  # the mannequin's head, mm
