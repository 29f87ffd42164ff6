"""Hypernetwork H(z) -> weights of the field Phi, one small network per layer of Phi (as in SRN).

Each generated layer is a shared base weight plus a z-dependent offset, W(z) = W0 + dW(z): the
offset starts small (`offset_scale`), so Phi starts as an ordinary MLP and training is stable
from the first step (docs/NEURAL_FIELD.md).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from torch import nn


class LayerWeights(NamedTuple):
    """Weights of one linear layer per code, laid out for `torch.baddbmm(bias, h, weight)` on
    h (B, R, in): weight (B, in, out) (a transposed view), bias (B, 1, out). Made once per
    render, not once per field query (the marcher queries the field `march_steps` + 1 times)."""

    weight: torch.Tensor
    bias: torch.Tensor


class HyperLinear(nn.Module):
    """Generates one linear layer (in_features -> out_features) of Phi from z (B, latent_dim)."""

    def __init__(self, latent_dim: int, in_features: int, out_features: int, hidden: int,
                 offset_scale: float):
        super().__init__()
        self.in_features, self.out_features = in_features, out_features
        self.base_weight = nn.Parameter(torch.empty(out_features, in_features))
        self.base_bias = nn.Parameter(torch.zeros(out_features))
        nn.init.kaiming_normal_(self.base_weight, nonlinearity="relu")
        self.net = nn.Sequential(nn.Linear(latent_dim, hidden), nn.ReLU(),
                                 nn.Linear(hidden, out_features * in_features + out_features))
        last = self.net[-1]
        # Offsets of std ~ offset_scale * kaiming std for unit-size hidden activations.
        nn.init.normal_(last.weight, std=offset_scale * math.sqrt(2.0 / in_features)
                        / math.sqrt(hidden))
        nn.init.zeros_(last.bias)

    def forward(self, z: torch.Tensor) -> LayerWeights:
        """z (B, latent_dim) -> LayerWeights with weight (B, in, out), bias (B, 1, out)."""
        flat = self.net(z)
        n_w = self.out_features * self.in_features
        weight = self.base_weight + flat[:, :n_w].view(-1, self.out_features, self.in_features)
        bias = self.base_bias + flat[:, n_w:]
        return LayerWeights(weight.transpose(1, 2), bias.unsqueeze(1))


class HyperNetwork(nn.Module):
    """H(z): per-layer hypernetworks producing all layers of Phi.

    `layer_sizes` lists (in, out) of each generated layer.
    """

    def __init__(self, latent_dim: int, layer_sizes: list[tuple[int, int]], hidden: int,
                 offset_scale: float):
        super().__init__()
        self.layers = nn.ModuleList(HyperLinear(latent_dim, i, o, hidden, offset_scale)
                                    for i, o in layer_sizes)

    def forward(self, z: torch.Tensor) -> list[LayerWeights]:
        """z (B, latent_dim) -> one LayerWeights per layer of Phi."""
        return [layer(z) for layer in self.layers]
