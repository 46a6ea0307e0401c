"""Shared fixtures: synthetic subjects on disk, the shared real scans (skipped when absent), the CLI."""

from pathlib import Path

import pytest

from cpapfit.cli import main
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.phantom import write_phantom
from cpapfit.io.write import write_files
from cpapfit.pipeline import design
from cpapfit.phantom import make_phantom

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


@pytest.fixture(scope="session", params=[(3, "nasal"), (3, "oronasal"), (2, "nasal"), (2, "oronasal")], ids=str)
def designed(request, tmp_path_factory):
    """(phantom, Design) for two synthetic subjects and both masks."""
    seed, mask = request.param
    ph = make_phantom(seed)
    folder = tmp_path_factory.mktemp(f"design{seed}{mask}")
    write_files(folder, capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    return ph, design(load_scan(folder), mask)


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
