"""The segmenter's crop stage: a crop segmented at the network's input size and pasted back, the
square around a mask, the crop of each posed view around the object's floor box."""

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.perception.object_pose import (
    box_corners_W,
    category_size_ranges,
    estimate_object_pose,
    project_points,
)
from nfr_drake.perception.segmentation import crop
from nfr_drake.perception.segmentation.model import (
    SEGMENT_PX,
    Segmenter,
    SegmenterConfig,
    square_around,
    square_box,
)

SMALL = SegmenterConfig(channels=4, levels=2, bottleneck_dilations=(2,))
CAMERA = PinholeCamera.from_fov(128, 128, math.radians(50.0))


class Bright(Segmenter):
    """A stand-in network: the object and its amodal carcass are where the image is bright;
    records the sizes it is fed."""

    def __init__(self):
        super().__init__(SMALL)
        self.seen: list[tuple[int, int]] = []

    def _probabilities(self, image: np.ndarray) -> np.ndarray:
        self.seen.append(image.shape[:2])
        p = (image.mean(-1) > 128).astype(np.float32)
        return np.stack([1.0 - p, p, 0 * p, 0 * p, p], -1)


def _square_image(size: int, x0: int, y0: int, side: int) -> np.ndarray:
    image = np.full((size, size, 3), 30, np.uint8)
    image[y0:y0 + side, x0:x0 + side] = 220
    return image


def test_a_crop_is_segmented_at_the_input_size_and_pasted_back():
    net = Bright()
    image = _square_image(256, 100, 120, 20)
    mask = net.object_mask(image, box=(90, 110, 130, 150))
    assert mask.shape == (256, 256) and mask.dtype == np.float32
    assert net.seen[-1] == (SEGMENT_PX, SEGMENT_PX)  # the 40 px crop enlarged to the input size
    assert mask[:110].max() == 0 and mask[150:].max() == 0 and mask[:, :90].max() == 0
    inside = mask[125:135, 105:115]
    assert inside.min() > 0.9
    truth = np.zeros((256, 256), bool)
    truth[120:140, 100:120] = True
    assert np.count_nonzero((mask > 0.5) ^ truth) <= 2 * 20 * 2  # at most a pixel off along the outline


def test_a_box_beyond_the_image_is_clipped_and_an_empty_one_gives_nothing():
    net = Bright()
    image = _square_image(64, 0, 0, 20)
    mask = net.object_mask(image, box=(-30, -30, 30, 30))
    assert mask.shape == (64, 64) and mask[:15, :15].min() > 0.9 and mask[:, 30:].max() == 0
    assert net.object_mask(image, box=(70, 70, 90, 90)).max() == 0.0


def test_square_around_a_mask():
    mask = np.zeros((100, 100), bool)
    mask[20:30, 40:80] = True  # 40 wide, 10 high
    box = square_box(mask, margin=0.25)
    assert box == square_around(40, 20, 80, 30, 0.25)
    x0, y0, x1, y1 = box
    assert x1 - x0 == pytest.approx(60, abs=1) and y1 - y0 == pytest.approx(60, abs=1)
    assert (x0 + x1) / 2 == pytest.approx(60, abs=0.5) and (y0 + y1) / 2 == pytest.approx(25, abs=0.5)
    assert square_box(np.zeros((10, 10), bool)) is None


def test_close_look_zooms_in_on_a_small_object():
    """The first look sees the 256 px photo at 96 px, the second the crop around its mask."""
    net = Bright()
    image = _square_image(256, 200, 30, 16)
    mask = net.close_look(image, margin=0.5)
    assert net.seen == [(SEGMENT_PX, SEGMENT_PX), (SEGMENT_PX, SEGMENT_PX)]
    assert mask[30:46, 200:216].min() > 0.9 and mask[:, :180].max() == 0
    assert np.array_equal(net.close_look(np.zeros((64, 64, 3), np.uint8)), np.zeros((64, 64), np.float32))


