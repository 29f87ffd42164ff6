"""`nfr-drake poses --world floor`: poses in the floor frame under a ChArUco board lying on the floor
(z up, the floor at z = 0), checked against the floor that the sparse points show."""

import json

import numpy as np
import pytest

from nfr_drake.cli import main
from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import read_capture_set
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.alignment import rotation_angle
from nfr_drake.perception.charuco import CharucoBoardSpec, floor_frame_in_board
from nfr_drake.perception.floor import MAX_HEIGHT_M, floor_plane
from nfr_drake.perception.synthetic import (
    RoomSpec,
    SyntheticPhotoScene,
    board_pose,
    floor_pose,
    orbit_poses,
    write_photo_folder,
)

BOARD = CharucoBoardSpec(square_m=0.08, marker_m=0.06, thickness_m=0.002)
ROOM = RoomSpec(board=BOARD, p_OB=(0.6, 0.1, BOARD.thickness_m), board_yaw_deg=30.0)


def _room_points(rng, floor_z=0.0, tilt_deg=0.0, n_floor=400):
    """Sparse points of a room in W: a floor (at height floor_z, tilted about x), a back wall and
    scattered points, with 3 mm noise."""
    xy = rng.uniform(-1.5, 1.5, (n_floor, 2))
    floor = np.column_stack([xy, floor_z + xy[:, 1] * np.tan(np.deg2rad(tilt_deg))])
    wall = np.column_stack([np.full(150, -1.0), rng.uniform(-1.5, 1.5, 150), rng.uniform(0, 2, 150)])
    scattered = rng.uniform([-1, -1, 0], [1, 1, 1], (100, 3))
    return np.concatenate([floor, wall, scattered]) + rng.normal(0, 0.003, (n_floor + 250, 3))


def test_floor_frame_is_under_the_board_with_z_up():
    X_OF = floor_pose(ROOM)
    assert np.allclose(X_OF[:3, 2], [0, 0, 1]) and abs(X_OF[2, 3]) < 1e-12
    assert np.allclose(X_OF[:3, 0], board_pose(ROOM)[:3, 0])  # x along the board's rows
    p_B = np.array([0.1, 0.2, 0.0])  # a point on the board's face
    assert np.isclose((np.linalg.inv(floor_frame_in_board(0.002)) @ [*p_B, 1])[2], 0.002)


def test_floor_plane_of_a_room():
    plane = floor_plane(_room_points(np.random.default_rng(0)))
    assert plane.found and plane.problem() is None
    assert plane.tilt_deg < 0.5 and abs(plane.height_m) < 0.003 and plane.support > 350


@pytest.mark.parametrize("floor_z, tilt_deg, words", [(-0.75, 0.0, "cm from it"),
                                                       (2 * MAX_HEIGHT_M, 0.0, "+6.0 cm"),
                                                       (0.0, 8.0, "tilted 8")])
def test_board_off_the_floor_is_named(floor_z, tilt_deg, words):
    """A board on a table (the floor 75 cm below it), on a box, or on a slope."""
    problem = floor_plane(_room_points(np.random.default_rng(1), floor_z, tilt_deg)).problem()
    assert problem is not None and "does not lie on the floor" in problem and words in problem


def test_no_floor_in_the_points_is_not_an_error():
    rng = np.random.default_rng(2)
    walls = np.column_stack([np.full(200, -1.0), rng.uniform(-1, 1, 200), rng.uniform(0, 2, 200)])
    plane = floor_plane(walls + rng.normal(0, 0.003, walls.shape))
    assert not plane.found and plane.problem() is None


def test_floor_world_needs_the_board(capsys, tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "a.json").write_text(json.dumps({f"{i}.jpg": [i, i % 2, 0] for i in range(3)}))
    status = main(["poses", str(tmp_path / "photos"), "--out", str(tmp_path / "out"), "--anchors",
                   str(tmp_path / "a.json"), "--world", "floor"])
    assert status == 2 and "--world floor needs --charuco" in capsys.readouterr().err


@pytest.fixture(scope="module")
def turned_board_photos(tmp_path_factory):
    """Eight 1024 x 768 Drake photos of a closet in a textured room with the board turned 30 deg
    on the floor, through a distorting lens, and their truth."""
    closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
    scene = SyntheticPhotoScene(closet, 0.0, PinholeCamera.from_fov(1024, 768, np.deg2rad(50)), ROOM)
    folder = write_photo_folder(tmp_path_factory.mktemp("floor") / "photos", scene,
                                orbit_poses(8, np.array([0.4, 0.0, 0.35])), (-0.12, 0.03, 5e-4, -3e-4))
    truth = json.loads((folder / "truth.json").read_text())
    (folder.parent / "camera.json").write_text(json.dumps(truth["camera"]))
    return folder, truth


def _board_args(folder, out, *extra):
    return ["poses", str(folder), "--out", str(out), "--intrinsics", str(folder.parent / "camera.json"),
            "--charuco", "--board.square-m", "0.08", "--board.marker-m", "0.06", *extra]


def test_poses_in_the_floor_frame_match_the_rendered_ones(turned_board_photos, tmp_path, capsys):
    folder, truth = turned_board_photos
    out = tmp_path / "capture"
    assert main(_board_args(folder, out, "--board.thickness-m", "0.002", "--world", "floor")) == 0
    assert "floor:" in capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    assert report["floor"]["found"] and report["floor"]["tilt_deg"] < 1.0
    assert abs(report["floor"]["height_m"]) < 0.015
    X_FO = np.linalg.inv(np.array(truth["X_OF"]))
    capture = read_capture_set(out)
    assert len(capture.frames) == 8
    for frame in capture.frames:
        X_FC = X_FO @ np.array(truth["X_OC"][report["frames"][f"images/{frame.image_path.name}"]])
        error_m = np.linalg.norm(frame.X_OC[:3, 3] - X_FC[:3, 3])
        error_deg = np.degrees(rotation_angle(X_FC[:3, :3].T @ frame.X_OC[:3, :3]))
        assert error_m < 0.010, f"{frame.image_path.name}: centre off by {1000 * error_m:.1f} mm"
        assert error_deg < 0.5, f"{frame.image_path.name}: rotation off by {error_deg:.2f} deg"
        assert frame.X_OC[2, 3] > 0.5  # cameras above the floor: z is up


@pytest.mark.slow
def test_board_said_to_stand_above_the_floor_is_refused(turned_board_photos, tmp_path, capsys):
    """The same photos with the board's face said to be 6 cm above the floor (on a box): the floor
    that the sparse points show lies 6 cm below W's z = 0, and nothing is written. Slow: a second
    reconstruction (about 30 s)."""
    folder, _ = turned_board_photos
    out = tmp_path / "capture"
    assert main(_board_args(folder, out, "--board.thickness-m", "0.06", "--world", "floor")) == 2
    err = capsys.readouterr().err
    assert "the board does not lie on the floor" in err and "--world board" in err
    assert not out.exists()
