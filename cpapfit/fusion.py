"""Many depth frames of one subject fused into one mesh (KinectFusion's way, with Open3D).

Each frame is tracked frame to model: point-to-plane ICP, coarse to fine, of its points against the
points of the frames tracked last, starting from the last pose moved on by the last motion; a
tracked frame is integrated, depth and colour, into a TSDF volume, whose zero level is the mesh
(marching cubes). Frames without depth, or that ICP cannot put on the model (another scene, a
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
    icp_voxel_mm: the point spacing tracked; icp_radii_mm: the ICP's pairing distances, coarse to
    fine; model_frames: how many frames tracked last make the model a frame is tracked against.
    min_depth_fraction: a frame with fewer valid pixels than this fraction of the sweep's median
    has no depth. min_overlap: the fraction of a frame's points the model must pair within the
    finest radius (ICP fitness), max_rms_mm: their RMS distance; below or above, the frame is not
    tracked. min_frames: fewer tracked frames and the sweep is refused."""

    voxel_mm: float = 0.8
    truncation_mm: float = 4.0
    subject_mm: float = 300.0
    icp_voxel_mm: float = 2.0
    icp_radii_mm: tuple[float, ...] = (10.0, 4.0, 2.0)
    icp_iterations: int = 15
    model_frames: int = 6
    min_depth_fraction: float = 0.3
    min_overlap: float = 0.6
    max_rms_mm: float = 1.5
    min_frames: int = 3


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
    vertices, faces, colors = _integrate(kept, [poses[f.name] for f in kept], params)
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


def _rgbd(frame: Frame, params: FusionParams):
    """The frame as an Open3D RGBDImage (depth mm; a grey image where it has no colour)."""
    o3d = _open3d()
    image = frame.image if frame.image is not None else np.full((*frame.depth.shape, 3), 128, np.uint8)
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(np.ascontiguousarray(image)), o3d.geometry.Image(_subject_depth(frame, params)),
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
    reg = o3d.pipelines.registration
    poses, lost, recent = {}, {}, []
    pose, motion = np.eye(4), np.eye(4)
    for frame in frames:
        cloud = _points(frame, params)
        if recent:
            model = o3d.geometry.PointCloud()
            for past in recent[-params.model_frames:]:
                model += past
            model = model.voxel_down_sample(params.icp_voxel_mm)
            guess = pose @ motion
            for radius in params.icp_radii_mm:
                source = cloud.voxel_down_sample(radius / 2.0) if radius > 2.0 * params.icp_voxel_mm else cloud
                fit = reg.registration_icp(source, model, radius, guess, reg.TransformationEstimationPointToPlane(),
                                           reg.ICPConvergenceCriteria(1e-5, 1e-5, params.icp_iterations))
                guess = fit.transformation
            if fit.fitness < params.min_overlap or fit.inlier_rmse > params.max_rms_mm:
                lost[frame.name] = (f"not tracked ({100 * fit.fitness:.0f} % of it meets the model within "
                                    f"{params.icp_radii_mm[-1]:g} mm, RMS {fit.inlier_rmse:.2f} mm)")
                continue
            guess = np.round(guess, POSE_DECIMALS)
            motion, pose = np.linalg.inv(pose) @ guess, guess
        poses[frame.name] = pose
        recent.append(o3d.geometry.PointCloud(cloud).transform(pose))
    return poses, lost


def _integrate(frames: list[Frame], poses: list[np.ndarray], params: FusionParams):
    """((N, 3) mm vertices, (M, 3) faces, (N, 3) uint8 colours): the frames' TSDF at its zero level,
    its largest connected piece."""
    o3d = _open3d()
    integration = o3d.pipelines.integration
    volume = integration.ScalableTSDFVolume(voxel_length=params.voxel_mm, sdf_trunc=params.truncation_mm,
                                            color_type=integration.TSDFVolumeColorType.RGB8)
    for frame, pose in zip(frames, poses):
        volume.integrate(_rgbd(frame, params), _camera(frame.intrinsics), np.linalg.inv(pose))
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