def test_each_view_crops_around_the_boxs_projection():
    box = np.array([0.3, -0.2, 0.4, 0.45, 0.6, 0.8])  # x, y, yaw, depth, width, height
    centre = np.array([0.3, -0.2, 0.4])
    X_WCs = [look_at(centre + [2.0 * math.cos(a), 2.0 * math.sin(a), 0.8], centre) for a in (0.0, 0.6, -0.7)]
    boxes = crop.view_boxes(box, X_WCs, [CAMERA] * 3, [(128, 128)] * 3, margin=0.2, reach=0.0)
    for X_WC, (x0, y0, x1, y1) in zip(X_WCs, boxes, strict=True):
        uv, _ = project_points(box_corners_W(box), X_WC, CAMERA)
        assert np.all((uv[:, 0] > x0) & (uv[:, 0] < x1) & (uv[:, 1] > y0) & (uv[:, 1] < y1))
        side = max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1]))
        assert x1 - x0 == pytest.approx(1.4 * side, abs=2) and abs((y1 - y0) - (x1 - x0)) <= 1
    reached = crop.view_boxes(box, X_WCs, [CAMERA] * 3, [(128, 128)] * 3, margin=0.2, reach=0.5)
    # the fronts' sweep widens the crop
    assert all((b[2] - b[0]) > (a[2] - a[0]) for a, b in zip(boxes, reached, strict=True))
    behind = crop.view_boxes(box, [look_at(centre + [0.1, 0.0, 0.1], centre + [1.0, 0.0, 0.1])], [CAMERA],
                             [(128, 128)], reach=0.0)
    assert behind == [None]


def _box_photos(rng, box: np.ndarray, n: int = 8):
    """Photos (128, 128, 3) of a bright floor box (x, y, yaw, depth, width, height) on a dark
    ground from n cameras in front of it, a bright blob in a far corner of each (spill that is not
    the object), its true masks and the camera poses."""
    photos, trues, X_WCs = [], [], []
    centre = np.array([box[0], box[1], box[5] / 2])
    for _ in range(n):
        az, el, dist = box[2] + rng.uniform(-1.0, 1.0), rng.uniform(0.2, 0.7), rng.uniform(2.5, 3.5)
        direction = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        eye = centre + dist * direction
        X_WC = look_at(eye, centre)
        uv, _ = project_points(box_corners_W(box), X_WC, CAMERA)
        true = np.zeros((128, 128), np.uint8)
        cv2.fillConvexPoly(true, cv2.convexHull(np.round((uv - 0.5) * 16).astype(np.int32)), 1, shift=4)
        photo = np.full((128, 128, 3), 30, np.uint8)
        photo[true > 0] = 220
        corner = rng.integers(0, 2, 2) * 112
        photo[corner[0]:corner[0] + 16, corner[1]:corner[1] + 16] = 220
        photos.append(photo)
        trues.append(true > 0)
        X_WCs.append(X_WC)
    return photos, trues, X_WCs


def test_the_posed_crop_stage_keeps_the_object_and_drops_spill_beyond_its_box():
    rng = np.random.default_rng(3)
    box = np.array([0.5, -0.3, 0.3, 0.45, 0.55, 0.5])
    photos, trues, X_WCs = _box_photos(rng, box)
    net = Bright()
    first = [net.object_mask(photo) > 0.5 for photo in photos]
    masks = crop.posed_close_look(net, photos, X_WCs, [CAMERA] * len(photos), reach=0.0)
    iou = lambda a, b: np.count_nonzero(a & b) / np.count_nonzero(a | b)  # noqa: E731
    assert all(iou(f, t) < 0.85 for f, t in zip(first, trues, strict=True))  # the blob is in the first look
    assert all(iou(m > 0.5, t) > 0.9 for m, t in zip(masks, trues, strict=True))
    assert len(net.seen) == 3 * len(photos)  # the first looks (this test's and the stage's), the crops


