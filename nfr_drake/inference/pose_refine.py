"""Refining an estimated object pose with the fitted field: (x, y, yaw) on the floor, z held.

An estimated X_WO (`perception.object_pose`, a box fitted to the segmenter's masks) is a few cm
and degrees off in a room, and the latent fit (`inference.fit`) runs in that frame O, X_WO fixed.
Once the field is fitted, its image loss against the photos says where the object stands better
than the box did: the refinement moves the object's frame, P, by a planar delta (dx, dy, dyaw)
about O's z axis (O's z is W's: the object stands on the floor, which stays at z = 0), by Adam on
the fit's own loss (image MSE on the painted photos, edge-weighted rays, the latent prior and
the handle sighting), the code z refined with it at a small learning rate, so that a shape the
fit bent to the wrong pose can straighten. The rays, in O, are re-posed into P at every step by
the differentiable inverse of the delta (`repose`), which turns about the model's bound centre
(the object's middle), not O's origin, so that a turn barely moves the object's centre and x, y
and yaw stay nearly independent.

The delta is bounded (`FitConfig.pose_max_shift_m`, `pose_max_yaw_deg`): a larger move is
refused, the fit kept as it was in O; so is one that does not lower the loss on fixed rays.
Used only where the pose is estimated (`infer(..., refine_pose=True)`): a given pose stays.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import torch

from nfr_drake.data.capture import CaptureSet
from nfr_drake.inference.fit import (
    FitConfig,
    FitOutcome,
    ObservedRays,
    PartSighting,
    per_code_mse,
    sighting_loss,
)
from nfr_drake.nfr.latent import z_art_to_q
from nfr_drake.nfr.losses import latent_loss
from nfr_drake.nfr.model import NFRModel
from nfr_drake.nfr.rays import Rays


def yaw_matrix(yaw: torch.Tensor) -> torch.Tensor:
    """Rotation (3, 3) by `yaw` (scalar tensor, rad) about z, differentiable."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    zero, one = torch.zeros_like(yaw), torch.ones_like(yaw)
    return torch.stack([torch.stack([c, -s, zero]), torch.stack([s, c, zero]),
                        torch.stack([zero, zero, one])])


def in_P(points: torch.Tensor, delta: torch.Tensor, pivot: torch.Tensor) -> torch.Tensor:
    """Points (..., 3) in O as points in P, differentiably in `delta`.

    delta (3,): dx, dy (m) and dyaw (rad) of P in O, the turn about the vertical line through
    `pivot` (3,) in O: a point p_P of P lies at p_O = R(dyaw) (p_P - c) + c + (dx, dy, 0) with
    c the pivot (`delta_transform`); so p_P = R^T (p_O - c - t) + c."""
    R = yaw_matrix(delta[2]).to(points)
    t = torch.cat([delta[:2], delta.new_zeros(1)]).to(points)
    c = pivot.to(points)
    return (points - c - t) @ R + c


