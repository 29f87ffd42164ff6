"""Training the segmenter on room datasets: the loss and a resumable training loop.

OUT/checkpoint/ is a safetensors + JSON checkpoint (`write_training_checkpoint`: weights, Adam
moments, torch RNG; trainer.json: step, scheduler, the sampler's RNG, losses), written every
`checkpoint_every` steps; a run resumed from it ends with the weights of a run never stopped.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from nfr_drake.cpu import set_torch_threads
from nfr_drake.errors import ConfigError
from nfr_drake.nfr.resumable import ResumableRun
from nfr_drake.perception.segmentation.data import RoomImages, sample_batch
from nfr_drake.perception.segmentation.model import (
    AMODAL_CHANNEL,
    NUM_CLASSES,
    Segmenter,
    SegmenterConfig,
    load_segmenter,
    save_segmenter,
)

CHECKPOINT_DIR = "checkpoint"


@dataclass(frozen=True)
class SegmenterTrainConfig:
    """Training: `steps` Adam steps of `batch` augmented crops of `crop` px; the learning rate
    decays from `lr` to 0 (cosine); the loss adds `dice_weight` times a soft Dice loss of the
    object mask to the per-pixel cross-entropy of the classes, and, for a model with the amodal
    output, `amodal_weight` times the binary cross-entropy of the amodal carcass."""

    steps: int = 3000
    batch: int = 16
    crop: int = 80
    lr: float = 2e-3
    dice_weight: float = 1.0
    amodal_weight: float = 1.0
    checkpoint_every: int = 100
    seed: int = 0
    threads: int | None = None
    """torch CPU threads (None: the free cores, `nfr_drake.cpu.free_cores`)."""

    def __post_init__(self):
        threads = 1 if self.threads is None else self.threads
        if min(self.steps, self.batch, self.checkpoint_every, threads) < 1:
            raise ConfigError("segmenter training: steps, batch, checkpoint_every and threads must be >= 1")
        if self.crop < 16 or self.lr <= 0 or self.dice_weight < 0:
            raise ConfigError("segmenter training: crop must be >= 16 px, lr > 0, dice_weight >= 0")


def segmentation_loss(logits: torch.Tensor, labels: torch.Tensor, dice_weight: float,
                      amodal: torch.Tensor | None = None, amodal_weight: float = 1.0) -> torch.Tensor:
    """Cross-entropy of the classes plus `dice_weight` times the soft Dice loss of the object
    mask (every class but background), plus, given `amodal` (B, H, W) float 0/1, `amodal_weight`
    times the binary cross-entropy of the amodal carcass logit. logits (B, 4 or 5, H, W), labels
    (B, H, W) int64."""
    classes = logits[:, :NUM_CLASSES]
    ce = nn.functional.cross_entropy(classes, labels)
    p = 1.0 - torch.softmax(classes, dim=1)[:, 0]
    mask = (labels > 0).float()
    dice = 1.0 - (2.0 * (p * mask).sum() + 1.0) / (p.sum() + mask.sum() + 1.0)
    loss = ce + dice_weight * dice
    if amodal is not None:
        loss = loss + amodal_weight * nn.functional.binary_cross_entropy_with_logits(
            logits[:, AMODAL_CHANNEL], amodal)
    return loss


def train_segmenter(data_dirs: list[Path], out: Path, config: SegmenterTrainConfig,
                    model: SegmenterConfig | None = None, resume: bool = False,
                    command: str = "", init_from: Path | None = None) -> dict:
    """Train a segmenter on room datasets (any categories and image sizes); writes OUT/.

    `model` is the architecture (default `SegmenterConfig()`; with `init_from`, a segmenter
    folder whose weights the run starts from, that folder's architecture). Returns the training
    record written into OUT/config.json; OUT/model.safetensors holds the weights (`load_segmenter`).
    """
    if not data_dirs:
        raise ConfigError("train-segmenter: give at least one --data folder")
    out = Path(out)
    ckpt_path = out / CHECKPOINT_DIR
    if ckpt_path.is_dir() and not resume:
        raise ConfigError(f"{out} already holds a checkpoint; pass --resume or another --out")
    set_torch_threads(config.threads)
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    data = RoomImages(list(data_dirs))
    start = None if init_from is None else load_segmenter(Path(init_from))[0]
    model = start.config if start is not None else model or SegmenterConfig()
    if model.amodal and not data.has_amodal:
        raise ConfigError("train-segmenter: a room of the data has no amodal carcass labels; run "
                          "`nfr-drake label-amodal --data ...` first (or train without the amodal output)")
    net = Segmenter(model)
    if start is not None:  # a checkpoint of this run, when resumed, replaces these weights
        net.load_state_dict(start.state_dict())
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    train_options = {k: v for k, v in asdict(config).items() if k != "threads"}  # any count resumes
    run = ResumableRun(ckpt_path, net, opt, sched, rng,
                       {"model": asdict(model), "train": train_options, "images": len(data)}, resume)
    out.mkdir(parents=True, exist_ok=True)

    def loss() -> torch.Tensor:
        rgb, labels, amodal = sample_batch(data, config.batch, config.crop, rng, model.amodal)
        return segmentation_loss(net(rgb), labels, config.dice_weight, amodal, config.amodal_weight)

    net.train()
    run.train(config.steps, config.checkpoint_every, loss, "train segmenter")
    record = {"data": [str(d) for d in data_dirs], "images": len(data), "train": asdict(config),
              "init_from": None if init_from is None else str(init_from), "command": command,
              "seconds": run.seconds, "final_loss": float(np.mean(run.losses[-100:]))}
    save_segmenter(out, net, record)
    return record
