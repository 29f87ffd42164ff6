"""Training the detector: the loss, a resumable training loop on rendered datasets of any image
sizes, and the held-out handle IoU and offset error it reports (with front outputs also the
front IoU, and the door accuracy and the corner error on the front pixels)."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.errors import ConfigError
from nfr_drake.nfr.checkpoint import CheckpointError
from nfr_drake.nfr.resumable import ResumableRun
from nfr_drake.perception.handle_detector.data import sample_batch, sample_front_batch
from nfr_drake.perception.handle_detector.model import (
    TUNABLE,
    HandleDetector,
    HandleDetectorConfig,
    load_detector,
    save_detector,
)

CHECKPOINT_DIR = "checkpoint"
PICKLED_CHECKPOINT = "checkpoint.pt"
"""What older versions wrote instead of CHECKPOINT_DIR: refused, never loaded."""


@dataclass(frozen=True)
class DetectorTrainConfig:
    """Training: `steps` Adam steps of `images_per_batch` crops (`crop` px) from each dataset."""

    steps: int = 4000
    images_per_batch: int = 8
    lr: float = 1e-3
    crop: int = 64
    pos_weight: float = 10.0
    offset_weight: float = 0.5
    corner_weight: float = 0.1
    """Weight of the corner offsets' Huber loss (px) beside the door cross-entropy (front outputs)."""
    checkpoint_every: int = 250
    seed: int = 0
    threads: int | None = None
    """torch CPU threads (None: the free cores, `nfr_drake.cpu.free_cores`)."""

    def __post_init__(self):
        if min(self.steps, self.images_per_batch, self.checkpoint_every,
               1 if self.threads is None else self.threads) < 1:
            raise ConfigError("handle detector training: steps, batch, checkpoint_every and "
                              "threads must be >= 1")
        if (self.crop < 8 or self.lr <= 0 or self.pos_weight <= 0
                or min(self.offset_weight, self.corner_weight) < 0):
            raise ConfigError("handle detector training: crop must be >= 8 px, lr and "
                              "pos_weight > 0, offset_weight and corner_weight >= 0")


def _loss(logits: torch.Tensor, offsets: torch.Tensor, mask: torch.Tensor, true_offsets: torch.Tensor,
          pos_weight: float, offset_weight: float) -> torch.Tensor:
    """Weighted binary cross-entropy plus a soft Dice term (handles are ~0.2% of the pixels), plus
    `offset_weight` times the Huber loss (1 px) of the offsets on the true handle pixels."""
    bce = nn.functional.binary_cross_entropy_with_logits(
        logits, mask, pos_weight=torch.tensor(pos_weight))
    p = torch.sigmoid(logits)
    dice = 1.0 - (2.0 * (p * mask).sum() + 1.0) / (p.sum() + mask.sum() + 1.0)
    on = mask > 0.5
    if not on.any():
        return bce + dice
    huber = nn.functional.huber_loss(offsets.permute(0, 2, 3, 1)[on],
                                     true_offsets.permute(0, 2, 3, 1)[on], delta=1.0)
    return bce + dice + offset_weight * huber


def _front_loss(front_logits: torch.Tensor, door_logits: torch.Tensor, corners: torch.Tensor,
                front: torch.Tensor, door: torch.Tensor, true_corners: torch.Tensor,
                corner_weight: float) -> torch.Tensor:
    """Cross-entropy of the front logits (B, H, W) on every pixel; on the front pixels that of
    the door logits (B, H, W) plus `corner_weight` times the Huber loss (1 px) of the corner
    offsets (B, 4, 2, H, W)."""
    loss = nn.functional.binary_cross_entropy_with_logits(front_logits, front)
    on = front > 0.5
    if not on.any():
        return loss
    bce = nn.functional.binary_cross_entropy_with_logits(door_logits[on], door[on])
    huber = nn.functional.huber_loss(corners.permute(0, 3, 4, 1, 2)[on],
                                     true_corners.permute(0, 3, 4, 1, 2)[on], delta=1.0)
    return loss + bce + corner_weight * huber


def _front_measures(front_logits: torch.Tensor, door_logits: torch.Tensor, corners: torch.Tensor,
                    front: torch.Tensor, door: torch.Tensor, true_corners: torch.Tensor
                    ) -> tuple[float, float, float]:
    """Front IoU, door accuracy and median corner error (map px), the last two on the front
    pixels."""
    on = front > 0.5
    iou = _iou(front_logits, front)
    accuracy = ((door_logits[on] > 0) == (door[on] > 0.5)).float().mean()
    error = (corners - true_corners).norm(dim=2).permute(0, 2, 3, 1)[on]
    return iou, float(accuracy), float(error.median())


def _offset_error_px(offsets: torch.Tensor, mask: torch.Tensor, true_offsets: torch.Tensor) -> float:
    """Median distance, px, between predicted and true offsets on the true handle pixels."""
    on = mask > 0.5
    d = (offsets - true_offsets).norm(dim=1)[on]
    return float(d.median()) if d.numel() else float("nan")


def _iou(logits: torch.Tensor, mask: torch.Tensor) -> float:
    pred, true = logits > 0, mask > 0.5
    union = (pred | true).sum().item()
    return float((pred & true).sum().item() / union) if union else 1.0


