"""Random training rays from a rendered dataset: random images, then random pixels per image.

A share of each image's pixels is drawn from object, moving-part and handle pixels (the label image
says which), because at 64 px a handle covers a few pixels and uniform sampling would hardly see it.
Arrays are read from the dataset's memory maps; nothing is loaded up front.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from nfr_drake.data.dataset import ObjectRecord
from nfr_drake.data.slot_dataset import SlotTargets
from nfr_drake.nfr.config import SamplerConfig

MOVING_CLASS = 2
HANDLE_CLASS = 3


class RayBatch(NamedTuple):
    """B images x R pixels. uv (B, R, 2) pixel positions (centre convention 0.5); rgb (B, R, 3) in
    [0, 1]; labels int64 (B, R); K (B, 3, 3); X_OC (B, 4, 4); q (B,), or (B, S) per slot;
    keypoints (B, K, 3) in O; object_index int64 (B,); exists bool (B, S) and types int64 (B, S)
    of the slots (one slot: True and 0)."""

    uv: torch.Tensor
    rgb: torch.Tensor
    labels: torch.Tensor
    K: torch.Tensor
    X_OC: torch.Tensor
    q: torch.Tensor
    keypoints: torch.Tensor
    object_index: torch.Tensor
    exists: torch.Tensor
    types: torch.Tensor

    def to(self, device) -> RayBatch:
        return RayBatch(*(t.to(device, non_blocking=True) for t in self))


def stratified_pixels(label: np.ndarray, n: int, config: SamplerConfig,
                      rng: np.random.Generator) -> np.ndarray:
    """Flat pixel indices (n,) of one label image (S, S): handle, moving, foreground, then uniform
    shares as configured; a class absent from the image gives its share to uniform sampling."""
    flat = label.reshape(-1)
    shares = [(config.handle_fraction, flat == HANDLE_CLASS),
              (config.moving_fraction, flat == MOVING_CLASS),
              (config.foreground_fraction, flat > 0)]
    picks = []
    used = 0
    for share, mask in shares:
        k = int(round(share * n))
        if k == 0:
            continue
        idx = np.flatnonzero(mask)
        if idx.size:
            picks.append(idx[rng.integers(0, idx.size, k)])
            used += k
    picks.append(rng.integers(0, flat.size, n - used))
    return np.concatenate(picks)


class RaySampler:
    """Draws `RayBatch`es from object records (all articulations and views of each object).

    `objects` are indices into `records` that this sampler may draw from (e.g. one DDP rank's
    share); object_index in the batch is the index into `records` (the code table row).
    `slots` (furniture, one `SlotTargets` per record) gives q, keypoints, existence and type
    per slot instead of the records' single q and keypoints.
    """

    def __init__(self, records: list[ObjectRecord], K: np.ndarray, config: SamplerConfig,
                 seed: int, objects: np.ndarray | None = None,
                 slots: list[SlotTargets] | None = None):
        self.records, self.config, self.slots = records, config, slots
        self.K = torch.as_tensor(np.asarray(K, np.float32))
        self.objects = np.arange(len(records)) if objects is None else np.asarray(objects)
        self.rng = np.random.default_rng(seed)
        A, V, S = records[0].rgb.shape[:3]
        self.A, self.V, self.S = A, V, S

    def sample(self) -> RayBatch:
        c, rng = self.config, self.rng
        B, R = c.images_per_batch, c.rays_per_image
        objs = self.objects[rng.integers(0, self.objects.size, B)]
        arts = rng.integers(0, self.A, B)
        views = rng.integers(0, self.V, B)
        uv = np.empty((B, R, 2), np.float32)
        rgb = np.empty((B, R, 3), np.float32)
        labels = np.empty((B, R), np.int64)
        X_OC = np.empty((B, 4, 4), np.float32)
        q, kps, exists, types = [], [], [], []
        for b, (j, a, v) in enumerate(zip(objs, arts, views, strict=True)):
            rec = self.records[j]
            label = np.asarray(rec.label[a, v])
            pix = stratified_pixels(label, R, c, rng)
            rows, cols = np.divmod(pix, self.S)
            uv[b, :, 0] = cols + 0.5
            uv[b, :, 1] = rows + 0.5
            rgb[b] = np.asarray(rec.rgb[a, v]).reshape(-1, 3)[pix] / 255.0
            labels[b] = label.reshape(-1)[pix]
            X_OC[b] = rec.X_OC[a, v]
            if self.slots is None:
                q.append(rec.q[a])
                kps.append(rec.keypoints[a])
                exists.append(np.ones(1, bool))
                types.append(np.zeros(1, np.int64))
            else:
                slot = self.slots[j]
                q.append(slot.q[a])
                kps.append(slot.keypoints[a].reshape(-1, 3))
                exists.append(slot.exists)
                types.append(slot.types)
        return RayBatch(torch.from_numpy(uv), torch.from_numpy(rgb), torch.from_numpy(labels),
                        self.K.expand(B, 3, 3).clone(), torch.from_numpy(X_OC),
                        torch.from_numpy(np.stack(q).astype(np.float32)),
                        torch.from_numpy(np.stack(kps)), torch.from_numpy(objs.astype(np.int64)),
                        torch.from_numpy(np.stack(exists)), torch.from_numpy(np.stack(types)))
