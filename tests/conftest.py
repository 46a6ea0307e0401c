"""Shared fixtures: synthetic subjects on disk, the shared real scans (skipped when absent), the CLI."""

from pathlib import Path

import pytest

from records import DATE_EPOCH
from cpapfit.api import Params, design as api_design
from cpapfit.cli import main
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.phantom import write_phantom
from cpapfit.io.write import write_files
from cpapfit.pipeline import design, place_template
from cpapfit.synthetic.template_phantom import make_phantom

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
# Fixtures that take seconds or more to make. The tests sharing one are sent to one worker process
# (pytest-xdist's loadgroup), so that it is made once, not once in each worker.
SHARED_WORK = ("placed_subjects", "designed", "nasal1", "report", "twice", "phantoms", "case", "closed_and_open", "rotated_stl",
               "ict1", "frontal_mesh", "ict_capture", "bare_and_worn")
WHOLE_DESIGNS = ("designed", "nasal1", "batched")  # fixtures that make whole designs: their tests are `slow`


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the groups off the markers
def pytest_collection_modifyitems(items):
    """Each test using one of SHARED_WORK goes in that fixture's xdist group (the first it uses); a
    test using one of WHOLE_DESIGNS is `slow`."""
    for item in items:
        shared = [name for name in SHARED_WORK if name in item.fixturenames]
        if shared:
            item.add_marker(pytest.mark.xdist_group(shared[0]))
        if any(name in item.fixturenames for name in WHOLE_DESIGNS):
            item.add_marker(pytest.mark.slow)


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
def nasal1(phantom1_dir):
    """Seed 1's nasal design through the Python API, beside the stock size the gauge picks, report
    included (its run date fixed by SOURCE_DATE_EPOCH = DATE_EPOCH): a `DesignResult`."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SOURCE_DATE_EPOCH", DATE_EPOCH)
        return api_design(load_scan(phantom1_dir), "nasal", params=Params(stock="gauge"))


@pytest.fixture
def placed1(nasal1, monkeypatch):
    """`place_template` answering with seed 1's placement (`nasal1`'s) in the design's stages and in
    `api.evaluate`, for tests of the stages after it (the `register` and `landmarks` commands place it themselves)."""
    from cpapfit import api, commands, pipeline  # commands imported first: its own names stay the real ones

    assert commands.place_template is pipeline.place_template is api.place_template
    placement = pipeline.Placement(nasal1.design.alignment, nasal1.design.registration, None)
    for module in (pipeline, api):
        monkeypatch.setattr(module, "place_template", lambda *args, **kwargs: placement)
    return placement


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


@pytest.fixture(scope="session", params=[(3, "nasal"), (3, "oronasal"), (2, "oronasal")], ids=str)
def designed(request, placed_subjects):
    """(phantom, Design): seed 3 with both masks, seed 2 with the oronasal (the larger cushion, the harder to make whole)."""
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
