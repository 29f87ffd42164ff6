"""Whole images from a model and explicit codes: RGB, segmentation and depth, for any camera."""

from __future__ import annotations

from typing import NamedTuple

import torch

from nfr_drake.nfr.model import NFRModel
from nfr_drake.nfr.rays import Rays, pixel_centers, pixel_rays


class Images(NamedTuple):
    """rgb (B, H, W, 3) clamped to [0, 1]; labels int64 (B, H, W) argmax classes;
    logits (B, H, W, C); depth (B, H, W) along the ray (m); points (B, H, W, 3) in O."""

    rgb: torch.Tensor
    labels: torch.Tensor
    logits: torch.Tensor
    depth: torch.Tensor
    points: torch.Tensor


def render_images(model: NFRModel, z: torch.Tensor, K: torch.Tensor, X_OC: torch.Tensor,
                  height: int, width: int, chunk: int = 8192) -> Images:
    """Render B full images of codes z (B, 2 + k) seen by cameras K (B, 3, 3) at X_OC (B, 4, 4).

    Rays are processed `chunk` per image at a time; gradients flow if enabled by the caller.
    """
    B = z.shape[0]
    uv = pixel_centers(height, width, device=z.device, dtype=z.dtype).expand(B, -1, -1)
    rays = pixel_rays(uv, K.to(z), X_OC.to(z))
    parts = []
    for s in range(0, uv.shape[1], chunk):
        sub = Rays(rays.origins[:, s:s + chunk], rays.directions[:, s:s + chunk])
        parts.append(model.render(z, sub))
    rgb = torch.cat([p.rgb for p in parts], 1)
    logits = torch.cat([p.logits for p in parts], 1)
    depth = torch.cat([p.depth for p in parts], 1)
    points = torch.cat([p.points for p in parts], 1)
    shape = (B, height, width)
    return Images(rgb.clamp(0, 1).view(*shape, 3), logits.argmax(-1).view(shape),
                  logits.view(*shape, -1), depth.view(shape), points.view(*shape, 3))
