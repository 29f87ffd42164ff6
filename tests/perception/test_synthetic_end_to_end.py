"""End to end in simulation: Drake renders photos of a closet in a textured room with a ChArUco
board at known poses (through a distorting lens); `estimate_poses` must find those poses in O."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from nfr_drake.cli import main
from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import read_capture_set, write_capture_set
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.alignment import rotation_angle
from nfr_drake.perception.charuco import CharucoBoardSpec
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
    camera = PinholeCamera.from_json(truth["camera"]) if known_intrinsics else None
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
    assert frame.camera.distortion == ()
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


@pytest.fixture(scope="module")
def closet_model():
    """The trained closet model: $NFR_DRAKE_CLOSET_MODEL or models/closet in the repository."""
    folder = Path(os.environ.get("NFR_DRAKE_CLOSET_MODEL",
                                 Path(__file__).parents[2] / "models" / "closet"))
    if not (folder / "model.safetensors").is_file():
        pytest.skip(f"no trained closet model at {folder} (set NFR_DRAKE_CLOSET_MODEL)")
    return folder


@pytest.mark.slow
def test_infer_on_estimated_poses_matches_true_poses(closet_model, known, scene, photos, tmp_path):
    """`nfr-drake infer` with the estimated poses finds nearly the q and keypoints it finds with
    the true ones. Both capture sets hold the same object-only renders (the model was trained
    without a room around the object), so only the poses differ. Both use the default fit
    (4 starts, at most 400 steps) with the same seeds."""
    capture, report = known
    truth = photos[1]
    camera = scene.camera.scaled(128, 96)
    renderer = ObjectRenderer(scene.obj, camera)
    names = [report.frames[f"images/{f.image_path.name}"] for f in capture.frames]
    X_true = [np.array(truth["X_OC"][n]) for n in names]
    images = [renderer.render_rgb(scene.q, X) for X in X_true]
    results = {}
    for label, poses in (("true", X_true), ("estimated", [f.X_OC for f in capture.frames])):
        write_capture_set(tmp_path / label, images, poses, camera)
        out = tmp_path / f"{label}.json"
        assert main(["infer", str(tmp_path / label), "--model", str(closet_model), "--out", str(out),
                     "--category", "closet", "--threads", "1"]) == 0
        results[label] = json.loads(out.read_text())
    assert abs(results["true"]["q"] - results["estimated"]["q"]) < 0.05
    # Two fits of the shipped model differ in their keypoints by about the model's own keypoint
    # error on unseen closets (3.3 cm median, docs/EVALUATION.md), whatever the poses; 4 cm
    # tells pose errors (which would add to it) from that.
    for name, p_true in results["true"]["keypoints"].items():
        distance = np.linalg.norm(np.subtract(results["estimated"]["keypoints"][name], p_true))
        assert distance < 0.04, f"{name}: {1000 * distance:.0f} mm apart"
