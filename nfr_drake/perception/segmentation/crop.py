"""The crop stage over posed views: a second, close look at the object in each photo.

The first look segments each whole photo (`Segmenter.object_mask`); in a room its mask spreads
over textures it has not learnt (floors, walls, the furniture beside the object; docs/ROOMS.md,
"The crop stage"). The masks of all views give the object's pose and floor box
(`perception.object_pose.estimate_object_pose`); that box, grown forward by what its fronts may
sweep when open (`reach`), projected into each view and widened by `margin`, is the crop of that
view, which the segmenter looks at again at its input size (`Segmenter.object_mask(box=...)`,
the mask 0 outside the crop). Without a pose (the first masks agree on no object) each view gets
the single-photo second look (`Segmenter.close_look`: the crop around its own first mask).
The carcass's amodal masks get the same second look (`posed_carcass_look`), at the crop around the
carcass's box from the first amodal masks, not grown forward (the carcass has no fronts).

The object is the one the cameras aim at (`aim_point`, where their optical axes meet). A whole
photo also holds the furniture beside the object, which the segmenter can take for it (a drawer
unit beside a drawer); a pose whose floor box does not hold the aim point (`aimed_at`) is then not
the object's. The aimed look (`aimed_looks`) starts at the aim instead of from whole photos: the
carcass's amodal masks are looked at in the crop around a box of the category's middle size there
(`aimed_box`), the pose comes from those masks, and the object's masks from the crop around that
pose's box; the crop around the aim leaves most of a neighbour out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.perception.object_pose import (
    HullConfig,
    ObjectPoseError,
    ObjectPoseEstimate,
    box_image_rect,
    category_size_ranges,
    estimate_object_pose,
    estimate_object_pose_carcass_first,
)
from nfr_drake.perception.segmentation.model import CROP_MARGIN, SEGMENT_PX, Box, Segmenter, square_around

REACH = 0.5
"""How far the crop's box reaches in front of the fitted floor box, as a fraction of the box's
larger horizontal side: an open door sweeps up to its width forward, a drawer up to its depth,
and the floor box settles on the carcass."""

AimedLook = Literal["off-aim", "always", "never"]
"""When the aimed look gives the pose and masks (with the crop stage and an estimated pose):
"off-aim", where the whole photos' pose has a floor box that does not hold the aim point, or
none; "always", before the whole photos (which then run only where it gives no pose); "never"."""

AIM_MIN_SPREAD_DEG = 10.0
"""Cameras have an aim (`aim_point`) only when their viewing directions spread about this much: the
optical axes of views from one direction meet nowhere in particular."""


def view_boxes(box: np.ndarray, X_WCs: list[np.ndarray], cameras: list[PinholeCamera],
               shapes: list[tuple[int, int]], margin: float = CROP_MARGIN, reach: float = REACH
               ) -> list[Box | None]:
    """The crop of each view (pixels of an image of its `shapes` (H, W)) around the floor box
    (x, y, yaw, depth, width, height; m, rad, in W) grown forward by `reach` times its larger
    horizontal side: the square around its projection with `margin`; None where the box lies
    behind the camera."""
    x, y, yaw, depth, width, height = np.asarray(box, float)
    grow = reach * max(depth, width)
    grown = np.array([x + grow / 2 * np.cos(yaw), y + grow / 2 * np.sin(yaw), yaw, depth + grow, width,
                      height])
    boxes: list[Box | None] = []
    for X_WC, camera, shape in zip(X_WCs, cameras, shapes, strict=True):
        rect = box_image_rect(grown, np.asarray(X_WC, float), camera, shape)
        boxes.append(None if rect is None else square_around(*rect, margin))
    return boxes


def posed_close_look(net: Segmenter, images: list[np.ndarray], X_WCs: list[np.ndarray],
                     cameras: list[PinholeCamera], category: str | None = None,
                     hull: HullConfig | None = None, size: int | None = SEGMENT_PX,
                     margin: float = CROP_MARGIN, reach: float = REACH) -> list[np.ndarray]:
    """The object's mask (H, W) float32 in [0, 1] per uint8 RGB photo (H, W, 3) from the crop
    stage of the module docstring. X_WCs: camera poses (4, 4) in a floor frame W (z up, the floor
    at z = 0, metres, OpenCV axes); cameras: their intrinsics; category: the object's, when known
    (the floor box keeps within its sizes); hull: the pose's options (default `HullConfig()`)."""
    first = [net.object_mask(image, size) for image in images]
    try:
        estimate = estimate_object_pose(first, X_WCs, cameras, hull or HullConfig(), category)
    except ObjectPoseError:
        return [net.close_look(image, size=size, margin=margin) for image in images]
    boxes = view_boxes(estimate.box, X_WCs, cameras, [image.shape[:2] for image in images], margin, reach)
    return [net.close_look(image, box, size, margin) for image, box in zip(images, boxes, strict=True)]


