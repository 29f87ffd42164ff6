"""The segmenter's masks refined by the photo's colours (`segmentation.refine`)."""

import numpy as np
import pytest

from nfr_drake.perception.segmentation.refine import refine_mask, refine_masks


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 96 px photo: a brown box (rows 30-69, columns 25-74) on a grey-blue floor, with noise, and
    its true silhouette."""
    rng = np.random.default_rng(seed)
    image = np.empty((96, 96, 3), np.float32)
    image[:] = (110, 120, 140)
    truth = np.zeros((96, 96), bool)
    truth[30:70, 25:75] = True
    image[truth] = (150, 95, 50)
    image += rng.normal(0.0, 6.0, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8), truth


def test_spill_over_the_floor_is_removed_and_the_object_kept():
    image, truth = _scene()
    mask = np.where(truth, 0.97, 0.02).astype(np.float32)
    spill = np.zeros_like(truth)
    spill[70:76, 25:75] = True  # the segmenter's spill below the front, unsure but above one half
    spill[30:70, 75:79] = True
    mask[spill] = 0.7
    mask[32:68, 27:35] = 0.8  # part of the object the segmenter is less sure of
    refined = refine_mask(image, mask)
    assert refined.dtype == np.float32 and refined.shape == mask.shape
    assert (refined[spill] == 0.0).mean() > 0.95
    np.testing.assert_array_equal(refined[truth], mask[truth])  # the object's pixels keep their probability
    assert np.all(refined <= mask)  # it only removes


def test_nothing_to_refine_is_returned_unchanged():
    image, truth = _scene()
    for mask in (np.full(truth.shape, 0.1, np.float32), np.full(truth.shape, 0.9, np.float32)):
        np.testing.assert_array_equal(refine_mask(image, mask), mask)


def test_refine_masks_each_view_and_shapes_checked():
    (a, ta), (b, tb) = _scene(0), _scene(1)
    masks = [np.where(t, 0.99, 0.0).astype(np.float32) for t in (ta, tb)]
    assert len(refine_masks([a, b], masks)) == 2
    with pytest.raises(ValueError, match="image"):
        refine_mask(a[:50], masks[0])
    with pytest.raises(ValueError):
        refine_masks([a], masks)


def test_a_refinement_that_would_take_most_of_the_mask_keeps_it():
    """A patchy mask with no sure pixel, the object the colour of the floor around it: GrabCut's
    models cannot tell them apart, and the mask is kept rather than emptied."""
    rng = np.random.default_rng(3)
    image = np.clip(rng.normal(120.0, 30.0, (64, 64, 3)), 0, 255).astype(np.uint8)
    mask = np.zeros((64, 64), np.float32)
    mask[20:44, 20:44] = 0.6 + 0.3 * rng.random((24, 24))
    out = refine_mask(image, mask)
    assert np.count_nonzero(out > 0.5) > 0.5 * np.count_nonzero(mask > 0.5)
