"""Training losses: L_SRN (image MSE + latent prior + negative-depth penalty) + lambda_1 L_SEG +
lambda_2 L_KP (+ the slot term of furniture models). Each term is a plain function; `nfr_loss`
weights them with a `LossConfig`."""

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


def keypoint_loss(pred: torch.Tensor, target: torch.Tensor,
                  mask: torch.Tensor | None = None) -> torch.Tensor:
    """Squared distance (m^2) between keypoints (B, K, 3), averaged over keypoints and batch;
    with a bool `mask` (B, K) over the keypoints it marks only (those of existing slots)."""
    d2 = ((pred - target) ** 2).sum(-1)
    if mask is None:
        return d2.mean()
    return (d2 * mask).sum() / mask.sum().clamp_min(1)


def slot_loss(logits: torch.Tensor, exists: torch.Tensor, types: torch.Tensor) -> torch.Tensor:
    """Existence BCE over all slots plus type CE over existing ones (nats): logits (B, S, 3)
    (existence, door, drawer), exists bool (B, S), types int64 (B, S)."""
    bce = F.binary_cross_entropy_with_logits(logits[..., 0], exists.to(logits.dtype))
    ce = F.cross_entropy(logits[..., 1:][exists], types[exists]) if exists.any() \
        else logits.new_zeros(())
    return bce + ce


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
    slots: torch.Tensor


def nfr_loss(render: RenderOutput, keypoints: torch.Tensor, z_obj: torch.Tensor,
             rgb: torch.Tensor, labels: torch.Tensor, keypoints_gt: torch.Tensor,
             weights: LossConfig, slot_logits: torch.Tensor | None = None,
             exists: torch.Tensor | None = None, types: torch.Tensor | None = None) -> LossTerms:
    """The paper's training loss for one batch.

    render: rendered rays (B, R, ...); keypoints (B, K, 3) predicted; z_obj (B, k) codes used;
    rgb (B, R, 3) and labels (B, R) at the sampled pixels; keypoints_gt (B, K, 3).
    Several slots: slot_logits (B, S, 3), exists bool (B, S), types int64 (B, S); the K = S x L
    keypoints (slot-major) count only where their slot exists.
    """
    mask, slots = None, z_obj.new_zeros(())
    if slot_logits is not None:
        per_slot = keypoints.shape[1] // exists.shape[1]
        mask = exists.repeat_interleave(per_slot, dim=1)
        slots = slot_loss(slot_logits, exists, types)
    terms = dict(image=image_loss(render.rgb, rgb), seg=segmentation_loss(render.logits, labels),
                 keypoint=keypoint_loss(keypoints, keypoints_gt, mask), latent=latent_loss(z_obj),
                 depth=depth_loss(render.depth_trace), slots=slots)
    total = (weights.image_weight * terms["image"] + weights.seg_weight * terms["seg"]
             + weights.keypoint_weight * terms["keypoint"] + weights.latent_weight * terms["latent"]
             + weights.depth_weight * terms["depth"] + weights.slot_weight * terms["slots"])
    return LossTerms(total=total, **terms)
