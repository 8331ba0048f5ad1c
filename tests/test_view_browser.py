"""The HTML view in a real browser (headless Chromium, installed by scripts/setup_browser.sh
when missing): no console errors, a 3D canvas that is not blank, and the slider moving the
view to step k shows step k's table row and colours."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from selenium.webdriver.common.keys import Keys

from browser import chromium, element_pixels, wait_drawn
from rbe_ros.cli import main

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    out = tmp_path_factory.mktemp("view") / "report.html"
    assert main(["view", str(REPO / "examples" / "build_sequence.json"), "-o", str(out)]) == 0
    browser = chromium()
    try:
        browser.get(out.as_uri())
        wait_drawn(browser, 0)
        yield browser
    finally:
        browser.quit()


def reddish(pixels: np.ndarray) -> int:
    """Pixels of the unstable blocks' red (translucent over white, so pink too)."""
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    return int(np.sum((r > 180) & (r - g > 70) & (r - b > 70) & (abs(g - b) < 40)))


def current_row(browser) -> list[str]:
    row = browser.find_element("css selector", "#steps tr.current")
    return [td.text for td in row.find_elements("css selector", "td")]


def trace_blocks(browser, role: str) -> set[str]:
    """The ids of the blocks drawn in ``role``'s mesh."""
    return set(browser.execute_script(
        "const t = document.getElementById('plot').data.find(t => t.name === arguments[0]);"
        "return t ? Array.from(new Set(t.text)) : [];", role))


def test_page_draws_without_errors(page):
    errors = [e for e in page.get_log("browser") if e["level"] == "SEVERE"]
    assert errors == []
    pixels = element_pixels(page, "#plot")
    assert pixels.std() > 20                           # not blank
    assert len(np.unique(pixels.reshape(-1, 3) // 16, axis=0)) > 20
    assert current_row(page)[:4] == ["portal with an overhanging cap", "0", "pillar_left",
                                     "STABLE"]
    assert trace_blocks(page, "placed") == {"pillar_left"}
    assert trace_blocks(page, "support") == {"ground"}
    assert reddish(pixels) == 0


def test_slider_shows_step_k(page):
    slider = page.find_element("css selector", "#slider")
    slider.click()
    slider.send_keys(Keys.HOME)
    for k in range(1, 6):
        slider.send_keys(Keys.ARROW_RIGHT)
        wait_drawn(page, k)
        assert page.execute_script("return document.body.dataset.step") == str(k)
        row = current_row(page)
        assert row[1] == str(k)
    # step 5 places the cap, which tips: its row says so and the cap is drawn red
    assert row[2:4] == ["cap", "TENSION_REQUIRED"] and row[4] == "470.9"
    assert trace_blocks(page, "unstable") == {"cap"}
    assert trace_blocks(page, "stable") == {"pillar_left", "pillar_right", "lintel",
                                            "block_left", "wedge"}
    assert reddish(element_pixels(page, "#plot")) > 500
    slider.send_keys(Keys.ARROW_LEFT)                   # back to step 4: nothing red
    wait_drawn(page, 4)
    assert current_row(page)[1:4] == ["4", "wedge", "STABLE"]
    assert trace_blocks(page, "unstable") == set()
    assert reddish(element_pixels(page, "#plot")) == 0
    assert [e for e in page.get_log("browser") if e["level"] == "SEVERE"] == []
