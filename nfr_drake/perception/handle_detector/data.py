"""Training data of the detector: crops of rendered images with their handle masks (label class
3) and, per pixel, the offset to the projected handle keypoint (the grip centre) of the pixel's
own part: furniture (several fronts) has one handle per front, and a handle pixel votes for its
front's grip centre (the part image `part.npy`); closets and drawers have one. For the front
outputs (furniture): whole images scaled to `FRONT_HEIGHT_PX` rows with, per pixel of a front,
whether it is a door and the offsets to its projected face corners (meta.json `face_corners`)."""

from __future__ import annotations

import cv2
import numpy as np
import torch

from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.objects import SemanticClass
from nfr_drake.perception.front_reading import FRONT_HEIGHT_PX


def handle_points(data: RenderedDataset, j: int, a: int) -> np.ndarray:
    """Handle keypoints (P, 3) in O, m, of object j at articulation a: one per part (furniture:
    front k in row k), one for closets and drawers."""
    rec = data.records[j]
    if data.has_parts:
        return np.array([part["keypoints"]["handle"][a] for part in rec.meta["parts"]], np.float64)
    return rec.keypoints[a, data.keypoint_names.index("handle")][None].astype(np.float64)


def projected_handles(data: RenderedDataset, j: int, a: int, v: int) -> np.ndarray:
    """Pixels (P, 2) (u, v; top-left pixel centre at (0.5, 0.5)) of the handle keypoints
    (`handle_points`) of object j at articulation a in view v."""
    return project_points(data, j, a, v, handle_points(data, j, a))


def project_points(data: RenderedDataset, j: int, a: int, v: int, p_O: np.ndarray) -> np.ndarray:
    """Pixels (..., 2) (top-left pixel centre at (0.5, 0.5)) of points p_O (..., 3) in view v of
    object j at articulation a."""
    X_OC = data.records[j].X_OC[a, v].astype(np.float64)
    p_C = (np.asarray(p_O, np.float64) - X_OC[:3, 3]) @ X_OC[:3, :3]
    return (p_C / p_C[..., 2:]) @ data.camera.K[:2].T


def sample_batch(data: RenderedDataset, n: int, crop: int, rng: np.random.Generator):
    """n random images of `data`, cut to crop x crop px (3 in 4 about a handle pixel where the
    image shows one): rgb (n, 3, c, c) float32 in [0, 1], handle mask (n, c, c) float32 and the
    offset of every pixel to the projected handle keypoint (n, 2, c, c) float32, px."""
    A, V, S = data.spec.articulations, data.spec.views, data.spec.size
    c = min(crop, S)
    rgb, mask = np.empty((n, c, c, 3), np.float32), np.empty((n, c, c), bool)
    offset = np.empty((n, 2, c, c), np.float32)
    for b, (j, a, v) in enumerate(zip(rng.integers(0, data.num_objects, n),
                                      rng.integers(0, A, n), rng.integers(0, V, n), strict=True)):
        rec = data.records[j]
        handle = np.asarray(rec.label[a, v]) == SemanticClass.HANDLE
        rows, cols = np.nonzero(handle)
        if rows.size and rng.random() < 0.75:
            k = rng.integers(rows.size)
            r0 = np.clip(rows[k] - rng.integers(0, c), 0, S - c)
            c0 = np.clip(cols[k] - rng.integers(0, c), 0, S - c)
        else:
            r0, c0 = rng.integers(0, S - c + 1, 2)
        rgb[b] = np.asarray(rec.rgb[a, v, r0:r0 + c, c0:c0 + c], np.float32) / 255.0
        mask[b] = handle[r0:r0 + c, c0:c0 + c]
        uv = projected_handles(data, j, a, v)
        if data.has_parts:  # each pixel's target: its front's handle (none: the crop's centre)
            part = np.asarray(rec.part[a, v, r0:r0 + c, c0:c0 + c], np.int64)
            target = np.where((part >= 0)[..., None], uv[np.clip(part, 0, len(uv) - 1)],
                              [c0 + c / 2, r0 + c / 2])
        else:
            target = np.broadcast_to(uv[0], (c, c, 2))
        offset[b, 0] = target[..., 0] - (c0 + np.arange(c) + 0.5)[None, :]
        offset[b, 1] = target[..., 1] - (r0 + np.arange(c) + 0.5)[:, None]
    flip = rng.random(n) < 0.5  # mirror images: hinges on either side look alike
    rgb[flip], mask[flip] = rgb[flip, :, ::-1], mask[flip, :, ::-1]
    offset[flip] = offset[flip, :, :, ::-1]
    offset[flip, 0] *= -1.0
    return (torch.from_numpy(rgb).permute(0, 3, 1, 2).contiguous(),
            torch.from_numpy(mask.astype(np.float32)), torch.from_numpy(offset))


def sample_front_batch(data: RenderedDataset, n: int, rng: np.random.Generator):
    """n random whole images of a furniture dataset scaled to FRONT_HEIGHT_PX rows (h x w): rgb
    (n, 3, h, w) float32 in [0, 1]; front mask (n, h, w) float32 (the pixel shows a front);
    door (n, h, w) float32 (its front is a door); corner offsets (n, 4, 2, h, w) float32, map
    pixels, to its front's projected face corners (`FACE_CORNERS` order). Half the images are
    mirrored, their left and right corners swapped."""
    if not data.has_parts:
        raise ValueError(f"{data.root}: front outputs need a furniture dataset")
    A, V, S = data.spec.articulations, data.spec.views, data.spec.size
    h = FRONT_HEIGHT_PX
    scale = S / h
    w = round(S / scale)
    rgb = np.empty((n, h, w, 3), np.float32)
    front, door = np.zeros((n, h, w), bool), np.zeros((n, h, w), bool)
    offset = np.zeros((n, 4, 2, h, w), np.float32)
    centres_u, centres_v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    for b, (j, a, v) in enumerate(zip(rng.integers(0, data.num_objects, n),
                                      rng.integers(0, A, n), rng.integers(0, V, n), strict=True)):
        rec = data.records[j]
        rgb[b] = cv2.resize(np.asarray(rec.rgb[a, v]), (w, h), interpolation=cv2.INTER_AREA) / 255.0
        part = cv2.resize(np.asarray(rec.part[a, v], np.int32).astype(np.float32), (w, h),
                          interpolation=cv2.INTER_NEAREST).astype(np.int64)
        parts = rec.meta["parts"]
        corners = project_points(data, j, a, v, np.array([p["face_corners"][a] for p in parts])) / scale
        front[b] = part >= 0
        k = np.clip(part, 0, len(parts) - 1)
        door[b] = front[b] & np.array([p["type"] == "door" for p in parts])[k]
        for c in range(4):
            offset[b, c, 0] = np.where(front[b], corners[k, c, 0] - centres_u, 0.0)
            offset[b, c, 1] = np.where(front[b], corners[k, c, 1] - centres_v, 0.0)
    flip = rng.random(n) < 0.5
    rgb[flip], front[flip], door[flip] = rgb[flip, :, ::-1], front[flip, :, ::-1], door[flip, :, ::-1]
    offset[flip] = offset[flip][..., ::-1][:, [1, 0, 3, 2]]
    offset[flip, :, 0] *= -1.0
    return (torch.from_numpy(rgb).permute(0, 3, 1, 2).contiguous(),
            torch.from_numpy(front.astype(np.float32)), torch.from_numpy(door.astype(np.float32)),
            torch.from_numpy(np.ascontiguousarray(offset)))
