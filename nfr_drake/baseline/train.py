"""Training the image-encoder baseline on a rendered dataset; `nfr-drake train-baseline`.

Each step draws `batch` (object, articulation) instances, each with a random subset of its views,
and regresses q, the keypoints and (prismatic categories) the travel. Checkpoints are written
atomically every `checkpoint_every` steps; `--resume` continues a killed run.
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
from tqdm import tqdm

from nfr_drake.baseline.model import BaselineConfig, ImageEncoderBaseline
from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.dataset import RenderedDataset
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


def _sample_batch(data: RenderedDataset, rng: np.random.Generator, batch: int, views: int):
    """images (B, V', 3, S, S), X_OC (B, V', 4, 4), q (B,), keypoints (B, K, 3), travel (B,)."""
    A, V = data.spec.articulations, data.spec.views
    n_views = min(views, V)
    images, poses, qs, kps, travel = [], [], [], [], []
    for _ in range(batch):
        rec = data.records[rng.integers(data.num_objects)]
        a = rng.integers(A)
        vs = np.sort(rng.choice(V, n_views, replace=False))
        images.append(np.asarray(rec.rgb[a, vs]))
        poses.append(rec.X_OC[a, vs])
        qs.append(rec.q[a])
        kps.append(rec.keypoints[a])
        travel.append(rec.meta["joint_upper"])
    images = torch.from_numpy(np.stack(images)).permute(0, 1, 4, 2, 3).float() / 255.0
    return (images, torch.from_numpy(np.stack(poses)), torch.tensor(np.array(qs)),
            torch.from_numpy(np.stack(kps)), torch.tensor(travel, dtype=torch.float32))


def train_baseline(data_dir: Path, out: Path, config: BaselineTrainConfig, resume: bool = False,
                   progress: bool = True, allow_incomplete: bool = False) -> Path:
    """Train (or resume) a baseline into `out`; returns `out`. A dataset missing objects is
    refused unless `allow_incomplete`."""
    set_torch_threads(config.threads)
    data = RenderedDataset(data_dir)
    data.require_complete(allow_incomplete)
    joint_type = "revolute" if data.spec.category == "closet" else "prismatic"
    arch = BaselineConfig(data.spec.category, data.keypoint_names, joint_type)
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
            images, poses, q, kp, travel = _sample_batch(data, rng, config.batch, config.views)
            pred = model(images, poses)
            q_mse = ((pred.q - q) ** 2).mean()
            kp_mse = ((pred.keypoints - kp) ** 2).sum(-1).mean()
            loss = q_mse + config.keypoint_weight * kp_mse
            if joint_type == "prismatic":
                loss = loss + config.travel_weight * ((pred.travel - travel) ** 2).mean()
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
    """Train the paper's image-encoder baseline on a dataset from `nfr-drake generate`.

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
