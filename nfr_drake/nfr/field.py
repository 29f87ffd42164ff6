"""The field Phi: x in frame O -> feature vector v, with weights generated per code by H(z)."""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from nfr_drake.nfr.hyper import LayerWeights


def encoding_frequencies(frequencies: int, base: float, dtype=torch.float32,
                         device=None) -> torch.Tensor:
    """The angular frequencies w_i = base 2**i, i < F, of `positional_encoding`: (F,)."""
    return base * 2.0 ** torch.arange(frequencies, dtype=dtype, device=device)


def positional_encoding(x: torch.Tensor, frequencies: int, base: float,
                        w: torch.Tensor | None = None) -> torch.Tensor:
    """x (..., 3) -> (..., 3 + 6 F): [x, sin(w_i x), cos(w_i x)] with w_i = base 2**i, i < F;
    `w`: those frequencies (F,) in x's dtype, made already (`encoding_frequencies`)."""
    if frequencies == 0:
        return x
    if w is None:
        w = encoding_frequencies(frequencies, base, x.dtype, x.device)
    angles = (x[..., None, :] * w[:, None]).flatten(-2)  # (..., F*3)
    return torch.cat([x, torch.sin(angles), torch.cos(angles)], dim=-1)


def encoding_dim(frequencies: int) -> int:
    """Size of `positional_encoding`'s output for 3-D inputs."""
    return 3 + 6 * frequencies


def field_forward(h: torch.Tensor, weights: list[LayerWeights], layer_norm: bool) -> torch.Tensor:
    """Apply the generated MLP per code: h (B, R, in) -> (B, R, out of the last layer).

    Hidden layers: linear, optional layer norm (no affine), ReLU. The last layer is linear.
    """
    last = len(weights) - 1
    for i, (w, b) in enumerate(weights):
        h = torch.baddbmm(b, h, w)
        if i < last:
            if layer_norm:
                h = F.layer_norm(h, h.shape[-1:])
            h = torch.relu(h)
    return h


class Field(nn.Module):
    """Phi: points p_OX (B, R, 3) in frame O -> features (B, R, n), given the generated weights.

    Stateless apart from the encoding settings; the weights come from `HyperNetwork(z)`.
    """

    def __init__(self, center: tuple[float, float, float], frequencies: int, base: float,
                 layer_norm: bool):
        super().__init__()
        self.register_buffer("center", torch.tensor(center, dtype=torch.float32), persistent=False)
        self.frequencies, self.base, self.layer_norm = frequencies, base, layer_norm
        self._w: dict[tuple, torch.Tensor] = {}  # encoding frequencies per (dtype, device)

    def forward(self, p_OX: torch.Tensor, weights: list[LayerWeights]) -> torch.Tensor:
        key = (p_OX.dtype, p_OX.device)
        if key not in self._w:
            self._w[key] = encoding_frequencies(self.frequencies, self.base, *key)
        h = positional_encoding(p_OX - self.center.to(p_OX.dtype), self.frequencies, self.base,
                                self._w[key])
        return field_forward(h, weights, self.layer_norm)
