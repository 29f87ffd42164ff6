"""Configuration dataclasses of the neural field: architecture, losses, ray sampling, optimiser, run.

One dataclass per concern, validated in `__post_init__` with a `ConfigError` that names the field.
`TrainConfig` nests the others and is what `nfr-drake train` exposes through tyro
(e.g. `--model.field-width 128 --loss.seg-weight 0.2 --optim.steps 50000`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Literal

from nfr_drake.errors import ConfigError


def _positive(obj, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value > 0:
            raise ConfigError(f"{type(obj).__name__}.{name} must be positive, got {value!r}")


def _fraction(obj, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not 0.0 <= value <= 1.0:
            raise ConfigError(f"{type(obj).__name__}.{name} must lie in [0, 1], got {value!r}")


@dataclass(frozen=True)
class NFRModelConfig:
    """Architecture of the neural field (hypernetwork, field, raymarcher, heads).

    Defaults were chosen by measurement on a 2-core CPU (docs/BENCHMARKS.md); `srn_reference()`
    gives the sizes of the SRN paper.
    """

    latent_obj_dim: int = 32
    """k, size of the object code z_obj (shape and appearance); z = [z_art (2 S), z_obj (k)]."""
    num_slots: int = 1
    """S, articulation slots: 1 for closets and drawers; furniture: one per front in canonical
    order, `MAX_FRONTS` (set from the dataset when training). Above 1 the keypoint head also
    gives each slot's existence and type logits."""
    hyper_hidden: int = 64
    """Hidden width of each per-layer hypernetwork (one hidden layer, as in SRN)."""
    field_width: int = 64
    """Width of the hidden layers of the field Phi."""
    field_layers: int = 3
    """Number of linear layers of Phi (the last one outputs the feature vector)."""
    feature_dim: int = 64
    """n, size of the feature vector v = Phi(x) read by the marcher and the pixel generators."""
    pe_frequencies: int = 5
    """Octaves of the positional encoding of x (0 = raw coordinates only)."""
    pe_base_frequency: float = math.pi
    """Angular frequency (rad/m) of the lowest octave; octave i uses base * 2**i."""
    layer_norm: bool = True
    """Layer norm (no affine) after each hidden layer of Phi, as SRN's hyper layers do."""
    hyper_offset_scale: float = 0.1
    """Initial size of the z-dependent weight offset relative to the shared base weight."""
    march_steps: int = 10
    """Fixed number of LSTM raymarching steps."""
    march_max_step: float = 0.3
    """Largest step (m) of one marching iteration (tanh-bounded); 10 steps span the sphere."""
    march_init_step: float = 0.0
    """Step (m) of every marching iteration at initialisation: the step head's bias starts at
    atanh(march_init_step / march_max_step); 0 keeps PyTorch's default bias. Furniture cameras sit
    inside the bounding sphere, so marching starts at `min_depth` from the camera, up to 1.5 m
    before the surface: a forward initial step lets the first renders reach it."""
    lstm_hidden: int = 16
    """State size of the LSTM raymarcher."""
    pixel_hidden: int = 64
    """Hidden width of the RGB (psi_1) and segmentation (psi_2) pixel generators."""
    num_classes: int = 4
    """Semantic classes: 0 background, 1 carcass, 2 door or drawer, 3 handle (docs/CONVENTIONS.md)."""
    num_keypoints: int = 4
    """K, keypoints predicted by Gamma(z); set from the dataset's keypoint names when training
    (furniture: S x 4, slot-major)."""
    keypoint_hidden: int = 128
    """Hidden width of the keypoint head Gamma (two hidden layers)."""
    bound_center: tuple[float, float, float] = (0.3, 0.0, 0.45)
    """Centre of the object's bounding sphere in frame O (m); the encoding is relative to it."""
    bound_radius: float = 0.9
    """Radius of the bounding sphere (m); marching starts where the ray enters it."""
    min_depth: float = 0.05
    """Smallest start depth along a ray (m), used when the camera is inside the sphere."""

    def __post_init__(self):
        _positive(self, "latent_obj_dim", "num_slots", "hyper_hidden", "field_width", "field_layers",
                  "feature_dim", "march_steps", "march_max_step", "lstm_hidden", "pixel_hidden",
                  "num_classes", "num_keypoints", "keypoint_hidden", "bound_radius", "min_depth",
                  "pe_base_frequency")
        if self.field_layers < 2:
            raise ConfigError("NFRModelConfig.field_layers must be at least 2 (hidden + output)")
        if self.pe_frequencies < 0:
            raise ConfigError(f"NFRModelConfig.pe_frequencies must be >= 0, got {self.pe_frequencies}")
        if not 0 <= self.march_init_step < self.march_max_step:
            raise ConfigError("NFRModelConfig.march_init_step must lie in [0, march_max_step)")
        if self.hyper_offset_scale < 0:
            raise ConfigError("NFRModelConfig.hyper_offset_scale must be >= 0")
        if len(self.bound_center) != 3:
            raise ConfigError("NFRModelConfig.bound_center must have 3 entries")

    @property
    def art_dim(self) -> int:
        """Size of z_art: 2 per slot."""
        return 2 * self.num_slots

    @property
    def latent_dim(self) -> int:
        """Size of the whole code z = [z_art (2 S), z_obj (k)]."""
        return self.art_dim + self.latent_obj_dim

    @property
    def slot_logits(self) -> int:
        """Logits per slot from the keypoint head: existence, door, drawer (S > 1), else none."""
        return 3 if self.num_slots > 1 else 0

    @classmethod
    def srn_reference(cls, **overrides) -> NFRModelConfig:
        """The SRN paper's sizes: latent 256, widths 256, 10 marching steps."""
        base = dict(latent_obj_dim=256, hyper_hidden=256, field_width=256, feature_dim=256,
                    field_layers=4, pixel_hidden=256, keypoint_hidden=256, march_steps=10)
        base.update(overrides)
        return cls(**base)

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> NFRModelConfig:
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ConfigError(f"unknown model config keys {sorted(unknown)}")
        d = dict(d)
        if "bound_center" in d:
            d["bound_center"] = tuple(d["bound_center"])
        return cls(**d)


