"""The interactive 3-D view of the report: face and custom cushion, rims coloured by a quantity,
drawn by plotly.js (embedded whole, so the page works offline).

The scene is shown in the template's orientation (x to the patient's left, y up, z out of the
face; mm, true size), so every scan opens facing the viewer."""

import numpy as np
import plotly.graph_objects as go
import plotly.io as pio
import trimesh
from scipy.spatial import cKDTree

from ..clustering import clustered
from ..similarity import Similarity
from .figure import ColourScale
from .frame import Face

MAX_TRIANGLES = 30_000
CLUSTERED = 4  # a crop of more triangles than this many times the most shown is first thinned (the decimator keeps its largest input's size held)
CROP_MM = 110.0  # face shown within this distance of the seal's centre
SKIN = "#d9c0ad"
CUSHION_SKIN = "#8fb8e6"
STOPS = 32
LIGHT = {"lighting": {"ambient": 0.25, "diffuse": 0.95, "specular": 0.05, "roughness": 0.9},
         "lightposition": {"x": -1e5, "y": 1e5, "z": 1e5}}  # in front of the face, above on its right


def viewer_face(face: Face, centre: np.ndarray, radius_mm: float = CROP_MM, max_triangles: int = MAX_TRIANGLES) -> Face:
    """The face cropped to triangles within radius_mm of `centre` (mm) and decimated (quadric error)
    to at most max_triangles; a crop of more than CLUSTERED times that many is first thinned to
    CLUSTERED to about twice that many by vertex clustering (`clustered`)."""
    keep = (np.linalg.norm(face.vertices - centre, axis=1) < radius_mm)[face.faces].all(axis=1)
    mesh = trimesh.Trimesh(np.array(face.vertices), face.faces[keep], process=False)  # writable: the decimator needs it
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) > CLUSTERED * max_triangles:
        area = trimesh.triangles.area(mesh.vertices[mesh.faces]).sum()  # not the mesh's: its cache would outlive the crop
        cube = np.sqrt(2.0 * area / (CLUSTERED * max_triangles))  # two triangles a cube's face on a flat face; more where it curves
        mesh = trimesh.Trimesh(*clustered(mesh.vertices, mesh.faces, cube), process=False)
    if len(mesh.faces) > max_triangles:
        mesh = mesh.simplify_quadric_decimation(face_count=max_triangles)
    return Face(np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64))


def rim_values_on(vertices: np.ndarray, rim: np.ndarray, values: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N,) values of the rim point (K, 3) below each vertex (N, 3) along the unit mask axis (nearest in the
    plane across it, among the points with a value)."""
    flat = lambda p: p - np.outer(p @ axis, axis)  # noqa: E731
    known = np.isfinite(values)
    return values[known][cKDTree(flat(rim[known])).query(flat(vertices))[1]]


def colourscale(scale: ColourScale) -> list:
    """The scale as a plotly colourscale [[t, 'rgb(r,g,b)'], ...] (sampled, steps kept sharp)."""
    t = np.linspace(0.0, 1.0, STOPS)
    rgb = scale.rgb(scale.lo + t * (scale.hi - scale.lo))
    return [[float(x), f"rgb({r},{g},{b})"] for x, (r, g, b) in zip(t, rgb)]


def _upright(points: np.ndarray, similarity: Similarity, centre: np.ndarray) -> dict:
    """x, y, z arrays (float32) of (K, 3) scan-frame points in the template's orientation about centre."""
    q = ((points - centre) @ similarity.rotation).astype(np.float32)
    return {"x": q[:, 0], "y": q[:, 1], "z": q[:, 2]}


def _mesh(face: Face, similarity: Similarity, centre: np.ndarray, **style) -> go.Mesh3d:
    f = face.faces.astype(np.int32)
    return go.Mesh3d(**_upright(face.vertices, similarity, centre), i=f[:, 0], j=f[:, 1], k=f[:, 2], **style)


def viewer_figure(face: Face, cushion: Face, rims: dict, scale: ColourScale, similarity: Similarity, axis: np.ndarray) -> go.Figure:
    """Face, custom cushion (coloured by the custom rim's values) and each rim of {name: (points (K, 3) mm,
    values (K,))}, with buttons to show the custom cushion or the other cushion's rim (stock or generic)."""
    centre = np.vstack([p for p, _ in rims.values()]).mean(axis=0)
    colours = {"colorscale": colourscale(scale), "cmin": scale.lo, "cmax": scale.hi}
    custom_points, custom_values = rims["custom"]
    traces = [
        _mesh(face, similarity, centre, color=SKIN, name="face", hoverinfo="skip", **LIGHT),
        _mesh(cushion, similarity, centre, intensity=rim_values_on(cushion.vertices, custom_points, custom_values, axis).astype(np.float32),
              name="custom cushion", hoverinfo="skip", **LIGHT, showscale=True, colorbar={"title": {"text": scale.label}, "len": 0.8}, **colours),
    ]
    for name, (points, values) in rims.items():
        loop = np.where(np.isnan(values)[:, None], np.nan, points)  # no value (no skin found): a break in the line
        loop = np.vstack([loop, loop[:1]])
        vals = np.nan_to_num(np.append(values, values[0])).astype(np.float32)
        traces.append(go.Scatter3d(**_upright(loop, similarity, centre), mode="lines", name=f"{name} rim",
                                   line={"width": 9, "color": vals, **colours}, customdata=vals,
                                   hovertemplate=f"{name} rim: %{{customdata:.2f}}<extra></extra>"))
    other = next((name for name in rims if name != "custom"), None)
    shown = {"custom cushion": [True, True, True, False]}
    if other:
        shown |= {f"{other} rim": [True, False, False, True], "both rims": [True, False, True, True]}
    buttons = [{"label": label, "method": "restyle", "args": [{"visible": vis[:len(traces)]}]} for label, vis in shown.items()]
    for trace, visible in zip(traces, shown["custom cushion"]):
        trace.visible = visible
    fig = go.Figure(traces)
    fig.update_layout(
        template="none", height=620, margin={"l": 0, "r": 0, "t": 10, "b": 0}, showlegend=False,
        scene={"aspectmode": "data", "camera": {"eye": {"x": 0.0, "y": 0.0, "z": 1.4}, "up": {"x": 0.0, "y": 1.0, "z": 0.0}},
               **{a: {"visible": False} for a in ("xaxis", "yaxis", "zaxis")}},
        updatemenus=[{"type": "buttons", "direction": "right", "buttons": buttons, "x": 0.0, "y": 1.0, "xanchor": "left", "yanchor": "top"}],
    )
    return fig


def viewer_html(fig: go.Figure, div_id: str = "viewer") -> str:
    """An HTML fragment: plotly.js inline (no network) and the figure in a div with a fixed id (same figure, same bytes)."""
    return pio.to_html(fig, include_plotlyjs=True, full_html=False, div_id=div_id, default_width="100%",
                       config={"displaylogo": False, "responsive": True})
