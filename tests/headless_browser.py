"""Pages rendered in headless Chromium (Debian package `chromium`), for the tests of offline HTML."""

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
from PIL import Image

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

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
