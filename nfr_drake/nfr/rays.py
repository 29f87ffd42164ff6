"""Camera rays from intrinsics and poses (OpenCV axes: x right, y down, z forward), any resolution.

Pixel convention (docs/CONVENTIONS.md, COLMAP/nerfstudio): the top-left pixel's centre is at
(u, v) = (0.5, 0.5), so pixel (row i, column j) has centre (j + 0.5, i + 0.5).
"""

from __future__ import annotations

from typing import NamedTuple

import torch


class Rays(NamedTuple):
    """origins (..., 3) camera centres in O; directions (..., 3) unit vectors in O."""

    origins: torch.Tensor
    directions: torch.Tensor


def pixel_centers(height: int, width: int, device=None, dtype=torch.float32) -> torch.Tensor:
    """(u, v) of every pixel centre, shape (height * width, 2), row-major (index = i * width + j)."""
    v, u = torch.meshgrid(torch.arange(height, device=device, dtype=dtype) + 0.5,
                          torch.arange(width, device=device, dtype=dtype) + 0.5, indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1)


def pixel_rays(uv: torch.Tensor, K: torch.Tensor, X_OC: torch.Tensor) -> Rays:
    """Rays through pixel positions uv (B, R, 2) of cameras K (B, 3, 3) at poses X_OC (B, 4, 4).

    Returns origins (B, R, 3) and unit directions (B, R, 3) in frame O. Depths along these rays are
    Euclidean distances from the camera centre (not z-depth).
    """
    fx, fy = K[:, 0, 0, None], K[:, 1, 1, None]
    cx, cy = K[:, 0, 2, None], K[:, 1, 2, None]
    x = (uv[..., 0] - cx) / fx
    y = (uv[..., 1] - cy) / fy
    d_C = torch.stack([x, y, torch.ones_like(x)], dim=-1)  # (B, R, 3)
    R_OC, p_OC = X_OC[:, :3, :3], X_OC[:, :3, 3]
    d_O = d_C @ R_OC.transpose(1, 2)
    d_O = d_O / d_O.norm(dim=-1, keepdim=True)
    return Rays(p_OC[:, None, :].expand_as(d_O), d_O)


def sphere_interval(rays: Rays, center: torch.Tensor, radius: float,
                    min_depth: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Depths (near, far), each (B, R), where each ray enters and leaves the sphere (center (3,),
    radius), both at least `min_depth`. A ray that misses the sphere gets near = far = its closest
    approach to the centre."""
    oc = center - rays.origins
    t_mid = (oc * rays.directions).sum(-1)  # closest approach
    d2 = (oc * oc).sum(-1) - t_mid ** 2
    half = torch.sqrt(torch.clamp(radius ** 2 - d2, min=0.0))
    return torch.clamp(t_mid - half, min=min_depth), torch.clamp(t_mid + half, min=min_depth)
