"""Furniture datasets read as articulation slots: slot k is front k in canonical order.

Every object is padded to `MAX_FRONTS` slots: a slot without a front is shut (q = 0), has zero
keypoints and `exists` False. Each slot has four keypoints in O (metres), `SLOT_KEYPOINTS`:
the handle, the goal, and two points on the joint's axis that fix the part's motion: a door's
hinge_top and hinge_bottom; a drawer's handle when shut and when fully open (its pull line and
travel). docs/NEURAL_FIELD.md, "Furniture: several parts".
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from nfr_drake.data.dataset import DEPTH_SCALE, RenderedDataset
from nfr_drake.data.shards import PART_CATEGORIES, read_spec
from nfr_drake.errors import DatasetError
from nfr_drake.objects.articulated import MAX_FRONTS, axis_angle_rotation
from nfr_drake.objects.fronts import DOOR_OPENING

SLOT_KEYPOINTS = ("handle", "goal", "axis_0", "axis_1")
"""Keypoints of one slot, in this order."""
PART_TYPES = ("door", "drawer")
"""Slot type classes: index 0 door, 1 drawer."""


def slot_keypoint_names(num_slots: int = MAX_FRONTS) -> tuple[str, ...]:
    """Names of the S x 4 keypoints, slot-major: 'front0/handle', 'front0/goal', ..."""
    return tuple(f"front{k}/{n}" for k in range(num_slots) for n in SLOT_KEYPOINTS)


def slot_part(slot: int, part_type: int, q: float, keypoints: np.ndarray, q_grid: np.ndarray,
              path: np.ndarray) -> dict:
    """One slot as a part of a fit result's `parts` (`inference.result.FitResult`), {index, type,
    q, keypoints, trajectory}: part_type indexes `PART_TYPES`; keypoints (4, 3) in O at q,
    `SLOT_KEYPOINTS` order, written name -> [x, y, z]; trajectory q (N,) = q_grid and name ->
    (N, 3) from path (N, 4, 3)."""
    return {"index": int(slot), "type": PART_TYPES[int(part_type)], "q": float(q),
            "keypoints": {n: np.asarray(keypoints[i], float).tolist() for i, n in enumerate(SLOT_KEYPOINTS)},
            "trajectory": {"q": np.asarray(q_grid, float).tolist(),
                           "keypoints": {n: np.asarray(path[:, i], float).tolist()
                                         for i, n in enumerate(SLOT_KEYPOINTS)}}}


def slot_trajectory(part_type: str, keypoints: np.ndarray, q: float, q_grid: np.ndarray) -> np.ndarray:
    """A furniture slot's keypoints at other articulations from one observed state, by explicit
    geometric assumption, the one-part baseline's (`nfr_drake.baseline.model.extrapolate_keypoints`) per
    slot; the furniture fit turns its doors so too (`nfr_drake.inference.furniture_fit.slot_path`).

    A door turns about the line through its axis points by `DOOR_OPENING` over q in [0, 1], its
    free edge (the side of the goal, which lies behind the door) swinging out of the carcass (+x
    of O); only the handle moves. A drawer's handle and goal move along its axis points' line
    (shut handle -> fully open handle) by their difference over [0, 1].

    Args:
        part_type: "door" or "drawer" (`PART_TYPES`).
        keypoints: (4, 3) at articulation q in O, m, `SLOT_KEYPOINTS` order.
        q_grid: (N,) articulations to predict.
    Returns: (N, 4, 3).
    """
    handle, goal, axis_0, axis_1 = (SLOT_KEYPOINTS.index(n) for n in ("handle", "goal", "axis_0", "axis_1"))
    kp = np.asarray(keypoints, float)
    out = np.repeat(kp[None], len(q_grid), axis=0)
    dq = np.asarray(q_grid, float) - q
    if part_type == "drawer":
        out[:, [handle, goal]] += (dq[:, None] * (kp[axis_1] - kp[axis_0]))[:, None]
        return out
    axis = kp[axis_1] - kp[axis_0]
    axis /= max(np.linalg.norm(axis), 1e-9)
    sign = 1.0 if np.cross(axis, kp[goal] - kp[axis_0])[0] >= 0 else -1.0
    for i, angle in enumerate(sign * dq * DOOR_OPENING):
        out[i, handle] = kp[axis_0] + axis_angle_rotation(axis, angle) @ (kp[handle] - kp[axis_0])
    return out


class SlotTargets(NamedTuple):
    """One object's slot targets: q float32 (A, S), 0 where no front; keypoints float32
    (A, S, 4, 3) in O, zero where no front; exists bool (S,); types int64 (S,) index into
    `PART_TYPES`, 0 where no front."""

    q: np.ndarray
    keypoints: np.ndarray
    exists: np.ndarray
    types: np.ndarray


def _part_keypoints(part: dict) -> np.ndarray:
    """(A, 4, 3) keypoints of one meta.json part in `SLOT_KEYPOINTS` order."""
    kp = {name: np.asarray(v, np.float64) for name, v in part["keypoints"].items()}
    if part["type"] == "door":
        axis = (kp["hinge_top"], kp["hinge_bottom"])
    else:
        pull = np.asarray(part["pull_axis"], np.float64) * part["travel"]
        shut = kp["handle"] - np.asarray(part["q"], np.float64)[:, None] * pull
        axis = (shut, shut + pull)
    return np.stack([kp["handle"], kp["goal"], *axis], axis=1)


def slot_targets(meta: dict, num_slots: int = MAX_FRONTS) -> SlotTargets:
    """The slot targets of one furniture object's meta.json (docs/DATASET_FORMAT.md)."""
    parts = meta["parts"]
    if len(parts) > num_slots:
        raise DatasetError(f"{meta.get('name', 'object')}: {len(parts)} fronts, more than the "
                           f"{num_slots} slots")
    A = len(meta["q"])
    q = np.zeros((A, num_slots), np.float32)
    keypoints = np.zeros((A, num_slots, len(SLOT_KEYPOINTS), 3), np.float32)
    exists = np.zeros(num_slots, bool)
    types = np.zeros(num_slots, np.int64)
    for part in parts:
        k = part["index"]
        q[:, k] = part["q"]
        keypoints[:, k] = _part_keypoints(part)
        exists[k] = True
        types[k] = PART_TYPES.index(part["type"])
    return SlotTargets(q, keypoints, exists, types)


