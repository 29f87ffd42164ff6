"""A 2D handle detector: a small fully convolutional network that finds the handle in a photo.

The neural field pins a handle (1-4 px wide in the photos) down only loosely; this detector looks
for it in each photo directly, and `nfr_drake.perception.handle_triangulation` turns its output in
posed views into one 3D point. Per pixel it predicts whether the pixel shows the handle and, for
handle pixels, the offset (du, dv) in pixels to the projection of the handle keypoint (the grip
centre): a bar's visible pixels (posts included) are not centred on the grip, and their votes
are. It is trained on the same Drake renders as the neural field (label class 3 = handle), on
images of several sizes so that it works at any resolution: the network has no pooling and no
fully connected layer, so it runs on images of any size, and it sees about 65 px around each
pixel (dilated convolutions).

Files in a model folder's `handle_detector/`: `config.json` (`HandleDetectorConfig` and training
record) and `model.safetensors`. A training run's `checkpoint/` is a resumable safetensors + JSON
checkpoint (`nfr_drake.nfr.checkpoint.write_training_checkpoint`); nothing is ever unpickled.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import save_file
from torch import nn
from tqdm import tqdm

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.errors import ConfigError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import (
    TRAINER_FILE,
    CheckpointError,
    load_strict,
    read_tensors,
    read_training_checkpoint,
    write_training_checkpoint,
)
from nfr_drake.objects import SemanticClass
from nfr_drake.perception.handle_triangulation import HandleMap

DETECTOR_DIR = "handle_detector"
CHECKPOINT_DIR = "checkpoint"
PICKLED_CHECKPOINT = "checkpoint.pt"
"""What older versions wrote instead of CHECKPOINT_DIR: refused, never loaded."""
OFFSET_SCALE_PX = 4.0
"""The offset outputs are in units of this many pixels (keeps them near 1 for the optimiser)."""


@dataclass(frozen=True)
class HandleDetectorConfig:
    """Architecture: 3x3 convolutions of `channels` channels with these dilations, then a 1x1
    convolution to three outputs per pixel (handle logit, du, dv)."""

    channels: int = 32
    dilations: tuple[int, ...] = (1, 1, 2, 4, 8, 16, 1)

    def __post_init__(self):
        if self.channels < 1 or not self.dilations or min(self.dilations) < 1:
            raise ConfigError("handle detector: channels and dilations must be positive")

    @classmethod
    def from_json(cls, d: dict) -> HandleDetectorConfig:
        return cls(channels=int(d["channels"]), dilations=tuple(int(x) for x in d["dilations"]))


class HandleDetector(nn.Module):
    """(B, 3, H, W) RGB in [0, 1] -> handle logits (B, H, W) and offsets to the projected grip
    centre (B, 2, H, W), pixels (du right, dv down); any H and W."""

    def __init__(self, config: HandleDetectorConfig):
        super().__init__()
        self.config = config
        layers, c_in = [], 3
        for d in config.dilations:
            layers += [nn.Conv2d(c_in, config.channels, 3, padding=d, dilation=d), nn.ReLU()]
            c_in = config.channels
        layers.append(nn.Conv2d(c_in, 3, 1))
        self.net = nn.Sequential(*layers)

    def forward(self, rgb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.net(rgb - 0.5)
        return out[:, 0], out[:, 1:] * OFFSET_SCALE_PX

    @torch.no_grad()
    def detect(self, images: list[np.ndarray]) -> list[HandleMap]:
        """The handle map of each uint8 RGB image (H, W, 3)."""
        self.eval()
        out = []
        for img in images:
            x = torch.from_numpy(np.ascontiguousarray(img, np.float32) / 255.0).permute(2, 0, 1)
            logits, offsets = self(x[None])
            out.append(HandleMap(torch.sigmoid(logits)[0].numpy(),
                                 offsets[0].permute(1, 2, 0).numpy()))
        return out


@dataclass(frozen=True)
class DetectorTrainConfig:
    """Training: `steps` Adam steps of `images_per_batch` crops (`crop` px) from each dataset."""

    steps: int = 4000
    images_per_batch: int = 8
    lr: float = 1e-3
    crop: int = 64
    pos_weight: float = 10.0
    offset_weight: float = 0.5
    checkpoint_every: int = 250
    seed: int = 0
    threads: int | None = None
    """torch CPU threads (None: the free cores, `nfr_drake.cpu.free_cores`)."""

    def __post_init__(self):
        if min(self.steps, self.images_per_batch, self.checkpoint_every,
               1 if self.threads is None else self.threads) < 1:
            raise ConfigError("handle detector training: steps, batch, checkpoint_every and "
                              "threads must be >= 1")
        if self.crop < 8 or self.lr <= 0 or self.pos_weight <= 0 or self.offset_weight < 0:
            raise ConfigError("handle detector training: crop must be >= 8 px, lr and "
                              "pos_weight > 0, offset_weight >= 0")


def _projected_handle(data: RenderedDataset, j: int, a: int, v: int) -> np.ndarray:
    """Pixel (u, v) (top-left pixel centre at (0.5, 0.5)) of the handle keypoint of object j at
    articulation a in view v."""
    rec = data.records[j]
    p_O = rec.keypoints[a, data.keypoint_names.index("handle")].astype(np.float64)
    X_OC = rec.X_OC[a, v].astype(np.float64)
    p_C = X_OC[:3, :3].T @ (p_O - X_OC[:3, 3])
    return (data.camera.K @ (p_C / p_C[2]))[:2]


def _batch(data: RenderedDataset, n: int, crop: int, rng: np.random.Generator):
    """n random images of `data`, cut to crop x crop px (3 in 4 about a handle pixel where the
    image shows one): rgb (n, 3, c, c) float32 in [0, 1], handle mask (n, c, c) float32 and the
    offset of every pixel to the projected handle keypoint (n, 2, c, c) float32, px."""
    A, V, S = data.spec.articulations, data.spec.views, data.spec.size
    c = min(crop, S)
    rgb, mask = np.empty((n, c, c, 3), np.float32), np.empty((n, c, c), bool)
    offset = np.empty((n, 2, c, c), np.float32)
    for b, (j, a, v) in enumerate(zip(rng.integers(0, data.num_objects, n),
                                      rng.integers(0, A, n), rng.integers(0, V, n), strict=True)):
        rec = data.records[j]
        handle = np.asarray(rec.label[a, v]) == SemanticClass.HANDLE
        rows, cols = np.nonzero(handle)
        if rows.size and rng.random() < 0.75:
            k = rng.integers(rows.size)
            r0 = np.clip(rows[k] - rng.integers(0, c), 0, S - c)
            c0 = np.clip(cols[k] - rng.integers(0, c), 0, S - c)
        else:
            r0, c0 = rng.integers(0, S - c + 1, 2)
        rgb[b] = np.asarray(rec.rgb[a, v, r0:r0 + c, c0:c0 + c], np.float32) / 255.0
        mask[b] = handle[r0:r0 + c, c0:c0 + c]
        u, w = _projected_handle(data, j, a, v)
        offset[b, 0] = u - (c0 + np.arange(c) + 0.5)[None, :]
        offset[b, 1] = w - (r0 + np.arange(c) + 0.5)[:, None]
    flip = rng.random(n) < 0.5  # mirror images: hinges on either side look alike
    rgb[flip], mask[flip] = rgb[flip, :, ::-1], mask[flip, :, ::-1]
    offset[flip] = offset[flip, :, :, ::-1]
    offset[flip, 0] *= -1.0
    return (torch.from_numpy(rgb).permute(0, 3, 1, 2).contiguous(),
            torch.from_numpy(mask.astype(np.float32)), torch.from_numpy(offset))


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
                   command: str = "", allow_incomplete: bool = False) -> dict:
    """Train a detector on rendered datasets (of one category, any image sizes); writes OUT/.

    Each step draws `images_per_batch` crops from every dataset. The last 5% of each dataset's
    objects are held out; the handle IoU and the median offset error (px, on handle pixels) on 64
    of their full images per dataset are reported.
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
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    train_options = {k: v for k, v in asdict(config).items() if k != "threads"}  # any count resumes
    options = json.loads(json.dumps({"model": asdict(model), "train": train_options}))
    step, seconds, losses = 0, 0.0, []
    if resume and ckpt_path.is_dir():
        saved = read_json(ckpt_path / TRAINER_FILE, CheckpointError, "checkpoint state")
        if not isinstance(saved, dict) or {k: saved.get(k) for k in options} != options:
            raise ConfigError(f"{ckpt_path}: --resume with other options than the run's")
        state = read_training_checkpoint(ckpt_path, net, opt)
        try:
            sched.load_state_dict(state["sched"])
            rng.bit_generator.state = state["rng"]
            step, seconds, losses = int(state["step"]), float(state["seconds"]), list(state["losses"])
        except (KeyError, TypeError, ValueError) as err:
            raise CheckpointError(f"{ckpt_path / TRAINER_FILE}: bad training state ({err})") from None
    out.mkdir(parents=True, exist_ok=True)

    def checkpoint() -> None:
        write_training_checkpoint(ckpt_path, net, opt, {
            **options, "sched": sched.state_dict(), "rng": rng.bit_generator.state, "step": step,
            "seconds": seconds, "losses": losses})

    bar = tqdm(total=config.steps, initial=step, desc="train handle detector", mininterval=5.0)
    while step < config.steps:
        t0 = time.perf_counter()
        loss = sum(_loss(*net(rgb), mask, offsets, config.pos_weight, config.offset_weight)
                   for rgb, mask, offsets in
                   (_batch(s, config.images_per_batch, config.crop, rng) for s in train_sets))
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        losses.append(loss.item())
        step += 1
        seconds += time.perf_counter() - t0
        bar.update(1)
        bar.set_postfix(loss=f"{np.mean(losses[-50:]):.3f}", refresh=False)
        if step % config.checkpoint_every == 0 or step == config.steps:
            checkpoint()
    bar.close()
    val_rng = np.random.default_rng(12345)
    net.eval()
    with torch.no_grad():
        ious, offset_errors = {}, {}
        for v in val_sets:
            rgb, mask, true_offsets = _batch(v, 64, v.spec.size, val_rng)
            logits, offsets = net(rgb)
            ious[str(v.root)] = _iou(logits, mask)
            offset_errors[str(v.root)] = _offset_error_px(offsets, mask, true_offsets)
    record = {"category": categories.pop(), "model": asdict(model), "train": asdict(config),
              "data": [str(d) for d in data_dirs], "command": command, "seconds": seconds,
              "final_loss": float(np.mean(losses[-100:])), "held_out_handle_iou": ious,
              "held_out_offset_error_px": offset_errors}
    save_detector(out, net, record)
    return record


