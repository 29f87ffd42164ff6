"""Baseline predictions for a capture set: q and keypoints now, keypoints along q by assumption."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

from nfr_drake.baseline.model import ImageEncoderBaseline, extrapolate_keypoints
from nfr_drake.data.capture import CaptureSet
from nfr_drake.data.slot_dataset import PART_TYPES, slot_part, slot_trajectory


@dataclass
class BaselinePrediction:
    """Per slot (S = 1 but for furniture): q (S,) in [0, 1]; keypoints (S, K, 3) in O at q;
    travel (S,) m (prismatic); exists bool (S,) and types (S,) index into `PART_TYPES` (one part:
    the category's, a closet's door or a drawer); trajectory (S, N, K, 3) on q_grid (N,), each slot
    swept with the others held."""

    q: np.ndarray
    keypoints: np.ndarray
    travel: np.ndarray
    exists: np.ndarray
    types: np.ndarray
    q_grid: np.ndarray
    trajectory: np.ndarray

    def parts(self) -> list[dict]:
        """Furniture: the slots found as the furniture fit's result lists them, `parts: [{index,
        type, q, keypoints, trajectory}]` (`data.slot_dataset.slot_part`)."""
        return [slot_part(k, self.types[k], self.q[k], self.keypoints[k], self.q_grid, self.trajectory[k])
                for k in np.flatnonzero(self.exists)]


@torch.no_grad()
def predict_capture(model: ImageEncoderBaseline, capture: CaptureSet, image_size: int,
                    q_grid: np.ndarray) -> BaselinePrediction:
    """Run the baseline on every view of `capture` (resized to the training `image_size`)."""
    images = [cv2.resize(im, (image_size, image_size), interpolation=cv2.INTER_AREA)
              for im in capture.load_images()]
    x = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).float()[None] / 255.0
    poses = torch.from_numpy(np.stack([f.X_OC for f in capture.frames])).float()[None]
    out = model(x, poses)
    q = out.q[0].double().numpy()
    keypoints = out.keypoints[0].double().numpy()
    travel = out.travel[0].double().numpy()
    cfg = model.config
    if cfg.joint_type == "per_slot":
        exists = (out.exists[0] > 0).numpy()
        types = out.types[0].argmax(-1).numpy()
        trajectory = np.stack([slot_trajectory(PART_TYPES[t], kp, qk, q_grid)
                               for t, kp, qk in zip(types, keypoints, q, strict=True)])
    else:
        exists = np.ones(1, bool)
        types = np.array([PART_TYPES.index("door" if cfg.joint_type == "revolute" else "drawer")])
        trajectory = extrapolate_keypoints(cfg.keypoint_names, cfg.joint_type, keypoints[0], q[0],
                                           travel[0], q_grid)[None]
    return BaselinePrediction(q, keypoints, travel, exists, types, np.asarray(q_grid), trajectory)
