"""The camera model: COLMAP and OpenCV conversions, undistortion, JSON files."""

import json

import cv2
import numpy as np
import pycolmap
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.errors import ConfigError

CAMERA = PinholeCamera(452.5, 456.8, 318.2, 278.3, 640, 480, (0.12, -0.3, 1e-3, -5e-4, 0.2))


@pytest.mark.parametrize("camera", [
    PinholeCamera(500.0, 510.0, 320.0, 240.0, 640, 480),
    PinholeCamera(500.0, 510.0, 320.0, 240.0, 640, 480, (0.1, -0.05, 1e-3, 2e-3)),
    CAMERA,
])
def test_colmap_round_trip(camera):
    model, params = camera.colmap_model()
    colmap = pycolmap.Camera.create_from_model_name(1, model, 500.0, camera.width, camera.height)
    colmap.params = params
    back = PinholeCamera.from_colmap(colmap)
    assert back.K == pytest.approx(camera.K)
    np.testing.assert_allclose(np.pad(back.distortion, (0, 8 - len(back.distortion))),
                               np.pad(camera.distortion, (0, 8 - len(camera.distortion))))


def test_colmap_and_opencv_project_alike():
    """Same 3D point -> same pixel in COLMAP (centre at 0.5) and OpenCV (centre at 0) + 0.5."""
    model, params = CAMERA.colmap_model()
    colmap = pycolmap.Camera.create_from_model_name(1, model, 500.0, 640, 480)
    colmap.params = params
    p_C = np.array([[0.1, -0.05, 1.0], [-0.2, 0.15, 1.2]])
    uv_colmap = colmap.img_from_cam(p_C)
    uv_cv, _ = cv2.projectPoints(p_C, np.zeros(3), np.zeros(3), CAMERA.K_opencv, CAMERA.dist_opencv)
    np.testing.assert_allclose(uv_colmap, uv_cv.reshape(-1, 2) + 0.5, atol=1e-6)


def test_undistort_moves_points_to_their_pinhole_projection():
    image = np.zeros((480, 640), np.uint8)
    p_C = np.array([[0.15, -0.1, 1.0]])
    uv, _ = cv2.projectPoints(p_C, np.zeros(3), np.zeros(3), CAMERA.K_opencv, CAMERA.dist_opencv)
    u, v = uv.ravel()
    cv2.circle(image, (round(u * 16), round(v * 16)), 3 * 16, 255, -1, cv2.LINE_AA, shift=4)
    undistorted, pinhole = CAMERA.undistort(image)
    ys, xs = np.nonzero(undistorted > 64)
    w = undistorted[ys, xs].astype(float)
    centre = np.array([np.average(xs, weights=w), np.average(ys, weights=w)]) + 0.5
    expected = (pinhole.K @ p_C[0])[:2] / p_C[0, 2]
    np.testing.assert_allclose(centre, expected, atol=0.3)


def test_json_file(tmp_path):
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(CAMERA.to_json()))
    assert PinholeCamera.from_json_file(path) == CAMERA
    path.write_text(json.dumps({"fl_x": 500, "cx": 1}))
    with pytest.raises(ConfigError, match="fl_y"):
        PinholeCamera.from_json_file(path)


def test_scaled():
    half = CAMERA.scaled(320, 240)
    assert (half.fx, half.cx, half.width) == pytest.approx((CAMERA.fx / 2, CAMERA.cx / 2, 320))
