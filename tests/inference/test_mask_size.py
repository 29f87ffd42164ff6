"""`infer --estimate-pose --masks segmenter` on large photos: the segmenter runs near the scale it
was trained at and the pose is estimated from masks of `MASK_SIZE_PX`, the masks for the fit's loss
keep the photo's size."""

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import read_capture_set, write_capture_set
from nfr_drake.inference import infer
from nfr_drake.inference.infer import MASK_SIZE_PX, object_masks, shrunk
from nfr_drake.perception import object_pose


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


def _three_views(height: int, width: int):
    """A stand-in capture of three black (height, width) photos, all at X_OC = identity."""

    class _Capture:
        frames = [type("F", (), {"X_OC": np.eye(4), "camera": None})()] * 3

        def load_images(self):
            return [np.zeros((height, width, 3), np.uint8)] * 3

    return _Capture()


def test_pose_is_estimated_from_shrunk_masks(monkeypatch):
    """Ten 1024 px masks made the visual hull take minutes: the estimate gets them at MASK_SIZE_PX."""
    seen = []

    class Stop(Exception):
        pass

    def estimate(masks, X_WCs, cameras, config=None, category=None, amodal=False):
        seen.extend((m.shape, float(m.mean()), amodal) for m in masks)
        raise Stop

    monkeypatch.setattr(object_pose, "estimate_object_pose", estimate)

    with pytest.raises(Stop):
        infer.infer_in_world(type("Fitted", (), {"category": "closet"})(), _three_views(768, 1024), None,
                             np.linspace(0, 1, 3), [np.ones((768, 1024))] * 3)
    assert seen == [((MASK_SIZE_PX * 3 // 4, MASK_SIZE_PX), 1.0, False)] * 3
    seen.clear()  # the segmenter's amodal carcass, when given, makes the pose (the box is the carcass)
    with pytest.raises(Stop):
        infer.infer_in_world(type("Fitted", (), {"category": "closet"})(), _three_views(768, 1024), None,
                             np.linspace(0, 1, 3), [np.ones((768, 1024))] * 3,
                             carcass=[np.zeros((768, 1024))] * 3)
    assert seen == [((MASK_SIZE_PX * 3 // 4, MASK_SIZE_PX), 0.0, True)] * 3


def test_amodal_masks_that_give_no_pose_fall_back_to_the_visible_ones(monkeypatch):
    from nfr_drake.perception.object_pose import ObjectPoseError

    asked = []

    class Stop(Exception):
        pass

    def estimate(masks, X_WCs, cameras, config=None, category=None, amodal=False):
        asked.append(amodal)
        if amodal:
            raise ObjectPoseError("object pose: the masks agree on no object")
        raise Stop

    monkeypatch.setattr(object_pose, "estimate_object_pose", estimate)

    with pytest.raises(Stop):
        infer.infer_in_world(type("Fitted", (), {"category": "closet"})(), _three_views(60, 80), None,
                             np.linspace(0, 1, 3), [np.ones((60, 80))] * 3, carcass=[np.zeros((60, 80))] * 3)
    assert asked == [True, False]


@pytest.mark.parametrize("room_loss", ["background", "masked"])
def test_room_photos_off_the_mask_are_painted_or_left_out(monkeypatch, tmp_path, room_loss):
    """With "background" the fit sees the photo painted in the training background off the mask
    (so it cannot grow an open door where the mask is not) and every pixel counts; with "masked"
    the photo as it is and only the mask's pixels."""
    seen = {}

    class Stop(Exception):
        pass

    estimate = type("Estimate", (), {"X_WO": np.eye(4), "size": np.array([0.4, 0.5, 0.6])})()
    monkeypatch.setattr(object_pose, "estimate_object_pose", lambda *args, **kwargs: estimate)

    def fake_infer(fitted, capture, config, grid, images, source, masks, masked_loss, room,
                   refine_pose=False, kept=None):
        seen.update(images=images, masked_loss=masked_loss, kept=kept)
        raise Stop

    monkeypatch.setattr(infer, "infer", fake_infer)
    photo = np.full((40, 60, 3), 50, np.uint8)
    mask = np.zeros((40, 60), np.float32)
    mask[10:30, 20:40] = 1.0

    write_capture_set(tmp_path / "capture", [photo] * 3, [np.eye(4)] * 3, PinholeCamera.from_fov(60, 40, 1.0))
    with pytest.raises(Stop):
        infer.infer_in_world(type("Fitted", (), {"category": "closet"})(),
                             read_capture_set(tmp_path / "capture"), None, np.linspace(0, 1, 3),
                             [mask] * 3, room_loss)
    image = seen["images"][0]
    assert (image[10:30, 20:40] == 50).all()
    assert (image[0, 0] == (235 if room_loss == "background" else 50)).all()
    assert seen["masked_loss"] is (room_loss == "masked")
    if room_loss == "background":  # the painted photos' kept pixels: the mask's
        np.testing.assert_array_equal(seen["kept"][0], mask > 0.5)
    else:
        assert seen["kept"] is None


@pytest.mark.parametrize("amodal", [True, False])
def test_the_crop_stage_sees_shrunk_photos_and_gives_masks_of_the_photo_size(monkeypatch, tmp_path, amodal):
    from nfr_drake.perception.segmentation import crop

    seen = []

    def look(name: str, value: float):
        def stage(net, images, X_WCs, cameras, category, *options):
            seen.append((name, images[0].shape, len(X_WCs), category))
            return [np.full(image.shape[:2], value, np.float32) for image in images]
        return stage

    monkeypatch.setattr(crop, "posed_close_look", look("visible", 1.0))
    monkeypatch.setattr(crop, "posed_carcass_look", look("carcass", 0.5))
    monkeypatch.setattr(crop, "aimed_at", lambda box, X_WCs: True)  # the pose is of the piece aimed at
    box = np.array([1.0, 0.0, 0.0, 0.5, 0.6, 0.9])
    monkeypatch.setattr(crop, "estimate_object_pose_carcass_first", lambda *args: (
        object_pose.ObjectPoseEstimate.from_box(box, 0.0, 1, np.zeros(6)), amodal, []))
    net = type("Net", (), {"config": type("Config", (), {"amodal": amodal})()})()
    monkeypatch.setattr("nfr_drake.perception.segmentation.model.load_segmenter", lambda folder: (net, {}))
    views, carcass, looks = infer.cropped_masks([np.zeros((768, 1024, 3), np.uint8)] * 3,
                                                _three_views(768, 1024), tmp_path, "drawer")
    assert not looks.aimed
    looks = ["visible", "carcass"] if amodal else ["visible"]
    assert seen == [(name, (192, 256, 3), 3, "drawer") for name in looks]
    assert [m.shape for m in views] == [(768, 1024)] * 3 and views[0].min() == 1.0
    if amodal:
        assert [m.shape for m in carcass] == [(768, 1024)] * 3 and carcass[0].max() == 0.5
    else:
        assert carcass is None


@pytest.mark.parametrize("other", [False, True])
@pytest.mark.parametrize("holds_aim", [True, False, None])
def test_the_aimed_look_replaces_a_pose_off_the_cameras_aim(monkeypatch, tmp_path, holds_aim, other):
    """The crop stage's masks are kept when their pose's box holds the cameras' aim point; when it
    does not, or they give no pose (None), the aimed look's (on the shrunk photos). The other look
    (`other`, to look again) is the one not kept: none where the whole photos give no pose."""
    from nfr_drake.perception.object_pose import ObjectPoseError, ObjectPoseEstimate
    from nfr_drake.perception.segmentation import crop

    seen = []

    def aimed(net, images, X_WCs, cameras, category, hull):
        seen.append((images[0].shape, len(X_WCs), category))
        return ([np.full(i.shape[:2], 0.25, np.float32) for i in images],
                [np.full(i.shape[:2], 0.75, np.float32) for i in images], None)

    def estimate(*args, **kwargs):
        if holds_aim is None:
            raise ObjectPoseError("object pose: the masks agree on no object")
        box = np.array([1.0, 0.0, 0.0, 0.5, 0.6, 0.9])
        return ObjectPoseEstimate.from_box(box, 0.0, 1, np.zeros(6)), True, []

    monkeypatch.setattr(crop, "aimed_looks", aimed)
    monkeypatch.setattr(crop, "aimed_at", lambda box, X_WCs: bool(holds_aim))
    monkeypatch.setattr(crop, "posed_close_look",
                        lambda net, images, *args: [np.ones(i.shape[:2], np.float32) for i in images])
    monkeypatch.setattr(crop, "posed_carcass_look",
                        lambda net, images, *args: [np.full(i.shape[:2], 0.5, np.float32) for i in images])
    monkeypatch.setattr(crop, "estimate_object_pose_carcass_first", estimate)
    net = type("Net", (), {"config": type("Config", (), {"amodal": True})(),
                           "object_mask": lambda self, image: np.zeros(image.shape[:2], np.float32)})()
    monkeypatch.setattr("nfr_drake.perception.segmentation.model.load_segmenter", lambda folder: (net, {}))
    photos, capture = [np.zeros((768, 1024, 3), np.uint8)] * 3, _three_views(768, 1024)
    looked = infer.cropped_masks(photos, capture, tmp_path, "drawer")
    if other:  # the look the first call did not give, from that call's look
        seen.clear()
        looked = infer.cropped_masks(photos, capture, tmp_path, "drawer", after=looked[2])
    if other and holds_aim is None:
        assert looked is None and seen == []  # the aimed look gave the first: whole photos give none
        return
    views, carcass, looks = looked
    aimed = looks.aimed
    assert [m.shape for m in views] == [(768, 1024)] * 3 and [m.shape for m in carcass] == [(768, 1024)] * 3
    assert aimed == ((holds_aim is not True) != other)
    if not aimed:
        assert seen == [] and views[0].min() == 1.0
        assert carcass[0].max() == 0.5
    else:
        assert seen == [((192, 256, 3), 3, "drawer")]
        assert views[0].max() == 0.25 and carcass[0].min() == 0.75


@pytest.mark.parametrize("first_p, other_p, kept", [
    (0.2, 0.7, "other"), (0.2, 0.1, "first"), (0.8, 0.9, None)])
def test_infer_looks_again_where_the_fit_is_refused(monkeypatch, tmp_path, capsys, first_p, other_p, kept):
    """`infer --estimate-pose --mask-crop`: a fit its confidence refuses is followed by one at the
    other look's masks, the more confident written; a confident fit is fitted once."""
    import json
    from types import SimpleNamespace

    from nfr_drake.inference.result import FitResult

    looks = []

    def cropped(images, capture, segmenter, category, after=None):
        other = after is not None
        assert not other or after.aimed is False  # the first look's, handed back
        looks.append(other)
        value = 0.75 if other else 0.25
        return [np.full(i.shape[:2], value, np.float32) for i in images], None, SimpleNamespace(aimed=other)

    def in_world(fitted, capture, fit, q_grid, masks, *args, **kwargs):
        other = float(masks[0].mean()) == 0.75
        p = other_p if other else first_p
        confidence = {"p_handle_within_2cm": p, "threshold": 0.5, "weakest": None,
                      "calibration": "confidence_room.json", "features": {
                          "views": 3, "image_loss": 0.01, "image_loss_worst_view": 0.02, "room": True,
                          "silhouette_iou": 0.8, "silhouette_iou_worst_view": 0.7}}
        X_WO = np.eye(4)
        X_WO[0, 3] = 1.0 if other else 0.0
        result = FitResult("closet", 0.0, {}, np.zeros(1), {}, 0.01, 1.0, confidence=confidence,
                           extra={"warnings": [],
                                  "object_pose": {"X_WO": X_WO.tolist(), "size": [0.4, 0.5, 0.9]}})
        return result, SimpleNamespace(steps=1, focus=False), capture

    write_capture_set(tmp_path / "capture", [np.zeros((40, 60, 3), np.uint8)] * 3, [np.eye(4)] * 3,
                      PinholeCamera.from_fov(60, 40, 1.0))
    (tmp_path / "segmenter").mkdir()
    (tmp_path / "segmenter" / "config.json").write_text("{}")
    fitted = SimpleNamespace(category="closet", num_slots=1, check_capture=lambda *args: None)
    monkeypatch.setattr(infer, "FittedModel", lambda folder: fitted)
    monkeypatch.setattr(infer, "cropped_masks", cropped)
    monkeypatch.setattr(infer, "infer_in_world", in_world)
    out = tmp_path / "result.json"
    infer.infer_command(tmp_path / "capture", out=out, estimate_pose=True, mask_crop=True,
                        segmenter=tmp_path / "segmenter", threads=1)
    written = json.loads(out.read_text())
    assert looks == ([False] if kept is None else [False, True])
    assert written["extra"]["object_pose"]["X_WO"][0][3] == (1.0 if kept == "other" else 0.0)
    if kept is not None:
        assert written["extra"]["object_pose"]["looked_again"]["kept"] == kept
        assert "looking again, at the aimed look" in capsys.readouterr().out
    else:
        assert "looked_again" not in written["extra"]["object_pose"]
