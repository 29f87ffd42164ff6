"""ChArUco board poses in the real photos of the shared data (opencv_contrib tutorial images)."""

import cv2
import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.perception.charuco import CharucoBoardSpec, CharucoPoseEstimator

# From OpenCV's samples/data/aruco/tutorial_camera_charuco.yml (OpenCV pixel convention, so the
# principal point moves by +0.5 into ours); see the data README.
TUTORIAL_CAMERA = PinholeCamera(452.5107, 456.7671, 317.7030 + 0.5, 277.7516 + 0.5, 640, 480,
                              (0.121369, -1.085466, 1.17868e-4, -4.62407e-4, 2.954259))
PHOTOS = ["img_00.jpg", "img_01.jpg", "img_02.jpg", "img_03.jpg", "chocclusion_original.jpg"]


@pytest.fixture(scope="module")
def estimator():
    return CharucoPoseEstimator(CharucoBoardSpec((5, 7), 0.04, 0.02, "DICT_6X6_250"))


@pytest.mark.parametrize("name", PHOTOS)
def test_board_pose_in_each_photo(shared_data, estimator, name):
    path = shared_data / "charuco" / name
    if not path.is_file():
        pytest.skip(f"{path} not found")
    pose = estimator.estimate(cv2.imread(str(path)), TUTORIAL_CAMERA)
    assert pose is not None, "board not found"
    assert 16 <= pose.corners <= 24
    assert pose.reprojection_error_px < 0.5
    distance = np.linalg.norm(pose.X_BC[:3, 3])
    assert 0.38 < distance < 0.49
    # The camera looks at the board's front: it is on the -z side of B and faces +z.
    assert pose.X_BC[2, 3] < 0 and pose.X_BC[2, 2] > 0.5
    np.testing.assert_allclose(pose.X_BC[:3, :3].T @ pose.X_BC[:3, :3], np.eye(3), atol=1e-9)


def test_no_board_in_a_blank_photo(estimator):
    assert estimator.estimate(np.full((480, 640, 3), 128, np.uint8), TUTORIAL_CAMERA) is None


def test_wrong_dictionary_finds_nothing(shared_data):
    path = shared_data / "charuco" / "img_00.jpg"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    wrong = CharucoPoseEstimator(CharucoBoardSpec((5, 7), 0.04, 0.02, "DICT_4X4_50"))
    assert wrong.estimate(cv2.imread(str(path)), TUTORIAL_CAMERA) is None