def test_eval_segmenter_crops_each_articulation_with_its_own_cameras(tmp_path, monkeypatch):
    """`--crop posed`: the crop stage runs once per (room, articulation) on its views, with their
    camera poses in the room's frame, and each mask lands on its own image."""
    from nfr_drake.data.room_dataset import RoomDatasetSpec, generate_rooms
    from nfr_drake.data.rooms import RoomDistribution
    from nfr_drake.perception.segmentation import evaluation
    from nfr_drake.perception.segmentation.data import RoomImages

    root = tmp_path / "rooms"
    spec = RoomDatasetSpec("drawer", 2, articulations=2, views=3, size=32,
                           room=RoomDistribution(clutter=(0, 1), neighbours=(0, 0)))
    generate_rooms(spec, root, progress=False)
    data = RoomImages([root])
    calls = []

    def stage(net, images, X_WCs, cameras, category):
        calls.append((images, X_WCs, category))
        return [np.full(image.shape[:2], len(calls), np.float32) for image in images]

    monkeypatch.setattr(evaluation, "posed_close_look", stage)
    masks = evaluation.predicted_masks(Bright(), data, "posed")
    assert len(calls) == 4 and all(len(images) == 3 and category == "drawer" for images, _, category in calls)
    for i, (rec, a, v) in enumerate(data.index):
        call = int(masks[i][0, 0])
        images, X_WCs, _ = calls[call - 1]
        assert masks[i].shape == (32, 32)
        np.testing.assert_array_equal(images[v], data.image(i)[0])
        np.testing.assert_allclose(X_WCs[v], rec.X_OC[a, v])


def test_the_carcass_second_look_keeps_the_carcass_and_drops_spill_beyond_its_box():
    rng = np.random.default_rng(4)
    box = np.array([-0.4, 0.6, -0.2, 0.4, 0.6, 0.45])
    photos, trues, X_WCs = _box_photos(rng, box)
    net = Bright()
    first = [net.carcass_amodal(photo) > 0.5 for photo in photos]
    masks = crop.posed_carcass_look(net, photos, X_WCs, [CAMERA] * len(photos), category="closet")
    iou = lambda a, b: np.count_nonzero(a & b) / np.count_nonzero(a | b)  # noqa: E731
    assert all(iou(f, t) < 0.85 for f, t in zip(first, trues, strict=True))
    assert all(iou(m > 0.5, t) > 0.9 for m, t in zip(masks, trues, strict=True))
    assert len(net.seen) == 3 * len(photos)


def test_the_carcass_second_look_keeps_the_first_where_it_gives_no_pose():
    net = Bright()
    dark = [np.full((128, 128, 3), 30, np.uint8) for _ in range(4)]
    X_WCs = [look_at(np.array([2.0, y, 1.0]), np.zeros(3)) for y in (-1.0, -0.3, 0.3, 1.0)]
    masks = crop.posed_carcass_look(net, dark, X_WCs, [CAMERA] * 4)
    assert all(not m.any() for m in masks) and len(net.seen) == 4


def test_the_aim_is_where_the_optical_axes_meet():
    rng = np.random.default_rng(5)
    target = np.array([0.4, -0.7, 0.35])
    X_WCs = [look_at(target + [2.0 * math.cos(a), 2.0 * math.sin(a), 0.9], target)
             for a in (-0.8, -0.2, 0.5, 0.9)]
    np.testing.assert_allclose(crop.aim_point(X_WCs), target, atol=1e-9)
    jittered = [look_at(X[:3, 3], target + rng.normal(0.0, 0.03, 3)) for X in X_WCs]
    assert np.linalg.norm(crop.aim_point(jittered) - target) < 0.06
    # views from one direction meet nowhere in particular; a point behind the cameras is no aim
    parallel = [look_at(np.array([2.0, y, 1.0]), np.array([0.0, y, 1.0])) for y in (-0.5, 0.0, 0.5)]
    assert crop.aim_point(parallel) is None
    away = [look_at(X[:3, 3], 2 * X[:3, 3] - target) for X in X_WCs]
    assert crop.aim_point(away) is None


