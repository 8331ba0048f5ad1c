#!/usr/bin/env python3
"""The README's screenshots of the HTML view (docs/view.png), made as the browser test sees
the page: ``rbe-ros view`` of a bag or a scene, opened in headless Chromium at one step.

Usage: .venv/bin/python scripts/view_screenshot.py [--bag bags/wall_misplaced] [--step 12]
The robot cell's (docs/figures/view_cell_dome10x8.png), from its plan:
    rbe-ros plan tests/data/issue31/dome10x8.json --cell examples/cells/dome_3robots.yaml \
        -o plan.json
    .venv/bin/python scripts/view_screenshot.py --bag plan.json --step 41 \
        -o docs/figures/view_cell_dome10x8.png
"""
from __future__ import annotations

import argparse
import io
import sys
import tempfile
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from browser import chromium, wait_drawn  # noqa: E402
from rbe_ros.cli import main as rbe_ros  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", default=str(ROOT / "bags" / "wall_misplaced"),
                        help="a bag, or a scene (checked step by step)")
    parser.add_argument("--step", type=int, default=12, help="row of the table to show")
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "view.png"))
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "report.html"
        rbe_ros(["view", args.bag, "-o", str(page)])
        browser = chromium(1100, 1000)
        try:
            browser.get(page.as_uri())
            wait_drawn(browser, 0)
            browser.execute_script("document.getElementById('steps').rows"
                                   f"[{args.step + 1}].click()")
            wait_drawn(browser, args.step)
            png = browser.get_screenshot_as_png()
        finally:
            browser.quit()
    image = Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    image.save(args.output, optimize=True)
    print(f"screenshot written to {args.output} ({Path(args.output).stat().st_size // 1024} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
