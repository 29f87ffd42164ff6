"""The recorded HTML replay renders offline in headless Chromium (Debian package `chromium`)."""

import numpy as np
import pytest
from headless_browser import CHROMIUM, JS_ERROR, screenshot
from pydrake.geometry import Meshcat

from nfr_drake.systems.replay import write_replay

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Chromium: apt-get install chromium")


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
