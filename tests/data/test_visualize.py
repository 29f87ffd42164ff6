"""The one image grid and label colouring serve uint8 and float images alike."""

import numpy as np

from nfr_drake.data.visualize import SEMANTIC_PALETTE, as_uint8, colorize_labels, image_grid


def test_as_uint8_scales_and_clips_floats_and_keeps_uint8():
    np.testing.assert_array_equal(as_uint8(np.array([-0.5, 0.0, 0.5, 1.0, 2.0])), [0, 0, 128, 255, 255])
    image = np.arange(12, dtype=np.uint8).reshape(2, 2, 3)
    assert as_uint8(image) is image


def test_colorize_labels_takes_a_batch_and_clips_unknown_classes():
    labels = np.array([[[0, 1], [2, 3]], [[3, 9], [-1, 0]]])
    colours = colorize_labels(labels)
    assert colours.shape == (2, 2, 2, 3) and colours.dtype == np.uint8
    np.testing.assert_array_equal(colours[1, 0, 1], SEMANTIC_PALETTE[3])
    np.testing.assert_array_equal(colours[1, 1, 0], SEMANTIC_PALETTE[0])


def test_image_grid_mixes_float_and_uint8_and_scales_pixels():
    grey = np.full((2, 3, 3), 0.5, np.float32)
    rgba = np.zeros((2, 3, 4), np.float32)
    labels = colorize_labels(np.full((2, 3), 3))
    grid = image_grid([[grey, labels], [rgba]], pad=1, scale=2)
    assert grid.dtype == np.uint8 and grid.shape == (2 * (4 + 1) + 1, 2 * (6 + 1) + 1, 3)
    np.testing.assert_array_equal(grid[1:5, 1:7], 128)
    np.testing.assert_array_equal(grid[1:5, 8:14], np.broadcast_to(SEMANTIC_PALETTE[3], (4, 6, 3)))
    np.testing.assert_array_equal(grid[6:10, 1:7], 0)
    np.testing.assert_array_equal(grid[6:10, 8:14], 255)  # a missing cell stays the fill
    np.testing.assert_array_equal(grid[0], 255)
