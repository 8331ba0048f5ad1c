"""Headless Chromium through selenium, for the HTML view's test and its README screenshot.

Debian's chromium and chromium-driver are installed by scripts/setup_browser.sh (run here
when they are missing); selenium is given the driver's path, so it downloads nothing.
"""
from __future__ import annotations

import io
import shutil
import subprocess
from pathlib import Path

import numpy as np
from PIL import Image
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.support.ui import WebDriverWait

REPO = Path(__file__).resolve().parents[1]


def ensure_browser() -> tuple[str, str]:
    """Paths of chromium and chromedriver, installing them with the project's setup."""
    if not (shutil.which("chromium") and shutil.which("chromedriver")):
        subprocess.run(["bash", str(REPO / "scripts" / "setup_browser.sh")], check=True,
                       timeout=1200)
    return shutil.which("chromium"), shutil.which("chromedriver")


def chromium(width: int = 1200, height: int = 1000) -> webdriver.Chrome:
    """A headless Chromium with software WebGL, keeping the console log."""
    binary, driver = ensure_browser()
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                 "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                 f"--window-size={width},{height}", "--hide-scrollbars"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(options=options, service=Service(executable_path=driver))


def wait_drawn(browser, step: int, timeout: float = 30.0) -> None:
    """Wait until the page has drawn step ``step`` (its WebGL canvas there)."""
    WebDriverWait(browser, timeout).until(lambda b: b.execute_script(
        "return document.querySelector('#plot canvas') !== null && "
        "document.body.dataset.drawn === arguments[0]", str(step)))


def element_pixels(browser, css: str) -> np.ndarray:
    """RGB pixels (h, w, 3) of a screenshot of the element ``css``."""
    png = browser.find_element("css selector", css).screenshot_as_png
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
