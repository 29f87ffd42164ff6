"""`paint_background`: a room photo's pixels off the object's mask become the training background,
those on it keep their colour; an unsure mask does not blend the room into the background.
`paint_thresholds`: the decision threshold where the object can lie, only the sure pixels kept off it.
`paint_off_object`: the painted photos and the pixels kept."""

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera, project_points
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.inference.infer import (
    PAINT_THRESHOLD,
    PAINTINGS,
    SURE_THRESHOLD,
    paint_background,
    paint_off_object,
    paint_thresholds,
)


def test_pixels_are_kept_or_painted_never_blended():
    rng = np.random.default_rng(0)
    photo = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    mask = np.tile(np.linspace(0.0, 1.0, 8, dtype=np.float32), (6, 1))  # sure off .. unsure .. sure on
    painted = paint_background([photo], [mask])[0]
    background = np.round(255 * np.asarray(DEFAULT_BACKGROUND_RGB)).astype(np.uint8)
    on = mask > PAINT_THRESHOLD
    assert painted.dtype == np.uint8 and painted.shape == photo.shape
    np.testing.assert_array_equal(painted[on], photo[on])
    np.testing.assert_array_equal(painted[~on], np.broadcast_to(background, painted[~on].shape))
    assert 0 < on.sum() < on.size  # both kinds of pixel were checked


def test_background_colour_is_the_one_asked_for():
    photo = np.full((2, 2, 3), 7, np.uint8)
    painted = paint_background([photo, photo], [np.zeros((2, 2)), np.full((2, 2), 0.4)], (0.0, 1.0, 0.5))
    for image in painted:
        np.testing.assert_array_equal(image, np.broadcast_to(np.array([0, 255, 128], np.uint8), (2, 2, 3)))


def test_threshold_asked_for():
    """With a higher threshold the pixels the segmenter leans towards but is unsure of (its spill
    beside the object, p 0.6 here) are painted, those it is sure of kept."""
    photo = np.full((1, 3, 3), 40, np.uint8)
    mask = np.array([[0.4, 0.6, 0.95]], np.float32)
    background = np.round(255 * np.asarray(DEFAULT_BACKGROUND_RGB)).astype(np.uint8)
    default = paint_background([photo], [mask])[0]
    sure = paint_background([photo], [mask], threshold=0.9)[0]
    np.testing.assert_array_equal(default[0, 1:], photo[0, 1:])
    np.testing.assert_array_equal(sure[0, :2], np.broadcast_to(background, (2, 3)))
    np.testing.assert_array_equal(sure[0, 2], photo[0, 2])


def _camera_before_object():
    """A 64 px camera 2 m in front of O's origin (+x), 0.5 m up, looking along -x; (X_WC, camera)."""
    X_WC = np.eye(4)
    X_WC[:3, :3] = np.column_stack([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])  # x_C y_C z_C
    X_WC[:3, 3] = [2.0, 0.0, 0.5]
    return X_WC, PinholeCamera.from_fov(64, 64, 1.0)


def _pixel(p_W, X_WC, camera) -> tuple[int, int]:
    uv = project_points(np.array([p_W], float), X_WC, camera)[0][0]
    return int(uv[1]), int(uv[0])  # row, column


def test_thresholds_keep_the_object_region_at_the_decision_threshold():
    """The carcass (0.4 x 0.5 x 0.3 m at O = W) and its edge are at PAINT_THRESHOLD; the floor beside
    it and in front of it (a neighbour, the spill under a front) at SURE_THRESHOLD; grown by the
    fronts' reach, the floor in front joins the object's region."""
    X_WC, camera = _camera_before_object()
    size = np.array([0.4, 0.5, 0.3])
    front = _pixel([0.2, 0.0, 0.15], X_WC, camera)
    edge = _pixel([0.2, 0.24, 0.15], X_WC, camera)
    beside = _pixel([0.2, 0.45, 0.0], X_WC, camera)
    ahead = _pixel([0.5, 0.0, 0.0], X_WC, camera)
    near = paint_thresholds(np.eye(4), size, [X_WC], [camera], [(64, 64)])[0]
    assert near.shape == (64, 64) and near.dtype == np.float32
    assert near[front] == near[edge] == PAINT_THRESHOLD
    assert near[beside] == near[ahead] == SURE_THRESHOLD
    reach = paint_thresholds(np.eye(4), size, [X_WC], [camera], [(64, 64)], reach_m=0.5)[0]
    assert reach[ahead] == PAINT_THRESHOLD and reach[beside] == SURE_THRESHOLD


