"""The mask's rigid frame (manifold3d booleans), printed in a medical resin or nylon: the shell the
cushion's far end fits into, carrying the ISO 5356-1 22 mm male connector, the exhaust vents, for
oronasal masks the anti-asphyxia valve opening with its flap seat, and four headgear strap slots.

Built in the mask's frame (x across the face, y up, z along the mask axis out of the face, origin
the centre of the cushion's frame ring, mm) and returned in the scan's. The collar around the ring
is the frame's solid less the cushion itself: its groove is the cushion's last GROOVE_MM, so the
two touch without interference, and the collar reaches COLLAR_RIM_MM beyond the cushion's end on
the outside and SPIGOT_MM beyond it on the inside (a spigot all round, wherever the end leans), so
that the end is held on both faces (the mould casts that end with the rest of the cushion). Over
the collar a dome of wall WALL_MM rises to the connector's shoulder; the port's axis is the mask
axis, pointing away from the face.
"""

from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh

from ..cushion.nurbs import FRAME_RING_MM, Cushion
from ..solids import to_manifold, to_trimesh
from .files import written_clean
from ..frozen import freeze_arrays
from .vents import Vents, sized_vents

CONE_TIP_MM, CONE_TAPER, CONE_MM = 21.995, 1.0 / 40.0, 22.0  # ISO 5356-1 22 mm male: tip diameter, taper on diameter, length
GAUGE_PLANE_MM = 15.0  # from the tip, where the diameter is 22.37 mm
BORE_MM = 16.0  # the connector's bore
SHOULDER_MM = (28.0, 2.0)  # diameter, length: the stop the hose's socket meets
WALL_MM = 2.0  # the dome's wall
GROOVE_MM = 4.0  # how far the cushion's end enters the frame
COLLAR_TOP_MM, COLLAR_RIM_MM, SPIGOT_MM = 2.5, 2.0, 2.0  # frame above, outside and inside the cushion's end
END_MM = GROOVE_MM + 1.0  # the cushion's end the frame meets: its last END_MM (the frame lies above -GROOVE_MM)
DOME_MM = 8.0  # the dome's rise from the collar to the shoulder
SEGMENTS = 128  # around the cone: a slice's polygon lies within 4e-3 mm of its circle
VENT_ROWS = (0.45, 0.65, 0.85)  # where the vent rows lie from the collar (0) to the shoulder (1)
VENT_ARC_DEG = 35.0  # vents within this angle of the head's up direction around the axis: away from a bed partner
VENT_PITCH = 3.0  # centre spacing in hole diameters
VALVE_MM = (12.0, 18.0, 1.5)  # anti-asphyxia valve: opening and seat diameters, seat height inside the shell
VALVE_AT, SEAT_CLEAR_MM = (0.5, 0.55, 0.6, 0.65, 0.7), 0.5  # where the valve may lie up the dome; its seat's clearance over the collar
TAB_MM = (13.0, 22.0, 3.0)  # headgear tab: reach beyond the collar, width, thickness
SLOT_MM = (4.0, 17.0, 5.0)  # strap slot: width, length, distance from the collar
ANCHOR_DEG = (35.0, 145.0, 215.0, 325.0)  # the tabs' angles from the patient's left towards up


@dataclass(frozen=True)
class Frame:
    """The frame (scan frame, mm): `mesh` the solid; `airspace` the air it and the cushion's end enclose up
    to the connector's bore (a solid); `port_tip` (3,) and `port_axis` (3,) unit, out of the port;
    `vents` their sizing, `vent_holes` (n, 2, 3) each hole's outer centre and unit direction; `valve`
    (2, 3) the anti-asphyxia opening's outer centre and direction, or None; `anchors` (4, 3) the strap
    slots' centres; `holes` the through-holes (vents, valve, slots); `assembly` the cushion in its
    groove (`assembly_checks`)."""

    mesh: trimesh.Trimesh
    airspace: trimesh.Trimesh
    port_tip: np.ndarray
    port_axis: np.ndarray
    vents: Vents
    vent_holes: np.ndarray
    valve: np.ndarray | None
    anchors: np.ndarray
    holes: int
    assembly: dict

    def __post_init__(self):
        freeze_arrays(self)


def cone_diameter_mm(from_tip_mm):
    """The ISO 5356-1 22 mm male cone's diameter (mm) at a distance (mm) from its tip."""
    return CONE_TIP_MM + CONE_TAPER * np.asarray(from_tip_mm)