def repose(origins: torch.Tensor, directions: torch.Tensor, delta: torch.Tensor,
           pivot: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Rays in O, origins and directions (..., 3), as rays in P (`in_P`; d_P = R^T d_O),
    differentiably in `delta`."""
    return in_P(origins, delta, pivot), directions @ yaw_matrix(delta[2]).to(directions)


def delta_transform(delta: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """X_OP (4, 4): the frame P of `repose`'s delta (dx, dy m, dyaw rad) about `pivot` (3,) in O."""
    c, s = math.cos(delta[2]), math.sin(delta[2])
    X = np.eye(4)
    X[:2, :2] = [[c, -s], [s, c]]
    centre = np.array([pivot[0], pivot[1], 0.0])
    X[:3, 3] = centre + np.array([delta[0], delta[1], 0.0]) - X[:3, :3] @ centre
    return X


@dataclass
class PoseRefinement:
    """X_OP (4, 4): the refined object frame P in the fit's frame O (identity when refused);
    z (D,) the code in P (the fit's when refused); delta (dx m, dy m, dyaw deg) of the last
    step, kept or not; loss_before, loss_after: the fit's loss on fixed rays in O and in P;
    image_loss: the kept code's image MSE on uniformly drawn rays in P (nan when refused);
    status: "kept" or why it was refused; steps run; seconds of wall time."""

    X_OP: np.ndarray
    z: torch.Tensor
    delta: tuple[float, float, float]
    loss_before: float
    loss_after: float
    image_loss: float
    status: str
    steps: int
    seconds: float

    @property
    def kept(self) -> bool:
        return self.status == "kept"

    def to_json(self) -> dict:
        """What the result's `extra["object_pose"]["refinement"]` says."""
        return {"status": self.status, "dx_m": self.delta[0], "dy_m": self.delta[1],
                "dyaw_deg": self.delta[2], "X_OP": self.X_OP.tolist(),
                "loss_before": self.loss_before, "loss_after": self.loss_after,
                "steps": self.steps, "seconds": self.seconds}


def refine_object_pose(model: NFRModel, z: torch.Tensor, rays: ObservedRays, config: FitConfig,
                sighting: PartSighting | None = None) -> PoseRefinement:
    """Refine the object's frame from the fitted code z (D,) on the observed rays (in O) with
    `config.pose_steps` Adam steps (module docstring; `config` resolved or not). The networks
    are left frozen; the returned code is detached."""
    started = time.perf_counter()
    config = config.resolved()
    flags = [p.requires_grad for p in model.parameters()]
    for p in model.parameters():
        p.requires_grad_(False)
    try:
        return _refine(model, z.detach(), rays, config, sighting, started)
    finally:
        for p, flag in zip(model.parameters(), flags, strict=True):
            p.requires_grad_(flag)


def _refine(model: NFRModel, z0: torch.Tensor, rays: ObservedRays, config: FitConfig,
            sighting: PartSighting | None, started: float) -> PoseRefinement:
    dtype = rays.rgb.dtype
    pivot = torch.tensor(model.config.bound_center, dtype=dtype)
    pivot[2] = 0.0
    generator = torch.Generator(device="cpu").manual_seed(config.seed + 1)
    held = rays.sample(config.pose_held_rays, config.detail_fraction, generator)

    def loss(delta: torch.Tensor, z: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        """The fit's loss (image MSE, latent prior, sighting) of code z (D,) in the frame P of
        `delta`, on rays `index`."""
        origins, directions = repose(rays.origins[index], rays.directions[index], delta, pivot)
        image = per_code_mse(model, z[None], Rays(origins[None], directions[None]), rays.rgb[index])
        total = image[0] + config.latent_weight * latent_loss(z[None, 2:])
        if sighting is not None:
            p_P = in_P(sighting.p_O.to(dtype), delta, pivot)
            total = total + sighting_loss(model, z[None], PartSighting(sighting.keypoint, p_P), config)[0]
        return total

    zero = torch.zeros(3, dtype=dtype)
    with torch.no_grad():
        before = float(loss(zero, z0, held))
    # Adam's step is about its learning rate whatever the gradient's scale, so the delta is
    # optimised in units of its coordinates' rates (m, m, rad per step): delta = scale * u.
    scale = torch.tensor([config.pose_lr_m, config.pose_lr_m, math.radians(config.pose_lr_deg)],
                         dtype=dtype)
    u = torch.zeros(3, dtype=dtype, requires_grad=True)
    z = z0.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([{"params": [u], "lr": 1.0},
                                  {"params": [z], "lr": config.pose_z_lr}])
    schedule = torch.optim.lr_scheduler.LambdaLR(  # rates down to 0 at the end: it settles
        optimiser, lambda step: 1.0 - step / max(1, config.pose_steps))
    for _ in range(config.pose_steps):
        index = rays.sample(config.pose_rays, config.detail_fraction, generator)
        value = loss(scale * u, z, index)
        optimiser.zero_grad()
        value.backward()
        optimiser.step()
        schedule.step()
        with torch.no_grad():
            z[1].abs_()  # z_art on the upper half circle (`fit._adam`)
    delta = (scale * u).detach()
    z = z.detach()
    with torch.no_grad():
        after = float(loss(delta, z, held))
    shift, yaw = float(delta[:2].norm()), math.degrees(float(delta[2]))
    moved = (float(delta[0]), float(delta[1]), yaw)
    if shift > config.pose_max_shift_m or abs(yaw) > config.pose_max_yaw_deg:
        status = (f"refused: a move of {100 * shift:.1f} cm and {yaw:.1f} deg, beyond "
                  f"{100 * config.pose_max_shift_m:.1f} cm and {config.pose_max_yaw_deg:.1f} deg")
    elif after >= before:
        status = f"refused: the loss on fixed rays did not drop ({before:.5f} -> {after:.5f})"
    else:
        status = "kept"
    if status != "kept":
        return PoseRefinement(np.eye(4), z0, moved, before, after, math.nan, status, config.pose_steps,
                              time.perf_counter() - started)
    uniform = torch.randint(rays.rgb.shape[0], (config.eval_rays,), generator=generator)
    with torch.no_grad():
        origins, directions = repose(rays.origins[uniform], rays.directions[uniform], delta, pivot)
        image_loss = float(per_code_mse(model, z[None], Rays(origins[None], directions[None]),
                                        rays.rgb[uniform])[0])
    return PoseRefinement(delta_transform(delta.double().numpy(), pivot.double().numpy()), z, moved,
                          before, after, image_loss, status, config.pose_steps,
                          time.perf_counter() - started)


def in_refined_frame(refinement: PoseRefinement, capture: CaptureSet, outcome: FitOutcome
                     ) -> tuple[CaptureSet, FitOutcome]:
    """The capture with its poses in P (X_PC = X_PO X_OC) and the fit's outcome with the kept
    refinement's code, q, image loss and X_OP; both as they were when it was refused."""
    if not refinement.kept:
        return capture, outcome
    X_PO = np.linalg.inv(refinement.X_OP)
    frames = [replace(f, X_OC=X_PO @ f.X_OC) for f in capture.frames]
    return (CaptureSet(capture.root, frames, capture.gt, capture.extra),
            replace(outcome, z=refinement.z, q=float(z_art_to_q(refinement.z[:2])),
                    image_loss=refinement.image_loss, X_OP=refinement.X_OP))

