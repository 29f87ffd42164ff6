"""Training losses: L_SRN (image MSE + latent prior + negative-depth penalty) + lambda_1 L_SEG +
lambda_2 L_KP. Each term is a plain function; `nfr_loss` weights them with a `LossConfig`."""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch.nn import functional as F

from nfr_drake.nfr.config import LossConfig
from nfr_drake.nfr.model import RenderOutput


def image_loss(rgb: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared error of rgb (..., 3) against target (..., 3), both in [0, 1]."""
    return F.mse_loss(rgb, target)


def segmentation_loss(logits: torch.Tensor, labels: torch.Tensor) -> torch.Tensor:
    """Cross-entropy (nats) of class logits (..., C) against int64 labels (...)."""
    return F.cross_entropy(logits.reshape(-1, logits.shape[-1]), labels.reshape(-1))


def keypoint_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Squared distance (m^2) between keypoints (B, K, 3), averaged over keypoints and batch."""
    return ((pred - target) ** 2).sum(-1).mean()


def latent_loss(z_obj: torch.Tensor) -> torch.Tensor:
    """Gaussian prior on object codes (B, k): mean of squares (SRN)."""
    return (z_obj ** 2).mean()


def depth_loss(depth_trace: torch.Tensor) -> torch.Tensor:
    """Penalty on marching depths behind the camera: mean of min(d, 0)^2 over all steps."""
    return torch.clamp(depth_trace, max=0.0).pow(2).mean()


class LossTerms(NamedTuple):
    """The weighted total and each unweighted term (scalars)."""

    total: torch.Tensor
    image: torch.Tensor
    seg: torch.Tensor
    keypoint: torch.Tensor
    latent: torch.Tensor
    depth: torch.Tensor


def nfr_loss(render: RenderOutput, keypoints: torch.Tensor, z_obj: torch.Tensor,
             rgb: torch.Tensor, labels: torch.Tensor, keypoints_gt: torch.Tensor,
             weights: LossConfig) -> LossTerms:
    """The paper's training loss for one batch.

    render: rendered rays (B, R, ...); keypoints (B, K, 3) predicted; z_obj (B, k) codes used;
    rgb (B, R, 3) and labels (B, R) at the sampled pixels; keypoints_gt (B, K, 3).
    """
    terms = dict(image=image_loss(render.rgb, rgb), seg=segmentation_loss(render.logits, labels),
                 keypoint=keypoint_loss(keypoints, keypoints_gt), latent=latent_loss(z_obj),
                 depth=depth_loss(render.depth_trace))
    total = (weights.image_weight * terms["image"] + weights.seg_weight * terms["seg"]
             + weights.keypoint_weight * terms["keypoint"] + weights.latent_weight * terms["latent"]
             + weights.depth_weight * terms["depth"])
    return LossTerms(total=total, **terms)
