"""End to end in simulation: Drake renders photos of a closet in a textured room with a ChArUco
board at known poses (through a distorting lens); `estimate_poses` must find those poses in O."""

import json

import numpy as np
import pytest

from nfr_drake.data.capture import PinholeCamera, read_capture_set
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.alignment import rotation_angle
from nfr_drake.perception.charuco import CharucoBoardSpec
from nfr_drake.perception.intrinsics import PhotoCamera
from nfr_drake.perception.poses import Alignment, estimate_poses
from nfr_drake.perception.synthetic import SyntheticPhotoScene, orbit_poses, write_photo_folder

DISTORTION = (-0.12, 0.03, 5e-4, -3e-4)
TARGET_O = np.array([0.4, 0.0, 0.35])


@pytest.fixture(scope="module")
def scene():
    closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
    return SyntheticPhotoScene(closet, 0.5, PinholeCamera.from_fov(1024, 768, np.deg2rad(50)))


@pytest.fixture(scope="module")
def photos(scene, tmp_path_factory):
    folder = tmp_path_factory.mktemp("synthetic") / "photos"
    write_photo_folder(folder, scene, orbit_poses(8, TARGET_O), DISTORTION)
    return folder, json.loads((folder / "truth.json").read_text())


def _run(photos, out, known_intrinsics: bool):
    folder, truth = photos
    b = truth["board"]
    board = CharucoBoardSpec(tuple(b["squares"]), b["square_m"], b["marker_m"], b["dictionary"])
    camera = PhotoCamera.from_json(truth["camera"]) if known_intrinsics else None
    report = estimate_poses(folder, out, Alignment(charuco=board), camera,
                            X_WO=np.linalg.inv(np.array(truth["X_OB"])), progress=lambda _: None)
    return read_capture_set(out), report


def _pose_errors(capture, report, truth):
    errors = {}
    for frame in capture.frames:
        name = report.frames[f"images/{frame.image_path.name}"]
        X_OC = np.array(truth["X_OC"][name])
        errors[name] = (np.linalg.norm(frame.X_OC[:3, 3] - X_OC[:3, 3]),
                        np.degrees(rotation_angle(X_OC[:3, :3].T @ frame.X_OC[:3, :3])))
    return errors


@pytest.fixture(scope="module")
def known(photos, tmp_path_factory):
    return _run(photos, tmp_path_factory.mktemp("known") / "capture", known_intrinsics=True)


def test_poses_match_the_rendered_ones(known, photos):
    capture, report = known
    assert report.unregistered == [] and len(capture.frames) == 8
    assert report.mean_reprojection_error_px < 0.5
    assert len(report.board_poses) == 8
    for name, (error_m, error_deg) in _pose_errors(capture, report, photos[1]).items():
        assert error_m < 0.010, f"{name}: centre off by {1000 * error_m:.1f} mm"
        assert error_deg < 0.5, f"{name}: rotation off by {error_deg:.2f} deg"


def test_images_are_undistorted(known, scene, photos):
    """The written (undistorted, pinhole) image equals a pinhole render from the true pose."""
    capture, report = known
    frame = capture.frames[0]
    assert frame.camera.distortion is None
    truth = np.array(photos[1]["X_OC"][report.frames[f"images/{frame.image_path.name}"]])
    rendered = scene.render(truth).astype(float)
    written = frame.load_rgb().astype(float)
    h, w = rendered.shape[:2]
    centre = (slice(h // 4, 3 * h // 4), slice(w // 4, 3 * w // 4))
    assert np.abs(written[centre] - rendered[centre]).mean() < 6.0  # of 255; blur and texture


@pytest.mark.slow
def test_self_calibration(photos, tmp_path):
    capture, report = _run(photos, tmp_path / "capture", known_intrinsics=False)
    assert report.calibration == "self-calibrated" and report.unregistered == []
    for name, (error_m, error_deg) in _pose_errors(capture, report, photos[1]).items():
        assert error_m < 0.020, f"{name}: centre off by {1000 * error_m:.1f} mm"
        assert error_deg < 0.5, f"{name}: rotation off by {error_deg:.2f} deg"
