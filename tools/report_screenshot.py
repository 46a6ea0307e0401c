"""A screenshot of the top of a report.html for the README, taken with headless Chromium offline.

Usage: .venv/bin/python tools/report_screenshot.py cpapfit-demo/design/report.html docs/report.png
"""

import io
import sys
import tempfile
from pathlib import Path

from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from browser import Chromium  # noqa: E402

HEIGHT = 1560  # page pixels: warnings, the headline table and the 3-D view


def main(report: Path, out: Path) -> None:
    with tempfile.TemporaryDirectory() as profile:
        browser = Chromium(Path(profile), width=1280, height=HEIGHT)
        try:
            browser.open(report)
            browser.settle(1.5)
            png = browser.screenshot()
        finally:
            browser.close()
    Image.open(io.BytesIO(png)).convert("RGB").save(out, optimize=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
