"""Auto-decoder training of the neural field (paper, "Training"): codes and networks jointly.

`nfr-drake train --data DIR --out RUN` writes into RUN:
```
RUN/train_config.json        the TrainConfig, data folder and command of the run
RUN/metrics.csv              training loss terms every `log_every` steps
RUN/val.csv                  validation metrics every `val_every` steps
RUN/val/step_0002000.png     ground truth | render | predicted segmentation | true segmentation
RUN/val/qsweep_0002000.png   one training object rendered at q = 0 ... 1 (door follows q?)
RUN/curves.png               loss curves
RUN/checkpoints/step_*/      resumable checkpoints (model + optimizer + trainer state)
RUN/best/                    model folder (model.safetensors + config.json) with the best val PSNR
```
`--resume` continues from the newest checkpoint. SIGTERM/SIGINT write a checkpoint, then the run
ends with `Interrupted` (exit status 143/130), never as if it had completed. A dataset with fewer
objects on disk than its dataset.json declares is refused unless `--allow-incomplete`.
Data-parallel: `torchrun --nproc_per_node 2 -m nfr_drake.cli train ...` (gloo on CPU, NCCL on GPU).
"""

from __future__ import annotations

import csv
import json
import math
import os
import shlex
import shutil
import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated

import numpy as np
import torch
import tyro
from tqdm import tqdm

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.slot_dataset import SlotDataset, SlotTargets, open_dataset
from nfr_drake.data.visualize import colorize_labels, image_grid
from nfr_drake.errors import ConfigError, Interrupted
from nfr_drake.nfr.checkpoint import (
    CheckpointError,
    init_from_model_folder,
    read_checkpoint,
    write_checkpoint,
    write_model_folder,
)
from nfr_drake.nfr.config import TrainConfig
from nfr_drake.nfr.losses import nfr_loss
from nfr_drake.nfr.model import NFRAutoDecoder
from nfr_drake.nfr.rays import pixel_rays
from nfr_drake.nfr.render import render_images
from nfr_drake.nfr.sampling import RaySampler
from nfr_drake.nfr.viz import plot_curves, save_png

TRAIN_FIELDS = ["step", "seconds", "lr_scale", "total", "image", "seg", "keypoint", "latent",
                "depth", "psnr", "rays_per_s", "slots"]
VAL_FIELDS = ["step", "seconds", "image_mse", "psnr", "pixel_acc", "miou", "handle_iou",
              "kp_mean_cm", "kp_handle_cm", "slot_exists_acc", "slot_type_acc"]


@dataclass
class DistInfo:
    """This process's place in a torchrun job (rank 0 of 1 when not distributed)."""

    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @property
    def main(self) -> bool:
        return self.rank == 0