def sliced_diameters(mesh, tip: np.ndarray, axis: np.ndarray, from_tip) -> np.ndarray:
    """(K,) mm: the largest least-squares circle's diameter (Kasa's algebraic fit) of `mesh`'s section
    across the unit `axis` at each distance (mm) of `from_tip` back from the point `tip`."""
    out = []
    for d in from_tip:
        flat, _ = mesh.section(plane_origin=tip - d * axis, plane_normal=axis).to_2D()
        out.append(max(_circle_diameter(np.asarray(loop)) for loop in flat.discrete))
    return np.array(out)


def _circle_diameter(points: np.ndarray) -> float:
    """Diameter (mm) of the least-squares circle through (K, 2) points."""
    a = np.column_stack([points, np.ones(len(points))])
    cx, cy, c = np.linalg.lstsq(a, (points**2).sum(axis=1), rcond=None)[0]
    return float(2.0 * np.sqrt(c + (cx**2 + cy**2) / 4.0))


def mask_frame(cushion: Cushion) -> np.ndarray:
    """(4, 4) the mask's frame to the scan's: x across the face, y up, z the mask axis, origin the ring's centre."""
    axis = cushion.axis
    up = cushion.up - (cushion.up @ axis) * axis
    up /= np.linalg.norm(up)
    out = np.eye(4)
    out[:3, :3] = np.stack([np.cross(up, axis), up, axis], axis=1)
    out[:3, 3] = cushion.grid(64, 2)[:, -1].mean(axis=0)
    return out


def build_frame(cushion: Cushion, solid: trimesh.Trimesh) -> Frame:
    """The frame of a cushion whose printable solid is `solid` (mm, scan frame)."""
    to_scan = mask_frame(cushion)
    end = _end(to_manifold(solid).transform(np.linalg.inv(to_scan)[:3]))
    ring = np.array(FRAME_RING_MM[cushion.mask]) / 2
    inside, outside = _reach(end, *ring)
    outer = ring + outside + COLLAR_RIM_MM
    top = COLLAR_TOP_MM + DOME_MM
    vents = sized_vents()
    holes = _vent_holes(outer, vents)
    valve = _valve(outer) if cushion.mask == "oronasal" else None
    drilled = [_drill(p, d, vents.diameter_mm) for p, d in holes] + ([_drill(*valve, VALVE_MM[0])] if valve is not None else [])
    anchors = [_anchor(outer, angle) for angle in ANCHOR_DEG]
    body = m3.Manifold.batch_boolean([_outer(outer, top)] + [tab for tab, _ in anchors], m3.OpType.Add)
    air = _inner(ring - inside - SPIGOT_MM, outer, top)
    bore = m3.Manifold.cylinder(top + SHOULDER_MM[1] + CONE_MM + 2, BORE_MM / 2, BORE_MM / 2, SEGMENTS).translate([0, 0, top - WALL_MM - 1])
    seat = _seat(*valve) if valve is not None else m3.Manifold()
    shell = body - (air + bore) + seat - m3.Manifold.batch_boolean(drilled + [slot for _, slot in anchors], m3.OpType.Add)
    place = to_scan[:3]  # the cushion's end is cut from the frame where it lies: the groove is its own faces
    rotation, at = to_scan[:3, :3], to_scan[:3, 3]
    scan = lambda p: np.asarray(p) @ rotation.T + at  # noqa: E731
    return Frame(
        written_clean(to_trimesh((shell - end).transform(place))), to_trimesh((air - end).transform(place)),
        scan([0.0, 0.0, top + SHOULDER_MM[1] + CONE_MM]), rotation[:, 2],
        vents, np.stack([np.stack([scan(p), rotation @ d]) for p, d in holes]),
        None if valve is None else np.stack([scan(valve[0]), rotation @ valve[1]]),
        np.stack([scan(_slot_centre(outer, angle)) for angle in ANCHOR_DEG]),
        len(drilled) + len(anchors), assembly_checks(shell, end, len(drilled) + len(anchors)),
    )


