"""Capture sets: transforms.json round trip and one clear error per kind of invalid input."""

import json
import subprocess
import sys

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.capture import opencv_from_opengl, opengl_from_opencv, read_capture_set, write_capture_set
from nfr_drake.errors import CaptureSetError


def _poses(n=3):
    return [look_at(np.array([1.5, 0.4 * i - 0.4, 0.8]), np.array([0.0, 0.0, 0.4])) for i in range(n)]


def _images(n=3, w=40, h=30):
    rng = np.random.default_rng(0)
    return [rng.integers(0, 255, (h, w, 3), dtype=np.uint8) for _ in range(n)]


@pytest.fixture
def capture(tmp_path):
    camera = PinholeCamera(50.0, 52.0, 20.5, 15.0, 40, 30)
    return write_capture_set(tmp_path / "cap", _images(), _poses(), camera, gt={"q": 0.3})


def test_round_trip_keeps_poses_intrinsics_and_pixels(tmp_path):
    cameras = [PinholeCamera(50.0, 52.0, 20.5, 15.0, 40, 30, (0.1, -0.02, 0.001, 0.002)),
               PinholeCamera(45.0, 45.0, 20.0, 15.0, 40, 30), PinholeCamera(40.0, 41.0, 19.0, 14.0, 40, 30)]
    images, poses = _images(), _poses()
    root = write_capture_set(tmp_path / "cap", images, poses, cameras, gt={"q": 0.25})
    cap = read_capture_set(root)
    assert cap.gt == {"q": 0.25}
    for frame, image, X_OC, camera in zip(cap.frames, images, poses, cameras, strict=True):
        np.testing.assert_allclose(frame.X_OC, X_OC, atol=1e-12)
        assert frame.camera == camera
        np.testing.assert_array_equal(frame.load_rgb(), image)


def test_file_uses_opengl_axes(capture):
    doc = json.loads((capture / "transforms.json").read_text())
    X_file = np.array(doc["frames"][0]["transform_matrix"])
    X_OC = _poses()[0]
    # OpenGL's camera z points backwards: away from the object the camera looks at.
    np.testing.assert_allclose(X_file[:3, 2], -X_OC[:3, 2])
    np.testing.assert_allclose(opencv_from_opengl(opengl_from_opencv(X_OC)), X_OC)
    assert doc["camera_model"] == "PINHOLE" and doc["w"] == 40 and doc["h"] == 30


def _edit(capture, change):
    path = capture / "transforms.json"
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))


def test_missing_image(capture):
    (capture / "images" / "frame_001.png").unlink()
    with pytest.raises(CaptureSetError, match=r"frame_001\.png.*not found"):
        read_capture_set(capture)


def test_image_size_differs_from_intrinsics(capture):
    _edit(capture, lambda d: d.update(w=64))
    with pytest.raises(CaptureSetError, match=r"frame_000\.png: image is 40x30 but .* says 64x30"):
        read_capture_set(capture)


def test_non_finite_transform(capture):
    def change(d):
        d["frames"][2]["transform_matrix"][0][3] = float("nan")
    _edit(capture, change)
    with pytest.raises(CaptureSetError, match=r"transforms\.json: frame 2: .*non-finite"):
        read_capture_set(capture)


def test_non_rigid_transform(capture):
    def change(d):
        d["frames"][1]["transform_matrix"][0][0] += 0.5
    _edit(capture, change)
    with pytest.raises(CaptureSetError, match=r"frame 1: transform_matrix is not a rigid"):
        read_capture_set(capture)


def test_malformed_json(capture):
    (capture / "transforms.json").write_text('{"frames": [')
    with pytest.raises(CaptureSetError, match=r"transforms\.json: malformed JSON"):
        read_capture_set(capture)


def test_missing_intrinsics_and_missing_folder(capture, tmp_path):
    _edit(capture, lambda d: d.pop("fl_x"))
    with pytest.raises(CaptureSetError, match="missing intrinsic 'fl_x'"):
        read_capture_set(capture)
    with pytest.raises(CaptureSetError, match="folder not found"):
        read_capture_set(tmp_path / "nowhere")


def test_cli_reports_invalid_capture_with_status_2_and_no_traceback(capture):
    _edit(capture, lambda d: d["frames"][0].update(transform_matrix=[[1, 0], [0, 1]]))
    result = subprocess.run([sys.executable, "-m", "nfr_drake.cli", "validate", str(capture)],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert "has shape (2, 2), expected 4x4" in result.stderr
    assert "Traceback" not in result.stderr


def test_cli_accepts_a_valid_capture(capture):
    result = subprocess.run([sys.executable, "-m", "nfr_drake.cli", "validate", str(capture)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "3 frames" in result.stdout


def test_captures_at_a_fixed_articulation_keep_objects_and_cameras(tmp_path):
    from nfr_drake.data.captures import captures_command
    from nfr_drake.errors import ConfigError

    captures_command("drawer", n=1, out=tmp_path / "random", views=2, size=16, seed=5)
    captures_command("drawer", n=1, out=tmp_path / "closed", views=2, size=16, seed=5, q=0.0)
    random, closed = (read_capture_set(tmp_path / name / "drawer_000") for name in ("random", "closed"))
    assert closed.gt["q"] == 0.0 and random.gt["q"] > 0.0
    assert closed.gt["object"] == random.gt["object"]
    for a, b in zip(random.frames, closed.frames, strict=True):
        np.testing.assert_array_equal(a.X_OC, b.X_OC)
    with pytest.raises(ConfigError):
        captures_command("drawer", n=1, out=tmp_path / "bad", q=1.5)
