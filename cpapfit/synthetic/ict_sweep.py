"""Synthetic sweeps: one ICT subject seen by the virtual depth camera (`camera.py`) from a path
round the face (yaw from -yaw_deg to +yaw_deg, a hand's jitter in pitch, roll and framing), each
frame with its own sensor noise. Every frame's truth is the face in that frame's camera frame, so
a fused sweep (in its first frame's camera frame) is measured against frame 0's truth.
"""

import numpy as np

from ..render import raycast
from .camera import (
    Phantom, PoseRange, SensorModel, camera_image, place_in_view, random_intrinsics, random_light, sensor_depth,
    to_camera,
)
from .skin import skin_tone
from ..template import load_template
from .ict_phantom import ict_albedo, scene
from ..ict import random_subject, template_truth

SWEEP_YAW_DEG = 35.0
JITTER = PoseRange(yaw_deg=0.0, pitch_deg=3.0, roll_deg=2.0, off_centre=0.15)  # a hand-held camera's wobble
DISTANCE_MM = (400.0, 550.0)


def make_ict_sweep(seed: int, frames: int, yaw_deg: float = SWEEP_YAW_DEG, sensor: SensorModel = SensorModel(),
                   mouth_open_mm: float = 0.0) -> tuple[Phantom, ...]:
    """`frames` captures (Phantoms, in order) of the ICT subject of `seed` (the face of
    `make_ict_phantom(seed)`), yaw -yaw_deg to +yaw_deg (degrees) at one distance; same seed, same arrays."""
    rng = np.random.default_rng(seed)
    template = load_template()
    face, identity = random_subject(rng, mouth_open_mm)
    truth = template_truth(face)
    intrinsics = random_intrinsics(rng)
    vertices, triangles = scene(face)
    light, background = random_light(rng)
    albedo = ict_albedo(skin_tone(rng))
    distance = float(rng.uniform(*DISTANCE_MM))
    sweep = []
    for k, yaw in enumerate(np.linspace(-yaw_deg, yaw_deg, frames)):
        frame_rng = np.random.default_rng([seed, k])
        surface, placed = place_in_view(truth, template, intrinsics, frame_rng, float(yaw), distance, JITTER)
        seen = to_camera(vertices, placed)
        hits = raycast(seen, triangles, intrinsics)
        image = camera_image(hits, seen, triangles, albedo, light, background, frame_rng)
        depth_raw = sensor_depth(hits, intrinsics, sensor, frame_rng)
        sweep.append(Phantom(seed, image, depth_raw, intrinsics, sensor, surface, template.faces, identity, placed))
    return tuple(sweep)
