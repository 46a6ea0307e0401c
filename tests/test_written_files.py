"""Mesh files checked as a slicer reads them back: float32 corners, vertices merged by position."""

from pathlib import Path

import numpy as np
import pytest
import trimesh

from cpapfit.fabrication.files import SolidError, check_closed, check_file, checked_files, read_3mf_parts, read_stl, stl_bytes, threemf_bytes

BOX = trimesh.creation.box((10.0, 10.0, 10.0))


def with_edge_split(mesh: trimesh.Trimesh, share: float) -> trimesh.Trimesh:
    """`mesh` with its first edge split at `share` of its length: a closed mesh, a T-junction nowhere."""
    v0, v1 = mesh.edges_unique[0]
    vertices = np.vstack([mesh.vertices, mesh.vertices[v0] + share * (mesh.vertices[v1] - mesh.vertices[v0])])
    w, faces = len(mesh.vertices), []
    for face in mesh.faces:
        for k in range(3):
            a, b, c = face[k], face[(k + 1) % 3], face[(k + 2) % 3]
            if {a, b} == {v0, v1}:
                faces += [[a, w, c], [w, b, c]]
                break
        else:
            faces.append(face)
    return trimesh.Trimesh(vertices, np.array(faces), process=False)


def test_a_clean_solid_reads_back_as_written_from_stl_and_3mf():
    stl, threemf = read_stl(stl_bytes(BOX)), read_3mf_parts(threemf_bytes(BOX, "box"))[0]
    assert len(stl.faces) == len(threemf.faces) == 12 and len(stl.vertices) == len(threemf.vertices) == 8
    assert np.array_equal(stl.vertices, threemf.vertices) and np.array_equal(stl.faces, threemf.faces)
    assert check_file(stl, "box.stl")["edges_not_in_two_triangles"] == 0
    assert checked_files(BOX, "box", ("stl", "3mf")) == {"box.stl": stl_bytes(BOX), "box.3mf": threemf_bytes(BOX, "box")}


def test_solids_touching_in_float32_pass_in_float64_but_not_as_written():
    """Two cubes 1e-9 mm apart along an edge: apart in float64, one edge of four triangles in the file."""
    other = BOX.copy().apply_translation((10.0 + 1e-9, 10.0 + 1e-9, 0.0))
    pair = trimesh.util.concatenate([BOX, other])
    assert check_closed(pair, "pair")["self_intersecting_edges"] == 0
    with pytest.raises(SolidError) as refused:
        checked_files(pair, "pair")
    assert refused.value.found["edges_not_in_two_triangles"] == 1 and "pair.stl" in str(refused.value)


def test_a_vertex_rounding_onto_its_neighbour_leaves_zero_area_triangles():
    """An edge split 1e-9 mm from its end: a closed solid in float64, two degenerate triangles in float32."""
    split = with_edge_split(BOX, 1e-10)
    assert split.is_watertight and split.area_faces.min() > 1e-10
    with pytest.raises(SolidError) as refused:
        checked_files(split, "split", ("3mf",))
    assert refused.value.found["zero_area_triangles"] == 2


def test_designed_files_are_clean_as_written(designed):
    """Every part of a design, as its STL (and the cushion's 3MF) reads back: no vertex merged away, closed."""
    _, d = designed
    for name, part in {"cushion": d.solid, "frame": d.frame.mesh, **d.mould_parts}.items():
        back = read_stl(checked_files(part, name)[f"{name}.stl"])
        assert len(back.faces) == len(part.faces) and len(back.vertices) == len(part.vertices), name
    threemf = checked_files(d.solid, "cushion", ("3mf",))["cushion.3mf"]
    assert check_file(read_3mf_parts(threemf)[0], "cushion.3mf")["volume_mm3"] == pytest.approx(d.solid.volume, rel=1e-5)


def test_sheets_touching_along_an_edge_are_parted_before_writing():
    """Two cubes sharing an edge: one manifold3d solid, but the edge is in four triangles as written;
    `clean_as_written` cuts them apart there, losing a negligible volume."""
    import manifold3d

    from cpapfit.fabrication.files import clean_as_written

    cube = manifold3d.Manifold.cube([10.0, 10.0, 10.0])
    pair = manifold3d.Manifold.compose([cube, cube.translate([10.0, 10.0, 0.0])])
    with pytest.raises(SolidError):
        checked_files(trimesh.Trimesh(pair.to_mesh().vert_properties, pair.to_mesh().tri_verts), "pair")
    parted = clean_as_written(pair)
    assert check_file(read_stl(checked_files(parted, "pair")["pair.stl"]), "pair.stl")["edges_not_in_two_triangles"] == 0
    assert parted.volume == pytest.approx(2000.0, rel=1e-3)


def test_a_solid_two_metres_from_the_origin_is_welded_where_its_file_would_merge_vertices():
    """A closed box with one triangle split about a point 0.05 µm from a corner: clean as written at
    the origin (kept as it is); 2 m out on every axis the float32 file merges the point into the
    corner (two triangles of no area, their edges unpaired), so it is welded there first, with the
    same volume to 1e-6 mm3, and its file reads back clean."""
    from cpapfit.fabrication.files import written_clean

    a, b, c = BOX.faces[0]
    towards = BOX.vertices[b] + BOX.vertices[c] - 2 * BOX.vertices[a]
    vertices = np.vstack([BOX.vertices, BOX.vertices[a] + 5e-5 * towards / np.linalg.norm(towards)])
    k = len(vertices) - 1
    split = trimesh.Trimesh(vertices, np.vstack([BOX.faces[1:], [[k, b, c], [a, b, k], [a, k, c]]]), process=False)
    assert written_clean(split) is split
    far = trimesh.Trimesh(split.vertices + 2000.0, split.faces, process=False)
    with pytest.raises(SolidError, match="not a closed 2-manifold"):
        checked_files(far, "far")
    welded = written_clean(far)
    assert welded.volume == pytest.approx(far.volume, abs=1e-6)
    assert check_file(read_stl(checked_files(welded, "far")["far.stl"]), "far.stl")["zero_area_triangles"] == 0


def test_a_sliver_a_few_float32_steps_across_is_welded_wider_until_its_file_is_clean():
    """A mould half of a design on an ICT head as its STL read back (tests/data/mould_part_sliver.npz,
    5 066 vertices): one triangle of it, 3e-5 mm across where two sheets 1 mm apart meet, has no area
    as written, and a weld at WELD_MM keeps it; the wider welds that follow take it out, the volume
    the same to 0.01 mm3 (of 195 000)."""
    from cpapfit.fabrication.files import WELD_MM, _welded, as_written, clean_as_written
    from cpapfit.solids import to_manifold, to_trimesh

    data = np.load(Path(__file__).parent / "data" / "mould_part_sliver.npz")
    part = trimesh.Trimesh(data["vertices"].astype(np.float64), data["faces"].astype(np.int64), process=False)
    with pytest.raises(SolidError, match="'zero_area_triangles': 1"):
        checked_files(part, "part")
    solid = to_manifold(part)
    assert as_written(to_trimesh(_welded(solid, WELD_MM))).area_faces.min() < 1e-10
    cleaned = clean_as_written(solid)
    assert check_file(read_stl(checked_files(cleaned, "part")["part.stl"]), "part.stl")["zero_area_triangles"] == 0
    assert cleaned.volume == pytest.approx(part.volume, abs=0.01)
