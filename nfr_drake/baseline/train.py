"""Training the image-encoder baseline on a rendered dataset; `nfr-drake train-baseline`.

Each step draws `batch` (object, articulation) instances, each with a random subset of its views,
and regresses q, the keypoints and (prismatic categories) the travel; on a furniture dataset the
same per slot (slot k = front k, `data.slot_dataset`), over the slots that hold a front, plus
whether each slot holds one and its type (cross-entropies). Checkpoints are written atomically
every `checkpoint_every` steps; `--resume` continues a killed run.
"""

from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import save_file
from torch import nn
from tqdm import tqdm

from nfr_drake.baseline.model import BaselineConfig, BaselineOutput, ImageEncoderBaseline
from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS, SlotDataset, open_dataset
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import CheckpointError, load_strict, read_tensors

MODEL_KIND = "nfr-drake-image-encoder-baseline"


@dataclass(frozen=True)
class BaselineTrainConfig:
    """Training options of the baseline.

    Attributes:
        steps: optimiser steps in total.
        batch: instances per step.
        views: views per instance (a random subset of the instance's views).
        lr: Adam learning rate, decayed x0.1 over the last quarter.
        keypoint_weight: weight of the keypoint MSE (m^2) against the q MSE; keypoints matter most.
        travel_weight: weight of the travel MSE (m^2), prismatic categories only.
        slot_weight: weight of the slot exists and type cross-entropies, furniture only.
        checkpoint_every: steps between checkpoints.
        log_every: steps between rows of metrics.csv.
        seed: seed of the sampler and the initial weights.
        threads: torch CPU threads (None: the free cores, `nfr_drake.cpu.free_cores`).
    """

    steps: int = 6000
    batch: int = 8
    views: int = 5
    lr: float = 1e-3
    keypoint_weight: float = 100.0
    travel_weight: float = 100.0
    slot_weight: float = 1.0
    checkpoint_every: int = 500
    log_every: int = 50
    seed: int = 0
    threads: int | None = None

    def __post_init__(self):
        if min(self.steps, self.batch, self.views, self.checkpoint_every, self.log_every,
               1 if self.threads is None else self.threads) < 1:
            raise ConfigError("steps, batch, views, checkpoint_every, log_every, threads must be >= 1")


def save_baseline(folder: Path, model: ImageEncoderBaseline, extra: dict) -> None:
    """Write model.safetensors + config.json into `folder`, each atomically."""
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".model.safetensors.tmp-{os.getpid()}"
    save_file({k: v.contiguous() for k, v in model.state_dict().items()}, str(tmp))
    os.replace(tmp, folder / "model.safetensors")
    doc = {"kind": MODEL_KIND, "architecture": model.config.to_json(), **extra}
    tmp = folder / f".config.json.tmp-{os.getpid()}"
    tmp.write_text(json.dumps(doc, indent=2))
    os.replace(tmp, folder / "config.json")


def load_baseline(folder: Path) -> tuple[ImageEncoderBaseline, dict]:
    """Load a baseline folder; NfrDrakeError for a missing, corrupt or foreign checkpoint."""
    folder = Path(folder)
    doc = read_json(folder / "config.json", CheckpointError, "baseline config")
    if not isinstance(doc, dict) or doc.get("kind") != MODEL_KIND:
        raise CheckpointError(f"{folder / 'config.json'}: not an image-encoder baseline")
    try:
        model = ImageEncoderBaseline(BaselineConfig.from_json(doc["architecture"]))
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{folder / 'config.json'}: bad architecture ({err})") from None
    load_strict(model, read_tensors(folder / "model.safetensors"), folder / "model.safetensors")
    return model.eval(), doc


def baseline_architecture(data: RenderedDataset) -> BaselineConfig:
    """The baseline of a dataset's category: one revolute (closets) or prismatic (drawers) part, or
    a `SlotDataset`'s slots (furniture)."""
    if isinstance(data, SlotDataset):
        return BaselineConfig(data.spec.category, SLOT_KEYPOINTS, "per_slot", num_slots=data.num_slots)
    joint_type = "revolute" if data.spec.category == "closet" else "prismatic"
    return BaselineConfig(data.spec.category, data.keypoint_names, joint_type)


def _sample_batch(data: RenderedDataset, rng: np.random.Generator, batch: int, views: int):
    """images (B, V', 3, S, S), X_OC (B, V', 4, 4), and per slot (one but for furniture) q (B, S),
    keypoints (B, S, K, 3), travel (B, S) (m, one part), exists bool (B, S), types (B, S)."""
    A, V = data.spec.articulations, data.spec.views
    n_views = min(views, V)
    images, poses, qs, kps, travel, exists, types = [], [], [], [], [], [], []
    for _ in range(batch):
        j = rng.integers(data.num_objects)
        rec = data.records[j]
        a = rng.integers(A)
        vs = np.sort(rng.choice(V, n_views, replace=False))
        images.append(np.asarray(rec.rgb[a, vs]))
        poses.append(rec.X_OC[a, vs])
        if isinstance(data, SlotDataset):
            slots = data.slots[j]
            qs.append(slots.q[a])
            kps.append(slots.keypoints[a])
            travel.append(np.zeros(data.num_slots, np.float32))
            exists.append(slots.exists)
            types.append(slots.types)
        else:
            qs.append(rec.q[a, None])
            kps.append(rec.keypoints[a, None])
            travel.append(np.array([rec.meta["joint_upper"]], np.float32))
            exists.append(np.ones(1, bool))
            types.append(np.zeros(1, np.int64))
    images = torch.from_numpy(np.stack(images)).permute(0, 1, 4, 2, 3).float() / 255.0
    return (images, torch.from_numpy(np.stack(poses)),
            *(torch.from_numpy(np.stack(x)) for x in (qs, kps, travel, exists, types)))


