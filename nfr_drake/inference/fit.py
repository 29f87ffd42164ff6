"""Auto-decoding: find the latent code z = [z_art, z_obj] of an unseen object from posed images.

The networks stay frozen; only z moves, by Adam on the image loss (paper: lambda_1 = lambda_2 = 0)
plus SRN's latent prior. The image loss has local minima in q, so the fit explores first: several
codes are fitted together for `explore_steps`, and the one with the lowest image loss on a fixed
evaluation set of rays is then refined alone until its loss has not improved by `min_improvement`
for `patience` steps, or `max_steps` steps in all have run.

The fast preset, the default, looks its starts up (`FitConfig.start`): candidate codes at a grid of
articulations, with the mean training code and with the training codes whose keypoint head puts
the handle where the handle detector saw it, are scored by one forward pass without gradient, and
the best candidate of each band of q is explored (at a larger learning rate, so that z_obj leaves
its start quickly): the starts' losses say which basin of q is right only once z_obj has
adapted, and a start at its band's best q, with codes near the sighting, adapts sooner. The
refinement's loss is measured on fixed rays every `stop_every` steps, which tells convergence
from the noise of the steps' random rays, so the fit stops when it has converged. The thorough
preset spreads its starts evenly over q and runs longer stages, at about 4 times the CPU time.

A drawer's pull and depth trade along a shallow valley of the image loss (a deeper drawer pulled
out less puts its front and handle at the same place), along which Adam creeps: with z_obj held,
the loss rises steeply on either side of the refined q, yet without help the fast fit ended
1.4 cm from the true pull (median of 20 drawers; docs/BENCHMARKS.md). Two things help where the
focus part slides with q (a drawer's front; a door swings, and its angle shows in its plane).
The valley scan (`FitConfig.valley_codes`) holds a few articulations around the code's, starts
each z_obj along the direction in which the keypoint head keeps the focus part in place, fits
the z_obj of all of them together and goes on from the minimum of their losses' profile over q;
it runs after the refinement, or (`valley_first`) before it, from the exploration's winner.
The valley coordinate (`valley_lr`) gives the refinement one more coordinate along that
direction, so that one Adam step moves q and z_obj together along the valley. The fast preset
uses both, the scan first (docs/BENCHMARKS.md).

A last stage takes a closer look at one part (`FocusTarget`, the handle): for `focus_steps` more
steps, a `detail_fraction` share of the rays (half by default) is drawn among those passing within
`focus_radius_m` of where the keypoint head puts that part, the rest over all pixels. A
handle is one or two pixels wide, so it barely weighs in an image loss over the whole object, yet it
is what a robot grasps. The stage can pull z off the codes the keypoint head was trained on, so its
result is kept only when the head's part and the part the field renders (the centroid of the
focused rays' surface points labelled with the part's class) stay within `focus_agreement_m`.

A part seen by other means (`PartSighting`: the handle triangulated from a 2D detector's masks,
`nfr_drake.perception.handle_triangulation`) adds a robust term w log(1 + d^2 / s^2) on the keypoint
head's distance d to it, in every stage and in the choice among the starts, and brings starts
from the training codes whose head puts the part nearest the sighting: among the lookup's
candidates, or (starts spread) one more start after the exploration at the winner's q. It is
what fixes the hinge side of a shut door, which the image loss alone, with a handle of a few
pixels, leaves open.

Rays come from each frame's own intrinsics and pose, so any resolution, field of view or number of
views works (the paper's claim of robustness to camera parameters never seen in training).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Annotated, ClassVar, Literal

import cv2
import numpy as np
import torch
import tyro

from nfr_drake.data.capture import CaptureFrame, CaptureSet
from nfr_drake.errors import ConfigError
from nfr_drake.nfr.latent import normalize_z_art, q_to_z_art, z_art_to_q
from nfr_drake.nfr.losses import latent_loss
from nfr_drake.nfr.model import NFRModel
from nfr_drake.nfr.rays import Rays, pixel_centers, pixel_rays


@dataclass(frozen=True)
class FitConfig:
    """Options of the auto-decoding fit, shared by `infer`, `eval`, `eval-pipeline`, `demo`,
    `tune-head` and the scenario YAML (`fit:`). On the command line each option is `--fit.NAME`;
    the five that commands took before also answer to their old flags (`--max-steps`, ...).

    The fields of `PRESETS` default to None, "the preset's value"; a fit runs with `resolved()`,
    where each of them left at None has its preset's value and one set keeps the value set."""

    preset: Literal["thorough", "fast"] = "fast"
    """The values of the fields left at None (`PRESETS`). "fast", the default: starts looked up,
    explored 30 steps at lr 0.03 with 64 rays each and compared on 1024 fixed rays; where the
    handle slides (a drawer) a valley scan of 3 codes for 15 steps and a valley coordinate in
    the refinement; at most 100 steps in all, the refinement's of 128 rays with early stopping
    on fixed rays; a close look of 20 steps. "thorough": 4 starts spread over q, explored 120
    steps, compared on 4096 rays, refined with 256 rays per step until the smoothed loss stops
    improving (at most 400 steps), a close look of 150 steps: about 4 times the fast fit's CPU
    time (2.1-2.3 s median against 8.5-9.1 s), as accurate within the noise of 20-40 fits
    (docs/BENCHMARKS.md)."""
    start: Literal["lookup", "spread"] | None = None
    """How the starts are chosen. "lookup": candidate codes at `lookup_q` articulations, each with
    the starts' z_obj and, with a sighting, the mean of the `sighting_codes` training z_obj whose
    part the keypoint head puts nearest it at that articulation, are scored by one forward pass on
    `lookup_rays` rays (no gradient); the best candidate of each of `restarts` equal bands of q
    is explored. "spread": `restarts` codes at q = (i + 0.5) / restarts, and the sighted start
    after the exploration. None: the preset's (thorough 'spread', fast 'lookup')."""
    lookup_q: int = 12
    """Articulations of the lookup's candidates, q = (i + 0.5) / lookup_q."""
    lookup_rays: int = 512
    """Rays (edge-weighted like the steps') on which the lookup scores its candidates; as many
    fixed rays measure the refinement's loss for early stopping."""
    restarts: Annotated[int, tyro.conf.arg(aliases=("--restarts",))] = 4
    """Codes explored in parallel (see `start`); the lowest image loss wins. At most `lookup_q`
    with start "lookup"."""
    explore_steps: int | None = None
    """Adam steps of the exploration phase (all starts), at most `max_steps`.
    None: the preset's (thorough 120, fast 30)."""
    max_steps: Annotated[int | None, tyro.conf.arg(aliases=("--max-steps",))] = None
    """Adam steps at most, exploration included. None: the preset's (thorough 400, fast 100)."""
    explore_rays: int | None = None
    """Random pixels (over all views) per exploration step and start, shared by the starts.
    None: the preset's (thorough 128, fast 64)."""
    rays_per_step: int | None = None
    """Random pixels per refinement step. None: the preset's (thorough 256, fast 128)."""
    lr: float = 1e-2
    """Adam learning rate of z in the refinement."""
    explore_lr: float | None = None
    """Adam learning rate of the exploration (all starts, and the sighted start); the fast preset's
    is larger than `lr`, so that z_obj leaves its start within a few tens of steps and the starts'
    losses can be compared sooner. None: the preset's (thorough 0.01, fast 0.03)."""
    latent_weight: float = 1e-3
    """Weight of the Gaussian prior on z_obj (training's value keeps codes where the networks have
    seen them)."""
    patience: int | None = None
    """Refinement steps without an improvement of `min_improvement` that end the fit.
    None: the preset's (thorough 60, fast 30)."""
    min_improvement: float = 0.01
    """Relative improvement of the refinement's loss that counts as progress."""
    stop_every: int | None = None
    """Early stopping measures the refined code's image loss on `lookup_rays` fixed rays (drawn
    like the steps'), without gradient, every `stop_every` refinement steps; 0: it watches the
    steps' own loss on their random rays, smoothed (noisy: it seldom stops before `max_steps`).
    None: the preset's (thorough 0, fast 10)."""
    eval_rays: int | None = None
    """Fixed rays on which the starts are compared and the final loss is measured.
    None: the preset's (thorough 4096, fast 1024)."""
    detail_fraction: Annotated[float, tyro.conf.arg(aliases=("--detail-fraction",))] = 0.5
    """Share of each step's rays drawn in proportion to the observed image's gradient magnitude
    (edges: a door's outline, a handle a few pixels wide), the rest uniformly; the small parts that
    decide q and the hinge side weigh more in the loss."""
    seed: int = 0
    """Seed of ray sampling."""
    valley_codes: int | None = None
    """Codes of the valley scan after the refinement (before it with `valley_first`; 0: none),
    when the focus part slides (the keypoint head moves it along a straight line with q, as a
    drawer's handle; a door's handle swings, and its angle shows in the door's plane): the
    code's q and z_obj trade along a shallow valley of the image loss (a deeper drawer pulled
    out less puts its handle at the same point), along which Adam walks slowly. The scan holds
    `valley_codes` articulations evenly over `valley_span` around the code's q, each with
    z_obj moved along the keypoint head's valley (the focus part kept in place, to first
    order), fits their z_obj with q held for `valley_steps` shared steps, and goes on from the
    best of them on `valley_held_rays` fixed rays or, when its loss there is lower, the code at
    the minimum of a parabola through their losses (z_obj interpolated between its
    neighbours). None: the preset's (thorough 0, fast 3)."""
    valley_lr: float | None = None
    """Adam learning rate, in q per step, of the refinement's valley coordinate (0: none), when
    the focus part slides (see `valley_codes`): the refined code gets one more coordinate t, the
    rendered code being z + t dz/dq along the keypoint head's valley (the focus part kept in
    place, to first order; `_valley_tangent`), so that a step moves q and z_obj together along
    the valley instead of creeping along it by small moves of each.
    None: the preset's (thorough 0, fast 0.005)."""
    valley_first: bool | None = None
    """Run the valley scan before the refinement (from the exploration's winner, so that the
    refinement starts in the valley's minimum and settles z_obj there) rather than after it.
    None: the preset's (thorough false, fast true)."""
    valley_span: float = 0.2
    """Width of the valley scan's grid of q (shifted to lie in [0, 1])."""
    valley_steps: int = 15
    """Adam steps of the valley scan's codes, all together, `valley_rays` rays each."""
    valley_rays: int = 128
    """Random pixels per valley scan step and code, shared by the codes."""
    valley_held_rays: int = 1024
    """Fixed rays (drawn like the steps') on which the valley scan's codes are compared."""
    focus_steps: Annotated[int | None, tyro.conf.arg(aliases=("--focus-steps",))] = None
    """Adam steps of the final close look at the focus part, the handle (0: none).
    None: the preset's (thorough 150, fast 20)."""
    focus_radius_m: float = 0.12
    """Rays passing within this distance of the part take part in the close look, m."""
    focus_lr: float = 5e-3
    """Adam learning rate of the close look (smaller than `lr`: z is near already)."""
    focus_agreement_m: float = 0.05
    """The close look is kept only when the keypoint head and the rendered segmentation then place
    the part within this distance of each other, m."""
    handle_detector: Annotated[bool, tyro.conf.arg(aliases=("--handle-detector",))] = True
    """Use the model's 2D handle detector, when it ships one: the handle it sights in the views,
    triangulated, joins the fit as a `PartSighting`."""
    sighting_weight: float = 2e-3
    """Weight w of the sighting term, w log(1 + d^2 / s^2) for the keypoint head's part at distance
    d from the sighted point (0: the sighting is ignored)."""
    sighting_scale_m: float = 0.015
    """s of the sighting term, m: about the sighting's accuracy; beyond it the term grows only
    logarithmically, so a wrong sighting cannot drag the fit far."""
    sighting_codes: int = 16
    """With a sighting and the training codes, starts from the mean of the `sighting_codes`
    training z_obj whose part the head puts nearest the sighting (0: none): among the lookup's
    candidates, or (start "spread") a second start at the exploration's winner's q that the two
    explore for half of `explore_steps` (within `max_steps`)."""
    refine_pose: bool = True
    """Where the object's pose is estimated (`infer --estimate-pose`, `eval-pipeline
    --object-pose estimated`, `NfrPerceptionSystem` without X_WO), refine it with the fitted
    field after the fit: (x, y, yaw) on the floor, z held, by `pose_steps` Adam steps on the
    fit's loss with the code refined too (`inference.pose_refine`). A given pose is never moved."""
    pose_steps: int = 60
    """Adam steps of the pose refinement (their learning rates fall linearly to 0)."""
    pose_rays: int = 256
    """Random pixels per pose refinement step (drawn like the fit's, `detail_fraction`)."""
    pose_held_rays: int = 1024
    """Fixed rays on which the pose refinement's loss is compared before and after: a move that
    does not lower it is refused."""
    pose_lr_m: float = 3e-3
    """Adam learning rate of the pose refinement's dx and dy, m per step."""
    pose_lr_deg: float = 0.4
    """Adam learning rate of the pose refinement's dyaw, degrees per step."""
    pose_z_lr: float = 2e-3
    """Adam learning rate of the code in the pose refinement (0: the code held)."""
    pose_max_shift_m: float = 0.05
    """The pose refinement refuses a move farther than this on the floor, m."""
    pose_max_yaw_deg: float = 8.0
    """The pose refinement refuses a turn larger than this, degrees."""

    PRESETS: ClassVar[dict[str, dict]] = {
        "thorough": dict(start="spread", explore_steps=120, max_steps=400, explore_rays=128,
                         rays_per_step=256, explore_lr=1e-2, patience=60, stop_every=0,
                         eval_rays=4096, valley_codes=0, valley_first=False, valley_lr=0.0,
                         focus_steps=150),
        "fast": dict(start="lookup", explore_steps=30, max_steps=100, explore_rays=64,
                     rays_per_step=128, explore_lr=3e-2, patience=30, stop_every=10,
                     eval_rays=1024, valley_codes=3, valley_first=True, valley_lr=5e-3,
                     focus_steps=20),
    }
    """Each preset's values of the fields it governs (the fields that default to None)."""

    @classmethod
    def fast(cls, **overrides) -> FitConfig:
        """The "fast" preset, with `overrides` on top."""
        return cls(preset="fast", **overrides)

    def resolved(self) -> FitConfig:
        """The configuration a fit runs with: every field of `PRESETS` left at None set to the
        preset's value, the fields set kept."""
        if self.preset not in self.PRESETS:
            raise ConfigError(f"FitConfig.preset must be one of {', '.join(self.PRESETS)}, "
                              f"not {self.preset!r}")
        unset = {name: value for name, value in self.PRESETS[self.preset].items()
                 if getattr(self, name) is None}
        return replace(self, **unset) if unset else self

    def __post_init__(self):
        resolved = self.resolved()
        if resolved is not self:  # the checks below run on the values the fit will use
            return
        if self.start not in ("lookup", "spread"):
            raise ConfigError(f"FitConfig.start must be 'lookup' or 'spread', not {self.start!r}")
        if self.start == "lookup" and self.restarts > self.lookup_q:
            raise ConfigError(f"FitConfig.restarts ({self.restarts}) must be at most lookup_q "
                              f"({self.lookup_q}): the looked-up starts lie at distinct q")
        for name in ("restarts", "max_steps", "explore_rays", "rays_per_step", "patience",
                     "eval_rays", "lookup_q", "lookup_rays", "valley_rays", "valley_held_rays"):
            if getattr(self, name) < 1:
                raise ConfigError(f"FitConfig.{name} must be >= 1")
        if not 0 <= self.explore_steps <= self.max_steps:
            raise ConfigError(f"FitConfig.explore_steps ({self.explore_steps}) must lie in "
                              f"[0, max_steps ({self.max_steps})]")
        if not 0.0 <= self.detail_fraction <= 1.0:
            raise ConfigError("FitConfig.detail_fraction must lie in [0, 1]")
        if self.stop_every < 0:
            raise ConfigError("FitConfig.stop_every must be >= 0")
        if self.lr <= 0 or self.explore_lr <= 0 or self.latent_weight < 0 or self.min_improvement < 0:
            raise ConfigError("FitConfig: lr and explore_lr must be > 0, latent_weight and "
                              "min_improvement >= 0")
        if self.sighting_weight < 0 or self.sighting_scale_m <= 0 or self.sighting_codes < 0:
            raise ConfigError("FitConfig: sighting_weight and sighting_codes must be >= 0, "
                              "sighting_scale_m > 0")
        if self.valley_codes < 0 or self.valley_codes == 1 or self.valley_steps < 0 \
                or not 0 < self.valley_span <= 1:
            raise ConfigError("FitConfig: valley_codes must be 0 or >= 2, valley_steps >= 0, "
                              "valley_span in (0, 1]")
        if self.valley_lr < 0:
            raise ConfigError("FitConfig.valley_lr must be >= 0")
        if self.pose_steps < 0 or min(self.pose_rays, self.pose_held_rays) < 1 or min(
                self.pose_lr_m, self.pose_lr_deg, self.pose_max_shift_m, self.pose_max_yaw_deg) <= 0 \
                or self.pose_z_lr < 0:
            raise ConfigError("FitConfig: pose_steps and pose_z_lr must be >= 0, pose_rays and "
                              "pose_held_rays >= 1; pose_lr_m, pose_lr_deg, pose_max_shift_m and "
                              "pose_max_yaw_deg > 0")
        if self.focus_steps < 0 or min(self.focus_radius_m, self.focus_lr,
                                       self.focus_agreement_m) <= 0:
            raise ConfigError("FitConfig: focus_steps must be >= 0; focus_radius_m, focus_lr and "
                              "focus_agreement_m > 0")

    @property
    def uses_sightings(self) -> bool:
        """Whether a handle detector's sighting, when there is one, takes part in the fit."""
        return self.handle_detector and self.sighting_weight > 0


