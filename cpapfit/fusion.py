"""Many depth frames of one subject fused into one mesh (KinectFusion's way, with Open3D).

Each frame is tracked frame to model: point-to-plane ICP, coarse to fine, of its points against the
points of the frames tracked last, starting from the last pose moved on by the last motion (and,
should that fail, from the same shifted to keep the subject's centre where it was); a
tracked frame is integrated, depth and colour, into a TSDF volume, whose zero level is the mesh
(marching cubes). Only the head is integrated: the depth within a ball round the point the cameras
look at (where their optical axes meet), and, of a long sweep, a subset of the tracked frames
spread evenly along it. Frames without depth, or that ICP cannot put on the model (another scene, a
blurred or torn frame), are dropped with a note; a sweep with too few tracked frames is refused.
Open3D is imported only here, when a sweep is fused (it takes seconds to import).
"""

import os
from dataclasses import dataclass

import numpy as np
import trimesh

from .errors import InputError
from .frozen import freeze_arrays
from .scan import Intrinsics
from .thresholds import SWEEP_MAX_RMS_MM, SWEEP_MIN_DEPTH_FRACTION, SWEEP_MIN_FRAMES, SWEEP_MIN_OVERLAP

POSE_DECIMALS = 6  # poses rounded so (rad, mm): ICP's threads sum in any order, rounded the same input fuses to the same bytes


@dataclass(frozen=True)
class Frame:
    """One depth frame of a sweep. name: its label (the capture folder's name).
    depth: (H, W) float64 mm, NaN where invalid. image: (H, W, 3) uint8 colour registered to it, or None."""

    name: str
    depth: np.ndarray
    image: np.ndarray | None
    intrinsics: Intrinsics

    def __post_init__(self):
        freeze_arrays(self)


@dataclass(frozen=True)
class FusionParams:
    """voxel_mm: the TSDF's voxel; truncation_mm: its truncation distance. subject_mm: depth kept
    behind each frame's nearest surface (2nd percentile), the rest (the room behind) dropped.
    icp_voxel_mm: the point spacing of the model; track_spacing_mm: of a frame put on it (at the
    least); icp_radii_mm: the ICP's pairing distances, coarse to fine; model_frames: how many
    frames tracked last make the model a frame is tracked against.
    min_depth_fraction: a frame with fewer valid pixels than this fraction of the sweep's median
    has no depth. min_overlap: the fraction of a frame's points the model must pair within the
    finest radius (ICP fitness), max_rms_mm: their RMS distance; below or above, the frame is not
    tracked. min_frames: fewer tracked frames and the sweep is refused. head_mm: the radius of the
    ball integrated, round the point the tracked cameras look at; max_integrated: the tracked
    frames integrated at most (evenly spread)."""

    voxel_mm: float = 0.8
    truncation_mm: float = 4.0
    subject_mm: float = 300.0
    icp_voxel_mm: float = 3.0
    track_spacing_mm: float = 4.0
    icp_radii_mm: tuple[float, ...] = (20.0, 6.0, 2.0)
    icp_iterations: int = 15
    model_frames: int = 3
    min_depth_fraction: float = SWEEP_MIN_DEPTH_FRACTION
    min_overlap: float = SWEEP_MIN_OVERLAP
    max_rms_mm: float = SWEEP_MAX_RMS_MM
    min_frames: int = SWEEP_MIN_FRAMES
    head_mm: float = 170.0
    max_integrated: int = 30


@dataclass(frozen=True)
class Fused:
    """A fused sweep. vertices: (N, 3) float64 mm in the first tracked frame's camera frame (x right,
    y down, z forward); faces: (M, 3) int64; colors: (N, 3) uint8. kept: the names of the frames
    fused, poses: (K, 4, 4) float64 their camera-to-model transforms (mm); dropped: (name, why) of the others."""

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    kept: tuple[str, ...]
    poses: np.ndarray
    dropped: tuple[tuple[str, str], ...]

    def __post_init__(self):
        freeze_arrays(self)

    def note(self) -> str:
        """In words: how many frames were fused, and which were dropped and why."""
        total = len(self.kept) + len(self.dropped)
        dropped = "; ".join(f"frame {name} dropped: {why}" for name, why in self.dropped)
        return f"fused {len(self.kept)} of {total} frames" + (f" ({dropped})" if dropped else "")


