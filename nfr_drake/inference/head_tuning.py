"""Tuning the keypoint head Gamma on the codes the fit finds for unseen objects.

The head is trained on the training objects' codes; the fit of an unseen object lands on another
code, where the head extrapolates while the field's geometry still matches the photos (a fitted
closet's rendered top edge is within a few millimetres of the truth where the head's hinge_top is
2 cm off). This module fits synthetic capture sets of objects never used in training or
evaluation (`nfr-drake captures` with a seed of its own) with the default fit, then trains the
head alone on (fitted z_obj, z_art(q)) -> the true keypoints along q, while keeping its answers
on the training codes (a distillation term), and writes a model folder in which only the head
differs. The fits are kept as OUT/fits/<capture>.json, so a killed run resumes without fitting
again. A model with several part slots (furniture) is fitted as `infer_parts` fits it (the
furniture fit's defaults, with the model's handle detector); its pairs are each part's sweep
with the other parts held at their true q, the targets every existing slot's keypoints that the
ground truth names (`PART_KEYPOINTS`), and the distillation keeps the slots' logits too.
"""

from __future__ import annotations

import copy
import json
import shutil
import sys
import time
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import save_file
from tqdm import tqdm

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import FittedModel, infer, infer_parts
from nfr_drake.inference.metrics import keypoint_rmse_cm
from nfr_drake.inference.result import PART_KEYPOINTS
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import CONFIG_FILE, WEIGHTS_FILE, read_model_config, read_tensors
from nfr_drake.nfr.latent import slots_q_to_z_art

FITS_DIR = "fits"
_HEAD_PREFIX = "keypoint_head."


@dataclass(frozen=True)
class HeadTuningConfig:
    """`steps` full-batch Adam steps at `lr`; `distill_weight` times the squared change of the
    head's keypoints on `distill_samples` random (training code, q) pairs per step joins the
    loss; the last `holdout` share of the fitted captures is held out, and the head of the step
    with the lowest held-out keypoint RMSE (checked every `check_every` steps) is kept."""

    steps: int = 3000
    lr: float = 3e-4
    distill_weight: float = 1.0
    distill_samples: int = 1024
    holdout: float = 0.1
    check_every: int = 50
    seed: int = 0

    def __post_init__(self):
        if min(self.steps, self.distill_samples, self.check_every) < 1 or self.lr <= 0:
            raise ConfigError("head tuning: steps, distill_samples, check_every >= 1, lr > 0")
        if not 0.0 < self.holdout < 0.5 or self.distill_weight < 0:
            raise ConfigError("head tuning: holdout in (0, 0.5), distill_weight >= 0")


_worker_model: FittedModel | None = None


_worker_fit: FitConfig = FitConfig()


def _start_worker(model_dir: Path, threads: int, fit: FitConfig) -> None:
    global _worker_model, _worker_fit
    set_torch_threads(threads)
    _worker_model, _worker_fit = FittedModel(model_dir), fit


def _fit_one(job: tuple[Path, Path]) -> str:
    """Fit one capture in a worker; writes OUT/fits/<capture>.json: z (2 S + k,), q."""
    capture_dir, out_file = job
    capture = read_capture_set(capture_dir)
    _worker_model.check_capture(capture)
    if _worker_model.num_slots > 1:
        result, _, _ = infer_parts(_worker_model, capture, FurnitureFitConfig(), np.array([0.0]))
    else:
        result, _ = infer(_worker_model, capture, _worker_fit, np.array([0.0]))
    tmp = out_file.with_suffix(".tmp")
    tmp.write_text(json.dumps({"capture": capture_dir.name, "q": result.q, "z": result.z.tolist()}))
    tmp.replace(out_file)
    return capture_dir.name


def fit_captures(model_dir: Path, captures: Path, out: Path, workers: int = 1, fit: FitConfig = FitConfig(),
                 threads: int | None = None) -> list[Path]:
    """Fit every capture set under `captures` that has no fit in OUT/fits yet, in `workers`
    processes of `threads` torch threads each (None: their share of the free cores); returns the
    capture folders (all of them, fitted now or before)."""
    dirs = capture_dirs(captures)
    missing = [d.name for d in dirs if not (d / "gt.json").is_file()]
    if missing:
        raise NfrDrakeError(f"{captures}: head tuning needs gt.json (the true keypoints) in every "
                            f"capture set; missing in {', '.join(missing[:5])}")
    fits = out / FITS_DIR
    fits.mkdir(parents=True, exist_ok=True)
    todo = [(d, fits / f"{d.name}.json") for d in dirs if not (fits / f"{d.name}.json").is_file()]
    if todo:
        per_worker = set_torch_threads(threads, workers)
        with get_context("spawn").Pool(workers, _start_worker, (model_dir, per_worker, fit)) as pool:
            for _ in tqdm(pool.imap_unordered(_fit_one, todo), total=len(todo),
                          desc="fit captures", unit="capture"):
                pass
    return dirs


