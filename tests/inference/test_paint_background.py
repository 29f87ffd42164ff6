"""`paint_background`: a room photo's pixels off the object's mask become the training background,
those on it keep their colour; an unsure mask does not blend the room into the background."""

import numpy as np

from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.inference.infer import PAINT_THRESHOLD, paint_background


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
