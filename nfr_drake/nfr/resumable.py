"""A resumable training run of a small network (the 2D handle detector, the segmenter): Adam steps
on a loss, a safetensors + JSON checkpoint every few steps, and a resume that ends with the weights
of a run never stopped."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from nfr_drake.errors import ConfigError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import (
    TRAINER_FILE,
    CheckpointError,
    read_training_checkpoint,
    write_training_checkpoint,
)


class ResumableRun:
    """The progress (`step`, `seconds` of stepping, `losses` per step) of training `module` with
    `optimizer`, its `scheduler` and the batch sampler's numpy `rng`.

    `folder` is the checkpoint (`write_training_checkpoint`: weights, Adam moments, torch RNG;
    trainer.json: `options`, the scheduler, the sampler's RNG and the progress). With `resume` and
    a checkpoint in `folder` the run continues from it: ConfigError when it was written with other
    `options` (JSON values: the architecture, the training options, the data), CheckpointError
    when its state is unreadable.
    """

    def __init__(self, folder: Path, module: nn.Module, optimizer: torch.optim.Optimizer,
                 scheduler: torch.optim.lr_scheduler.LRScheduler, rng: np.random.Generator,
                 options: dict, resume: bool):
        self.folder, self.module, self.optimizer = Path(folder), module, optimizer
        self.scheduler, self.rng = scheduler, rng
        self.options = json.loads(json.dumps(options))
        self.step, self.seconds, self.losses = 0, 0.0, []
        if resume and self.folder.is_dir():
            self._restore()

    def _restore(self) -> None:
        saved = read_json(self.folder / TRAINER_FILE, CheckpointError, "checkpoint state")
        if not isinstance(saved, dict):
            raise CheckpointError(f"{self.folder / TRAINER_FILE}: not a training state")
        differ = [k for k in self.options if saved.get(k) != self.options[k]]
        if differ:
            raise ConfigError(f"{self.folder}: --resume with other options than the run's "
                              f"({', '.join(differ)} differ)")
        state = read_training_checkpoint(self.folder, self.module, self.optimizer)
        try:
            self.scheduler.load_state_dict(state["sched"])
            self.rng.bit_generator.state = state["rng"]
            self.step, self.seconds = int(state["step"]), float(state["seconds"])
            self.losses = list(state["losses"])
        except (KeyError, TypeError, ValueError) as err:
            raise CheckpointError(f"{self.folder / TRAINER_FILE}: bad training state ({err})") from None

    def save(self) -> None:
        """Write the checkpoint (atomically)."""
        write_training_checkpoint(self.folder, self.module, self.optimizer, {
            **self.options, "sched": self.scheduler.state_dict(), "rng": self.rng.bit_generator.state,
            "step": self.step, "seconds": self.seconds, "losses": self.losses})

    def train(self, steps: int, checkpoint_every: int, loss: Callable[[], torch.Tensor], desc: str) -> None:
        """Adam steps on `loss()` (a fresh batch each call) until `steps` in all, with a progress
        bar named `desc`; a checkpoint every `checkpoint_every` steps and at the last."""
        bar = tqdm(total=steps, initial=self.step, desc=desc, mininterval=10.0)
        while self.step < steps:
            t0 = time.perf_counter()
            value = loss()
            self.optimizer.zero_grad()
            value.backward()
            self.optimizer.step()
            self.scheduler.step()
            self.losses.append(value.item())
            self.step += 1
            self.seconds += time.perf_counter() - t0
            bar.update(1)
            bar.set_postfix(loss=f"{np.mean(self.losses[-50:]):.3f}", refresh=False)
            if self.step % checkpoint_every == 0 or self.step == steps:
                self.save()
        bar.close()
