"""Similarity estimation, collinear anchors, object poses (no photos needed)."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nfr_drake.perception.alignment import (
    AlignmentError,
    Similarity,
    align_to_camera_poses,
    align_to_centres,
    check_not_collinear,
    parse_object_pose,
    read_anchors,
    rotation_angle,
)


def _random_poses(rng, n):
    poses = {}
    for i in range(n):
        X = np.eye(4)
        X[:3, :3] = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
        X[:3, 3] = rng.normal(size=3)
        poses[f"img_{i}.jpg"] = X
    return poses


@pytest.fixture
def truth():
    rng = np.random.default_rng(3)
    S = Similarity(2.5, Rotation.random(random_state=7).as_matrix(), np.array([0.3, -1.0, 2.0]))
    X_RCs = _random_poses(rng, 6)
    return S, X_RCs, {n: S.apply_pose(X) for n, X in X_RCs.items()}


def test_apply_pose_keeps_rotations_rigid(truth):
    S, X_RCs, X_WCs = truth
    for X in X_WCs.values():
        np.testing.assert_allclose(X[:3, :3].T @ X[:3, :3], np.eye(3), atol=1e-12)
        np.testing.assert_allclose(X[3], [0, 0, 0, 1])


def test_centres_recover_the_similarity(truth):
    S, X_RCs, X_WCs = truth
    anchors = {n: X[:3, 3] for n, X in X_WCs.items()}
    anchors["not_a_photo.jpg"] = np.zeros(3)  # ignored
    result = align_to_centres(X_RCs, anchors)
    assert result.similarity.scale == pytest.approx(S.scale, rel=1e-9)
    np.testing.assert_allclose(result.similarity.R_WR, S.R_WR, atol=1e-9)
    np.testing.assert_allclose(result.similarity.p_WR, S.p_WR, atol=1e-9)
    assert max(result.position_residuals_m.values()) < 1e-9
    assert set(result.position_residuals_m) == set(X_RCs)


def test_camera_poses_recover_the_similarity_from_two_images(truth):
    S, X_RCs, X_WCs = truth
    two = dict(list(X_WCs.items())[:2])
    result = align_to_camera_poses(X_RCs, two)
    assert result.similarity.scale == pytest.approx(S.scale, rel=1e-9)
    np.testing.assert_allclose(result.similarity.R_WR, S.R_WR, atol=1e-9)
    assert max(result.rotation_residuals_rad.values()) < 1e-9


def test_collinear_anchors_are_refused(truth):
    _, X_RCs, _ = truth
    line = {n: np.array([0.1 * i, 0.2 * i, 0.0]) + [0, 0, 1e-4 * (i % 2)]
            for i, n in enumerate(X_RCs)}
    with pytest.raises(AlignmentError, match="nearly collinear"):
        align_to_centres(X_RCs, line)
    with pytest.raises(AlignmentError, match="at least 3"):
        check_not_collinear(np.zeros((2, 3)), ["a", "b"])


def test_rotation_angle():
    R = Rotation.from_rotvec([0.0, 0.0, 0.3]).as_matrix()
    assert rotation_angle(R) == pytest.approx(0.3)


def test_object_pose_formats(tmp_path):
    X = parse_object_pose("1, 2, 3, 0, 0, 1.5707963267948966")
    np.testing.assert_allclose(X[:3, 3], [1, 2, 3])
    np.testing.assert_allclose(X[:3, 0], [0, 1, 0], atol=1e-12)  # yaw 90 deg: x_O along y_W
    path = tmp_path / "X_WO.json"
    path.write_text(json.dumps(X.tolist()))
    np.testing.assert_allclose(parse_object_pose(str(path)), X)
    path.write_text(json.dumps({"xyz": [1, 2, 3], "rpy": [0, 0, np.pi / 2]}))
    np.testing.assert_allclose(parse_object_pose(str(path)), X, atol=1e-12)
    with pytest.raises(AlignmentError, match="6 numbers"):
        parse_object_pose("1 2 3")
    path.write_text(json.dumps((2 * np.eye(4)).tolist()))
    with pytest.raises(AlignmentError, match="not a rigid"):
        parse_object_pose(str(path))


def test_read_anchors_errors(tmp_path):
    path = tmp_path / "anchors.json"
    path.write_text('{"a.jpg": [1, 2]}')
    with pytest.raises(AlignmentError, match=r"\[x, y, z\]"):
        read_anchors(path)
    with pytest.raises(AlignmentError, match="not found"):
        read_anchors(tmp_path / "missing.json")


def test_anchors_of_other_photos_are_refused(truth):
    """Right anchors with 1 mm noise pass; the same anchors assigned to the wrong photos do not."""
    _, X_RCs, X_WCs = truth
    rng = np.random.default_rng(0)
    names = sorted(X_WCs)
    anchors = {n: X_WCs[n][:3, 3] + rng.normal(scale=0.001, size=3) for n in names}
    assert align_to_centres(X_RCs, anchors).rms_position_m < 0.002
    shuffled = dict(zip(names, [anchors[n] for n in names[1:] + names[:1]], strict=True))
    with pytest.raises(AlignmentError, match="belong to other photos"):
        align_to_centres(X_RCs, shuffled)
    assert align_to_centres(X_RCs, shuffled, max_residual=2.0).rms_position_m > 0.5


def test_read_anchors_names_the_line(tmp_path):
    path = tmp_path / "anchors.json"
    path.write_text('{\n  "a.jpg": [1, 2, 3],\n  "b.jpg": [1, "x", 3]\n}\n')
    with pytest.raises(AlignmentError, match=r"anchors.json, line 3: the anchor of 'b.jpg'"):
        read_anchors(path)
    path.write_text('{"é.jpg": [1, 2, 3], "a.jpg": [NaN, 2, 3]}')
    with pytest.raises(AlignmentError, match="line 1: the anchor of 'a.jpg' is"):
        read_anchors(path)
    path.write_text('{"é.jpg": [1, 2, 3],\n"a.jpg": [1, 2.5, -3]}')
    np.testing.assert_array_equal(read_anchors(path)["a.jpg"], [1, 2.5, -3])
