"""The report's pictures, ray-cast offscreen (no display needed) and laid out with matplotlib.

Each picture function takes plain arrays (mm, scan frame) and pre-rendered `Shot`s of the face
(one rendering serves several pictures) and returns PNG bytes; `loop_image` and `rim_image`
return the (H, W, 3) uint8 picture itself."""

import numpy as np
from matplotlib import colormaps

from ..similarity import Similarity
from ..landmarks.types import Landmarks
from ..render import Scene, raycast, scene_of, shade
from ..scan import Intrinsics
from ..template import TEMPLATE_TO_CAMERA, Template
from .draw import draw_dots, draw_loop
from .figure import FONT, ColourScale, panels_png, png, sized_figure
from .frame import Face, Shot, around_seal, face_view, place_name, shoot, to_pixels, whole_face_view
from ..loops import loop_lengths
from .rim import KPA_TO_MMHG

SKIN = np.array([0.85, 0.68, 0.58])
REGION_COLOURS = {"nasal": np.array([0.15, 0.45, 0.95]), "oronasal": np.array([0.95, 0.3, 0.15])}
CURVE_COLOUR = np.array([1.0, 1.0, 1.0])
CUSHION_COLOUR = np.array([0.45, 0.7, 0.95])
FRAME_COLOUR = np.array([0.92, 0.92, 0.88])  # a white resin
RESIDUAL_MAX_MM = 1.0
CUSHION_FRAME_MM = 150.0  # picture height around the cushion
ON_SCAN, OFF_SCAN = "#1f78b4", "#e31a1c"
SEALED, OPEN = "#1a9850", "#d73027"
OPEN_RGB = np.array([20, 20, 20], dtype=np.uint8)
NO_DATA_RGB = np.array([150, 150, 150], dtype=np.uint8)
COMPARED_STYLE = {"color": "#e08214", "linestyle": "--"}
PROFILE_PX = (900, 420)  # a profile's (width, height) px
PROFILE_MARGINS_PX = {"left": 80, "right": 80, "bottom": 75, "top": 40}  # room for the axes' labels and the title
LINE_STYLES = {"custom": {"color": "#1f4e9c", "linestyle": "-"}, "stock": COMPARED_STYLE, "generic": COMPARED_STYLE,
               "stock_gauge": {"color": "#7b3294", "linestyle": ":"}}


def _rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)], dtype=np.uint8)