def fuse(frames: tuple[Frame, ...], params: FusionParams = FusionParams()) -> Fused:
    """The frames (in order, one camera) fused into one mesh; InputError when too few can be tracked."""
    dropped = dict(_without_depth(frames, params))
    usable = [f for f in frames if f.name not in dropped]
    poses, lost = {}, {}
    for anchor in range(min(len(usable), 3)):  # the first frame may itself be the odd one out: try the next
        poses, lost = _track(usable[anchor:], params)
        if len(poses) >= max(params.min_frames, len(usable) - anchor) / 2:
            lost |= {f.name: "not tracked: before the first frame that could be" for f in usable[:anchor]}
            break
    if len(poses) < params.min_frames:
        raise InputError(
            f"the sweep cannot be tracked: only {len(poses)} of {len(frames)} frames could be put together "
            f"(at least {params.min_frames} are needed); is it one subject filmed in one continuous sweep?"
        )
    dropped |= lost
    kept = [f for f in frames if f.name in poses]
    vertices, faces, colors = _integrate(_spread(kept, params.max_integrated), poses, params)
    return Fused(vertices, faces, colors, tuple(f.name for f in kept), np.array([poses[f.name] for f in kept]),
                 tuple((f.name, dropped[f.name]) for f in frames if f.name in dropped))


def _open3d():
    """Open3D, imported on first use; its OpenMP threads wait passively (spinning, they slow a
    busy machine's other work and their own many times over)."""
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import open3d

    return open3d


def _without_depth(frames: tuple[Frame, ...], params: FusionParams):
    """(name, why) of the frames with too little valid depth against the sweep's median."""
    counts = np.array([np.isfinite(f.depth).sum() for f in frames])
    floor = params.min_depth_fraction * np.median(counts)
    for f, n in zip(frames, counts):
        if n < floor or n == 0:
            yield f.name, f"no depth ({int(n)} valid pixels, the sweep's median {int(np.median(counts))})"


def _subject_depth(frame: Frame, params: FusionParams) -> np.ndarray:
    """(H, W) float32 mm depth of the subject (0 elsewhere): the room behind it dropped."""
    depth = np.nan_to_num(frame.depth, nan=0.0)
    near = np.percentile(depth[depth > 0], 2.0)
    return np.where(depth <= near + params.subject_mm, depth, 0.0).astype(np.float32)


def _in_ball(depth: np.ndarray, intr: Intrinsics, pose: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """(H, W) float32 mm `depth` with 0 where its point (camera-to-model `pose`) lies over `radius` mm from `centre`."""
    v, u = np.indices(depth.shape)
    camera = np.stack([(u - intr.cx) / intr.fx * depth, (v - intr.cy) / intr.fy * depth, depth], axis=-1)
    near = np.linalg.norm(camera @ pose[:3, :3].T + pose[:3, 3] - centre, axis=-1) <= radius
    return np.where(near, depth, 0.0).astype(np.float32)


def _rgbd(frame: Frame, params: FusionParams, depth: np.ndarray | None = None):
    """The frame as an Open3D RGBDImage (its subject's depth, or `depth`: (H, W) float32 mm; a grey
    image where it has no colour)."""
    o3d = _open3d()
    image = frame.image if frame.image is not None else np.full((*frame.depth.shape, 3), 128, np.uint8)
    depth = _subject_depth(frame, params) if depth is None else depth
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(np.ascontiguousarray(image)), o3d.geometry.Image(depth),
        depth_scale=1.0, depth_trunc=np.inf, convert_rgb_to_intensity=False,
    )


def _camera(intr: Intrinsics):
    o3d = _open3d()
    return o3d.camera.PinholeCameraIntrinsic(intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy)


def _points(frame: Frame, params: FusionParams):
    """The frame's subject as an Open3D point cloud (mm, camera frame), icp_voxel_mm apart, with normals."""
    o3d = _open3d()
    cloud = o3d.geometry.PointCloud.create_from_rgbd_image(_rgbd(frame, params), _camera(frame.intrinsics))
    cloud = cloud.voxel_down_sample(params.icp_voxel_mm)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3.0 * params.icp_voxel_mm, max_nn=30))
    cloud.orient_normals_towards_camera_location()
    return cloud


def _track(frames: list[Frame], params: FusionParams) -> tuple[dict, dict]:
    """({name: (4, 4) camera-to-model pose} of the frames tracked, {name: why} of those not), the
    first frame's camera frame being the model's."""
    o3d = _open3d()
    poses, lost, recent = {}, {}, []
    pose, motion = np.eye(4), np.eye(4)
    for frame in frames:
        cloud = _points(frame, params)
        if recent:
            model = o3d.geometry.PointCloud()
            for past in recent[-params.model_frames:]:
                model += past
            model = model.voxel_down_sample(params.icp_voxel_mm)
            fit = _register(cloud, model, _guesses(pose, motion, cloud.get_center(), recent[-1].get_center()), params)
            if not _tracked(fit, params):
                lost[frame.name] = (f"not tracked ({100 * fit.fitness:.0f} % of it meets the model within "
                                    f"{params.icp_radii_mm[-1]:g} mm, RMS {fit.inlier_rmse:.2f} mm)")
                continue
            guess = np.round(fit.transformation, POSE_DECIMALS)
            motion, pose = np.linalg.inv(pose) @ guess, guess
        poses[frame.name] = pose
        recent.append(o3d.geometry.PointCloud(cloud).transform(pose))
    return poses, lost


