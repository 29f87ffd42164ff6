"""Read-outs: pixel generators psi_1 (RGB) and psi_2 (segmentation) on features, Gamma on codes."""

from __future__ import annotations

import torch
from torch import nn


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class PixelGenerator(nn.Module):
    """Feature v (..., n) -> pixel value (..., out): one hidden layer, linear output.

    psi_1: out = 3, RGB in [0, 1] (not squashed; clamp for display). psi_2: out = classes, logits.
    """

    def __init__(self, feature_dim: int, hidden: int, out: int):
        super().__init__()
        self.net = _mlp([feature_dim, hidden, out])

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        return self.net(v)


class KeypointHead(nn.Module):
    """Gamma(z): code z (B, 2 S + k) -> keypoint positions (B, K, 3) in frame O, metres, and
    slot logits (B, S, L).

    With several slots (furniture) K = S x 4 slot-major and L = 3 per slot: existence, door,
    drawer. One slot (closets, drawers): L = 0, the head is the paper's Gamma unchanged.
    """

    def __init__(self, latent_dim: int, hidden: int, num_keypoints: int, num_slots: int = 1,
                 slot_logits: int = 0):
        super().__init__()
        self.num_keypoints, self.num_slots, self.slot_logits = num_keypoints, num_slots, slot_logits
        self.net = _mlp([latent_dim, hidden, hidden, 3 * num_keypoints + num_slots * slot_logits])

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.net(z)
        n = 3 * self.num_keypoints
        return (out[..., :n].unflatten(-1, (self.num_keypoints, 3)),
                out[..., n:].unflatten(-1, (self.num_slots, self.slot_logits)))
