"""Reading rendered datasets: memory-mapped arrays and a torch Dataset of posed images.

Nothing is loaded up front: each object's arrays are memory-mapped on first use, so a dataset
larger than memory can be read, and a DataLoader's worker processes open their own maps.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.shards import (
    DEPTH_SCALE,
    OBJECTS_DIR,
    PART_CATEGORIES,
    completed_objects,
    object_dir_name,
    read_spec,
)
from nfr_drake.errors import DatasetError


class PosedImage(NamedTuple):
    """One rendered view; batched by torch's default collate (a leading batch dim B is added).

    rgb: float32 (S, S, 3) in [0, 1]. label: int64 (S, S) semantic class. depth: float32 (S, S),
    metres, inf where no surface. X_OC: float32 (4, 4) camera pose in O, OpenCV axes.
    K: float32 (3, 3) intrinsics, top-left pixel centre at (0.5, 0.5). q: float32 () articulation.
    keypoints: float32 (K, 3) in O. object_index: int64 () dense object index in [0, num_objects).
    """

    rgb: torch.Tensor
    label: torch.Tensor
    depth: torch.Tensor
    X_OC: torch.Tensor
    K: torch.Tensor
    q: torch.Tensor
    keypoints: torch.Tensor
    object_index: torch.Tensor


@dataclass
class ObjectRecord:
    """One object's folder (or a room's of `nfr-drake generate-rooms`: rgb and label, the label
    the target's class, 0 elsewhere); arrays are memory-mapped lazily."""

    path: Path

    @cached_property
    def meta(self) -> dict:
        return json.loads((self.path / "meta.json").read_text())

    @cached_property
    def rgb(self) -> np.ndarray:
        """uint8 (A, V, S, S, 3)."""
        return np.load(self.path / "rgb.npy", mmap_mode="r")

    @cached_property
    def label(self) -> np.ndarray:
        """uint8 (A, V, S, S)."""
        return np.load(self.path / "label.npy", mmap_mode="r")

    @cached_property
    def part(self) -> np.ndarray:
        """int8 (A, V, S, S) front index per pixel, -1 where none (furniture datasets only)."""
        return np.load(self.path / "part.npy", mmap_mode="r")

    @cached_property
    def depth_mm(self) -> np.ndarray:
        """uint16 (A, V, S, S), millimetres, 0 = no surface."""
        return np.load(self.path / "depth.npy", mmap_mode="r")

    @cached_property
    def q(self) -> np.ndarray:
        """float32 (A,), or (A, F) for furniture (one q per front)."""
        return np.asarray(self.meta["q"], np.float32)

    @cached_property
    def X_OC(self) -> np.ndarray:
        """float32 (A, V, 4, 4)."""
        return np.asarray(self.meta["X_OC"], np.float32)

    @cached_property
    def keypoints(self) -> np.ndarray:
        """float32 (A, K, 3) in O."""
        return np.asarray(self.meta["keypoints"], np.float32)

    def __getstate__(self):  # memory maps are reopened in each process
        return {"path": self.path}


class RenderedDataset(torch.utils.data.Dataset):
    """All (object, articulation, view) images of a dataset folder written by `nfr-drake generate`.

    Only complete objects are listed; `objects` limits the dataset to its first n objects.
    Items need one q and one keypoint set per image: furniture datasets (a q per front) give
    their records, not items.
    `missing` lists the indices below the declared count (dataset.json's, or `objects`) that are
    not on disk. Item i is view i % V of articulation (i // V) % A of object i // (A V).
    """

    def __init__(self, root: str | Path, objects: int | None = None):
        self.root = Path(root)
        self.spec = read_spec(self.root)
        indices = completed_objects(self.root)
        self.declared = self.spec.objects if objects is None else min(objects, self.spec.objects)
        self.missing = sorted(set(range(self.declared)) - set(indices))
        if objects is not None:
            indices = indices[:objects]
        if not indices:
            raise DatasetError(f"{self.root}: no complete objects yet")
        self.object_indices = indices
        self.records = [ObjectRecord(self.root / OBJECTS_DIR / object_dir_name(i))
                        for i in indices]
        self.camera = PinholeCamera.from_json(self.records[0].meta["camera"])
        self.has_parts = self.spec.category in PART_CATEGORIES
        self._keypoint_names = tuple(self.records[0].meta.get("keypoint_names", ()))

    @property
    def keypoint_names(self) -> tuple[str, ...]:
        """The keypoints of every object; DatasetError for furniture (keypoints per front)."""
        self._require_one_part()
        return self._keypoint_names

    def _require_one_part(self) -> None:
        if self.has_parts:
            raise DatasetError(f"{self.root}: a {self.spec.category} dataset has a q and keypoints per "
                               "front; training and posed images need closet or drawer datasets")

    @property
    def num_objects(self) -> int:
        return len(self.records)

    def require_complete(self, allow_incomplete: bool = False) -> None:
        """DatasetError naming the missing objects when some of the declared ones are not on disk
        (a `generate` killed or still running, a shard not copied in); with `allow_incomplete`,
        one warning line on stderr with the counts instead."""
        if not self.missing:
            return
        what = (f"{self.root}: {self.declared - len(self.missing)} of the {self.declared} objects "
                f"are on disk (missing {_index_ranges(self.missing)})")
        if not allow_incomplete:
            raise DatasetError(f"{what}; complete it with `nfr-drake generate` and the same options, "
                               "or pass --allow-incomplete to use the objects that are there")
        print(f"warning: {what}; using {self.num_objects} objects", file=sys.stderr)

    def __len__(self) -> int:
        return self.num_objects * self.spec.articulations * self.spec.views

    def __getitem__(self, i: int) -> PosedImage:
        A, V = self.spec.articulations, self.spec.views
        if not 0 <= i < len(self):
            raise IndexError(i)
        self._require_one_part()
        j, a, v = i // (A * V), (i // V) % A, i % V
        rec = self.records[j]
        depth = rec.depth_mm[a, v].astype(np.float32) / DEPTH_SCALE
        depth[depth == 0] = np.inf
        return PosedImage(
            rgb=torch.from_numpy(rec.rgb[a, v].astype(np.float32) / 255.0),
            label=torch.from_numpy(rec.label[a, v].astype(np.int64)),
            depth=torch.from_numpy(depth),
            X_OC=torch.from_numpy(rec.X_OC[a, v]),
            K=torch.from_numpy(self.camera.K.astype(np.float32)),
            q=torch.tensor(rec.q[a]),
            keypoints=torch.from_numpy(rec.keypoints[a]),
            object_index=torch.tensor(j),
        )


def _index_ranges(indices: list[int], most: int = 4) -> str:
    """Sorted object indices as "obj 3, 10-59": the first `most` runs, then how many more."""
    runs: list[list[int]] = []
    for i in indices:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    text = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs[:most])
    more = f" and {len(runs) - most} more runs" if len(runs) > most else ""
    return f"obj {text}{more}"
