"""The structured latent code z = [z_art (2), z_obj (k)] (paper, "Latent code"; docs/CONVENTIONS.md).

`z_art` is normalised onto the unit circle before the networks see it. The upper half of the circle
(angle in [0, pi]) covers q in [0, 1]; the lower half mirrors it, so there is no seam at q = 0 or
q = 1 and a Gaussian prior on the raw z_art gives a uniform angle. During training z_art is set
from the true q; when fitting an unseen object it is free.
"""

from __future__ import annotations

import math

import torch
from torch import nn

ART_DIM = 2
"""Size of the articulation code."""

_EPS = 1e-8


def q_to_z_art(q: torch.Tensor) -> torch.Tensor:
    """Articulation q in [0, 1], shape (...), to z_art = (cos(pi q), sin(pi q)), shape (..., 2)."""
    angle = math.pi * q
    return torch.stack([torch.cos(angle), torch.sin(angle)], dim=-1)


def normalize_z_art(z_art: torch.Tensor) -> torch.Tensor:
    """Project z_art (..., 2) onto the unit circle (the paper's normalisation layer)."""
    return z_art / z_art.norm(dim=-1, keepdim=True).clamp_min(_EPS)


def z_art_to_q(z_art: torch.Tensor) -> torch.Tensor:
    """q = |atan2(z_art[1], z_art[0])| / pi in [0, 1], shape (...); the lower half mirrors."""
    return torch.atan2(z_art[..., 1], z_art[..., 0]).abs() / math.pi


def compose_z(z_art: torch.Tensor, z_obj: torch.Tensor) -> torch.Tensor:
    """z = [normalize(z_art), z_obj]: (..., 2) and (..., k) -> (..., 2 + k), as the networks see it."""
    return torch.cat([normalize_z_art(z_art), z_obj], dim=-1)


def split_z(z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 2 + k) -> z_art (..., 2), z_obj (..., k)."""
    return z[..., :ART_DIM], z[..., ART_DIM:]


class ObjectCodes(nn.Module):
    """The auto-decoder's table of object codes z_obj, one row per training object."""

    def __init__(self, num_objects: int, dim: int, init_std: float = 0.01):
        super().__init__()
        self.weight = nn.Parameter(torch.randn(num_objects, dim) * init_std)

    @property
    def num_objects(self) -> int:
        return self.weight.shape[0]

    def forward(self, object_index: torch.Tensor) -> torch.Tensor:
        """object_index int64 (B,) -> z_obj (B, k)."""
        return self.weight[object_index]

    def z(self, object_index: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """The training code of each object at articulation q (B,): z (B, 2 + k), z_art from q."""
        return compose_z(q_to_z_art(q), self(object_index))
