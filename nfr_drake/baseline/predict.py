"""Baseline predictions for a capture set: q and keypoints now, keypoints along q by assumption."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

from nfr_drake.baseline.model import ImageEncoderBaseline, extrapolate_keypoints
from nfr_drake.data.capture import CaptureSet


@dataclass
class BaselinePrediction:
    """q in [0, 1]; keypoints (K, 3) in O at q; travel (m, prismatic); trajectory (N, K, 3) on q_grid."""

    q: float
    keypoints: np.ndarray
    travel: float
    q_grid: np.ndarray
    trajectory: np.ndarray


@torch.no_grad()
def predict_capture(model: ImageEncoderBaseline, capture: CaptureSet, image_size: int,
                    q_grid: np.ndarray) -> BaselinePrediction:
    """Run the baseline on every view of `capture` (resized to the training `image_size`)."""
    images = [cv2.resize(im, (image_size, image_size), interpolation=cv2.INTER_AREA)
              for im in capture.load_images()]
    x = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).float()[None] / 255.0
    poses = torch.from_numpy(np.stack([f.X_OC for f in capture.frames])).float()[None]
    out = model(x, poses)
    q = float(out.q[0])
    keypoints = out.keypoints[0].double().numpy()
    travel = float(out.travel[0])
    cfg = model.config
    trajectory = extrapolate_keypoints(cfg.keypoint_names, cfg.joint_type, keypoints, q, travel,
                                       q_grid)
    return BaselinePrediction(q, keypoints, travel, np.asarray(q_grid), trajectory)