def _pairs(fitted: FittedModel, dirs: list[Path], out: Path):
    """Training pairs and held-out checks of the fits in OUT/fits: (z (P, 2 S + k), true keypoints
    (P, K, 3) as the head lays them out (K = S x 4 for slots), mask (P, K) of those the ground truth
    gives, capture index (P,)) along each part's q grid (the other parts held at their true q), and
    per capture the fitted code and its parts at the observed state, [(keypoint indices into K,
    true keypoints (n, 3))]."""
    zs, kps, masks, owner, observed = [], [], [], [], []
    for i, d in enumerate(dirs):
        fit = read_json(out / FITS_DIR / f"{d.name}.json", NfrDrakeError, "fit")
        gt = read_json(d / "gt.json", NfrDrakeError, "ground truth")
        z = torch.tensor(fit["z"], dtype=torch.float32)
        for grid, z_art, target, known in _sweeps(fitted, gt):
            zs.append(torch.cat([z_art, z[z_art.shape[1]:].expand(len(grid), -1)], -1))
            kps.append(torch.tensor(target, dtype=torch.float32))
            masks.append(torch.tensor(known))
            owner.append(torch.full((len(grid),), i))
        observed.append((z, _observed_parts(fitted, gt)))
    return torch.cat(zs), torch.cat(kps), torch.cat(masks), torch.cat(owner), observed


def _slot_layout(part: dict) -> tuple[list[int], list[str]]:
    """Indices into the head's K keypoints of a furniture part (slot `index`) and their gt names."""
    names = PART_KEYPOINTS[part["type"]]
    return ([part["index"] * len(SLOT_KEYPOINTS) + SLOT_KEYPOINTS.index(n) for n in names],
            [names[n] for n in names])


def _observed_parts(fitted: FittedModel, gt: dict) -> list[tuple[list[int], np.ndarray]]:
    """Per part of gt (one for a one-part model): its keypoint indices into K and the true keypoints
    (n, 3) at the observed state."""
    if fitted.num_slots == 1:
        names = fitted.keypoint_names
        return [(list(range(len(names))), np.array([gt["keypoints"][n] for n in names]))]
    return [(index, np.array([p["keypoints"][n] for n in gt_names]))
            for p in gt["parts"] for index, gt_names in [_slot_layout(p)]]


def _sweeps(fitted: FittedModel, gt: dict):
    """Per swept part: q grid (N,), z_art (N, 2 S), true keypoints (N, K, 3), known (N, K) bool."""
    S = fitted.num_slots
    if S == 1:
        names = fitted.keypoint_names
        grid = np.asarray(gt["trajectory"]["q"], float)
        along = np.stack([np.asarray(gt["trajectory"]["keypoints"][n]) for n in names], 1)
        yield grid, slots_q_to_z_art(torch.tensor(grid, dtype=torch.float32), 1), along, \
            np.ones(along.shape[:2], bool)
        return
    K = S * len(SLOT_KEYPOINTS)
    held = np.zeros(S)
    held[[p["index"] for p in gt["parts"]]] = [p["q"] for p in gt["parts"]]
    for part in gt["parts"]:
        grid = np.asarray(part["trajectory"]["q"], float)
        q = np.tile(held, (len(grid), 1))
        q[:, part["index"]] = grid
        target, known = np.zeros((len(grid), K, 3)), np.zeros((len(grid), K), bool)
        along = part["trajectory"]["keypoints"]
        for other in gt["parts"]:
            index, gt_names = _slot_layout(other)
            known[:, index] = True
            target[:, index] = (np.stack([np.asarray(along[n]) for n in gt_names], 1) if other is part
                                else np.array([other["keypoints"][n] for n in gt_names]))
        yield grid, slots_q_to_z_art(torch.tensor(q, dtype=torch.float32), S), target, known


