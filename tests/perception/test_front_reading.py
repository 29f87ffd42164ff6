"""Reading the front behind a sighted handle: its face corners triangulated from the views'
corner votes, a door's hinge on the edge away from its handle at any opening, the shut edges that
give the canonical order; and the face corners the generator records."""

from pathlib import Path

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.capture import CaptureFrame
from nfr_drake.objects import object_rng, sample_object
from nfr_drake.objects.articulated import FACE_CORNERS
from nfr_drake.perception.front_reading import (
    FRONT_HEIGHT_PX,
    FrontMap,
    SightedFront,
    hinge_points,
    read_front,
    shut_edges,
    upright,
)
from nfr_drake.perception.handle_triangulation import TriangulatedHandle, nearest_point, project, ray


def _frames(n: int = 5, size: int = 128) -> list[CaptureFrame]:
    cam = PinholeCamera.from_fov(size, size, np.radians(50.0))
    return [CaptureFrame(Path(f"{az}.png"), look_at(np.array([2.0 * np.cos(np.radians(az)),
                                                               2.0 * np.sin(np.radians(az)), 1.0]),
                                                     np.array([0.0, 0.0, 0.5])), cam)
            for az in np.linspace(-40, 40, n)]


def _door(angle_deg: float, hinge_left: bool) -> tuple[np.ndarray, np.ndarray]:
    """A 0.4 x 0.6 m door face hinged at y = -0.2 (left) or 0.2 (right), turned outward (+x) by
    angle: its corners (4, 3) in FACE_CORNERS order and its handle 5 cm from the free edge."""
    a = np.radians(angle_deg)
    hinge_y, inward = (-0.2, 1.0) if hinge_left else (0.2, -1.0)
    along = np.array([np.sin(a), inward * np.cos(a), 0.0])  # hinge -> free edge
    hinge = np.array([0.3, hinge_y, 0.0])
    free = hinge + 0.4 * along
    left, right = (hinge, free) if hinge_left else (free, hinge)
    corners = np.array([left + [0, 0, 0.8], right + [0, 0, 0.8], left + [0, 0, 0.2], right + [0, 0, 0.2]])
    handle = hinge + 0.35 * along + [0.03 * np.cos(a), -inward * 0.03 * np.sin(a), 0.5]
    return corners, handle


def _true_map(frame: CaptureFrame, corners: np.ndarray) -> FrontMap:
    """A front map whose every pixel votes for the corners' projections, door probability 0.9."""
    scale = frame.camera.height / FRONT_HEIGHT_PX
    h = w = FRONT_HEIGHT_PX
    uv = np.array([project(frame, c) for c in corners]) / scale
    centres = np.stack(np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), -1)[:, :, None]
    return FrontMap(np.ones((h, w), np.float32), np.full((h, w), 0.9, np.float32),
                    (uv[None, None] - centres).astype(np.float32), np.array([scale, scale]))


@pytest.mark.parametrize("hinge_left", [True, False])
@pytest.mark.parametrize("angle", [0.0, 40.0, 80.0])
def test_corners_triangulate_and_the_hinge_is_the_edge_away_from_the_handle(hinge_left, angle):
    corners, handle = _door(angle, hinge_left)
    frames = _frames()
    maps = [_true_map(f, corners) for f in frames]
    front = read_front(TriangulatedHandle(handle, tuple(range(len(frames))), 0.0, len(frames)), maps, frames)
    assert front.views == len(frames) and front.is_door and front.door_probability == pytest.approx(0.9)
    np.testing.assert_allclose(front.corners, corners, atol=1e-6)
    hinge = corners[[0, 2]] if hinge_left else corners[[1, 3]]
    np.testing.assert_allclose(hinge_points(front), hinge, atol=1e-6)
    left, top = shut_edges(front)  # shut, the face spans y in [-0.2, 0.2] either way
    assert left == pytest.approx(-0.2, abs=1e-6) and top == pytest.approx(0.8, abs=1e-6)


def test_a_view_that_misreads_a_corner_moves_it_little():
    """One of five views reads the face's bottom edge 20 px lower (a stack's bottom): the points
    nearest all rays would follow it by centimetres, the median of the view pairs' points stays
    within 1 mm of the true corners."""
    corners, handle = _door(0.0, hinge_left=True)
    frames = _frames()
    maps = [_true_map(f, corners) for f in frames]
    bad = maps[2]
    offsets = bad.corner_offset_px.copy()
    offsets[:, :, 2:, 1] += 20.0 / bad.scale[1]  # bottom corners, map pixels down
    maps[2] = FrontMap(bad.front_probability, bad.door_probability, offsets, bad.scale)
    front = read_front(TriangulatedHandle(handle, tuple(range(len(frames))), 0.0, len(frames)), maps, frames)
    np.testing.assert_allclose(front.corners, corners, atol=1e-3)
    rays = [ray(f, project(f, corners[2]) + ([0.0, 20.0] if k == 2 else 0.0)) for k, f in enumerate(frames)]
    all_rays = nearest_point(np.array([o for o, _ in rays]), np.array([d for _, d in rays]))
    assert np.linalg.norm(all_rays - corners[2]) > 0.01


