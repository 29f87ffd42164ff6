"""`infer --estimate-pose --masks segmenter` on large photos: the segmenter runs near the scale it
was trained at and the pose is estimated from masks of `MASK_SIZE_PX`, the masks for the fit's loss
keep the photo's size."""

import numpy as np
import pytest

from nfr_drake.inference import infer
from nfr_drake.inference.infer import MASK_SIZE_PX, object_masks, shrunk


class _RecordingSegmenter:
    """Stands in for the segmenter: records the image sizes it is given, marks the left half."""

    def __init__(self):
        self.sizes = []

    def object_mask(self, image):
        self.sizes.append(image.shape[:2])
        mask = np.zeros(image.shape[:2], np.float32)
        mask[:, : image.shape[1] // 2] = 1.0
        return mask


def test_shrunk_keeps_small_images_and_the_aspect():
    assert shrunk(np.zeros((100, 80))).shape == (100, 80)
    assert shrunk(np.zeros((768, 1024, 3), np.uint8)).shape == (192, 256, 3)


def test_segmenter_sees_shrunk_photos_and_masks_keep_the_photo_size(monkeypatch, tmp_path):
    net = _RecordingSegmenter()
    monkeypatch.setattr("nfr_drake.perception.segmentation.model.load_segmenter", lambda folder: (net, {}))
    masks = object_masks([np.zeros((768, 1024, 3), np.uint8)] * 2, tmp_path)
    assert net.sizes == [(192, 256)] * 2
    assert [m.shape for m in masks] == [(768, 1024)] * 2
    assert masks[0][:, :500].min() > 0.99 and masks[0][:, 524:].max() < 0.01


def test_pose_is_estimated_from_shrunk_masks(monkeypatch):
    """Ten 1024 px masks made the visual hull take minutes: the estimate gets them at MASK_SIZE_PX."""
    seen = []

    class Stop(Exception):
        pass

    def estimate(masks, X_WCs, cameras, category=None):
        seen.extend(m.shape for m in masks)
        raise Stop

    monkeypatch.setattr(infer, "estimate_object_pose", estimate)

    class _Capture:
        frames = [type("F", (), {"X_OC": np.eye(4), "camera": None})()] * 3

        def load_images(self):
            return [np.zeros((768, 1024, 3), np.uint8)] * 3

    with pytest.raises(Stop):
        infer.infer_in_world(type("Fitted", (), {"category": "closet"})(), _Capture(), None,
                             np.linspace(0, 1, 3), [np.ones((768, 1024))] * 3)
    assert seen == [(MASK_SIZE_PX * 3 // 4, MASK_SIZE_PX)] * 3
