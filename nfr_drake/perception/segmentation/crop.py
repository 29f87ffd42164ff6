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
"""

from __future__ import annotations

import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.perception.object_pose import (
    HullConfig,
    ObjectPoseError,
    box_image_rect,
    estimate_object_pose,
)
from nfr_drake.perception.segmentation.model import CROP_MARGIN, SEGMENT_PX, Box, Segmenter, square_around

REACH = 0.5
"""How far the crop's box reaches in front of the fitted floor box, as a fraction of the box's
larger horizontal side: an open door sweeps up to its width forward, a drawer up to its depth,
and the floor box settles on the carcass."""


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