@dataclass(frozen=True)
class FocusTarget:
    """The part the fit's last stage looks at closely: keypoint index `keypoint` of the keypoint
    head and semantic class `label` of the segmentation head, both naming the same part."""

    keypoint: int
    label: int


@dataclass(frozen=True)
class PartSighting:
    """Where a part was seen by other means than the image loss (the handle detector's
    triangulation): keypoint index `keypoint` of the keypoint head, point p_O (3,) in O, m."""

    keypoint: int
    p_O: torch.Tensor


@dataclass
class ObservedRays:
    """All pixels of a capture as rays in O: origins, directions (N, 3); colours rgb (N, 3) in
    [0, 1]; frame (N,) index of the frame each pixel belongs to; detail (N,) the image gradient
    magnitude at each pixel (`image_detail`)."""

    origins: torch.Tensor
    directions: torch.Tensor
    rgb: torch.Tensor
    frame: torch.Tensor
    detail: torch.Tensor

    def __post_init__(self):
        # Cumulative detail, computed once: each step then draws in O(log N) per ray.
        self._detail_cdf = torch.cumsum(self.detail.double().cpu(), dim=0)

    def sample(self, count: int, detail_fraction: float, generator: torch.Generator
               ) -> torch.Tensor:
        """`count` pixel indices: a `detail_fraction` share drawn with probability proportional
        to `detail` (with replacement), the rest uniformly."""
        total = float(self._detail_cdf[-1])
        n_detail = round(detail_fraction * count) if total > 0 else 0
        index = torch.randint(self.rgb.shape[0], (count - n_detail,), generator=generator)
        if n_detail:
            u = torch.rand(n_detail, generator=generator, dtype=torch.float64) * total
            drawn = torch.searchsorted(self._detail_cdf, u, right=True)
            index = torch.cat([index, drawn.clamp_max(len(self._detail_cdf) - 1)])
        return index.to(self.rgb.device)

    def take(self, index: torch.Tensor, batch: int) -> tuple[Rays, torch.Tensor]:
        """Rays (batch, R, 3) repeated for `batch` codes and their colours (R, 3)."""
        o, d = self.origins[index], self.directions[index]
        return Rays(o.expand(batch, -1, -1), d.expand(batch, -1, -1)), self.rgb[index]

    def near(self, p_O: torch.Tensor, radius: float) -> torch.Tensor:
        """Boolean mask (N,) of the rays passing within `radius` (m) of the point p_O (3,)."""
        offset = p_O - self.origins
        along = (offset * self.directions).sum(-1, keepdim=True).clamp_min(0.0)
        return (offset - along * self.directions).norm(dim=-1) < radius

    def reweighted(self, detail: torch.Tensor) -> ObservedRays:
        """The same rays with another sampling weight per ray (N,)."""
        return ObservedRays(self.origins, self.directions, self.rgb, self.frame, detail)