def frontal_picture(vertices: np.ndarray, faces: np.ndarray, albedo: np.ndarray, width: int = 640, height: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 frontal view of a face given in the template's frame (mm), albedo (N, 3) in [0, 1]."""
    f = 1.25 * height  # at 280 mm this frames the face from brow to chin
    intr = Intrinsics(width, height, f, f, (width - 1) / 2, (height - 1) / 2)
    cam = vertices @ TEMPLATE_TO_CAMERA.T + [0.0, 20.0, 280.0]
    return shade(raycast(cam, faces, intr), cam, faces, albedo)


def template_regions_picture(template: Template, width: int = 640, height: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 frontal view of the template with each mask's contact band and centre curve."""
    albedo = np.tile(SKIN, (len(template.vertices), 1))
    for name, region in template.regions.items():
        albedo[region.band] = REGION_COLOURS[name]
        albedo[region.curve] = CURVE_COLOUR
    return frontal_picture(template.vertices, template.faces, albedo, width, height)


def residual_picture(vertices: np.ndarray, faces: np.ndarray, residual: np.ndarray, similarity: Similarity, title: str) -> bytes:
    """PNG: the registered template (N, 3) mm seen from the front, coloured by the registration
    residual (N,) mm (0-1 mm scale; grey where unmatched), with a labelled colour bar."""
    scale = ColourScale(colormaps["viridis"], 0.0, RESIDUAL_MAX_MM, "distance to the scan (mm); grey: no scan data")
    albedo = np.where(np.isfinite(residual)[:, None], scale.rgb01(np.nan_to_num(residual)), 0.6)
    shot = shoot(Face(vertices, faces, albedo), whole_face_view(similarity))
    return panels_png([shot.image], [title], "How closely the template follows the scan", scale)


def landmarks_picture(shot: Shot, landmarks: Landmarks) -> bytes:
    """PNG: the scan from the front with its landmarks coloured by confidence (hidden ones not drawn)."""
    px, seen = to_pixels(shot, landmarks.points)
    scale = ColourScale(colormaps["RdYlGn"], 0.0, 1.0, "landmark confidence (weight in the alignment)")
    image = draw_dots(shot.image, px[seen], scale.rgb(landmarks.confidence[seen]), radius=3.5)
    low = int((landmarks.confidence < 0.5).sum())
    title = f"{len(landmarks.points)} landmarks found ({landmarks.path}); {low} with confidence below 0.5"
    return panels_png([image], [title], "The scan and its landmarks", scale)


def loop_image(shot: Shot, points: np.ndarray, colours: np.ndarray, width: int = 7) -> np.ndarray:
    """(H, W, 3) uint8: the shot with the closed loop of (K, 3) mm points drawn in (K, 3) uint8 colours."""
    px, seen = to_pixels(shot, points)
    return draw_loop(shot.image, px, seen, colours, width)


def contact_picture(shots: tuple[Shot, Shot], curve: np.ndarray, on_scan: np.ndarray) -> bytes:
    """PNG: the seal curve (K, 3) mm on the scan in a whole-face and a close-up shot; red where the
    scan has no data under it (on_scan (K,) False)."""
    colours = np.where(on_scan[:, None], _rgb(ON_SCAN), _rgb(OFF_SCAN))
    images = [loop_image(shot, curve, colours, width) for shot, width in zip(shots, (4, 7))]
    title = f"{100 * on_scan.mean():.0f} % of the seal curve lies on scan data"
    legend = ((ON_SCAN, "on the scan"), (OFF_SCAN, "no scan data (follows the template)"))
    return panels_png(images, [title, "close-up"], "Where the cushion will touch the face", legend=legend)


def cushion_picture(face: Face, vertices: np.ndarray, faces: np.ndarray, similarity: Similarity, scene: Scene) -> bytes:
    """PNG: the cushion solid ((N, 3) mm, (M, 3)) on the face, from the front and turned 50 degrees
    (`scene`: the face's, `solids_picture`)."""
    return solids_picture(face, ((vertices, faces, CUSHION_COLOUR),), similarity, "The custom cushion on the face", scene)


def mask_picture(face: Face, cushion: Face, frame: Face, similarity: Similarity, scene: Scene) -> bytes:
    """PNG: the assembled mask, the cushion and the frame (mm, scan frame), on the face, from the
    front and turned 50 degrees (`scene`: the face's, `solids_picture`)."""
    return solids_picture(face, ((cushion.vertices, cushion.faces, CUSHION_COLOUR), (frame.vertices, frame.faces, FRAME_COLOUR)),
                          similarity, "The assembled mask on the face", scene)


def solids_picture(face: Face, solids: tuple, similarity: Similarity, heading: str, scene: Scene) -> bytes:
    """PNG: solids ((vertices (N, 3) mm, faces (M, 3), colour (3,) in [0, 1]), ...) on the face, from
    the front and turned 50 degrees, framed on them. The face and the solids are ray-cast apart and
    each pixel shows the nearer (`scene`: the face's, `render.scene_of`, shared with the report's
    other pictures: a dense scan's is hundreds of MB)."""
    count = np.cumsum([0] + [len(v) for v, _, _ in solids])
    parts = Face(np.vstack([v for v, _, _ in solids]), np.vstack([f + n for (_, f, _), n in zip(solids, count)]),
                 np.vstack([np.tile(colour, (len(v), 1)) for v, _, colour in solids]))
    extent = max(CUSHION_FRAME_MM * similarity.scale, 1.8 * float(np.ptp(parts.vertices, axis=0).max()))
    scenes = (scene, scene_of(parts.vertices, parts.faces))
    images = []
    for yaw in (0.0, 50.0):
        view = face_view(similarity, parts.vertices.mean(axis=0), extent, yaw)
        skin, solid = shoot(face, view, scenes[0]), shoot(parts, view, scenes[1])
        nearer = np.isfinite(solid.depth) & ~(skin.depth <= solid.depth)
        images.append(np.where(nearer[..., None], solid.image, skin.image))
    return panels_png(images, ["front", "turned 50° (patient's right side)"], heading)


def rim_image(shot: Shot, points: np.ndarray, values: np.ndarray, scale: ColourScale, open_: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 3) uint8: the shot with a rim (K, 3) mm drawn in the colours of its (K,) values, grey where
    a value is NaN (no skin found), near-black where open."""
    colours = scale.rgb(np.nan_to_num(values))
    colours[np.isnan(values)] = NO_DATA_RGB
    if open_ is not None:
        colours[open_] = OPEN_RGB
    return loop_image(shot, points, colours)


def rim_map_picture(shot: Shot, rims: dict, scale: ColourScale, titles: dict, heading: str, columns: int | None = None) -> bytes:
    """PNG: each rim of {name: (points (K, 3) mm, values (K,), open (K,) bool or None)} coloured on the
    same close-up shot, side by side (in rows of `columns`), with the scale's colour bar."""
    images = [rim_image(shot, p, v, scale, o) for p, v, o in rims.values()]
    any_open = any(o is not None and o.any() for _, _, o in rims.values())
    any_nan = any(np.isnan(v).any() for _, v, _ in rims.values())
    legend = ((OPEN_RGB / 255, "open: no contact (leak)"),) * any_open + ((NO_DATA_RGB / 255, "no skin found under the rim (hole in the scan)"),) * any_nan
    return panels_png(images, [titles[n] for n in rims], heading, scale, legend, columns)


def leak_picture(shot: Shot, rims: dict, titles: dict) -> bytes:
    """PNG: where each rim of {name: (points (K, 3) mm, open (K,) bool)} leaves the skin (red), side by side."""
    images = [loop_image(shot, p, np.where(o[:, None], _rgb(OPEN), _rgb(SEALED))) for p, o in rims.values()]
    return panels_png(images, [titles[n] for n in rims], "Where the seal would leak", legend=((SEALED, "sealed"), (OPEN, "open (leak)")))


def profile_picture(similarity: Similarity, mask: str, rims: dict, ylabel: str, heading: str, window: tuple | None = None,
                    mmhg: bool = False) -> bytes:
    """PNG: values along each rim of {name: (points (K, 3) mm, values (K,), open (K,) bool or None)}
    against the position around the seal, custom vs stock (or generic); a window (lo, hi) kPa shaded; open
    stretches marked; a mmHg axis beside kPa if `mmhg`."""
    fig = sized_figure(*PROFILE_PX)
    (w, h), m = PROFILE_PX, PROFILE_MARGINS_PX
    ax = fig.subplots(gridspec_kw={"left": m["left"] / w, "right": 1 - m["right"] / w, "bottom": m["bottom"] / h, "top": 1 - m["top"] / h})
    if window:
        ax.axhspan(*window, color="#a1d99b", alpha=0.45, label=f"safe window {window[0]:.1f}-{window[1]:.1f} kPa")
    for name, (points, values, open_) in rims.items():
        angle = around_seal(points, similarity)
        order = np.argsort(angle)
        ax.plot(angle[order], values[order], linewidth=2, label=name, **LINE_STYLES.get(name, {}))
        if open_ is not None and open_.any():
            ax.plot(angle[open_], np.zeros(open_.sum()), "|", color=OPEN, markersize=14, markeredgewidth=2,
                    label=f"{name}: open ({loop_lengths(points)[open_].sum():.0f} mm)")
    ticks = [0, 90, 180, 270, 360]
    ax.set_xticks(ticks, [place_name(t % 360, mask).removeprefix("the ") for t in ticks], fontsize=FONT - 1)
    ax.set_xlim(0, 360)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("position around the seal, seen from the front (clockwise from the nasal bridge)", fontsize=FONT)
    ax.set_ylabel(ylabel, fontsize=FONT)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=FONT - 1, loc="upper right")
    ax.set_title(heading, fontsize=FONT + 2, fontweight="bold")
    if mmhg:
        right = ax.secondary_yaxis("right", functions=(lambda k: k * KPA_TO_MMHG, lambda m: m / KPA_TO_MMHG))
        right.set_ylabel("mmHg", fontsize=FONT)
    return png(fig)