def posed_carcass_look(net: Segmenter, images: list[np.ndarray], X_WCs: list[np.ndarray],
                       cameras: list[PinholeCamera], category: str | None = None,
                       hull: HullConfig | None = None, size: int | None = SEGMENT_PX,
                       margin: float = CROP_MARGIN) -> list[np.ndarray]:
    """The carcass's amodal mask (H, W) float32 in [0, 1] per uint8 RGB photo (H, W, 3)
    (`Segmenter.carcass_amodal`), looked at again in the crop around the carcass's floor box that
    the first look's amodal masks give (`estimate_object_pose(amodal=True)`; `reach` 0); the
    first look's masks where they give no pose, and in views the box lies behind. Arguments as in
    `posed_close_look`."""
    first = [net.carcass_amodal(image, size) for image in images]
    try:
        estimate = estimate_object_pose(first, X_WCs, cameras, hull or HullConfig(), category, amodal=True)
    except ObjectPoseError:
        return first
    boxes = view_boxes(estimate.box, X_WCs, cameras, [image.shape[:2] for image in images], margin, reach=0.0)
    return [mask if box is None else net.carcass_amodal(image, size, box)
            for image, mask, box in zip(images, first, boxes, strict=True)]


def aim_point(X_WCs: list[np.ndarray], min_spread_deg: float = AIM_MIN_SPREAD_DEG) -> np.ndarray | None:
    """Where the cameras aim: the point nearest all their optical axes (least squares), (3,) in the
    frame of the poses X_WCs ((4, 4) each, OpenCV axes: +z the optical axis), m. None when the axes
    are nearly parallel (their directions spread less than about `min_spread_deg`) or the point lies
    behind a camera."""
    origins = np.stack([np.asarray(X, float)[:3, 3] for X in X_WCs])
    axes = np.stack([np.asarray(X, float)[:3, 2] for X in X_WCs])
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    across = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]  # projections across each axis
    A, b = across.sum(0), np.einsum("nij,nj->i", across, origins)
    # two axes an angle t apart give A's smallest eigenvalue 1 - cos t over the 2 views
    if np.linalg.eigvalsh(A)[0] / len(X_WCs) < (1.0 - np.cos(np.radians(min_spread_deg))) / 2.0:
        return None
    point = np.linalg.solve(A, b)
    return point if np.all(np.einsum("ni,ni->n", point - origins, axes) > 0.0) else None


def aimed_at(box: np.ndarray, X_WCs: list[np.ndarray]) -> bool:
    """Whether the floor box (x, y, yaw, depth, width, height; m, rad) holds the cameras'
    `aim_point` in its footprint; True when they have no aim (nothing to contradict the box)."""
    aim = aim_point(X_WCs)
    if aim is None:
        return True
    x, y, yaw, depth, width, _ = np.asarray(box, float)
    dx, dy = aim[0] - x, aim[1] - y
    along, across = np.cos(yaw) * dx + np.sin(yaw) * dy, -np.sin(yaw) * dx + np.cos(yaw) * dy
    return bool(abs(along) <= depth / 2 and abs(across) <= width / 2)


def aimed_box(X_WCs: list[np.ndarray], category: str) -> np.ndarray | None:
    """The floor box (x, y, yaw, depth, width, height; m, rad, in the floor frame of X_WCs) that the
    aimed look crops around: the category's middle carcass depth and width centred under the
    cameras' `aim_point`, +x toward the cameras' mean position, as tall as twice the aim's height
    (the cameras aim at the object's middle) within the category's heights. None without an aim."""
    aim = aim_point(X_WCs)
    if aim is None:
        return None
    (d0, d1), (w0, w1), (h0, h1) = category_size_ranges(category)
    toward = np.mean([np.asarray(X, float)[:2, 3] for X in X_WCs], 0) - aim[:2]
    return np.array([aim[0], aim[1], np.arctan2(toward[1], toward[0]), (d0 + d1) / 2, (w0 + w1) / 2,
                     np.clip(2.0 * aim[2], h0, h1)])


def aimed_looks(net: Segmenter, images: list[np.ndarray], X_WCs: list[np.ndarray],
                cameras: list[PinholeCamera], category: str, hull: HullConfig | None = None,
                size: int | None = SEGMENT_PX, margin: float = CROP_MARGIN, reach: float = REACH
                ) -> tuple[list[np.ndarray], list[np.ndarray], ObjectPoseEstimate] | None:
    """The aimed look of the module docstring: the object's masks and its carcass's amodal masks,
    (H, W) float32 in [0, 1] per uint8 RGB photo (H, W, 3), and the pose estimated from the latter
    (`estimate_object_pose(amodal=True)`). The carcass is looked at in the crop around `aimed_box`
    (the whole photo in views it lies behind), the object in the crop around the pose's box grown
    forward by `reach`. None when the cameras have no aim, the segmenter has no amodal output or
    its masks there give no pose. Other arguments as in `posed_close_look`."""
    box = aimed_box(X_WCs, category)
    if box is None or not net.config.amodal:
        return None
    shapes = [image.shape[:2] for image in images]
    crops = view_boxes(box, X_WCs, cameras, shapes, margin, reach=0.0)
    carcass = [net.carcass_amodal(image, size, crop) for image, crop in zip(images, crops, strict=True)]
    try:
        estimate = estimate_object_pose(carcass, X_WCs, cameras, hull or HullConfig(), category, amodal=True)
    except ObjectPoseError:
        return None
    crops = view_boxes(estimate.box, X_WCs, cameras, shapes, margin, reach)
    return ([net.close_look(image, crop, size, margin) for image, crop in zip(images, crops, strict=True)],
            carcass, estimate)