def select_device(name: str, dist: DistInfo) -> torch.device:
    """'auto' -> CUDA (this rank's GPU) when available, else CPU."""
    if name == "cuda" or (name == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise ConfigError("device 'cuda' requested but CUDA is not available")
        return torch.device("cuda", dist.local_rank % torch.cuda.device_count())
    return torch.device("cpu")


def init_distributed(device_name: str) -> DistInfo:
    """Join the torchrun process group when WORLD_SIZE > 1 (gloo on CPU, NCCL on CUDA)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world == 1:
        return DistInfo()
    info = DistInfo(int(os.environ["RANK"]), world, int(os.environ.get("LOCAL_RANK", "0")))
    use_cuda = device_name == "cuda" or (device_name == "auto" and torch.cuda.is_available())
    torch.distributed.init_process_group("nccl" if use_cuda else "gloo")
    return info


def latest_checkpoint(run: Path) -> Path | None:
    """The newest complete checkpoint folder of a run, or None."""
    ckpts = sorted(p for p in (run / "checkpoints").glob("step_*")
                   if p.is_dir() and not p.name.endswith((".tmp", ".old")))
    return ckpts[-1] if ckpts else None


def _append_csv(path: Path, fields: list[str], row: dict) -> None:
    new = not path.is_file()
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        if new:
            w.writeheader()
        w.writerow({k: row.get(k, "") for k in fields})


def _truncate_csv(path: Path, step: int) -> None:
    """Drop rows after `step` (written after the checkpoint a resumed run starts from)."""
    if not path.is_file():
        return
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return
    fields = list(rows[0])
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(r for r in rows if int(float(r["step"])) <= step)


def validation_set(data: RenderedDataset, n: int) -> list[tuple[int, int, int]]:
    """Fixed (object, articulation, view) triples spread over objects and the range of q."""
    A, V = data.spec.articulations, data.spec.views
    objs = np.linspace(0, data.num_objects - 1, n).round().astype(int)
    arts = np.linspace(0, A - 1, n).round().astype(int)
    return [(int(o), int(a), int(i % V)) for i, (o, a) in enumerate(zip(objs, arts, strict=True))]


def _iou(pred: np.ndarray, true: np.ndarray, c: int) -> float:
    union = np.logical_or(pred == c, true == c).sum()
    return float(np.logical_and(pred == c, true == c).sum() / union) if union else math.nan


def _targets(data: RenderedDataset) -> tuple[list[np.ndarray], list[np.ndarray], list[SlotTargets]
                                                 | None]:
    """Per object: q (A,) or (A, S), keypoints (A, K, 3), and the slot targets of furniture."""
    if isinstance(data, SlotDataset):
        return ([t.q for t in data.slots],
                [t.keypoints.reshape(len(t.q), -1, 3) for t in data.slots], data.slots)
    return [r.q for r in data.records], [r.keypoints for r in data.records], None


@torch.no_grad()
def _start_keypoints_at_mean(module: NFRAutoDecoder, data: RenderedDataset) -> None:
    """Set the keypoint head's output bias to the training keypoints' mean (each keypoint over the
    objects where its slot exists; the overall mean where none), so that the keypoint loss starts
    at the data's spread instead of at |p|^2 (about 1 m^2 for furniture, whose clipped gradient
    then leaves little to the image loss)."""
    _, kps, slots = _targets(data)
    true = np.concatenate(kps)  # (N A, K, 3)
    valid = np.ones(true.shape[:2], bool)
    if slots is not None:
        A = data.spec.articulations
        exists = np.repeat(np.stack([t.exists for t in slots]), A, axis=0)
        valid = np.repeat(exists, true.shape[1] // exists.shape[1], axis=1)
    overall = true[valid].mean(0)
    count = valid.sum(0)[:, None]
    mean = np.where(count > 0, (true * valid[..., None]).sum(0) / np.maximum(count, 1), overall)
    bias = module.model.keypoint_head.net[-1].bias
    bias[:mean.size] = torch.from_numpy(mean.reshape(-1)).to(bias)


@torch.no_grad()
def validate(module: NFRAutoDecoder, data: RenderedDataset, items: list[tuple[int, int, int]],
             device: torch.device, run: Path, step: int) -> dict:
    """Render the fixed validation images in full, write the PNG grids, return metrics.

    Keypoint errors count the keypoints of existing slots only; furniture adds the slot head's
    existence and type accuracy (training objects, their true q)."""
    model = module.model
    model.eval()
    S = data.spec.size
    recs = data.records
    qs_all, kps_all, slots = _targets(data)
    obj = torch.tensor([o for o, _, _ in items], device=device)
    q = torch.from_numpy(np.stack([qs_all[o][a] for o, a, _ in items])).to(device)
    X = torch.from_numpy(np.stack([recs[o].X_OC[a, v] for o, a, v in items])).to(device)
    K = torch.from_numpy(data.camera.K.astype(np.float32)).expand(len(items), 3, 3).to(device)
    out = render_images(model, module.code(obj, q), K, X, S, S)
    gt_rgb = np.stack([recs[o].rgb[a, v] for o, a, v in items]).astype(np.float32) / 255.0
    gt_lab = np.stack([recs[o].label[a, v] for o, a, v in items]).astype(np.int64)
    rgb, lab = out.rgb.cpu().numpy(), out.labels.cpu().numpy()
    mse = float(((rgb - gt_rgb) ** 2).mean())
    ious = [_iou(lab, gt_lab, c) for c in range(model.config.num_classes)]
    rows = [[gt_rgb[i], rgb[i], colorize_labels(lab[i]), colorize_labels(gt_lab[i])]
            for i in range(len(items))]
    save_png(run / "val" / f"step_{step:07d}.png", image_grid(rows, scale=2))
    # q sweep of the first validation object, camera of its first item.
    # (furniture: every existing front of the object swept together, absent slots shut).
    qs = torch.linspace(0, 1, 5, device=device)
    if slots is not None:
        qs = qs[:, None] * torch.from_numpy(slots[items[0][0]].exists).to(qs)
    o0 = obj[:1].expand(5)
    sweep = render_images(model, module.code(o0, qs), K[:1].expand(5, 3, 3), X[:1].expand(5, 4, 4),
                          S, S)
    save_png(run / "val" / f"qsweep_{step:07d}.png",
             image_grid([list(sweep.rgb.cpu().numpy()),
                         list(colorize_labels(sweep.labels.cpu().numpy()))], scale=2))
    # Keypoints of every training object at every articulation.
    A = data.spec.articulations
    all_obj = torch.arange(data.num_objects, device=device).repeat_interleave(A)
    all_q = torch.from_numpy(np.concatenate(qs_all)).to(device)
    z_all = module.code(all_obj, all_q)
    pred = model.keypoints(z_all).cpu().numpy()
    true = np.concatenate(kps_all)
    err = np.linalg.norm(pred - true, axis=-1) * 100.0  # (N A, K) cm
    names = [n.split("/")[-1] for n in data.keypoint_names]
    valid = np.ones(err.shape, bool)
    slot_metrics = {}
    if slots is not None:
        exists = np.repeat(np.stack([t.exists for t in slots]), A, axis=0)  # (N A, S)
        types = np.repeat(np.stack([t.types for t in slots]), A, axis=0)
        valid = np.repeat(exists, err.shape[1] // exists.shape[1], axis=1)
        logits = model.slot_logits(z_all).cpu().numpy()
        slot_metrics = dict(
            slot_exists_acc=float(((logits[..., 0] > 0) == exists).mean()),
            slot_type_acc=float((logits[..., 1:].argmax(-1) == types)[exists].mean()))
    handle = valid & (np.asarray(names) == ("handle" if "handle" in names else names[0]))
    model.train()
    return dict(step=step, image_mse=mse, psnr=-10.0 * math.log10(max(mse, 1e-12)),
                pixel_acc=float((lab == gt_lab).mean()), miou=float(np.nanmean(ious)),
                handle_iou=ious[3] if len(ious) > 3 else math.nan,
                kp_mean_cm=float(err[valid].mean()), kp_handle_cm=float(err[handle].mean()),
                **slot_metrics)


class _StopFlag:
    """Set by SIGTERM/SIGINT (`signum`) so the loop can write a checkpoint and exit cleanly."""

    def __init__(self):
        self.stop = False
        self.signum = signal.SIGTERM
        self._old = {}

    def __enter__(self):
        for sig in (signal.SIGTERM, signal.SIGINT):
            self._old[sig] = signal.signal(sig, self._handler)
        return self

    def _handler(self, signum, frame):
        self.stop, self.signum = True, signum

    def __exit__(self, *exc):
        for sig, old in self._old.items():
            signal.signal(sig, old)


def train(data_dir: Path, out: Path, config: TrainConfig, resume: bool = False,
          command: str = "", init_from: Path | None = None, allow_incomplete: bool = False) -> Path:
    """Train a neural field on a rendered dataset; returns RUN/best (the best model folder).

    `init_from`: a model folder to start from (fine-tuning), trained on this dataset or on its
    first objects (same spec, fewer objects, any image size); ignored when resuming a run that
    has checkpoints. `allow_incomplete`: train on the objects on disk when some are missing.
    Raises `Interrupted` after writing a checkpoint when SIGTERM/SIGINT stopped the run.
    """
    data_dir, run = Path(data_dir), Path(out)
    dist = init_distributed(config.device)
    device = select_device(config.device, dist)
    if device.type == "cpu":
        set_torch_threads(config.threads, dist.world)
    data = open_dataset(data_dir, objects=config.objects)
    data.require_complete(allow_incomplete)
    names = data.keypoint_names
    num_slots = data.num_slots if isinstance(data, SlotDataset) else 1
    if (config.model.num_keypoints, config.model.num_slots) != (len(names), num_slots):
        config = replace(config, model=replace(config.model, num_keypoints=len(names),
                                               num_slots=num_slots))
    ckpt = latest_checkpoint(run) if resume else None
    if not resume and latest_checkpoint(run) is not None:
        raise ConfigError(f"{run} already holds checkpoints; pass --resume to continue it or "
                          "choose another --out")
    if ckpt is not None and (run / "train_config.json").is_file():
        saved = TrainConfig.from_json(json.loads((run / "train_config.json").read_text())["config"])
        if saved.model != config.model:
            raise ConfigError(f"{run}: --resume with another architecture than the run's "
                              "(see train_config.json)")
    torch.manual_seed(config.seed)
    module = NFRAutoDecoder(config.model, data.num_objects, config.code_init_std)
    if init_from is None and ckpt is None:
        _start_keypoints_at_mean(module, data)
    if init_from is not None and ckpt is None:
        start = init_from_model_folder(init_from, module)
        spec = json.loads(json.dumps(data.spec.to_json()))
        start_spec = dict(start.get("training", {}).get("dataset_spec", {}))
        # Objects, lighting, articulations and cameras are drawn independently of the image
        # size, so object i is the same at any size and its code carries over.
        if {**start_spec, "objects": spec["objects"], "size": spec["size"]} != spec:
            raise ConfigError(f"--init-from {init_from}: that model was trained on other data "
                              f"than {data_dir} (only the number of objects may grow and the image "
                              "size change); its object codes would not match")
    module = module.to(device)
    net_params = [p for n, p in module.named_parameters() if not n.startswith("codes.")]
    optimizer = torch.optim.Adam([
        {"params": net_params, "lr": config.optim.lr_networks, "name": "networks"},
        {"params": list(module.codes.parameters()), "lr": config.optim.lr_codes, "name": "codes"},
    ])
    sampler = RaySampler(data.records, data.camera.K, config.sampler, seed=config.seed + dist.rank,
                         slots=_targets(data)[2])
    info = {"category": data.spec.category, "keypoint_names": list(names),
            "image_size": data.spec.size,
            "training": {"data": str(data_dir), "dataset_spec": data.spec.to_json(),
                         "objects": data.num_objects, "command": command,
                         "init_from": None if init_from is None else str(init_from),
                         "train_config": config.to_json()}}
    step, seconds, best_psnr = 0, 0.0, -math.inf
    if ckpt is not None:
        try:
            trainer = read_checkpoint(ckpt, module, optimizer)
        except CheckpointError as err:
            raise CheckpointError(f"cannot resume: {err}") from None
        step, seconds = trainer["step"], trainer["seconds"]
        best_psnr = trainer.get("best_psnr", -math.inf)
        sampler.rng.bit_generator.state = trainer["sampler_rng"][str(dist.rank)] \
            if str(dist.rank) in trainer["sampler_rng"] else sampler.rng.bit_generator.state
    if dist.main:
        run.mkdir(parents=True, exist_ok=True)
        _write_json_atomic(run / "train_config.json",
                           {"config": config.to_json(), "data": str(data_dir), "command": command})
        if ckpt is not None:
            for name in ("metrics.csv", "val.csv"):
                _truncate_csv(run / name, step)
    ddp = module
    if dist.world > 1:
        ddp = torch.nn.parallel.DistributedDataParallel(
            module, device_ids=[device.index] if device.type == "cuda" else None)
    val_items = validation_set(data, config.val_images)

    def save(step_now: int) -> None:
        rngs = [None] * dist.world
        state = sampler.rng.bit_generator.state
        if dist.world > 1:
            torch.distributed.all_gather_object(rngs, state)
        else:
            rngs = [state]
        if not dist.main:
            return
        trainer = {"step": step_now, "seconds": seconds, "best_psnr": best_psnr,
                   "sampler_rng": {str(r): s for r, s in enumerate(rngs)}}
        write_checkpoint(run / "checkpoints" / f"step_{step_now:07d}", module, optimizer,
                         {**info, "step": step_now}, trainer)
        old = sorted(p for p in (run / "checkpoints").glob("step_*") if p.is_dir())
        for p in old[:-config.keep_checkpoints]:
            shutil.rmtree(p, ignore_errors=True)

    sums = dict.fromkeys(["total", "image", "seg", "keypoint", "latent", "depth", "slots"], 0.0)
    count, window_t, window_rays = 0, 0.0, 0
    bar = tqdm(total=config.optim.steps, initial=step, disable=not dist.main, mininterval=5.0,
               desc="train", dynamic_ncols=True)
    with _StopFlag() as flag:
        while step < config.optim.steps:
            t0 = time.perf_counter()
            scale = config.optim.lr_scale(step)
            for group, base in zip(optimizer.param_groups,
                                   (config.optim.lr_networks, config.optim.lr_codes), strict=True):
                group["lr"] = base * scale
            batch = sampler.sample().to(device)
            rays = pixel_rays(batch.uv, batch.K, batch.X_OC)
            render, keypoints, z = ddp(batch.object_index, batch.q, rays)
            slot_logits = module.model.slot_logits(z) if num_slots > 1 else None
            terms = nfr_loss(render, keypoints, z[:, config.model.art_dim:], batch.rgb,
                             batch.labels, batch.keypoints, config.loss, slot_logits,
                             batch.exists, batch.types)
            optimizer.zero_grad(set_to_none=True)
            terms.total.backward()
            if config.optim.grad_clip > 0:
                torch.nn.utils.clip_grad_norm_(module.parameters(), config.optim.grad_clip)
            optimizer.step()
            step += 1
            dt = time.perf_counter() - t0
            seconds += dt
            window_t += dt
            window_rays += batch.uv.shape[0] * batch.uv.shape[1] * dist.world
            for k in sums:
                sums[k] += getattr(terms, k).item()
            count += 1
            bar.update(1)
            if step % config.log_every == 0 or step == config.optim.steps:
                row = {k: v / count for k, v in sums.items()}
                row.update(step=step, seconds=round(seconds, 2), lr_scale=scale,
                           psnr=-10 * math.log10(max(row["image"], 1e-12)),
                           rays_per_s=round(window_rays / max(window_t, 1e-9)))
                if dist.main:
                    _append_csv(run / "metrics.csv", TRAIN_FIELDS, row)
                    bar.set_postfix(loss=f"{row['total']:.4f}", psnr=f"{row['psnr']:.1f}")
                sums = dict.fromkeys(sums, 0.0)
                count, window_t, window_rays = 0, 0.0, 0
            if step % config.val_every == 0 or step == config.optim.steps:
                if dist.main:
                    metrics = validate(module, data, val_items, device, run, step)
                    metrics["seconds"] = round(seconds, 2)
                    _append_csv(run / "val.csv", VAL_FIELDS, metrics)
                    if metrics["psnr"] > best_psnr:
                        best_psnr = metrics["psnr"]
                        write_model_folder(run / "best", module,
                                           {**info, "step": step, "val": metrics})
                    plot_curves(run, run / "curves.png")
                    bar.write(f"step {step}: val psnr {metrics['psnr']:.2f} dB, mIoU "
                              f"{metrics['miou']:.3f}, keypoints {metrics['kp_mean_cm']:.2f} cm")
            stop = flag.stop
            if dist.world > 1:
                t = torch.tensor([float(stop)], device=device)
                torch.distributed.all_reduce(t)
                stop = bool(t.item() > 0)
            if step % config.ckpt_every == 0 or step == config.optim.steps or stop:
                save(step)
            if stop:
                break
    bar.close()
    if dist.world > 1:
        torch.distributed.barrier()
        torch.distributed.destroy_process_group()
    if step < config.optim.steps:
        raise Interrupted(f"interrupted at step {step} of {config.optim.steps} (checkpoint in "
                          f"{run / 'checkpoints'}); rerun with --resume", flag.signum)
    return run / "best"


def _write_json_atomic(path: Path, data: dict) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    os.replace(tmp, path)


_DEFAULT_CONFIG = TrainConfig()


def train_command(data: Path, out: Path,
                  config: Annotated[TrainConfig, tyro.conf.arg(name="")] = _DEFAULT_CONFIG,
                  resume: bool = False, init_from: Path | None = None,
                  allow_incomplete: bool = False) -> int:
    """Train the neural field (auto-decoder) on a dataset written by `nfr-drake generate`.

    Args:
        data: dataset folder.
        out: run folder (checkpoints, logs, validation images, best model).
        config: training configuration; every field can be set, e.g. --optim.steps 20000.
        resume: continue the run in `out` from its newest checkpoint.
        init_from: start from this model folder (trained on this dataset or on its first
            objects; the architecture may add positional-encoding octaves) instead of a fresh
            initialisation.
        allow_incomplete: train on the objects on disk when the dataset misses some (a killed
            `generate`); without it such a dataset is refused.
    """
    command = " ".join(["nfr-drake", "train"] + [shlex.quote(a) for a in sys.argv[2:]])
    best = train(data, out, config, resume=resume, command=command, init_from=init_from,
                 allow_incomplete=allow_incomplete)
    if int(os.environ.get("RANK", "0")) == 0:
        print(f"best model: {best}")
    return 0
