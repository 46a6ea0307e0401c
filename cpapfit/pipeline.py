"""The stages strung together. Each stage is a pure function; this module only sequences them."""

from dataclasses import dataclass

from .align.check import FaceCheck
from .align.initial import initial_alignment
from .align.nonrigid import NonrigidParams, Registration, register
from .align.similarity import Similarity
from .landmarks.types import Landmarks
from .scan import Scan
from .template import load_template

# (stage, issue that builds it); order is the pipeline's.
STAGES = (
    ("scan", None), ("template", None), ("landmarks", 3), ("similarity", 3), ("nonrigid", 4),
    ("contact", 5), ("cushion", 5), ("export", 5), ("evaluate", 6), ("report", 7),
)
BUILT = {"scan", "template", "landmarks", "similarity", "nonrigid"}


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
