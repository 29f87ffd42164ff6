"""Training data of the detector: crops of rendered images with their handle masks (label class
3) and, per pixel, the offset to the projected handle keypoint (the grip centre)."""

from __future__ import annotations

import numpy as np
import torch

from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.objects import SemanticClass


def projected_handle(data: RenderedDataset, j: int, a: int, v: int) -> np.ndarray:
    """Pixel (u, v) (top-left pixel centre at (0.5, 0.5)) of the handle keypoint of object j at
    articulation a in view v."""
    rec = data.records[j]
    p_O = rec.keypoints[a, data.keypoint_names.index("handle")].astype(np.float64)
    X_OC = rec.X_OC[a, v].astype(np.float64)
    p_C = X_OC[:3, :3].T @ (p_O - X_OC[:3, 3])
    return (data.camera.K @ (p_C / p_C[2]))[:2]


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
        u, w = projected_handle(data, j, a, v)
        offset[b, 0] = u - (c0 + np.arange(c) + 0.5)[None, :]
        offset[b, 1] = w - (r0 + np.arange(c) + 0.5)[:, None]
    flip = rng.random(n) < 0.5  # mirror images: hinges on either side look alike
    rgb[flip], mask[flip] = rgb[flip, :, ::-1], mask[flip, :, ::-1]
    offset[flip] = offset[flip, :, :, ::-1]
    offset[flip, 0] *= -1.0
    return (torch.from_numpy(rgb).permute(0, 3, 1, 2).contiguous(),
            torch.from_numpy(mask.astype(np.float32)), torch.from_numpy(offset))