@dataclass(frozen=True)
class LossConfig:
    """Weights of the training loss L_SRN + lambda_1 L_SEG + lambda_2 L_KP (paper, eq. 'loss')."""

    image_weight: float = 1.0
    """Image MSE on RGB in [0, 1]: the reference term the others are scaled against."""
    seg_weight: float = 0.1
    """lambda_1 on the segmentation cross-entropy: CE (~1.4 at start, nats) is ~30x the image MSE,
    0.1 keeps it a helper that sharpens part boundaries without dominating the colours."""
    keypoint_weight: float = 10.0
    """lambda_2 on the keypoint MSE (m^2, summed over xyz): a 1 cm error then costs 1e-3, about the
    image MSE of a 30 dB render, so keypoints and images pull on the codes with similar force."""
    latent_weight: float = 1e-3
    """Gaussian prior on z_obj (mean of squares, SRN's latent regulariser): keeps codes near the
    origin where fitting of unseen objects starts, weak enough not to blur objects apart."""
    depth_weight: float = 1e3
    """Penalty on negative marching depths (mean of min(d, 0)^2, m^2) from SRN: a depth behind the
    camera is never right, so the term is large enough to act as a hard constraint."""
    slot_weight: float = 0.1
    """Several slots only: weight of the existence BCE plus the type CE of existing slots (nats,
    ~0.7 each at start, so 0.1 keeps them near the image term, like the segmentation)."""

    def __post_init__(self):
        for f in fields(self):
            if getattr(self, f.name) < 0:
                raise ConfigError(f"LossConfig.{f.name} must be >= 0, got {getattr(self, f.name)}")