def baseline_loss(pred: BaselineOutput, targets: tuple[torch.Tensor, ...], joint_type: str,
                  config: BaselineTrainConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(loss, q MSE, keypoint MSE in m^2) of a prediction against `_sample_batch`'s targets (q,
    keypoints, travel, exists, types) of a baseline of `joint_type`: the q
    and keypoint (and, prismatic, travel) errors averaged over the slots that hold a front, plus
    (furniture) the exists cross-entropy over every slot and the type's over the fronts."""
    q, keypoints, travel, exists, types = targets
    mask = exists.float()
    n = mask.sum().clamp(min=1.0)
    q_mse = (((pred.q - q) ** 2) * mask).sum() / n
    kp_mse = (((pred.keypoints - keypoints) ** 2).sum(-1).mean(-1) * mask).sum() / n
    loss = q_mse + config.keypoint_weight * kp_mse
    if joint_type == "per_slot":
        exists_ce = nn.functional.binary_cross_entropy_with_logits(pred.exists, mask)
        type_ce = (nn.functional.cross_entropy(pred.types.flatten(0, 1), types.flatten(), reduction="none")
                   * mask.flatten()).sum() / n
        loss = loss + config.slot_weight * (exists_ce + type_ce)
    elif joint_type == "prismatic":
        loss = loss + config.travel_weight * (((pred.travel - travel) ** 2) * mask).sum() / n
    return loss, q_mse, kp_mse


def train_baseline(data_dir: Path, out: Path, config: BaselineTrainConfig, resume: bool = False,
                   progress: bool = True, allow_incomplete: bool = False) -> Path:
    """Train (or resume) a baseline into `out`; returns `out`. A dataset missing objects is
    refused unless `allow_incomplete`."""
    set_torch_threads(config.threads)
    data = open_dataset(data_dir)
    data.require_complete(allow_incomplete)
    arch = baseline_architecture(data)
    torch.manual_seed(config.seed)
    model = ImageEncoderBaseline(arch)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.lr)
    start = 0
    state_path = out / "train_state.json"
    if resume and state_path.exists():
        model, _ = load_baseline(out)
        model.train()
        optimiser = torch.optim.Adam(model.parameters(), lr=config.lr)
        start = json.loads(state_path.read_text())["step"]
    elif out.exists() and any(out.iterdir()) and not resume:
        raise NfrDrakeError(f"{out} is not empty; pass --resume to continue or choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng([config.seed, start])
    log_path = out / "metrics.csv"
    new_log = not log_path.exists()
    extra = {"training": {"data": str(data_dir), "objects": data.num_objects,
                          "config": asdict(config), "image_size": data.spec.size}}
    started = time.time()
    with open(log_path, "a", newline="") as log_file:
        log = csv.writer(log_file)
        if new_log:
            log.writerow(["step", "loss", "q_mse", "keypoint_rmse_cm", "seconds"])
        bar = tqdm(range(start, config.steps), initial=start, total=config.steps,
                   disable=not progress, desc="baseline")
        for step in bar:
            lr = config.lr * (0.1 if step >= 0.75 * config.steps else 1.0)
            for group in optimiser.param_groups:
                group["lr"] = lr
            images, poses, *targets = _sample_batch(data, rng, config.batch, config.views)
            loss, q_mse, kp_mse = baseline_loss(model(images, poses), targets, arch.joint_type, config)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            if (step + 1) % config.log_every == 0:
                log.writerow([step + 1, f"{loss.item():.6f}", f"{q_mse.item():.6f}",
                              f"{100 * kp_mse.sqrt().item():.3f}",
                              f"{time.time() - started:.1f}"])
                bar.set_postfix(loss=f"{loss.item():.4f}", kp_cm=f"{100 * kp_mse.sqrt().item():.2f}")
            if (step + 1) % config.checkpoint_every == 0 or step + 1 == config.steps:
                log_file.flush()
                save_baseline(out, model, extra)
                state_path.write_text(json.dumps({"step": step + 1}))
    return out


def train_baseline_command(data: Path, out: Path, steps: int = 6000, batch: int = 8,
                           views: int = 5, lr: float = 1e-3, threads: int | None = None,
                           resume: bool = False, allow_incomplete: bool = False) -> None:
    """Train the paper's image-encoder baseline on a dataset from `nfr-drake generate` (a
    furniture dataset: one slot per front, as the furniture field's).

    Args:
        data: dataset folder.
        out: run folder (model.safetensors, config.json, metrics.csv).
        steps: optimiser steps.
        batch: instances per step.
        views: views per instance.
        lr: learning rate.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
        resume: continue a killed run in OUT.
        allow_incomplete: train on the objects on disk when the dataset misses some.
    """
    config = BaselineTrainConfig(steps=steps, batch=batch, views=views, lr=lr, threads=threads)
    train_baseline(data, out, config, resume, allow_incomplete=allow_incomplete)
    print(f"baseline written to {out}")
