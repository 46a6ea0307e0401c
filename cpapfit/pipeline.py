"""The stages strung together. Each stage is a pure function; this module only sequences them."""

from dataclasses import dataclass
from typing import Callable

from .align.check import FaceCheck
from .align.initial import initial_alignment
from .align.nonrigid import NonrigidParams, Registration, register
from .contact import Contact, transfer_contact
from .cushion.nurbs import Cushion, CushionParams, design_cushion
from .cushion.solid import cushion_solid
from .cushion.generic import place, template_cushion
from .evaluate.gap import RimGap, rim_gap, seat
from .export import check_solid, check_closed
from .mould import mould
from .quality import assess, require_quality
from .align.similarity import Similarity
from .landmarks.types import Landmarks
from .scan import Scan
from .template import load_template

# (stage, issue that builds it); order is the pipeline's.
STAGES = (
    ("scan", None), ("template", None), ("landmarks", 3), ("similarity", 3), ("nonrigid", 4),
    ("contact", 5), ("cushion", 5), ("export", 5), ("evaluate", 6), ("report", 7),
)
BUILT = {"scan", "template", "landmarks", "similarity", "nonrigid", "contact", "cushion", "export"}
NOT_BUILT_PARTS = ("pressure and leak (issue 6)",)


@dataclass(frozen=True)
class StageStatus:
    """Whether a pipeline stage is built, and what it did on the last run (one line)."""

    name: str
    built: bool
    summary: str


def missing_stages() -> list[str]:
    """Names of the stages not built yet, in pipeline order."""
    return [name for name, _ in STAGES if name not in BUILT]


def stage_table(summaries: dict[str, str]) -> list[StageStatus]:
    """Every stage in order with its summary, or "not built yet (issue N)"."""
    return [
        StageStatus(name, name in BUILT, summaries.get(name, "") if name in BUILT else f"not built yet (issue {issue})")
        for name, issue in STAGES
    ]


@dataclass(frozen=True)
class Alignment:
    """The template placed on a scan: landmarks, similarity (template -> scan, mm) and the face check."""

    landmarks: Landmarks
    similarity: Similarity
    check: FaceCheck


def align(scan: Scan, user_landmarks: Landmarks | None = None) -> Alignment:
    """Stages landmarks and similarity on a scan."""
    return Alignment(*initial_alignment(scan, load_template(), user_landmarks))


def register_template(scan: Scan, alignment: Alignment, params: NonrigidParams = NonrigidParams()) -> Registration:
    """Stage nonrigid: the similarity-aligned template warped onto the scan."""
    template = load_template()
    return register(alignment.similarity.apply(template.vertices), template.faces, scan, alignment.landmarks, params)


@dataclass(frozen=True)
class Design:
    """A custom cushion for a scan: every stage's result, the printable solid and its checks."""

    alignment: Alignment
    registration: Registration
    contact: Contact
    cushion: Cushion
    solid: object  # trimesh.Trimesh, checked
    checks: dict
    rim: RimGap
    seated: dict  # {"custom": Seating, "generic": Seating}: both cushions pushed onto the face
    mould_parts: dict  # {"mould_left" | "mould_right" | "mould_core": trimesh.Trimesh}, checked


def _silent(stage: str) -> None:
    """The default stage callback: nothing."""


def design(
    scan: Scan, mask: str, user_landmarks: Landmarks | None = None, params: CushionParams = CushionParams(),
    on_stage: Callable[[str], None] = _silent,
) -> Design:
    """Scan to checked printable cushion: align, register, carry the seal over, design, thicken,
    check. `on_stage(name)` is called as each stage starts (for progress displays)."""
    template = load_template()
    on_stage("landmarks and similarity")
    al = align(scan, user_landmarks)
    on_stage("non-rigid registration")
    reg = register_template(scan, al)
    on_stage("contact")
    contact = transfer_contact(template, reg.vertices, scan, mask)
    require_quality(assess(scan, al.landmarks, reg, contact))  # or refuse: rescan
    on_stage("cushion")
    axis, up = al.similarity.rotation[:, 2], al.similarity.rotation[:, 1]
    cushion = design_cushion(contact, axis, up, reg.vertices[4], params)
    on_stage("solid and checks")
    solid, wall = cushion_solid(cushion, contact.normals)
    checks = check_solid(solid, wall, params.wall_mm, f"the {mask} cushion")
    on_stage("casting mould")
    parts = mould(cushion, solid).parts
    for name, part in parts.items():
        check_closed(part, name)
    on_stage("fit before compression")
    rim = cushion.grid(256, 2)[:, 0]
    generic_rim = place(template_cushion(mask, params), al.similarity).grid(256, 2)[:, 0]
    seated = {"custom": seat(rim, axis, scan), "generic": seat(generic_rim, axis, scan)}
    return Design(al, reg, contact, cushion, solid, checks, rim_gap(rim, scan), seated, parts)