@dataclass(frozen=True)
class SamplerConfig:
    """Random rays per training step: images first, then pixels per image, stratified by class."""

    images_per_batch: int = 12
    """Images per step; each image has its own object code and articulation."""
    rays_per_image: int = 384
    """Pixels drawn per image (with replacement)."""
    foreground_fraction: float = 0.25
    """Share of rays drawn from any object pixel (label > 0)."""
    moving_fraction: float = 0.15
    """Share of rays drawn from door/drawer pixels (label 2): they carry the articulation."""
    handle_fraction: float = 0.1
    """Share of rays drawn from handle pixels (label 3): 1-3 px wide at 64 px, so oversampled."""

    def __post_init__(self):
        _positive(self, "images_per_batch", "rays_per_image")
        _fraction(self, "foreground_fraction", "moving_fraction", "handle_fraction")
        total = self.foreground_fraction + self.moving_fraction + self.handle_fraction
        if total > 1.0:
            raise ConfigError(f"SamplerConfig: class fractions sum to {total:.3f} > 1 (the rest is "
                              "drawn uniformly over the image)")


@dataclass(frozen=True)
class OptimConfig:
    """Adam on networks and codes with separate rates, one step decay."""

    steps: int = 60000
    """Total optimiser steps of the run (resume continues up to this number)."""
    lr_networks: float = 4e-4
    """Learning rate of all networks (hypernetwork, marcher, heads)."""
    lr_codes: float = 2e-3
    """Learning rate of the per-object codes z_obj (each is seen rarely, so it moves faster)."""
    decay_at: float = 0.75
    """Fraction of `steps` after which both rates are multiplied by `decay_factor`."""
    decay_factor: float = 0.3
    """Learning-rate multiplier after `decay_at`."""
    grad_clip: float = 1.0
    """Clip the global gradient norm to this value (0 = off); guards against marcher blow-ups."""

    def __post_init__(self):
        _positive(self, "steps", "lr_networks", "lr_codes", "decay_factor")
        _fraction(self, "decay_at")
        if self.grad_clip < 0:
            raise ConfigError("OptimConfig.grad_clip must be >= 0")

    def lr_scale(self, step: int) -> float:
        """Multiplier of both learning rates at `step`."""
        return self.decay_factor if step >= self.decay_at * self.steps else 1.0


@dataclass(frozen=True)
class TrainConfig:
    """A training run: what to build, how to sample and optimise, and how often to report."""

    model: NFRModelConfig = field(default_factory=NFRModelConfig)
    """Architecture."""
    loss: LossConfig = field(default_factory=LossConfig)
    """Loss weights."""
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    """Ray sampling."""
    optim: OptimConfig = field(default_factory=OptimConfig)
    """Optimiser and schedule."""
    objects: int | None = None
    """Use only the first n complete objects of the dataset (None = all)."""
    threads: int | None = None
    """torch intra-op threads per process (CPU); None: the free cores shared by the processes
    (`nfr_drake.cpu.free_cores`; a thread beyond them stalls whenever another process holds a
    core, docs/BENCHMARKS.md)."""
    device: Literal["auto", "cpu", "cuda"] = "auto"
    """'auto' = CUDA when available, else CPU."""
    seed: int = 0
    """Seed of initialisation and ray sampling (each DDP rank adds its rank)."""
    code_init_std: float = 0.01
    """Standard deviation of the initial object codes (SRN: 0.01)."""
    log_every: int = 50
    """Steps between rows of metrics.csv."""
    val_every: int = 2000
    """Steps between validations (PNG grid, val.csv row, best model update)."""
    ckpt_every: int = 2000
    """Steps between resumable checkpoints."""
    keep_checkpoints: int = 2
    """Resumable checkpoints kept on disk (oldest deleted first)."""
    val_images: int = 6
    """Training images rendered in full at each validation (fixed set)."""

    def __post_init__(self):
        if self.threads is not None:
            _positive(self, "threads")
        _positive(self, "log_every", "val_every", "ckpt_every", "keep_checkpoints",
                  "val_images")
        if self.objects is not None and self.objects < 1:
            raise ConfigError("TrainConfig.objects must be at least 1")
        if self.code_init_std < 0:
            raise ConfigError("TrainConfig.code_init_std must be >= 0")

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> TrainConfig:
        d = dict(d)
        return cls(model=NFRModelConfig.from_json(d.pop("model")), loss=LossConfig(**d.pop("loss")),
                   sampler=SamplerConfig(**d.pop("sampler")), optim=OptimConfig(**d.pop("optim")),
                   **d)