FIRST_LOOK = ("the crop stage's masks agree on no object; the segmenter's first look gave the pose and "
              "the masks")
"""The warning of `room_looks` when the crop stage's masks give no pose and the first look's do."""

AIMED_LOOK = ("the whole photos' masks gave a pose whose box does not hold the cameras' aim point (another "
              "piece taken for the object); the aimed look gave the pose and the masks")
"""The warning of `room_looks` when the aimed look replaced the whole photos' pose."""


@dataclass
class RoomLooks:
    """What `room_looks` found: the object's masks and the carcass's amodal masks ((H, W) float32
    per photo; carcass None without the amodal output), the pose estimate, whether the amodal
    masks gave it, whether the aimed look did, and warnings."""

    masks: list[np.ndarray]
    carcass: list[np.ndarray] | None
    estimate: ObjectPoseEstimate
    amodal: bool
    aimed: bool
    warnings: list[str] = field(default_factory=list)


def room_looks(net: Segmenter, images: list[np.ndarray], X_WCs: list[np.ndarray],
               cameras: list[PinholeCamera], category: str, hull: HullConfig | None = None,
               aimed_look: AimedLook = "off-aim") -> RoomLooks:
    """The object's masks and pose in photos of a room (uint8 RGB (H, W, 3), camera poses X_WCs
    (4, 4) in a floor frame): from whole photos, the crop stage (`posed_close_look`, and
    `posed_carcass_look` for the amodal masks that give the pose,
    `estimate_object_pose_carcass_first`; where its masks give no pose, the first look's, with
    `FIRST_LOOK`), or the aimed look's (`aimed_looks`) as `aimed_look` says: "off-aim" where the
    whole photos' floor box does not hold the cameras' aim point (`aimed_at`, with `AIMED_LOOK`)
    or they give no pose, "always" first, "never" not. ObjectPoseError when none gives a pose."""
    hull = hull or HullConfig()

    def aimed(warnings: list[str]) -> RoomLooks | None:
        looked = aimed_looks(net, images, X_WCs, cameras, category, hull)
        return None if looked is None else RoomLooks(*looked, amodal=True, aimed=True, warnings=warnings)

    if aimed_look == "always" and (first := aimed([])) is not None:
        return first
    try:
        whole = _whole_photo_looks(net, images, X_WCs, cameras, category, hull)
    except ObjectPoseError:
        fallback = aimed([]) if aimed_look == "off-aim" else None  # "always" has looked already
        if fallback is None:
            raise
        return fallback
    if aimed_look != "off-aim" or aimed_at(whole.estimate.box, X_WCs):
        return whole
    return aimed([AIMED_LOOK]) or whole


def other_look(net: Segmenter, images: list[np.ndarray], X_WCs: list[np.ndarray],
               cameras: list[PinholeCamera], category: str, first: RoomLooks, hull: HullConfig | None = None
               ) -> RoomLooks | None:
    """The look `room_looks` did not give: whole photos' after the aimed look (`first.aimed`), the
    aimed look's after whole photos; None where it gives no pose. Arguments as `room_looks`'s."""
    hull = hull or HullConfig()
    if first.aimed:
        try:
            return _whole_photo_looks(net, images, X_WCs, cameras, category, hull)
        except ObjectPoseError:
            return None
    looked = aimed_looks(net, images, X_WCs, cameras, category, hull)
    return None if looked is None else RoomLooks(*looked, amodal=True, aimed=True)


def _whole_photo_looks(net: Segmenter, images: list[np.ndarray], X_WCs: list[np.ndarray],
                       cameras: list[PinholeCamera], category: str, hull: HullConfig) -> RoomLooks:
    """`room_looks` from whole photos: the crop stage's masks, or the first look's where those give
    no pose. ObjectPoseError when neither does."""
    masks = posed_close_look(net, images, X_WCs, cameras, category, hull)
    carcass = posed_carcass_look(net, images, X_WCs, cameras, category, hull) if net.config.amodal else None
    try:
        estimate, amodal, warnings = estimate_object_pose_carcass_first(masks, carcass, X_WCs, cameras, hull,
                                                                        category)
    except ObjectPoseError:
        masks = [net.object_mask(image) for image in images]
        estimate, amodal, warnings = estimate_object_pose_carcass_first(masks, carcass, X_WCs, cameras, hull,
                                                                        category)
        warnings = warnings + [FIRST_LOOK]
    return RoomLooks(masks, carcass, estimate, amodal, False, warnings)