def test_a_drawer_keeps_its_face_edges_and_too_few_views_read_nothing():
    corners = np.array([[0.5, -0.3, 0.7], [0.5, 0.3, 0.7], [0.5, -0.3, 0.5], [0.5, 0.3, 0.5]])
    drawer = SightedFront(np.array([0.53, 0.0, 0.6]), 0.1, corners, 4)
    assert not drawer.is_door and shut_edges(drawer) == pytest.approx((-0.3, 0.7))
    frames = _frames(3)
    maps = [_true_map(f, corners) for f in frames]
    assert read_front(TriangulatedHandle(drawer.p_O, (0,), 0.0, 1), maps, frames) is None


def test_the_generator_records_each_fronts_face_corners():
    """The face corners move with the front: a door's hinge-side corners are its hinge points and
    stay; a drawer's corners slide by its travel along +x."""
    fronts = [f for i in range(4) for f in sample_object("furniture", object_rng(0, 3, i)).fronts]
    assert {f.kind for f in fronts} == {"door", "drawer"} and FACE_CORNERS[0] == "top_left"
    for front in fronts:
        shut, open_ = front.face_corners(0.0), front.face_corners(1.0)
        assert shut.shape == (4, 3) and front.face_corners(np.array([0.0, 1.0])).shape == (2, 4, 3)
        assert np.all(shut[[0, 2], 1] < shut[[1, 3], 1]) and np.all(shut[:2, 2] > shut[2:, 2])
        if front.kind == "drawer":
            np.testing.assert_allclose(open_ - shut, [[front.joint_upper, 0, 0]] * 4, atol=1e-9)
        else:
            kp = front.keypoints(0.7)
            hinge = np.array([kp["hinge_top"], kp["hinge_bottom"]])
            side = [0, 2] if np.allclose(shut[[0, 2]], hinge) else [1, 3]
            np.testing.assert_allclose(front.face_corners(0.7)[side], hinge, atol=1e-9)
            assert np.all(open_[[i for i in range(4) if i not in side], 0] > shut[0, 0] + 0.1)


def test_a_read_front_takes_its_corners_from_the_pixels_near_them():
    """Pixels vote for their own front's corners with an error that grows with the distance
    (10 % of it, all one way): the read front's corners lean on the pixels near each corner,
    closer than the handle's guess, and the neighbouring front's votes do not count."""
    h = w = FRONT_HEIGHT_PX
    rows, cols = np.mgrid[0:h, 0:w]
    centres = np.stack([cols + 0.5, rows + 0.5], -1)
    fronts = {"a": (np.array([[10, 10], [30, 10], [10, 50], [30, 50]], float), 0.95),
              "b": (np.array([[31, 10], [55, 10], [31, 30], [55, 30]], float), 0.05)}
    front = np.zeros((h, w), np.float32)
    door = np.zeros((h, w), np.float32)
    offsets = np.zeros((h, w, 4, 2), np.float32)
    for corners, p_door in fronts.values():
        inside = ((centres >= corners[0]) & (centres <= corners[3])).all(-1)
        to = corners[None, None] - centres[:, :, None]
        err = 0.1 * np.linalg.norm(to, axis=-1, keepdims=True) * np.array([1.0, 0.0])
        offsets[inside] = (to + err)[inside]
        front[inside], door[inside] = 1.0, p_door
    handle = np.array([27.0, 30.0])
    guess = (centres[:, :, None] + offsets)[np.linalg.norm(centres - handle, axis=-1) <= 1.5].mean(0)
    guess_error = np.linalg.norm(guess - fronts["a"][0], axis=1)
    p_door, corners = FrontMap(front, door, offsets, np.array([1.0, 1.0])).read(handle)
    error = np.linalg.norm(corners - fronts["a"][0], axis=1)
    assert guess_error.min() > 2.0 and np.all(error < guess_error) and error.mean() < 0.6 * guess_error.mean()
    assert p_door == pytest.approx(0.95)
    assert FrontMap(front * 0, door, offsets, np.array([1.0, 1.0])).read(handle) is None


def test_upright_squares_a_face_up_and_keeps_a_rectangle():
    corners, _ = _door(30.0, True)
    np.testing.assert_allclose(upright(corners), corners, atol=1e-12)
    noisy = corners + np.random.default_rng(0).normal(0.0, 0.01, corners.shape)
    square = upright(noisy)
    np.testing.assert_allclose(square[0, :2], square[2, :2])
    np.testing.assert_allclose(square[1, :2], square[3, :2])
    assert square[0, 2] == square[1, 2] and square[2, 2] == square[3, 2]
    assert np.abs(square - corners).mean() < np.abs(noisy - corners).mean()