def _guesses(pose: np.ndarray, motion: np.ndarray, centre: np.ndarray, last_centre: np.ndarray):
    """(4, 4) poses to start ICP from, in turn: the last pose moved on by the last motion, then the
    same shifted so that the frame's subject centre (`centre`, its camera frame, mm) lands on the
    last frame's (`last_centre`, the model's): the camera moves round a subject that stays put."""
    guess = pose @ motion
    shifted = guess.copy()
    shifted[:3, 3] += last_centre - guess[:3, :3] @ centre - guess[:3, 3]
    return guess, shifted


def _register(cloud, model, guesses, params: FusionParams):
    """Open3D's ICP result of the frame's `cloud` on the `model`: point to plane, coarse to fine
    (icp_radii_mm, the frame thinned to half each radius and at least track_spacing_mm), from each
    guess in turn until one is tracked; else the one that fits best."""
    reg = _open3d().pipelines.registration
    best = None
    for guess in guesses:
        for radius in params.icp_radii_mm:
            spacing = max(radius / 2.0, params.track_spacing_mm)
            source = cloud.voxel_down_sample(spacing) if spacing > params.icp_voxel_mm else cloud
            fit = reg.registration_icp(source, model, radius, guess, reg.TransformationEstimationPointToPlane(),
                                       reg.ICPConvergenceCriteria(1e-5, 1e-5, params.icp_iterations))
            guess = fit.transformation
        if _tracked(fit, params):
            return fit
        best = fit if best is None or fit.fitness > best.fitness else best
    return best


def _tracked(fit, params: FusionParams) -> bool:
    """True when the ICP result puts the frame on the model (min_overlap, max_rms_mm)."""
    return fit.fitness >= params.min_overlap and fit.inlier_rmse <= params.max_rms_mm


def _spread(frames: list[Frame], most: int) -> list[Frame]:
    """At most `most` of the frames, spread evenly from the first to the last."""
    if len(frames) <= most:
        return frames
    return [frames[k] for k in np.unique(np.round(np.linspace(0, len(frames) - 1, most)).astype(int))]


def _look_at(poses: np.ndarray) -> np.ndarray | None:
    """(3,) mm: the point nearest the optical axes of the (K, 4, 4) camera-to-model poses (least
    squares), or None when the axes are too near parallel (a sweep turning less than about 20 degrees) to meet."""
    centres, axes = poses[:, :3, 3], poses[:, :3, 2]
    across = np.eye(3) - axes[:, :, None] * axes[:, None, :]  # (K, 3, 3): each axis's perpendicular projector
    normal = across.mean(axis=0)
    if np.linalg.eigvalsh(normal)[0] < 0.01:
        return None
    return np.linalg.solve(normal, np.einsum("kij,kj->i", across, centres) / len(centres))


def _integrate(frames: list[Frame], poses: dict, params: FusionParams):
    """((N, 3) mm vertices, (M, 3) faces, (N, 3) uint8 colours): the TSDF of the frames (camera-to-model
    `poses` by name), within head_mm of where they look, at its zero level, its largest connected piece."""
    o3d = _open3d()
    integration = o3d.pipelines.integration
    volume = integration.ScalableTSDFVolume(voxel_length=params.voxel_mm, sdf_trunc=params.truncation_mm,
                                            color_type=integration.TSDFVolumeColorType.RGB8)
    centre = _look_at(np.array([poses[f.name] for f in frames]))
    for frame in frames:
        pose, depth = poses[frame.name], _subject_depth(frame, params)
        if centre is not None:
            depth = _in_ball(depth, frame.intrinsics, pose, centre, params.head_mm)
        volume.integrate(_rgbd(frame, params, depth), _camera(frame.intrinsics), np.linalg.inv(pose))
    mesh = volume.extract_triangle_mesh()
    vertices, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)
    colors = np.round(255.0 * np.asarray(mesh.vertex_colors)).astype(np.uint8)
    return _largest_piece(vertices, faces, colors)


def _largest_piece(vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray):
    """The mesh's largest edge-connected piece (most triangles), its unused vertices removed."""
    labels = trimesh.graph.connected_component_labels(trimesh.graph.face_adjacency(faces), node_count=len(faces))
    faces = faces[labels == np.argmax(np.bincount(labels))]
    used = np.unique(faces)
    index = np.full(len(vertices), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return vertices[used], index[faces], colors[used]