def assembly_checks(shell: m3.Manifold, end: m3.Manifold, holes: int) -> dict:
    """The cushion's `end` (`_end`) in the frame, which is the `shell` less the end (double precision):
    the frame is one piece; the volume it shares with the cushion (interference, mm3); and whether the
    airway is closed: the two joined are one solid whose genus is 1 (the tube from the face to the
    port) plus the frame's through-holes, so that no other opening runs between them. The joined
    solid is the shell and the end joined, the same set without the faces the groove shares with the
    end (whose round-off leaves slivers of no volume that would count as handles); the end's join to
    the rest of the cushion, a whole cross-section, adds no handle."""
    frame, joined = shell - end, shell + end
    genus, pieces = joined.genus(), len(frame.decompose()) + len(joined.decompose()) - 1
    return {"groove_mm": GROOVE_MM, "interference_mm3": round(max(0.0, (frame ^ end).volume()), 4), "through_holes": holes,
            "pieces": pieces, "joined_genus": genus, "airway_closed": pieces == 1 and genus == 1 + holes}


def _end(cast: m3.Manifold) -> m3.Manifold:
    """The cushion's last END_MM along the mask axis (a solid band; `cast` in the mask's frame): all of it the frame meets."""
    lo, hi = np.asarray(cast.bounding_box()).reshape(2, 3)
    size = hi - lo + 2.0
    return cast ^ m3.Manifold.cube([size[0], size[1], END_MM + 1.0]).translate([lo[0] - 1.0, lo[1] - 1.0, -END_MM])


def _reach(end: m3.Manifold, a: float, b: float) -> tuple[float, float]:
    """(inside, outside) mm: how far the cushion's `end` reaches inside and outside its ring (a, b
    semi-axes) across the axis, each at least 0."""
    v = np.asarray(end.to_mesh().vert_properties)[:, :3]
    angle = np.arctan2(v[:, 1], v[:, 0])
    off = np.hypot(v[:, 0], v[:, 1]) - a * b / np.hypot(b * np.cos(angle), a * np.sin(angle))
    return float(max(0.0, -off.min())), float(max(0.0, off.max()))


def _ellipse(semi: tuple, z: float, n: int = SEGMENTS) -> np.ndarray:
    """(n, 3) points of the ellipse of semi-axes `semi` (x, y) at height z."""
    t = 2 * np.pi * np.arange(n) / n
    return np.stack([semi[0] * np.cos(t), semi[1] * np.sin(t), np.full(n, z)], axis=1)


def _hull(*rings: np.ndarray) -> m3.Manifold:
    return m3.Manifold.hull_points(np.vstack(rings).tolist())


def _outer(outer: np.ndarray, top: float) -> m3.Manifold:
    """The frame's outside: collar, dome, shoulder and the connector's cone."""
    shoulder, length = SHOULDER_MM
    cone = m3.Manifold.cylinder(CONE_MM, cone_diameter_mm(CONE_MM) / 2, CONE_TIP_MM / 2, SEGMENTS).translate([0, 0, top + length])
    collar = _hull(_ellipse(outer, -GROOVE_MM), _ellipse(outer, COLLAR_TOP_MM), _ellipse((shoulder / 2,) * 2, top))
    return collar + m3.Manifold.cylinder(length + 0.5, shoulder / 2, shoulder / 2, SEGMENTS).translate([0, 0, top - 0.5]) + cone


def _inner(opening: np.ndarray, outer: np.ndarray, top: float) -> m3.Manifold:
    """The air inside the frame up to the bore: the opening through the collar (semi-axes `opening`)
    and the dome's inside, its wall WALL_MM thick (each semi-axis's line from collar to shoulder
    offset inwards by WALL_MM)."""
    drop = outer - SHOULDER_MM[0] / 2
    base = outer - WALL_MM * np.hypot(drop, DOME_MM) / DOME_MM
    rim = _ellipse(opening, 0.0)
    through = _hull(rim - [0, 0, END_MM], rim + [0, 0, COLLAR_TOP_MM + 0.01])
    return through + _hull(_ellipse(base, COLLAR_TOP_MM), _ellipse(base - drop * (DOME_MM - WALL_MM) / DOME_MM, top - WALL_MM))


def _dome_point(outer: np.ndarray, angle_deg: float, t: float) -> tuple[np.ndarray, np.ndarray]:
    """(point, unit outward normal) on the dome's outside at `angle_deg` around the axis (from the
    patient's left towards up) and `t` of the way from the collar (0) to the shoulder (1)."""
    top, r, theta = COLLAR_TOP_MM + DOME_MM, SHOULDER_MM[0] / 2, np.radians(angle_deg)
    c, s = np.cos(theta), np.sin(theta)
    point = np.array([((1 - t) * outer[0] + t * r) * c, ((1 - t) * outer[1] + t * r) * s, (1 - t) * COLLAR_TOP_MM + t * top])
    around = np.array([-((1 - t) * outer[0] + t * r) * s, ((1 - t) * outer[1] + t * r) * c, 0.0])
    along = np.array([(r - outer[0]) * c, (r - outer[1]) * s, DOME_MM])
    normal = np.cross(around, along)
    return point, normal / np.linalg.norm(normal) * np.sign(normal[2])


