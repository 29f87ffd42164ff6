"""The structured latent code z = [z_art (2 S), z_obj (k)] (paper, "Latent code"; docs/CONVENTIONS.md).

z_art holds one 2-vector per articulation slot: S = 1 for closets and drawers (z_art (2)), S =
`MAX_FRONTS` for furniture, where slot k is front k in canonical order (docs/NEURAL_FIELD.md,
"Furniture: several parts"). Each slot's 2-vector is normalised onto its unit circle before the
networks see it. The upper half of the circle
(angle in [0, pi]) covers q in [0, 1]; the lower half mirrors it, so there is no seam at q = 0 or
q = 1 and a Gaussian prior on the raw z_art gives a uniform angle. During training z_art is set
from the true q; when fitting an unseen object it is free.
"""

from __future__ import annotations

import math

import torch
from torch import nn

ART_DIM = 2
"""Size of one slot's articulation code."""

_EPS = 1e-8


def q_to_z_art(q: torch.Tensor) -> torch.Tensor:
    """Articulation q in [0, 1], shape (...), to z_art = (cos(pi q), sin(pi q)), shape (..., 2)."""
    angle = math.pi * q
    return torch.stack([torch.cos(angle), torch.sin(angle)], dim=-1)


def slots_q_to_z_art(q: torch.Tensor, num_slots: int) -> torch.Tensor:
    """q per slot (B, S) (or (B,) when S = 1) -> z_art (B, 2 S), slot k in entries 2k, 2k + 1."""
    return q_to_z_art(q.reshape(q.shape[0], num_slots)).flatten(-2)


def normalize_z_art(z_art: torch.Tensor) -> torch.Tensor:
    """Project each slot's 2-vector of z_art (..., 2 S) onto its unit circle (the paper's
    normalisation layer, per slot)."""
    slots = z_art.unflatten(-1, (-1, ART_DIM))
    return (slots / slots.norm(dim=-1, keepdim=True).clamp_min(_EPS)).flatten(-2)


def z_art_to_q(z_art: torch.Tensor) -> torch.Tensor:
    """q = |atan2(z_art[1], z_art[0])| / pi in [0, 1], shape (...); the lower half mirrors."""
    return torch.atan2(z_art[..., 1], z_art[..., 0]).abs() / math.pi


def compose_z(z_art: torch.Tensor, z_obj: torch.Tensor) -> torch.Tensor:
    """z = [normalize(z_art), z_obj]: (..., 2 S) and (..., k) -> (..., 2 S + k), as the networks
    see it."""
    return torch.cat([normalize_z_art(z_art), z_obj], dim=-1)


def split_z(z: torch.Tensor, num_slots: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 2 S + k) -> z_art (..., 2 S), z_obj (..., k)."""
    return z[..., :ART_DIM * num_slots], z[..., ART_DIM * num_slots:]


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

    def z(self, object_index: torch.Tensor, q: torch.Tensor, num_slots: int = 1) -> torch.Tensor:
        """The training code of each object at articulation q (B,) or per slot (B, S):
        z (B, 2 S + k), z_art from q."""
        return compose_z(slots_q_to_z_art(q, num_slots), self(object_index))
