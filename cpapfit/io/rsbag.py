"""Intel RealSense recordings (.bag) read as a sweep: the depth frames in the order recorded, each
with the colour frame recorded nearest it registered to it (`rgbd.color_to_depth`), the depth
stream's intrinsics and depth scale; fused as a sweep folder is (`sweep.fused_scan`).

pyrealsense2 plays the file back frame by frame, not in real time, so every frame is read, in
order, the same on every run (Open3D's RSBagReader plays in real time: on a busy machine it can
lose a frame). It is imported only when a .bag is read.
"""

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..frozen import freeze_arrays
from ..rgbd import color_to_depth
from ..scan import Intrinsics
from ..thresholds import DEPTH_RANGE_MM, SWEEP_MIN_FRAMES
from .capture import depth_mm

BAG_SUFFIX = ".bag"
COLOR_CHANNELS = {"rgb8": [0, 1, 2], "bgr8": [2, 1, 0], "rgba8": [0, 1, 2], "bgra8": [2, 1, 0]}  # R, G, B of each colour format read
PLAYBACK_S = 60.0  # a playback not over after this (plus twice the recording's length, s) is refused
QUEUE_FRAMES = 64  # frames played but not yet read at most


@dataclass(frozen=True)
class Recording:
    """A recording's depth stream: depth (K, H, W) uint16 raw, depth_ms (K,) float64 timestamps (ms),
    intrinsics, depth_scale (units per metre), fps; and its colour stream, or None: color (L, h, w, 3)
    uint8 RGB, color_ms (L,) ms, color_intrinsics, depth_to_color (4, 4) float64 (mm)."""

    depth: np.ndarray
    depth_ms: np.ndarray
    intrinsics: Intrinsics
    depth_scale: float
    fps: float
    color: np.ndarray | None
    color_ms: np.ndarray | None
    color_intrinsics: Intrinsics | None
    depth_to_color: np.ndarray | None

    def __post_init__(self):
        freeze_arrays(self)


def is_bag(path: Path) -> bool:
    """True when `path` names a RealSense recording (.bag)."""
    return Path(path).suffix.lower() == BAG_SUFFIX


def read_bag(path: Path, depth_range_mm: tuple[float, float] = DEPTH_RANGE_MM):
    """The recording's frames (`fusion.Frame`, named 000, 001, ... in the order recorded) and
    {its depth_scale}, as `sweep.read_frames` gives a sweep folder's."""
    recording = play(Path(path))
    return bag_frames(recording, depth_range_mm), {recording.depth_scale}


def bag_frames(recording: Recording, depth_range_mm: tuple[float, float] = DEPTH_RANGE_MM):
    """The recording's depth frames (`fusion.Frame`: mm, NaN where invalid or outside
    `depth_range_mm`), each with the colour frame nearest in time registered to it, if any."""
    from ..fusion import Frame

    frames = []
    for k, (raw, ms) in enumerate(zip(recording.depth, recording.depth_ms)):
        depth, color = depth_mm(raw, recording.depth_scale, depth_range_mm), _nearest_color(recording, ms)
        image = None if color is None else color_to_depth(
            depth, recording.intrinsics, color, recording.color_intrinsics, recording.depth_to_color)
        frames.append(Frame(f"{k:03d}", depth, image, recording.intrinsics))
    return tuple(frames)


def _nearest_color(recording: Recording, ms: float) -> np.ndarray | None:
    """(h, w, 3) uint8: the colour frame recorded nearest `ms`, if within half a depth frame's period."""
    if recording.color is None or not len(recording.color):
        return None
    k = int(np.argmin(np.abs(recording.color_ms - ms)))
    return recording.color[k] if abs(recording.color_ms[k] - ms) <= 500.0 / recording.fps else None


def play(path: Path) -> Recording:
    """Every frame of the recording's first depth stream (Z16) and first colour stream (RGB8, BGR8,
    RGBA8 or BGRA8; other colour formats are not read); InputError for a file that is no readable
    recording, has no depth stream or fewer than SWEEP_MIN_FRAMES depth frames."""
    import pyrealsense2 as rs

    if not path.is_file():
        raise InputError(f"{path}: no such file")
    try:
        device = rs.context().load_device(str(path))
        depth = _stream(device, rs.stream.depth, ("z16",))
        color = _stream(device, rs.stream.color, COLOR_CHANNELS)
        if depth is None:
            raise InputError(f"{path}: the recording has no depth stream (Z16); record the depth stream too")
        limit = PLAYBACK_S + 2.0 * device.as_playback().get_duration().total_seconds()
        depth_frames = _played(path, rs.stream.depth, ("z16",), limit)
        color_frames = None if color is None else _played(path, rs.stream.color, COLOR_CHANNELS, limit)
        recording = _recording(depth, depth_frames, color, color_frames)
    except RuntimeError as exc:
        raise InputError(f"{path}: not a readable RealSense recording ({exc})") from None
    if len(recording.depth) < SWEEP_MIN_FRAMES:
        raise InputError(f"{path}: {len(recording.depth)} depth frames recorded; a sweep needs at least {SWEEP_MIN_FRAMES}")
    return recording


