"""Fitting a furniture field (several articulation slots) to posed images, and what it gives.

The networks stay frozen; z = [z_art (2 per slot), z_obj] moves by Adam on the image loss plus
SRN's latent prior (`FurnitureFitConfig`). Starts: `starts` training codes (evenly spaced over the
code table) with every slot shut and with every slot half open are scored by one forward pass on
`lookup_rays` rays; the best `keep` are fitted together, and the lowest image loss wins. Each slot
of the result has its q (its own z_art), the keypoint head's existence and type logits and its four
keypoints; forward simulation sweeps one slot's q with the others held (`part_trajectory`).
docs/NEURAL_FIELD.md, "Furniture: several parts".
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import ObservedRays
from nfr_drake.nfr.latent import slots_q_to_z_art, split_z, z_art_to_q
from nfr_drake.nfr.losses import latent_loss
from nfr_drake.nfr.model import NFRModel


@dataclass(frozen=True)
class FurnitureFitConfig:
    """Options of the furniture fit."""

    starts: int = 16
    """Training codes looked up as starts (each with all slots shut and all half open)."""
    lookup_rays: int = 1024
    """Rays (edge-weighted as the steps') on which the lookup scores the start codes."""
    keep: int = 2
    """Best looked-up starts fitted together; the lowest image loss wins."""
    steps: int = 150
    """Adam steps."""
    rays_per_step: int = 512
    """Random pixels (over all views) per step, shared by the starts."""
    detail_fraction: float = 0.5
    """Share of each step's rays drawn where the image has edges (handles, gaps between fronts)."""
    lr: float = 1e-2
    """Adam learning rate of z."""
    latent_weight: float = 1e-3
    """SRN's prior on z_obj (mean of squares), as in training."""
    seed: int = 0
    """Seed of the ray draws."""

    def __post_init__(self):
        if min(self.starts, self.lookup_rays, self.keep, self.steps, self.rays_per_step) < 1:
            raise ConfigError("FurnitureFitConfig: starts, lookup_rays, keep, steps and "
                              "rays_per_step must be at least 1")
        if not 0.0 <= self.detail_fraction <= 1.0 or self.lr <= 0 or self.latent_weight < 0:
            raise ConfigError("FurnitureFitConfig: detail_fraction in [0, 1], lr > 0, "
                              "latent_weight >= 0")


@dataclass
class FurnitureFit:
    """The fitted code z (2 S + k,); per slot q (S,), exists bool (S,) (existence logit > 0),
    types (S,) index into PART_TYPES, keypoints (S, 4, 3) in O (`SLOT_KEYPOINTS`); image_loss
    (MSE on the last step's rays), steps, seconds of wall time; the starts fitted together
    (`keep` of them): their final codes start_z (keep, 2 S + k) and image losses on the last
    step's rays start_losses (keep,); z is the one of the lowest loss."""

    z: torch.Tensor
    q: np.ndarray
    exists: np.ndarray
    types: np.ndarray
    keypoints: np.ndarray
    image_loss: float
    steps: int
    seconds: float
    start_z: torch.Tensor | None = None
    start_losses: np.ndarray | None = None


def _mse(model: NFRModel, z: torch.Tensor, rays: ObservedRays, index: torch.Tensor) -> torch.Tensor:
    """Image MSE (B,) of codes z (B, D) on the rays `index`."""
    r, rgb = rays.take(index, z.shape[0])
    return ((model.render(z, r).rgb - rgb) ** 2).mean(dim=(1, 2))


def fit_furniture(model: NFRModel, rays: ObservedRays, codes: torch.Tensor,
                  config: FurnitureFitConfig = FurnitureFitConfig()) -> FurnitureFit:
    """Fit z of a model with several slots to the observed rays of a capture; codes (N, k) are
    the training codes the starts come from."""
    S = model.config.num_slots
    if S < 2:
        raise ConfigError("fit_furniture needs a model with several articulation slots")
    t0 = time.perf_counter()
    generator = torch.Generator().manual_seed(config.seed)
    pick = torch.linspace(0, len(codes) - 1, min(config.starts, len(codes))).round().long()
    z_obj = codes[pick].to(rays.rgb)
    cands = torch.cat([torch.cat([slots_q_to_z_art(torch.full((len(z_obj), S), q), S).to(z_obj),
                                  z_obj], -1) for q in (0.0, 0.5)])
    with torch.no_grad():
        index = rays.sample(config.lookup_rays, config.detail_fraction, generator)
        loss = _mse(model, cands, rays, index)
    z = cands[loss.argsort()[:config.keep]].clone().requires_grad_(True)
    optimiser = torch.optim.Adam([z], lr=config.lr)
    for _ in range(config.steps):
        index = rays.sample(config.rays_per_step, config.detail_fraction, generator)
        per_code = _mse(model, z, rays, index)
        total = per_code.sum() + config.latent_weight * latent_loss(split_z(z, S)[1]) * len(z)
        optimiser.zero_grad(set_to_none=True)
        total.backward()
        optimiser.step()
    with torch.no_grad():
        best = int(per_code.argmin())
        z_best = z[best].detach()
        logits = model.slot_logits(z_best[None])[0]
        keypoints = model.keypoints(z_best[None])[0].view(S, len(SLOT_KEYPOINTS), 3)
        q = z_art_to_q(split_z(z_best, S)[0].view(S, 2))
    return FurnitureFit(z_best, q.double().cpu().numpy(), (logits[:, 0] > 0).cpu().numpy(),
                        logits[:, 1:].argmax(-1).cpu().numpy(), keypoints.double().cpu().numpy(),
                        float(per_code[best].detach()), config.steps, time.perf_counter() - t0,
                        start_z=z.detach().clone(), start_losses=per_code.detach().double().cpu().numpy())


@torch.no_grad()
def part_trajectory(model: NFRModel, z: torch.Tensor, slot: int, q_grid: np.ndarray) -> np.ndarray:
    """Forward simulation of one part: slot `slot`'s keypoints (N, 4, 3) in O as its q sweeps
    q_grid (N,), the other slots held at their q in z."""
    S = model.config.num_slots
    z_art, z_obj = split_z(z, S)
    art = z_art.view(S, 2).expand(len(q_grid), S, 2).clone()
    qs = torch.as_tensor(np.asarray(q_grid), dtype=z.dtype, device=z.device)
    art[:, slot] = slots_q_to_z_art(qs[:, None], 1)
    codes = torch.cat([art.flatten(1), z_obj.expand(len(q_grid), -1)], -1)
    kp = model.keypoints(codes).view(len(q_grid), S, len(SLOT_KEYPOINTS), 3)
    return kp[:, slot].double().cpu().numpy()


def part_json(model: NFRModel, fit: FurnitureFit, slot: int, q_grid: np.ndarray) -> dict:
    """Slot `slot` of a fit as a part, {index, type, q, keypoints, trajectory}: keypoints name ->
    [x, y, z] in O at the fitted q; trajectory q (N,) and name -> (N, 3), the slot swept over
    q_grid (N,) with the others held."""
    path = part_trajectory(model, fit.z, slot, q_grid)
    return {"index": slot, "type": PART_TYPES[int(fit.types[slot])], "q": float(fit.q[slot]),
            "keypoints": {n: fit.keypoints[slot, i].tolist() for i, n in enumerate(SLOT_KEYPOINTS)},
            "trajectory": {"q": np.asarray(q_grid, float).tolist(),
                           "keypoints": {n: path[:, i].tolist() for i, n in enumerate(SLOT_KEYPOINTS)}}}


def parts_json(model: NFRModel, fit: FurnitureFit, q_grid: np.ndarray) -> list[dict]:
    """`parts: [{index, type, q, keypoints, trajectory}]` (`part_json`) of the slots the head says
    exist."""
    return [part_json(model, fit, int(k), q_grid) for k in np.flatnonzero(fit.exists)]
