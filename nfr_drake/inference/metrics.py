"""Evaluation metrics of the paper's experiments: articulation, keypoints, images, segmentation.

Positions in metres in; errors are returned in the units that reports use (degrees, cm, dB).
"""

from __future__ import annotations

import numpy as np


def articulation_error(q_pred: float, q_true: float, joint_type: str, joint_upper: float) -> float:
    """|q_pred - q_true| in report units: degrees for revolute joints, cm for prismatic ones."""
    delta = abs(float(q_pred) - float(q_true)) * joint_upper
    return float(np.degrees(delta)) if joint_type == "revolute" else float(100.0 * delta)


def keypoint_rmse_cm(pred: np.ndarray, true: np.ndarray) -> float:
    """Root mean square of the Euclidean errors of K keypoints, (K, 3) and (K, 3) in m -> cm."""
    d = np.linalg.norm(np.asarray(pred) - np.asarray(true), axis=-1)
    return float(100.0 * np.sqrt(np.mean(d**2)))


def trajectory_rmse_cm(pred: np.ndarray, true: np.ndarray) -> float:
    """RMS Euclidean error of one keypoint along a q grid, (N, 3) and (N, 3) in m -> cm."""
    return keypoint_rmse_cm(pred, true)


def psnr(pred: np.ndarray, true: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Peak signal-to-noise ratio (dB) of images in [0, 1], optionally over masked pixels only."""
    err = (np.asarray(pred, float) - np.asarray(true, float)) ** 2
    if mask is not None:
        err = err[np.asarray(mask, bool)]
    mse = float(np.mean(err))
    return float("inf") if mse == 0.0 else float(-10.0 * np.log10(mse))


def mean_iou(pred: np.ndarray, true: np.ndarray, num_classes: int = 4) -> float:
    """Mean intersection over union of label images, over the classes present in either image."""
    pred, true = np.asarray(pred), np.asarray(true)
    ious = []
    for c in range(num_classes):
        p, t = pred == c, true == c
        union = np.logical_or(p, t).sum()
        if union:
            ious.append(np.logical_and(p, t).sum() / union)
    return float(np.mean(ious))
