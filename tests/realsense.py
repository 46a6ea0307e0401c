"""RealSense recordings (.bag) made at test time: a synthetic sweep's frames played into a
pyrealsense2 software device (a depth and a colour sensor of one camera) and recorded."""

from pathlib import Path

import numpy as np
import pyrealsense2 as rs

FPS = 30


def write_bag(sweep, path: Path, depth: bool = True, color: bool = True) -> Path:
    """Record the sweep's (Phantoms) depth (Z16, in the sensor's depth units) and colour (RGB8)
    frames, in order, 1/FPS s apart, at `path`; the depth or the colour stream left out on request."""
    intr, units = sweep[0].intrinsics, 1.0 / sweep[0].sensor.depth_scale
    device = rs.software_device()
    device.register_info(rs.camera_info.name, "cpapfit synthetic sweep")
    device.register_info(rs.camera_info.serial_number, "0")  # librealsense's playback needs one
    streams = []
    if depth:
        sensor = device.add_sensor("Depth")
        sensor.add_read_only_option(rs.option.depth_units, units)
        streams.append((sensor, _profile(sensor, rs.stream.depth, rs.format.z16, 2, intr), lambda ph: ph.depth_raw))
    if color:
        sensor = device.add_sensor("Color")
        streams.append((sensor, _profile(sensor, rs.stream.color, rs.format.rgb8, 3, intr), lambda ph: ph.image))
    if depth and color:
        identity = rs.extrinsics()
        identity.rotation, identity.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
        streams[0][1].register_extrinsics_to(streams[1][1], identity)
    recorder = rs.recorder(str(path), device)
    for sensor, profile, _ in streams:
        sensor.open(profile)
        sensor.start(lambda frame: None)
    for k, ph in enumerate(sweep):
        for sensor, profile, pixels in streams:
            sensor.on_video_frame(_frame(pixels(ph), k, profile))
    for sensor, _, _ in streams:
        sensor.stop()
        sensor.close()
    del recorder  # the file is complete once the recorder is gone
    return path


def _profile(sensor, kind, fmt, bpp: int, intr):
    stream = rs.video_stream()
    stream.type, stream.index, stream.uid, stream.fmt, stream.bpp, stream.fps = kind, 0, int(kind), fmt, bpp, FPS
    stream.width, stream.height = intr.width, intr.height
    k = rs.intrinsics()
    k.width, k.height, k.fx, k.fy, k.ppx, k.ppy = intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy
    k.model, k.coeffs = rs.distortion.none, [0.0] * 5
    stream.intrinsics = k
    return sensor.add_video_stream(stream, True)  # a default stream: playback streams it


def _frame(pixels: np.ndarray, k: int, profile):
    frame = rs.software_video_frame()
    frame.pixels = np.ascontiguousarray(pixels)
    frame.bpp = pixels.itemsize * (pixels.shape[2] if pixels.ndim == 3 else 1)
    frame.stride = frame.bpp * pixels.shape[1]
    frame.timestamp, frame.frame_number = 1000.0 * k / FPS, k + 1
    frame.domain, frame.profile = rs.timestamp_domain.hardware_clock, profile.as_video_stream_profile()
    return frame
