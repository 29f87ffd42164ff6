"""Images of room datasets (`nfr-drake generate-rooms`) and augmented training batches of them.

Augmentation, on top of what the renders already vary (rooms, lights, exposure, noise, blur):
a random zoom (0.7-1.4) and crop, a horizontal flip, brightness, contrast and per-channel
gains, a random swap of colour channels, and more noise or blur.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch

from nfr_drake.data.amodal import AMODAL_FILE
from nfr_drake.data.dataset import ObjectRecord
from nfr_drake.data.room_dataset import read_room_spec, room_dirs
from nfr_drake.errors import DatasetError


class RoomImages:
    """Every (room, articulation, view) image of some room datasets, in a fixed order.

    `category` names the target category of each image; DatasetError when a folder is not a room
    dataset or holds no complete room. `has_amodal`: every room holds its amodal carcass labels
    (`carcass_amodal.npy`, `nfr-drake label-amodal`).
    """

    def __init__(self, roots: list[Path]):
        self.roots = [Path(r) for r in roots]
        self.index: list[tuple[ObjectRecord, int, int]] = []
        self.category: list[str] = []
        for root in self.roots:
            spec = read_room_spec(root)
            records = [ObjectRecord(p) for p in room_dirs(root)]
            if not records:
                raise DatasetError(f"{root}: no complete rooms yet")
            for rec in records:
                for a in range(spec.articulations):
                    for v in range(spec.views):
                        self.index.append((rec, a, v))
                        self.category.append(spec.category)
        self.has_amodal = all((rec.path / AMODAL_FILE).is_file() for rec, _, _ in self.index)
        self._amodal: dict[Path, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.index)

    def image(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Image i: RGB uint8 (S, S, 3) and the target's class per pixel uint8 (S, S)."""
        rec, a, v = self.index[i]
        return np.asarray(rec.rgb[a, v]), np.asarray(rec.label[a, v])

    def amodal(self, i: int) -> np.ndarray:
        """Image i's amodal carcass label uint8 (S, S), 1 on the carcass; DatasetError when its
        room has none."""
        rec, a, v = self.index[i]
        if rec.path not in self._amodal:
            path = rec.path / AMODAL_FILE
            if not path.is_file():
                raise DatasetError(f"{rec.path}: no amodal carcass labels; run `nfr-drake label-amodal "
                                   f"--data {rec.path.parent.parent}`")
            self._amodal[rec.path] = np.load(path, mmap_mode="r")
        return np.asarray(self._amodal[rec.path][a, v])


def augment(rgb: np.ndarray, label: np.ndarray, crop: int, rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray]:
    """A randomly zoomed, cropped, flipped and recoloured copy: RGB float32 (crop, crop, 3) in
    [0, 1] and labels int64 (crop, crop), or (crop, crop, C) for labels uint8 (S, S, C)."""
    s = rgb.shape[0]
    zoom = rng.uniform(0.7, 1.4)
    side = max(crop, int(round(s * zoom)))
    rgb = cv2.resize(rgb, (side, side), interpolation=cv2.INTER_AREA if zoom < 1 else cv2.INTER_LINEAR)
    label = cv2.resize(label, (side, side), interpolation=cv2.INTER_NEAREST)
    r0, c0 = rng.integers(0, side - crop + 1, 2)
    x = rgb[r0:r0 + crop, c0:c0 + crop].astype(np.float32) / 255.0
    y = label[r0:r0 + crop, c0:c0 + crop].astype(np.int64)
    if rng.uniform() < 0.5:
        x, y = x[:, ::-1], y[:, ::-1]
    if rng.uniform() < 0.2:
        x = x[..., rng.permutation(3)]
    mean = x.mean()
    x = (x - mean) * rng.uniform(0.7, 1.3) + mean * rng.uniform(0.6, 1.5)
    x = x * rng.uniform(0.85, 1.15, 3).astype(np.float32)
    if rng.uniform() < 0.2:
        x = cv2.GaussianBlur(x, (0, 0), rng.uniform(0.5, 1.5))
    x = x + rng.normal(0.0, rng.uniform(0.0, 0.04), x.shape).astype(np.float32)
    return np.clip(x, 0.0, 1.0), np.ascontiguousarray(y)


def sample_batch(data: RoomImages, n: int, crop: int, rng: np.random.Generator, amodal: bool = False
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """n augmented crops of random images: RGB (n, 3, crop, crop) float32 in [0, 1], class
    labels (n, crop, crop) int64 and, with `amodal`, the amodal carcass labels (n, crop, crop)
    float32 0/1 (same zoom, crop and flip), else None."""
    xs, ys, zs = [], [], []
    for i in rng.integers(0, len(data), n):
        rgb, label = data.image(int(i))
        if amodal:
            label = np.stack([label, data.amodal(int(i))], -1)
        x, y = augment(rgb, label, crop, rng)
        xs.append(x)
        ys.append(y[..., 0] if amodal else y)
        if amodal:
            zs.append(y[..., 1])
    return (torch.from_numpy(np.stack(xs)).permute(0, 3, 1, 2).contiguous(),
            torch.from_numpy(np.stack(ys)),
            torch.from_numpy(np.stack(zs).astype(np.float32)) if amodal else None)