def _vent_holes(outer: np.ndarray, vents: Vents) -> list[tuple[np.ndarray, np.ndarray]]:
    """(outer centre, direction) of each vent hole: rows VENT_ROWS across the dome's upper side, the
    holes VENT_PITCH diameters apart, centred on the head's up direction, filled from the collar up."""
    holes, left = [], vents.count
    for t in VENT_ROWS:
        radius = (1 - t) * outer.min() + t * SHOULDER_MM[0] / 2
        step = np.degrees(VENT_PITCH * vents.diameter_mm / radius)
        k = min(left, int(2 * VENT_ARC_DEG // step) + 1)
        holes += [_dome_point(outer, 90.0 + step * (i - (k - 1) / 2), t) for i in range(k)]
        left -= k
    if left:
        raise ValueError(f"{left} vent holes do not fit on the frame's dome")
    return holes


def _valve(outer: np.ndarray) -> np.ndarray:
    """(2, 3): the anti-asphyxia valve's outer centre and direction on the dome's lower side, the lowest
    of VALVE_AT (from the collar, 0, to the shoulder, 1) whose seat stands SEAT_CLEAR_MM above the
    collar's top (a seat touching the collar would close a loop of solid round the air)."""
    for t in VALVE_AT:
        valve = np.stack(_dome_point(outer, -90.0, t))
        if _seat(*valve).bounding_box()[2] > COLLAR_TOP_MM + SEAT_CLEAR_MM:
            break
    return valve


def _drill(point: np.ndarray, direction: np.ndarray, diameter: float) -> m3.Manifold:
    """A round hole of `diameter` mm through the dome's wall at `point` on its outside, along `direction`."""
    return _cylinder(point + 0.8 * direction, -direction, WALL_MM + 2.5, diameter)


def _seat(point: np.ndarray, direction: np.ndarray) -> m3.Manifold:
    """The valve flap's seat: a ring standing VALVE_MM[2] inside the wall around the opening."""
    return _cylinder(point - 0.5 * direction, -direction, WALL_MM - 0.5 + VALVE_MM[2], VALVE_MM[1])


def _cylinder(start: np.ndarray, direction: np.ndarray, length: float, diameter: float) -> m3.Manifold:
    """A cylinder of `length` and `diameter` mm from `start` along the unit `direction`."""
    z = np.asarray(direction, dtype=float)
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    place = np.column_stack([x, np.cross(z, x), z, start])
    return m3.Manifold.cylinder(length, diameter / 2, diameter / 2, 32).transform(place)


def _collar_radius(outer: np.ndarray, angle_deg: float) -> float:
    """The collar's radius (mm) at `angle_deg` around the axis."""
    theta = np.radians(angle_deg)
    return float(outer[0] * outer[1] / np.hypot(outer[1] * np.cos(theta), outer[0] * np.sin(theta)))


def _anchor(outer: np.ndarray, angle_deg: float) -> tuple[m3.Manifold, m3.Manifold]:
    """(tab, slot) of a headgear anchor at `angle_deg` around the axis: a plate level with the collar's
    top reaching TAB_MM[0] beyond it, with a strap slot through it."""
    reach, width, thick = TAB_MM
    slot_w, slot_l, slot_at = SLOT_MM
    r = _collar_radius(outer, angle_deg)
    tab = m3.Manifold.cube([reach + 4.0, width, thick]).translate([r - 4.0, -width / 2, COLLAR_TOP_MM - thick])
    slot = m3.Manifold.cube([slot_w, slot_l, thick + 2.0]).translate([r + slot_at, -slot_l / 2, COLLAR_TOP_MM - thick - 1.0])
    return tab.rotate([0.0, 0.0, angle_deg]), slot.rotate([0.0, 0.0, angle_deg])


def _slot_centre(outer: np.ndarray, angle_deg: float) -> np.ndarray:
    """(3,) the centre of the strap slot at `angle_deg`, in the mask's frame."""
    r = _collar_radius(outer, angle_deg) + SLOT_MM[2] + SLOT_MM[0] / 2
    theta = np.radians(angle_deg)
    return np.array([r * np.cos(theta), r * np.sin(theta), COLLAR_TOP_MM - TAB_MM[2] / 2])
