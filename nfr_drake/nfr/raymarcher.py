"""The differentiable LSTM raymarcher of SRN: a fixed number of learned steps along each ray."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import torch
from torch import nn

from nfr_drake.nfr.rays import Rays

FieldFn = Callable[[torch.Tensor], torch.Tensor]
"""Points (B, R, 3) in O -> features (B, R, n)."""


class MarchState(NamedTuple):
    """depth (B, R) along the rays; LSTM hidden and cell states (B * R, hidden)."""

    depth: torch.Tensor
    h: torch.Tensor
    c: torch.Tensor


class MarchResult(NamedTuple):
    """points (B, R, 3) in O and features (B, R, n) where marching ended; depth (B, R) final;
    depth_trace (B, R, T + 1) the start depth and the depth after each of the T steps."""

    points: torch.Tensor
    features: torch.Tensor
    depth: torch.Tensor
    depth_trace: torch.Tensor


def march_step(field: FieldFn, rays: Rays, state: MarchState, cell: nn.LSTMCell,
               step_head: nn.Linear, max_step: float, near: torch.Tensor,
               far: torch.Tensor) -> MarchState:
    """One step: query Phi at the current points, update the LSTM, move by its predicted step.

    The step is max_step * tanh(raw) and the new depth is kept within [near, far] (B, R): the
    marcher cannot leave the object's bounding sphere or run away in the first iterations.
    """
    points = rays.origins + state.depth.unsqueeze(-1) * rays.directions
    v = field(points)
    h, c = cell(v.reshape(-1, v.shape[-1]), (state.h, state.c))
    step = max_step * torch.tanh(step_head(h).view_as(state.depth))
    depth = torch.minimum(torch.maximum(state.depth + step, near), far)
    return MarchState(depth, h, c)


class LSTMRaymarcher(nn.Module):
    """Marches `steps` times from a start depth; returns the surface points and their features."""

    def __init__(self, feature_dim: int, hidden: int, steps: int, max_step: float,
                 init_step: float = 0.0):
        super().__init__()
        self.steps, self.hidden, self.max_step = steps, hidden, max_step
        self.cell = nn.LSTMCell(feature_dim, hidden)
        self.step_head = nn.Linear(hidden, 1)
        with torch.no_grad():  # forget gate bias 1 (SRN's lstm_forget_gate_init)
            for b in (self.cell.bias_ih, self.cell.bias_hh):
                b.zero_()
                b[hidden:2 * hidden].fill_(0.5)
            if init_step:  # the first steps move forward by about init_step (m)
                self.step_head.bias.fill_(math.atanh(init_step / max_step))

    def forward(self, field: FieldFn, rays: Rays, near: torch.Tensor,
                far: torch.Tensor) -> MarchResult:
        """rays with origins/directions (B, R, 3); marching starts at near (B, R), stays <= far."""
        n = near.numel()
        zeros = near.new_zeros(n, self.hidden)
        state = MarchState(near, zeros, zeros)
        trace = [near]
        for _ in range(self.steps):
            state = march_step(field, rays, state, self.cell, self.step_head, self.max_step,
                               near, far)
            trace.append(state.depth)
        points = rays.origins + state.depth.unsqueeze(-1) * rays.directions
        return MarchResult(points, field(points), state.depth, torch.stack(trace, dim=-1))