def save_detector(folder: Path, net: HandleDetector, record: dict) -> None:
    """Write `model.safetensors` and `config.json` (`record`, with the architecture under
    "model") into `folder`, each atomically."""
    folder.mkdir(parents=True, exist_ok=True)
    save_file(net.state_dict(), str(folder / "model.safetensors.tmp"))
    (folder / "model.safetensors.tmp").replace(folder / "model.safetensors")
    (folder / "config.json.tmp").write_text(json.dumps(record, indent=2) + "\n")
    (folder / "config.json.tmp").replace(folder / "config.json")


def load_detector(folder: Path) -> tuple[HandleDetector, dict]:
    """A trained detector and its record from a `handle_detector/` folder; CheckpointError
    naming the file that is missing or damaged."""
    folder = Path(folder)
    record = read_json(folder / "config.json", CheckpointError, "handle detector config")
    try:
        net = HandleDetector(HandleDetectorConfig.from_json(record["model"]))
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{folder / 'config.json'}: not a handle detector ({err})") from None
    load_strict(net, read_tensors(folder / "model.safetensors"), folder / "model.safetensors")
    net.eval()
    return net, record


def train_detector_command(data: list[Path], out: Path,
                           steps: int = DetectorTrainConfig.steps,
                           batch: int = DetectorTrainConfig.images_per_batch,
                           crop: int = DetectorTrainConfig.crop,
                           lr: float = DetectorTrainConfig.lr,
                           threads: int | None = None,
                           resume: bool = False, allow_incomplete: bool = False) -> None:
    """Train the 2D handle detector on rendered datasets of one category (any image sizes).

    Args:
        data: dataset folders from `nfr-drake generate` (e.g. the same objects at 64 and 128 px).
        out: output folder; copy it to MODEL/handle_detector to ship it with a model.
        steps: optimiser steps.
        batch: crops per dataset per step.
        crop: crop size, px.
        lr: learning rate (cosine decay to 0).
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
        resume: continue a killed run from OUT/checkpoint/.
        allow_incomplete: train on the objects on disk when a dataset misses some.
    """
    config = DetectorTrainConfig(steps=steps, images_per_batch=batch, crop=crop, lr=lr,
                                 threads=threads)
    command = "nfr-drake train-handle-detector " + " ".join(sys.argv[2:])
    record = train_detector(list(data), out, config, resume=resume, command=command,
                            allow_incomplete=allow_incomplete)
    print(f"handle detector written to {out}: held-out handle IoU, offset error "
          + ", ".join(f"{k} {v:.3f}, {record['held_out_offset_error_px'][k]:.2f} px"
                      for k, v in record["held_out_handle_iou"].items()))