def test_spill_off_the_region_is_painted_and_the_edge_on_it_kept():
    """A mask at p 0.7 on the object's edge and on its spill beside it: with the region's thresholds
    the edge is kept and the spill painted; a sure pixel off the region (p 0.95) is kept."""
    X_WC, camera = _camera_before_object()
    edge = _pixel([0.2, 0.24, 0.15], X_WC, camera)
    spill = _pixel([0.2, 0.45, 0.0], X_WC, camera)
    sure = _pixel([0.2, -0.45, 0.0], X_WC, camera)
    mask = np.zeros((64, 64), np.float32)
    mask[edge] = mask[spill] = 0.7
    mask[sure] = 0.95
    photo = np.full((64, 64, 3), 40, np.uint8)
    thresholds = paint_thresholds(np.eye(4), np.array([0.4, 0.5, 0.3]), [X_WC], [camera], [(64, 64)])
    painted = paint_background([photo], [mask], threshold=thresholds)[0]
    background = np.round(255 * np.asarray(DEFAULT_BACKGROUND_RGB)).astype(np.uint8)
    np.testing.assert_array_equal(painted[edge], photo[edge])
    np.testing.assert_array_equal(painted[sure], photo[sure])
    np.testing.assert_array_equal(painted[spill], background)


def test_beyond_where_open_fronts_reach_even_sure_pixels_are_painted():
    """With the fronts' reach (0.5 m here): the carcass at PAINT_THRESHOLD, the floor in front of
    it (where a front opens) at SURE_THRESHOLD, and a neighbour 0.7 m to the side, which no front
    reaches, painted even where the segmenter is sure of it (p 0.99)."""
    X_WC, camera = _camera_before_object()
    front = _pixel([0.2, 0.0, 0.15], X_WC, camera)
    ahead = _pixel([0.5, 0.0, 0.0], X_WC, camera)
    neighbour = _pixel([-0.1, 0.7, 0.0], X_WC, camera)
    thresholds = paint_thresholds(np.eye(4), np.array([0.4, 0.5, 0.3]), [X_WC], [camera], [(64, 64)],
                                  front_reach_m=0.5)
    assert thresholds[0][front] == PAINT_THRESHOLD and thresholds[0][ahead] == SURE_THRESHOLD
    mask = np.full((64, 64), 0.99, np.float32)
    photo = np.full((64, 64, 3), 40, np.uint8)
    painted = paint_background([photo], [mask], threshold=thresholds)[0]
    background = np.round(255 * np.asarray(DEFAULT_BACKGROUND_RGB)).astype(np.uint8)
    np.testing.assert_array_equal(painted[ahead], photo[ahead])
    np.testing.assert_array_equal(painted[neighbour], background)


@pytest.mark.parametrize("painting", PAINTINGS)
def test_paint_off_object_says_which_pixels_it_kept(painting):
    """Every painting's kept pixels are exactly those left as in the photo; "sure" keeps fewer of
    an unsure mask (p 0.7) than "region"; "fronts" none of a sure neighbour no front reaches."""
    X_WC, camera = _camera_before_object()
    rng = np.random.default_rng(3)
    mask = rng.choice([0.3, 0.7, 0.99], size=(64, 64)).astype(np.float32)
    photo = np.full((64, 64, 3), 40, np.uint8)
    painted, kept = paint_off_object([photo], [mask], [X_WC], [camera], np.eye(4), np.array([0.4, 0.5, 0.3]),
                                     painting=painting)
    assert kept[0].dtype == bool and kept[0].shape == (64, 64)
    np.testing.assert_array_equal(np.all(painted[0] == photo, axis=-1), kept[0])
    edge = _pixel([0.2, 0.24, 0.15], X_WC, camera)
    neighbour = _pixel([-0.1, 0.7, 0.0], X_WC, camera)
    assert kept[0][edge] == (mask[edge] > (SURE_THRESHOLD if painting == "sure" else PAINT_THRESHOLD))
    assert kept[0][neighbour] == (painting != "fronts" and mask[neighbour] > SURE_THRESHOLD)