def frame_ray_directions(frame: CaptureFrame) -> np.ndarray:
    """Unit directions in O of every pixel centre of a frame, row-major, (H W, 3), float64.

    Pinhole frames use the training ray generator (`pixel_rays`); with OpenCV distortion
    (k1 k2 p1 p2) the pixel centres are undistorted first.
    """
    cam = frame.camera
    uv = pixel_centers(cam.height, cam.width, dtype=torch.float64)
    K = torch.from_numpy(cam.K)
    if cam.distortion:
        xy = cv2.undistortPoints((uv.numpy() - 0.5).reshape(-1, 1, 2), cam.K_opencv,
                                 cam.dist_opencv).reshape(-1, 2)
        uv, K = torch.from_numpy(xy), torch.eye(3, dtype=torch.float64)  # normalised coordinates
    rays = pixel_rays(uv[None], K[None], torch.from_numpy(frame.X_OC)[None])
    return rays.directions[0].numpy()


def image_detail(image: np.ndarray) -> np.ndarray:
    """Edge strength (H, W) of an RGB uint8 image (H, W, 3): the largest Sobel gradient magnitude
    over the colour channels, in colour units per pixel, spread to each pixel's 3 x 3
    neighbourhood so that a one-pixel bar (zero gradient at its centre) is covered too. 0 on flat
    regions."""
    rgb = image.astype(np.float32) / 255.0
    gx = cv2.Sobel(rgb, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(rgb, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    magnitude = np.sqrt(gx ** 2 + gy ** 2).max(axis=-1)
    return cv2.dilate(magnitude, np.ones((3, 3), np.uint8))


def observed_rays(capture: CaptureSet, images: list[np.ndarray] | None = None,
                  dtype=torch.float32, masks: list[np.ndarray] | None = None) -> ObservedRays:
    """Every pixel of every frame of `capture` as a ray with its observed colour; with `masks`
    ((H, W) object probability per frame, the frame's size) only the pixels on the object
    (probability > 0.5): the masked image loss, for photos whose background is not the training
    renders' (a room)."""
    images = capture.load_images() if images is None else images
    origins, directions, colours, frames, details = [], [], [], [], []
    for i, (frame, image) in enumerate(zip(capture.frames, images, strict=True)):
        keep = slice(None) if masks is None else np.asarray(masks[i]).reshape(-1) > 0.5
        d = frame_ray_directions(frame)[keep]
        directions.append(d)
        origins.append(np.broadcast_to(frame.X_OC[:3, 3], d.shape))
        colours.append(image.reshape(-1, 3)[keep] / 255.0)
        frames.append(np.full(len(d), i))
        details.append(image_detail(image).reshape(-1)[keep])
    cat = lambda xs: torch.from_numpy(np.concatenate(xs)).to(dtype)  # noqa: E731
    return ObservedRays(cat(origins), cat(directions), cat(colours),
                        torch.from_numpy(np.concatenate(frames)), cat(details))


@dataclass
class FitOutcome:
    """z (2 + k,) of the refined winning start; q its articulation; image_loss its MSE on the
    evaluation rays; start_losses (S,) (on the selection rays, edge-weighted when
    detail_fraction > 0) and start_q (S,) of every start after exploration; steps
    run in all; seconds of wall time; focus what became of the close look ("kept", "off", or
    why it was discarded); sighted_start whether the winning start came from the codes near the
    sighting (`FitConfig.sighting_codes`); X_OP (4, 4) the object frame P that z and q are
    in, in the frame O of the rays, when a pose refinement moved it (`pose_refine`), else None."""

    z: torch.Tensor
    q: float
    image_loss: float
    start_losses: np.ndarray
    start_q: np.ndarray
    steps: int
    seconds: float
    focus: str = "off"
    sighted_start: bool = False
    X_OP: np.ndarray | None = None


def per_code_mse(model: NFRModel, z: torch.Tensor, rays: Rays, target: torch.Tensor,
                  chunk: int = 4096) -> torch.Tensor:
    """Image MSE (S,) of each code z (S, D) on the same rays (S, R, 3), target (R, 3)."""
    losses = []
    R = target.shape[0]
    for s in range(0, R, chunk):
        sub = Rays(rays.origins[:, s:s + chunk], rays.directions[:, s:s + chunk])
        rgb = model.render(z, sub, logits=False).rgb
        losses.append(((rgb - target[s:s + chunk]) ** 2).sum(dim=(-1, -2)))
    return torch.stack(losses).sum(0) / (3 * R)


def fit_latent(model: NFRModel, rays: ObservedRays, config: FitConfig = FitConfig(),
               z_obj_init: torch.Tensor | None = None, focus: FocusTarget | None = None,
               sighting: PartSighting | None = None, codes: torch.Tensor | None = None
               ) -> FitOutcome:
    """Fit z to the observed rays with the networks frozen (see module docstring); the close
    look runs when `focus` names a part and `config.focus_steps` > 0. The fit runs with
    `config.resolved()` (the preset's values where fields are None).

    `z_obj_init`: the starts' z_obj (k,); zeros if None.
    `sighting`: a part seen by other means; its term joins every stage's loss and the choice
    among the starts. `codes`: the training z_obj (N, k), for the start near the sighting.
    """
    started = time.perf_counter()
    config = config.resolved()
    model.eval()
    flags = [p.requires_grad for p in model.parameters()]
    for p in model.parameters():  # frozen networks: no gradient work for their weights
        p.requires_grad_(False)
    try:
        return _fit(model, rays, config, z_obj_init, focus, sighting, codes, started)
    finally:
        for p, flag in zip(model.parameters(), flags, strict=True):
            p.requires_grad_(flag)


def sighting_loss(model: NFRModel, z: torch.Tensor, sighting: PartSighting | None,
                   config: FitConfig) -> torch.Tensor:
    """The sighting term (S,) of codes z (S, D) (`FitConfig.sighting_weight`); 0 without one."""
    if sighting is None or config.sighting_weight == 0:
        return torch.zeros(z.shape[0], dtype=z.dtype, device=z.device)
    d2 = ((model.keypoints(z)[:, sighting.keypoint] - sighting.p_O.to(z)) ** 2).sum(-1)
    return config.sighting_weight * torch.log1p(d2 / config.sighting_scale_m ** 2)


def _adam(model: NFRModel, z: torch.Tensor, rays: ObservedRays, config: FitConfig,
          generator: torch.Generator, steps: int, rays_per_step: int, stop_early: bool,
          sighting: PartSighting | None = None,
          held_loss: Callable[[torch.Tensor], float] | None = None, hold_q: bool = False,
          valley: Callable[[torch.Tensor], torch.Tensor] | None = None) -> int:
    """Up to `steps` Adam steps on the codes z (S, D), in place, `rays_per_step` random rays
    each; returns the steps run.

    After each step z_art is reflected onto the upper half of the circle: the networks were
    trained there only, and the reported q (`z_art_to_q`) mirrors the lower half, so a code left
    below would be reported at another articulation than the one that was rendered and fitted
    (a shut door fitted at q = -0.02 was reported, and forward-simulated, at +0.02).

    With `stop_early`, stops when the loss has not improved by `min_improvement` (relative) for
    `patience` steps: the summed per-step image loss, smoothed, or with `held_loss` (codes (S, D)
    -> their summed image loss on fixed rays) that loss, measured every `stop_every` steps.
    With `hold_q` only z_obj moves (Adam leaves a coordinate without gradient in place).
    With `valley` (codes (S, D) -> their valley tangents (S, D), `_valley_tangent`) each code has
    one more coordinate t, per unit of q, moved by its own Adam at `config.valley_lr`: the code
    rendered is z + t tangent, folded into z after every step (tangents renewed every
    `_VALLEY_RENEW` steps).
    """
    z.requires_grad_(True)
    optimiser = torch.optim.Adam([z], lr=config.lr)
    S = z.shape[0]
    t = None
    if valley is not None and config.valley_lr > 0:
        t = torch.zeros(S, 1, dtype=z.dtype, device=z.device, requires_grad=True)
        optimiser.add_param_group({"params": [t], "lr": config.valley_lr})
    best, since_best = math.inf, 0
    current = held_loss(z.detach()) if stop_early and held_loss is not None else None
    for step in range(1, steps + 1):
        if t is not None and (step - 1) % _VALLEY_RENEW == 0:
            tangent = valley(z.detach())
        code = z if t is None else z + t * tangent
        index = rays.sample(rays_per_step, config.detail_fraction, generator)
        batch_rays, target = rays.take(index, S)
        rgb = model.render(code, batch_rays, logits=False).rgb
        image = ((rgb - target) ** 2).mean(dim=(-1, -2)).sum()  # summed over starts
        loss = (image + config.latent_weight * S * latent_loss(code[:, 2:])
                + sighting_loss(model, code, sighting, config).sum())
        optimiser.zero_grad()
        loss.backward()
        if hold_q:
            z.grad[:, :2] = 0.0
        optimiser.step()
        with torch.no_grad():  # keep z_art on the upper half circle, where q lies (docstring)
            if t is not None:
                z += t * tangent
                t.zero_()
            z[:, 1].abs_()
        if not stop_early:
            continue
        if held_loss is None:
            value = float(image.detach())
            current = value if current is None else 0.9 * current + 0.1 * value
        elif step % config.stop_every == 0:
            current = held_loss(z.detach())
        if current < best * (1.0 - config.min_improvement):
            best, since_best = current, 0
        else:
            since_best += 1
        if since_best >= config.patience:
            return step
    return steps


_FOCUS_FLAT_WEIGHT = 0.05
"""Sampling weight of a flat pixel in the close look, beside its edge strength (colour units per
pixel, `image_detail`): the part's inside is sampled too, not only its outline."""


def _close_look(model: NFRModel, rays: ObservedRays, config: FitConfig, focus: FocusTarget,
                generator: torch.Generator, z: torch.Tensor, sighting: PartSighting | None
                ) -> tuple[torch.Tensor, str, int]:
    """The last stage (module docstring) from code z (D,): the code to keep, what happened, and
    the steps run."""
    with torch.no_grad():
        part = model.keypoints(z[None])[0, focus.keypoint]
    near = rays.near(part, config.focus_radius_m)
    if not bool(near.any()):
        return z, "discarded: no ray passes near the part", 0
    focused = rays.reweighted(near.to(rays.detail.dtype) * (rays.detail + _FOCUS_FLAT_WEIGHT))
    z_look = z[None].clone()
    _adam(model, z_look, focused, replace(config, lr=config.focus_lr), generator,
          config.focus_steps, config.rays_per_step, stop_early=False, sighting=sighting)
    z_look = z_look.detach()
    index = torch.nonzero(near).squeeze(-1)
    with torch.no_grad():
        part = model.keypoints(z_look)[0, focus.keypoint]
        surface = []
        for s in range(0, len(index), 4096):
            sub, _ = rays.take(index[s:s + 4096], 1)
            out = model.render(z_look, sub)
            surface.append(out.points[0][out.logits[0].argmax(-1) == focus.label])
        surface = torch.cat(surface)
    if len(surface) == 0:
        return z, "discarded: the part is not rendered any more", config.focus_steps
    gap = float((surface.mean(0) - part).norm())
    if gap > config.focus_agreement_m:
        return z, f"discarded: keypoint head and rendered part {100 * gap:.1f} cm apart", config.focus_steps
    return z_look[0], "kept", config.focus_steps


_SLIDE_TOLERANCE = 0.05
"""A part slides when the keypoint head's part at q = 1/2 lies within this share of the chord
from q = 0 to 1 off that chord (a door's handle, on an arc, lies 0.2 or more off it)."""


def _slides(model: NFRModel, z: torch.Tensor, keypoint: int) -> bool:
    """Whether the keypoint head moves part `keypoint` of code z (D,) along a straight line with q
    (a drawer's front), not on an arc (a door's)."""
    q = torch.tensor([0.0, 0.5, 1.0], dtype=z.dtype, device=z.device)
    with torch.no_grad():
        p = model.keypoints(torch.cat([q_to_z_art(q), z[2:].expand(3, -1)], -1))[:, keypoint]
    chord, middle = p[2] - p[0], p[1] - p[0]
    off = middle - (middle @ chord) / (chord @ chord).clamp_min(1e-12) * chord
    return bool(off.norm() <= _SLIDE_TOLERANCE * chord.norm())


def _valley_direction(model: NFRModel, z: torch.Tensor, keypoint: int) -> torch.Tensor:
    """d z_obj / d q (k,) along which the keypoint head's part `keypoint` stays in place, to
    first order, at code z (D,): -J_obj^+ dp/dq, the smallest change of z_obj that undoes q's
    move of the part."""
    def part(q: torch.Tensor, z_obj: torch.Tensor) -> torch.Tensor:
        return model.keypoints(torch.cat([q_to_z_art(q), z_obj])[None])[0, keypoint]

    q = z_art_to_q(z[:2]).detach()
    dp_dq, J_obj = torch.autograd.functional.jacobian(part, (q, z[2:].detach()))
    return -torch.linalg.pinv(J_obj) @ dp_dq


_VALLEY_RENEW = 10
"""Steps between renewals of the valley tangents in the refinement (`FitConfig.valley_lr`)."""


def _valley_tangent(model: NFRModel, z: torch.Tensor, keypoint: int) -> torch.Tensor:
    """The valley tangents (S, D) of codes z (S, D): d z / d q along which the keypoint head's
    part `keypoint` stays in place, to first order: z_art along its circle (pi (-z_1, z_0), its
    radius kept), z_obj along `_valley_direction`."""
    return torch.stack([torch.cat([math.pi * torch.stack([-c[1], c[0]]),
                                   _valley_direction(model, c, keypoint)]) for c in z])


def _valley_scan(model: NFRModel, rays: ObservedRays, config: FitConfig,
                 generator: torch.Generator, z: torch.Tensor, keypoint: int,
                 sighting: PartSighting | None,
                 held_losses: Callable[[torch.Tensor], torch.Tensor]) -> tuple[torch.Tensor, int]:
    """The valley scan (`FitConfig.valley_codes`) from the refined code z (D,): the code to go on
    from (D,) and the steps run. `held_losses`: codes (S, D) -> their losses (S,) on fixed rays."""
    q0 = z_art_to_q(z[:2])
    grid = torch.linspace(-config.valley_span / 2, config.valley_span / 2, config.valley_codes,
                          dtype=z.dtype) + q0
    grid = grid - (grid[-1] - 1).clamp_min(0) + (-grid[0]).clamp_min(0)  # inside [0, 1]
    z_obj = z[2:] + (grid - q0)[:, None] * _valley_direction(model, z, keypoint)
    codes = torch.cat([q_to_z_art(grid), z_obj], -1)
    _adam(model, codes, rays, config, generator, config.valley_steps, config.valley_rays,
          stop_early=False, sighting=sighting, hold_q=True)
    codes = codes.detach()
    losses = held_losses(codes).double()
    a, b, _ = np.polyfit(grid.double().numpy(), losses.numpy(), 2)
    best = int(torch.argmin(losses))
    q = float(np.clip(-b / (2 * a), float(grid[0]), float(grid[-1]))) if a > 0 else float(grid[best])
    right = int(torch.searchsorted(grid, torch.tensor(q, dtype=grid.dtype)).clamp(1, len(grid) - 1))
    t = (q - grid[right - 1]) / (grid[right] - grid[right - 1])
    candidate = torch.cat([q_to_z_art(torch.tensor(q, dtype=z.dtype)),
                           torch.lerp(codes[right - 1, 2:], codes[right, 2:], t)])
    pair = held_losses(torch.stack([codes[best], candidate]))
    return (candidate if pair[1] < pair[0] else codes[best]), config.valley_steps


def _sighted_start(model: NFRModel, rays: ObservedRays, config: FitConfig,
                   generator: torch.Generator, z_best: torch.Tensor, sighting: PartSighting,
                   codes: torch.Tensor, steps: int, select_losses) -> tuple[torch.Tensor, bool]:
    """The exploration's winner z_best (1, D) against a start from the training codes near the
    sighting at the winner's q (`FitConfig.sighting_codes`), both explored for `steps` steps;
    returns the better (1, D) and whether it is the new start.

    The codes are matched at the fitted q, not at the starts' spread q: matched at another q, a
    drawer's codes would be those whose handle reaches the sighted point after a shorter pull."""
    z_art = normalize_z_art(z_best[:, :2].detach())
    near = _nearest_codes(model, z_art, codes.to(z_best), sighting, config.sighting_codes)
    z = torch.cat([z_best, torch.cat([z_art, near], -1)]).clone()
    _adam(model, z, rays, config, generator, steps, config.explore_rays, stop_early=False,
          sighting=sighting)
    with torch.no_grad():
        losses = select_losses(z) + sighting_loss(model, z, sighting, config).cpu()
    best = int(torch.argmin(losses))
    return z.detach()[best:best + 1].clone(), best == 1


def _nearest_codes(model: NFRModel, z_art: torch.Tensor, codes: torch.Tensor,
                   sighting: PartSighting, count: int) -> torch.Tensor:
    """Per articulation z_art (Q, 2): the mean (Q, k) of the `count` training z_obj of codes
    (N, k) whose part the keypoint head puts nearest the sighting."""
    with torch.no_grad():
        Q, N = z_art.shape[0], codes.shape[0]
        z = torch.cat([z_art[:, None].expand(Q, N, 2), codes[None].expand(Q, N, -1)], -1)
        part = model.keypoints(z.reshape(Q * N, -1))[:, sighting.keypoint].view(Q, N, 3)
        near = torch.argsort((part - sighting.p_O.to(z)).norm(dim=-1), dim=-1)[:, :count]
        return codes[near].mean(1)


def _lookup_starts(model: NFRModel, rays: ObservedRays, config: FitConfig,
                   generator: torch.Generator, z_obj: torch.Tensor, sighting: PartSighting | None,
                   codes: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    """The starts (S, D) of the lookup (`FitConfig.start`) and whether each came from the codes
    near the sighting (S,) bool. Candidates at `lookup_q` articulations, z_obj (k,) and (with a
    sighting and training codes (N, k)) the mean of the codes nearest the sighting, are scored
    by image loss on `lookup_rays` rays plus the sighting term in one forward pass without
    gradient; the best of each of `restarts` equal bands of q is kept."""
    q = (torch.arange(config.lookup_q, dtype=z_obj.dtype, device=z_obj.device) + 0.5) / config.lookup_q
    z_art = q_to_z_art(q)
    candidates = [torch.cat([z_art, z_obj.expand(len(q), -1)], -1)]
    if sighting is not None and codes is not None and config.sighting_codes > 0:
        near = _nearest_codes(model, z_art, codes.to(z_obj), sighting, config.sighting_codes)
        candidates.append(torch.cat([z_art, near], -1))
    z = torch.cat(candidates)
    index = rays.sample(config.lookup_rays, config.detail_fraction, generator)
    with torch.no_grad():
        batch_rays, target = rays.take(index, len(z))
        losses = per_code_mse(model, z, batch_rays, target) + sighting_loss(model, z, sighting,
                                                                               config)
    losses = losses.view(len(candidates), len(q))
    band = torch.arange(len(q)) * config.restarts // len(q)
    best = []
    for b in range(config.restarts):
        in_band = losses[:, band == b]  # (candidates, articulations in the band)
        flat = int(in_band.argmin())
        best.append((flat // in_band.shape[1], int(torch.nonzero(band == b)[flat % in_band.shape[1]])))
    source = torch.tensor([c for c, _ in best])
    return z[source * len(q) + torch.tensor([i for _, i in best])].clone(), source > 0


def _fit(model: NFRModel, rays: ObservedRays, config: FitConfig, z_obj_init: torch.Tensor | None,
         focus: FocusTarget | None, sighting: PartSighting | None, codes: torch.Tensor | None,
         started: float) -> FitOutcome:
    S, k = config.restarts, model.config.latent_obj_dim
    dtype, device = rays.rgb.dtype, rays.rgb.device
    if z_obj_init is not None and z_obj_init.shape != (k,):
        raise ConfigError(f"fit: z_obj_init has shape {tuple(z_obj_init.shape)}, expected ({k},)")
    z_obj = (z_obj_init.to(dtype=dtype, device=device) if z_obj_init is not None
             else torch.zeros(k, dtype=dtype, device=device))
    generator = torch.Generator(device="cpu").manual_seed(config.seed)
    if config.start == "lookup":
        z, sighted = _lookup_starts(model, rays, config, generator, z_obj, sighting, codes)
    else:
        q0 = (torch.arange(S, dtype=dtype, device=device) + 0.5) / S
        z = torch.cat([q_to_z_art(q0), z_obj.expand(S, k)], dim=-1)
        sighted = torch.zeros(S, dtype=torch.bool)
    eval_index = torch.randperm(rays.rgb.shape[0], generator=generator)[:config.eval_rays]
    # Starts are compared on the loss they minimise (edge-weighted when detail_fraction > 0);
    # the reported image loss stays the plain MSE on uniformly drawn rays.
    select_index = (rays.sample(config.eval_rays, config.detail_fraction, generator)
                    if config.detail_fraction > 0 else eval_index)

    def eval_losses(candidates: torch.Tensor, index: torch.Tensor = eval_index) -> torch.Tensor:
        with torch.no_grad():
            eval_rays, eval_target = rays.take(index.to(device), candidates.shape[0])
            return per_code_mse(model, candidates.detach(), eval_rays, eval_target).cpu()

    explore = replace(config, lr=config.explore_lr)
    steps = _adam(model, z, rays, explore, generator, config.explore_steps, config.explore_rays,
                  stop_early=False, sighting=sighting)
    with torch.no_grad():
        start_losses = eval_losses(z, select_index) + sighting_loss(model, z, sighting, config).cpu()
    start_q = z_art_to_q(z.detach()[:, :2]).cpu().numpy()
    winner = int(torch.argmin(start_losses))
    z_best = z.detach()[winner:winner + 1].clone()
    sighted_start = bool(sighted[winner])
    second = min(config.explore_steps // 2, config.max_steps - steps)
    if (config.start == "spread" and sighting is not None and codes is not None
            and config.sighting_codes > 0 and second > 0):
        z_best, sighted_start = _sighted_start(model, rays, explore, generator, z_best, sighting,
                                               codes, second,
                                               lambda c: eval_losses(c, select_index))
        steps += second

    def scan(z: torch.Tensor) -> tuple[torch.Tensor, int]:
        """The valley scan from code z (D,) where the focus part slides, else z and 0 steps."""
        if focus is None or not config.valley_codes or not _slides(model, z, focus.keypoint):
            return z, 0
        valley_index = rays.sample(config.valley_held_rays, config.detail_fraction, generator)

        def valley_losses(c: torch.Tensor) -> torch.Tensor:
            return eval_losses(c, valley_index) + sighting_loss(model, c, sighting, config).cpu()

        return _valley_scan(model, rays, config, generator, z, focus.keypoint, sighting,
                            valley_losses)

    if config.valley_first:
        z_scanned, scan_steps = scan(z_best[0])
        z_best, steps = z_scanned[None].clone(), steps + scan_steps
    held_loss = None
    if config.stop_every:
        held_index = rays.sample(config.lookup_rays, config.detail_fraction, generator)
        held_loss = lambda c: float(eval_losses(c, held_index).sum())  # noqa: E731
    valley = None
    if focus is not None and config.valley_lr > 0 and _slides(model, z_best[0].detach(),
                                                              focus.keypoint):
        valley = lambda c: _valley_tangent(model, c, focus.keypoint)  # noqa: E731
    steps += _adam(model, z_best, rays, config, generator, max(0, config.max_steps - steps),
                   config.rays_per_step, stop_early=True, sighting=sighting, held_loss=held_loss,
                   valley=valley)
    z_best = z_best.detach()[0]
    if not config.valley_first:
        z_best, scan_steps = scan(z_best)
        steps += scan_steps
    look = "off"
    if focus is not None and config.focus_steps > 0:
        z_best, look, look_steps = _close_look(model, rays, config, focus, generator, z_best,
                                                sighting)
        steps += look_steps
    return FitOutcome(z=z_best, q=float(z_art_to_q(z_best[:2])),
                      image_loss=float(eval_losses(z_best[None])[0]),
                      start_losses=start_losses.numpy(), start_q=start_q, steps=steps,
                      seconds=time.perf_counter() - started, focus=look,
                      sighted_start=sighted_start)