def test_the_aimed_box_is_the_categorys_middle_size_under_the_aim_facing_the_cameras():
    target = np.array([1.0, 0.5, 0.3])
    X_WCs = [look_at(target + [2.0, 2.0 * s, 0.8], target) for s in (-0.4, 0.0, 0.4)]
    box = crop.aimed_box(X_WCs, "drawer")
    (d0, d1), (w0, w1), (h0, h1) = category_size_ranges("drawer")
    np.testing.assert_allclose(box[:2], target[:2], atol=1e-9)
    assert box[2] == pytest.approx(0.0, abs=1e-9)  # +x toward the cameras
    np.testing.assert_allclose(box[3:], [(d0 + d1) / 2, (w0 + w1) / 2, np.clip(0.6, h0, h1)])


class Largest(Bright):
    """A stand-in network that takes the most prominent piece in view for the object: the largest
    bright region of its input is the object and its amodal carcass."""

    def _probabilities(self, image: np.ndarray) -> np.ndarray:
        count, labels, stats, _ = cv2.connectedComponentsWithStats((image.mean(-1) > 128).astype(np.uint8))
        p = (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))) if count > 1 else labels < 0
        p = p.astype(np.float32)
        return np.stack([1.0 - p, p, 0 * p, 0 * p, p], -1)


def test_the_aimed_look_finds_the_object_the_cameras_aim_at_not_the_one_beside_it():
    """Two bright floor boxes, the cameras aimed at the smaller, a network that takes the largest
    piece in view for the object: from whole photos the pose is the larger neighbour's; the aimed
    look's pose is the aimed-at box's, and its masks cover it."""
    rng = np.random.default_rng(6)
    target = np.array([0.0, 0.0, 0.0, 0.4, 0.45, 0.5])
    neighbour = np.array([0.0, 0.95, 0.0, 0.5, 0.7, 0.8])
    centre = np.array([0.0, 0.0, 0.25])
    photos, trues, X_WCs = [], [], []
    for _ in range(8):
        az, el, dist = rng.uniform(-0.8, 0.8), rng.uniform(0.3, 0.7), rng.uniform(2.0, 2.5)
        X_WC = look_at(centre + dist * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                                                 math.sin(el)]), centre + rng.normal(0.0, 0.03, 3))
        masks = []
        for box in (target, neighbour):
            uv, _ = project_points(box_corners_W(box), X_WC, CAMERA)
            mask = np.zeros((128, 128), np.uint8)
            cv2.fillConvexPoly(mask, cv2.convexHull(np.round((uv - 0.5) * 16).astype(np.int32)), 1, shift=4)
            masks.append(mask > 0)
        photo = np.full((128, 128, 3), 30, np.uint8)
        photo[masks[0] | masks[1]] = 220
        photos.append(photo)
        trues.append(masks[0] & ~masks[1])  # what of the target the neighbour leaves in view
        X_WCs.append(X_WC)
    net = Largest()
    net.config = replace(net.config, amodal=True)
    whole = estimate_object_pose([net.carcass_amodal(p) for p in photos], X_WCs, [CAMERA] * 8,
                                 category="drawer", amodal=True)
    assert np.linalg.norm(whole.box[:2] - neighbour[:2]) < 0.1  # whole photos: the neighbour
    masks, carcass, estimate = crop.aimed_looks(net, photos, X_WCs, [CAMERA] * 8, "drawer")
    assert np.linalg.norm(estimate.box[:2] - target[:2]) < 0.06  # the neighbour lies 0.95 m away
    assert len(masks) == len(carcass) == 8
    covered = [np.count_nonzero((m > 0.5) & t) / np.count_nonzero(t)
               for m, t in zip(masks, trues, strict=True)]
    assert min(covered) > 0.9
