"""The neural field of one category: H(z) -> Phi, LSTM raymarcher, pixel generators, keypoint head.

`NFRModel` holds only the networks (phi, theta_RM, psi_1, psi_2, gamma) and takes the code z
explicitly, batched: fitting several codes at once (multi-start) is one call. `NFRAutoDecoder`
adds the table of training-object codes and is what training (and DistributedDataParallel) wraps.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.field import Field, encoding_dim
from nfr_drake.nfr.heads import KeypointHead, PixelGenerator
from nfr_drake.nfr.hyper import HyperNetwork
from nfr_drake.nfr.latent import ObjectCodes, compose_z, slots_q_to_z_art, split_z
from nfr_drake.nfr.raymarcher import LSTMRaymarcher
from nfr_drake.nfr.rays import Rays, sphere_interval


class RenderOutput(NamedTuple):
    """Per ray: rgb (B, R, 3), class logits (B, R, C) (None when not asked for), surface points
    (B, R, 3) in O, depth (B, R) along the ray, depth_trace (B, R, T + 1) of the marcher."""

    rgb: torch.Tensor
    logits: torch.Tensor
    points: torch.Tensor
    depth: torch.Tensor
    depth_trace: torch.Tensor


class NFRModel(nn.Module):
    """All networks of the neural field; the code z is an argument, never stored here."""

    def __init__(self, config: NFRModelConfig):
        super().__init__()
        self.config = config
        c = config
        sizes = [encoding_dim(c.pe_frequencies)] + [c.field_width] * (c.field_layers - 1) \
            + [c.feature_dim]
        self.hyper = HyperNetwork(c.latent_dim, list(zip(sizes[:-1], sizes[1:], strict=True)),
                                  c.hyper_hidden, c.hyper_offset_scale)
        self.field = Field(c.bound_center, c.pe_frequencies, c.pe_base_frequency, c.layer_norm)
        self.marcher = LSTMRaymarcher(c.feature_dim, c.lstm_hidden, c.march_steps,
                                      c.march_max_step, c.march_init_step)
        self.rgb_head = PixelGenerator(c.feature_dim, c.pixel_hidden, 3)
        self.seg_head = PixelGenerator(c.feature_dim, c.pixel_hidden, c.num_classes)
        self.keypoint_head = KeypointHead(c.latent_dim, c.keypoint_hidden, c.num_keypoints,
                                          c.num_slots, c.slot_logits)

    def depth_bounds(self, rays: Rays) -> tuple[torch.Tensor, torch.Tensor]:
        """(near, far) (B, R): where each ray enters and leaves the bounding sphere."""
        center = torch.tensor(self.config.bound_center, dtype=rays.origins.dtype,
                              device=rays.origins.device)
        return sphere_interval(rays, center, self.config.bound_radius, self.config.min_depth)

    def normalized(self, z: torch.Tensor) -> torch.Tensor:
        """z (..., 2 S + k) with each slot of z_art projected onto its unit circle."""
        return compose_z(*split_z(z, self.config.num_slots))

    def render(self, z: torch.Tensor, rays: Rays, logits: bool = True) -> RenderOutput:
        """Render rays (B, R, 3) of B codes z (B, 2 S + k); z_art is normalised here.

        z_art of z is projected onto the unit circle before use, so a free z_art can be optimised.
        `logits`: run the segmentation head psi_2 (an image loss alone needs only rgb).
        """
        z = self.normalized(z)
        weights = self.hyper(z)
        march = self.marcher(lambda p: self.field(p, weights), rays, *self.depth_bounds(rays))
        return RenderOutput(self.rgb_head(march.features),
                            self.seg_head(march.features) if logits else None,
                            march.points, march.depth, march.depth_trace)

    def keypoints(self, z: torch.Tensor) -> torch.Tensor:
        """Keypoints (B, K, 3) in O of codes z (B, 2 S + k) (z_art normalised here)."""
        return self.keypoint_head(self.normalized(z))[0]

    def slot_logits(self, z: torch.Tensor) -> torch.Tensor:
        """Per slot (B, S, 3) logits of existence, door and drawer of codes z (B, 2 S + k);
        (B, 1, 0) for a one-slot model."""
        return self.keypoint_head(self.normalized(z))[1]

    def forward(self, z: torch.Tensor, rays: Rays) -> tuple[RenderOutput, torch.Tensor]:
        """Both read-outs of codes z (B, 2 S + k): (render of rays (B, R, 3), keypoints (B, K, 3))."""
        return self.render(z, rays), self.keypoints(z)


class NFRAutoDecoder(nn.Module):
    """Training module: the networks plus one learnable z_obj per training object.

    forward(object_index (B,), q (B,) or per slot (B, S), rays) -> (RenderOutput, keypoints
    (B, K, 3), z (B, 2 S + k)), with each slot's z_art = (cos(pi q), sin(pi q)) from the true q
    (paper, "Training").
    """

    def __init__(self, config: NFRModelConfig, num_objects: int, code_init_std: float = 0.01):
        super().__init__()
        self.model = NFRModel(config)
        self.codes = ObjectCodes(num_objects, config.latent_obj_dim, code_init_std)

    def code(self, object_index: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        """z (B, 2 S + k) of training objects at articulations q (B,) or per slot (B, S)."""
        return torch.cat([slots_q_to_z_art(q, self.model.config.num_slots),
                          self.codes(object_index)], dim=-1)

    def forward(self, object_index: torch.Tensor, q: torch.Tensor, rays: Rays):
        z = self.code(object_index, q)
        render, keypoints = self.model(z, rays)
        return render, keypoints, z
