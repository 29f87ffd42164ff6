"""The recorded HTML replay renders offline in headless Chromium (Debian package `chromium`)."""

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pydrake.geometry import Meshcat

from nfr_drake.systems.replay import write_replay

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium: apt-get install chromium")

# A console message that reports a script error (Chromium logs console output as INFO:CONSOLE).
JS_ERROR = re.compile(r"CONSOLE.*(Uncaught|TypeError|ReferenceError|SyntaxError|RangeError)")


def screenshot(html: Path, tmp_path: Path) -> tuple[np.ndarray, str]:
    """Render `html` headless; the screenshot (H, W, 3) uint8 and Chromium's log."""
    png = tmp_path / f"{html.stem}.png"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr", "--v=0",
           "--enable-unsafe-swiftshader", "--window-size=800,600", "--virtual-time-budget=6000",
           f"--screenshot={png}", html.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert png.is_file(), proc.stderr[-2000:]
    return np.asarray(Image.open(png).convert("RGB")), proc.stdout + proc.stderr


def test_error_detector_sees_script_errors(tmp_path):
    page = tmp_path / "broken.html"
    page.write_text("<html><body><script>notAFunction();</script></body></html>")
    _, log = screenshot(page, tmp_path)
    assert JS_ERROR.search(log), log[-2000:]


def test_replay_renders(drawer_outcome, tmp_path):
    html = drawer_outcome.replay
    text = html.read_text()
    assert "<script src" not in text and "<link" not in text  # self-contained: works offline
    image, log = screenshot(html, tmp_path)
    errors = [line for line in log.splitlines() if JS_ERROR.search(line)]
    assert not errors, errors
    empty, _ = screenshot(write_replay(Meshcat(), tmp_path / "empty.html"), tmp_path)
    changed = np.any(np.abs(image.astype(int) - empty.astype(int)) > 12, axis=-1)
    assert changed.mean() > 0.01, f"only {changed.mean():.2%} of the pixels show the scene"
    assert image.std() > 10.0
