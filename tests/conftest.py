"""Shared fixtures: synthetic subjects on disk, the shared real scans (skipped when absent), the CLI."""

from pathlib import Path

import pytest

from cpapfit.cli import main
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.phantom import write_phantom
from cpapfit.io.write import write_files
from cpapfit.pipeline import design, place_template
from cpapfit.synthetic import make_phantom

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def phantom1():
    """The synthetic subject of seed 1 (arrays)."""
    return make_phantom(1)


@pytest.fixture(scope="session")
def phantom1_dir(tmp_path_factory, phantom1):
    """Seed 1 written as a capture folder with ground truth."""
    folder = tmp_path_factory.mktemp("phantom1")
    write_phantom(phantom1, folder)
    return folder


@pytest.fixture(scope="session")
def placed_subjects(tmp_path_factory):
    """seed -> (phantom, capture scan, `Placement`) of a synthetic subject, made once (both masks' designs share it)."""
    made = {}

    def placed(seed: int):
        if seed not in made:
            ph = make_phantom(seed)
            folder = tmp_path_factory.mktemp(f"design{seed}")
            write_files(folder, capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
            scan = load_scan(folder)
            made[seed] = ph, scan, place_template(scan)
        return made[seed]

    return placed


@pytest.fixture(scope="session", params=[(3, "nasal"), (3, "oronasal"), (2, "nasal"), (2, "oronasal")], ids=str)
def designed(request, placed_subjects):
    """(phantom, Design) for two synthetic subjects and both masks."""
    seed, mask = request.param
    ph, scan, placed = placed_subjects(seed)
    return ph, design(scan, mask, placement=placed)


@pytest.fixture
def shared_data():
    """../shared/data, or skip when this checkout has no shared folder beside it."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not present")
    return SHARED_DATA


@pytest.fixture
def cli(capsys):
    """Run the command line in-process: returns (exit code, stdout, stderr)."""

    def run(*argv):
        code = main([str(a) for a in argv])
        out, err = capsys.readouterr()
        return code, out, err

    return run