def tune_head(fitted: FittedModel, dirs: list[Path], out: Path, config: HeadTuningConfig) -> dict:
    """Train `fitted.model.keypoint_head` in place on the fits of `dirs` (module docstring);
    returns the record: held-out keypoint RMSE at the observed state before and after (median,
    cm), its curve, and the training pairs' mean squared error (m^2) at the first and last step."""
    if len(dirs) < 10:
        raise NfrDrakeError(f"head tuning needs at least 10 fitted captures, got {len(dirs)}")
    torch.manual_seed(config.seed)
    model, S = fitted.model, fitted.num_slots
    z_all, kp_all, known, owner, observed = _pairs(fitted, dirs, out)
    n_val = max(1, int(round(config.holdout * len(dirs))))
    train = owner < len(dirs) - n_val
    z_train_pairs, kp_train, known_train = z_all[train], kp_all[train], known[train]
    val = observed[-n_val:]
    head = model.keypoint_head
    old_model = copy.deepcopy(model).requires_grad_(False)
    head.requires_grad_(True)
    codes = fitted.codes.float()

    def held_out_rmse() -> float:
        with torch.no_grad():
            pred = model.keypoints(torch.stack([z for z, _ in val])).numpy()
        return float(np.median([keypoint_rmse_cm(p[index], t)
                                for p, (_, parts) in zip(pred, val, strict=True) for index, t in parts]))

    before = best = held_out_rmse()
    best_state, best_step, curve, fit_curve = copy.deepcopy(head.state_dict()), 0, [], []
    opt = torch.optim.Adam(head.parameters(), lr=config.lr)
    generator = torch.Generator().manual_seed(config.seed)
    for step in tqdm(range(1, config.steps + 1), desc="tune keypoint head", mininterval=5.0):
        pick = torch.randint(len(codes), (config.distill_samples,), generator=generator)
        q = torch.rand(config.distill_samples, S, generator=generator)
        z_train = torch.cat([slots_q_to_z_art(q, S), codes[pick]], -1)
        with torch.no_grad():
            keep, keep_logits = old_model.keypoints(z_train), old_model.slot_logits(z_train)
        fit_term = ((model.keypoints(z_train_pairs) - kp_train) ** 2).sum(-1)[known_train].mean()
        distill = ((model.keypoints(z_train) - keep) ** 2).sum(-1).mean()
        if S > 1:  # the slots' existence and type logits kept too
            distill = distill + ((model.slot_logits(z_train) - keep_logits) ** 2).mean()
        loss = fit_term + config.distill_weight * distill
        fit_curve.append(fit_term.item())
        opt.zero_grad()
        loss.backward()
        opt.step()
        if step % config.check_every == 0:
            rmse = held_out_rmse()
            curve.append((step, rmse))
            if rmse < best:
                best, best_step = rmse, step
                best_state = copy.deepcopy(head.state_dict())
    head.load_state_dict(best_state)
    return {"config": asdict(config), "captures": len(dirs), "held_out": n_val,
            "held_out_keypoint_rmse_cm": {"before": before, "after": best},
            "best_step": best_step, "held_out_curve": curve,
            "train_fit_m2": {"first": fit_curve[0], "last": fit_curve[-1]}}


def write_tuned_model(source: Path, fitted: FittedModel, out_model: Path, record: dict) -> None:
    """A copy of the model folder `source` (with its handle detector) whose keypoint head is
    `fitted.model.keypoint_head`; config.json gains `keypoint_head_tuning` = record."""
    tmp = out_model.with_name(out_model.name + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    shutil.copytree(source, tmp, ignore=shutil.ignore_patterns("MODEL_CARD.md", "baseline"))
    state = read_tensors(source / WEIGHTS_FILE)
    for k, v in fitted.model.keypoint_head.state_dict().items():
        state[_HEAD_PREFIX + k] = v.detach().clone().contiguous()
    save_file(state, str(tmp / WEIGHTS_FILE))
    config = read_model_config(source)
    config["keypoint_head_tuning"] = record
    (tmp / CONFIG_FILE).write_text(json.dumps(config, indent=2) + "\n")
    if out_model.exists():
        shutil.rmtree(out_model)
    tmp.replace(out_model)


def tune_head_command(model: Path, captures: Path, out: Path,
                      steps: int = HeadTuningConfig.steps, lr: float = HeadTuningConfig.lr,
                      distill_weight: float = HeadTuningConfig.distill_weight,
                      fit: FitConfig = FitConfig(),
                      workers: int = 1, threads: int | None = None) -> None:
    """Fit capture sets of unseen objects, then tune the keypoint head on the fitted codes.

    Args:
        model: model folder to tune (not changed).
        captures: folder of capture sets with gt.json (`nfr-drake captures`, a seed used for
            nothing else).
        out: work folder: fits/ (one per capture, kept on resume) and model/ (the tuned model).
        steps: Adam steps of the head.
        lr: learning rate.
        distill_weight: weight of keeping the head's keypoints on the training codes.
        fit: options of the fits of the captures (fits already in OUT/fits are kept as they are);
            a model with several part slots is fitted with the furniture fit's defaults.
        workers: fitting processes.
        threads: torch threads per fitting process (default: their share of the free cores,
            `nfr_drake.cpu.free_cores`).
    """
    out = Path(out)
    started = time.perf_counter()
    dirs = fit_captures(Path(model), Path(captures), out, workers, fit, threads)
    fitted = FittedModel(Path(model))
    set_torch_threads(threads)
    record = tune_head(fitted, dirs, out, HeadTuningConfig(steps=steps, lr=lr,
                                                           distill_weight=distill_weight))
    record.update(command="nfr-drake tune-head " + " ".join(sys.argv[2:]),
                  captures_dir=str(captures), seconds=time.perf_counter() - started)
    write_tuned_model(Path(model), fitted, out / "model", record)
    rmse = record["held_out_keypoint_rmse_cm"]
    print(f"tuned model written to {out / 'model'}: held-out keypoint RMSE "
          f"{rmse['before']:.2f} -> {rmse['after']:.2f} cm (step {record['best_step']})")