def train_detector(data_dirs: list[Path], out: Path, config: DetectorTrainConfig,
                   model: HandleDetectorConfig = HandleDetectorConfig(), resume: bool = False,
                   command: str = "", allow_incomplete: bool = False, init: Path | None = None,
                   tune: str = "fronts") -> dict:
    """Train a detector on rendered datasets (of one category, any image sizes); writes OUT/.

    Each step draws `images_per_batch` crops from every dataset (and, with front outputs, as
    many whole images scaled for them). The last 5% of each dataset's objects are held out; the
    handle IoU and the median offset error (px, on handle pixels) on 64 of their full images per
    dataset are reported, with front outputs also the front IoU and, on their front pixels, the
    door accuracy and the median corner error (px of the scaled image). `init`: a trained
    detector folder to start from (`HandleDetector.start_from`); `tune` names the network that
    trains from it, the other kept fixed: "fronts" (needs front outputs; from the folder's own
    front network where it has one) or "handles" (the handle network trained further; the front
    network, where the model has one, the folder's).
    OUT/checkpoint/ is written every `checkpoint_every` steps; `resume` continues from it.
    A dataset missing objects is refused unless `allow_incomplete`.
    Returns the training record written into OUT/config.json.
    """
    if not data_dirs:
        raise ConfigError("train-handle-detector: give at least one --data folder")
    out = Path(out)
    ckpt_path = out / CHECKPOINT_DIR
    if (out / PICKLED_CHECKPOINT).exists():
        raise CheckpointError(f"{out / PICKLED_CHECKPOINT}: a pickled checkpoint of an older version; "
                              "it is never loaded (unpickling can run code): delete it or use another "
                              "--out")
    if ckpt_path.is_dir() and not resume:
        raise ConfigError(f"{out} already holds a checkpoint; pass --resume or another --out")
    set_torch_threads(config.threads)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    sets = [RenderedDataset(d) for d in data_dirs]
    for s in sets:
        s.require_complete(allow_incomplete)
    categories = {s.spec.category for s in sets}
    if len(categories) != 1:
        raise ConfigError(f"train-handle-detector: datasets of several categories {categories}")
    if model.fronts and not all(s.has_parts for s in sets):
        raise ConfigError("train-handle-detector: front outputs need furniture datasets")
    if tune not in TUNABLE:
        raise ConfigError(f"train-handle-detector: --tune is one of {TUNABLE}, not {tune!r}")
    if init is None and tune == "handles":
        raise ConfigError("train-handle-detector: --tune handles trains a detector further; give --init")
    if init is not None and tune == "fronts" and not model.fronts:
        raise ConfigError("train-handle-detector: --init with --tune fronts adds front outputs to a "
                          "trained detector; give --fronts (or --tune handles)")
    train_sets, val_sets = [], []
    for s in sets:
        held = max(1, s.num_objects // 20)
        if s.num_objects <= held:
            raise ConfigError(f"{s.root}: too few objects ({s.num_objects}) to hold some out")
        val = RenderedDataset(s.root)
        val.records, s.records = s.records[-held:], s.records[:-held]
        train_sets.append(s)
        val_sets.append(val)
    net = HandleDetector(model)
    if init is not None:
        net.start_from(load_detector(Path(init))[0], tune)
    opt = torch.optim.Adam([p for p in net.parameters() if p.requires_grad], lr=config.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    train_options = {k: v for k, v in asdict(config).items() if k != "threads"}  # any count resumes
    run = ResumableRun(ckpt_path, net, opt, sched, rng, {"model": asdict(model), "train": train_options,
                                                         "init": None if init is None else str(init),
                                                         "tune": None if init is None else tune},
                       resume)
    out.mkdir(parents=True, exist_ok=True)

    def loss() -> torch.Tensor:  # crops from every dataset
        total = torch.zeros(())
        if init is None or tune == "handles":
            for s in train_sets:
                rgb, mask, offsets = sample_batch(s, config.images_per_batch, config.crop, rng)
                total = total + _loss(*net(rgb), mask, offsets, config.pos_weight, config.offset_weight)
        if model.fronts and (init is None or tune == "fronts"):
            for s in train_sets:
                rgb, *targets = sample_front_batch(s, config.images_per_batch, rng)
                total = total + _front_loss(*net.fronts(rgb), *targets, config.corner_weight)
        return total

    run.train(config.steps, config.checkpoint_every, loss, "train handle detector")
    val_rng = np.random.default_rng(12345)
    net.eval()
    with torch.no_grad():
        ious, offset_errors, front_ious, door_accuracy, corner_errors = {}, {}, {}, {}, {}
        for v in val_sets:
            rgb, mask, true_offsets = sample_batch(v, 64, v.spec.size, val_rng)
            logits, offsets = net(rgb)
            ious[str(v.root)] = _iou(logits, mask)
            offset_errors[str(v.root)] = _offset_error_px(offsets, mask, true_offsets)
            if model.fronts:
                rgb, *targets = sample_front_batch(v, 64, val_rng)
                front_ious[str(v.root)], door_accuracy[str(v.root)], corner_errors[str(v.root)] = \
                    _front_measures(*net.fronts(rgb), *targets)
    record = {"category": categories.pop(), "model": asdict(model), "train": asdict(config),
              "init": None if init is None else str(init), "tune": None if init is None else tune,
              "data": [str(d) for d in data_dirs], "command": command, "seconds": run.seconds,
              "final_loss": float(np.mean(run.losses[-100:])), "held_out_handle_iou": ious,
              "held_out_offset_error_px": offset_errors}
    if model.fronts:
        record.update(held_out_front_iou=front_ious, held_out_door_accuracy=door_accuracy,
                      held_out_corner_error_px=corner_errors)
    save_detector(out, net, record)
    return record