class SlotImage(NamedTuple):
    """One rendered view of a furniture dataset; batched by torch's default collate.

    As `PosedImage` (rgb, label, depth, X_OC, K, object_index), plus part: int64 (S, S) front
    index, -1 where none; q: float32 (S,) per slot; keypoints: float32 (S x 4, 3) in O,
    slot-major; exists: bool (S,); types: int64 (S,).
    """

    rgb: torch.Tensor
    label: torch.Tensor
    part: torch.Tensor
    depth: torch.Tensor
    X_OC: torch.Tensor
    K: torch.Tensor
    q: torch.Tensor
    keypoints: torch.Tensor
    exists: torch.Tensor
    types: torch.Tensor
    object_index: torch.Tensor


class SlotDataset(RenderedDataset):
    """A furniture dataset as `SlotImage` items and per-object `SlotTargets` (slot k = front k)."""

    num_slots = MAX_FRONTS

    def __init__(self, root, objects: int | None = None):
        super().__init__(root, objects)
        if not self.has_parts:
            raise DatasetError(f"{self.root}: a {self.spec.category} dataset has one front; "
                               "slots are read from furniture datasets")

    @property
    def keypoint_names(self) -> tuple[str, ...]:
        return slot_keypoint_names(self.num_slots)

    @cached_property
    def slots(self) -> list[SlotTargets]:
        """`SlotTargets` of every object, in record order."""
        return [slot_targets(r.meta, self.num_slots) for r in self.records]

    def __getitem__(self, i: int) -> SlotImage:
        A, V = self.spec.articulations, self.spec.views
        if not 0 <= i < len(self):
            raise IndexError(i)
        j, a, v = i // (A * V), (i // V) % A, i % V
        rec, slots = self.records[j], self.slots[j]
        depth = rec.depth_mm[a, v].astype(np.float32) / DEPTH_SCALE
        depth[depth == 0] = np.inf
        return SlotImage(
            rgb=torch.from_numpy(rec.rgb[a, v].astype(np.float32) / 255.0),
            label=torch.from_numpy(rec.label[a, v].astype(np.int64)),
            part=torch.from_numpy(rec.part[a, v].astype(np.int64)),
            depth=torch.from_numpy(depth),
            X_OC=torch.from_numpy(rec.X_OC[a, v]),
            K=torch.from_numpy(self.camera.K.astype(np.float32)),
            q=torch.from_numpy(slots.q[a]),
            keypoints=torch.from_numpy(slots.keypoints[a].reshape(-1, 3)),
            exists=torch.from_numpy(slots.exists),
            types=torch.from_numpy(slots.types),
            object_index=torch.tensor(j),
        )


def open_dataset(root, objects: int | None = None) -> RenderedDataset:
    """`SlotDataset` for a furniture dataset folder, `RenderedDataset` for the others."""
    parts = read_spec(Path(root)).category in PART_CATEGORIES
    return (SlotDataset if parts else RenderedDataset)(root, objects)