def _stream(device, kind, formats):
    """(sensor, profile) of the device's first stream of `kind` in one of `formats`, or None."""
    return next(((sensor, profile) for sensor in device.query_sensors() for profile in sensor.get_stream_profiles()
                 if profile.stream_type() == kind and profile.format().name in formats), None)


def _played(path: Path, kind, formats, limit_s: float) -> list:
    """[(timestamp ms, array copy)]: every frame of the recording's first stream of `kind` in one of
    `formats`, in order. Each stream is played on its own (a sensor started after the playback has
    begun misses its first frames), not in real time (none dropped), into a queue that is read
    here: no Python callback, which librealsense could call while its objects are released."""
    import pyrealsense2 as rs

    device = rs.context().load_device(str(path))
    playback = device.as_playback()
    playback.set_real_time(False)
    sensor, profile = _stream(device, kind, formats)
    queue, frames, started, ended = rs.frame_queue(QUEUE_FRAMES, True), [], False, False
    deadline = time.monotonic() + limit_s
    sensor.open(profile)
    sensor.start(queue)
    while not ended and time.monotonic() < deadline:
        frame = queue.poll_for_frame()
        if frame:
            started = True
            frames.append(_copied(frame))
            continue
        status = playback.current_status()  # stopped until the playback has begun, and again at its end
        if started and status == rs.playback_status.stopped:
            while frame := queue.poll_for_frame():
                frames.append(_copied(frame))
            ended = True
        started |= status == rs.playback_status.playing
        time.sleep(0.001)
    sensor.stop()
    sensor.close()
    if not ended:
        raise InputError(f"{path}: the recording did not play to its end in {limit_s:.0f} s; is the file complete?")
    return frames


def _copied(frame) -> tuple[float, np.ndarray]:
    """(timestamp ms, a copy of its pixels) of a played frame."""
    return frame.get_timestamp(), np.asanyarray(frame.get_data()).copy()


def _recording(depth, depth_frames: list, color, color_frames: list | None) -> Recording:
    """The played frames ([(ms, array)]) of the depth and colour streams ((sensor, profile); colour
    None when not recorded) as a `Recording`."""
    sensor, profile = depth
    depth_ms, raw = _stacked(depth_frames, np.uint16)
    units = sensor.as_depth_sensor().get_depth_scale()  # metres per depth unit, float32
    return Recording(depth=raw, depth_ms=depth_ms, intrinsics=_intrinsics(profile), depth_scale=float(f"{1.0 / units:.6g}"),
                     fps=float(profile.fps()), **_color(profile, color, color_frames))


def _color(depth_profile, color, frames: list | None) -> dict:
    """The colour fields of a `Recording` (None without a colour stream)."""
    if color is None:
        return dict(color=None, color_ms=None, color_intrinsics=None, depth_to_color=None)
    profile = color[1]
    color_ms, images = _stacked(frames, np.uint8)
    extrinsics = depth_profile.get_extrinsics_to(profile)
    to_color = np.eye(4)
    to_color[:3, :3] = np.reshape(extrinsics.rotation, (3, 3)).T  # librealsense stores it column-major
    to_color[:3, 3] = 1000.0 * np.asarray(extrinsics.translation)  # m -> mm
    rgb = images[..., COLOR_CHANNELS[profile.format().name]] if len(images) else images
    return dict(color=rgb, color_ms=color_ms, color_intrinsics=_intrinsics(profile), depth_to_color=to_color)


def _stacked(frames: list, dtype) -> tuple[np.ndarray, np.ndarray]:
    """((K,) float64 timestamps ms, (K, ...) `dtype` arrays) of [(timestamp, array)]."""
    times = np.array([ms for ms, _ in frames], dtype=np.float64)
    return times, np.array([array for _, array in frames], dtype=dtype)


def _intrinsics(profile) -> Intrinsics:
    """The stream's pinhole intrinsics (its distortion coefficients are not applied)."""
    k = profile.as_video_stream_profile().get_intrinsics()
    return Intrinsics(width=int(k.width), height=int(k.height), fx=float(k.fx), fy=float(k.fy), cx=float(k.ppx), cy=float(k.ppy))
