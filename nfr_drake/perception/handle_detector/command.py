"""`nfr-drake train-handle-detector`: options in, `train_detector`, one line out."""

from __future__ import annotations

import sys
from pathlib import Path

from nfr_drake.perception.handle_detector.model import HandleDetectorConfig
from nfr_drake.perception.handle_detector.training import DetectorTrainConfig, train_detector


def train_detector_command(data: list[Path], out: Path,
                           steps: int = DetectorTrainConfig.steps,
                           batch: int = DetectorTrainConfig.images_per_batch,
                           crop: int = DetectorTrainConfig.crop,
                           lr: float = DetectorTrainConfig.lr,
                           offset_weight: float = DetectorTrainConfig.offset_weight,
                           channels: int = HandleDetectorConfig.channels,
                           fronts: bool = False, init: Path | None = None, tune: str = "fronts",
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
        offset_weight: weight of the offsets' Huber loss (px) beside the handle mask's loss.
        channels: channels of every convolution (the network's width).
        fronts: also learn the front outputs (furniture: door or drawer, face corners;
            `nfr_drake.perception.front_reading`).
        init: a trained detector folder of the same width to start from (e.g. a handle
            detector to which --fronts adds the front outputs).
        tune: with --init, the network that trains, the other kept as it was: "fronts" or
            "handles" (the handle network trained further).
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
        resume: continue a killed run from OUT/checkpoint/.
        allow_incomplete: train on the objects on disk when a dataset misses some.
    """
    config = DetectorTrainConfig(steps=steps, images_per_batch=batch, crop=crop, lr=lr,
                                 offset_weight=offset_weight, threads=threads)
    command = "nfr-drake train-handle-detector " + " ".join(sys.argv[2:])
    record = train_detector(list(data), out, config, HandleDetectorConfig(channels=channels, fronts=fronts),
                            resume=resume, command=command,
                            allow_incomplete=allow_incomplete, init=init, tune=tune)
    print(f"handle detector written to {out}: held-out handle IoU, offset error "
          + ", ".join(f"{k} {v:.3f}, {record['held_out_offset_error_px'][k]:.2f} px"
                      for k, v in record["held_out_handle_iou"].items()))
    if fronts:
        print("held-out front IoU, door accuracy, corner error (px at the front scale) "
              + ", ".join(f"{k} {record['held_out_front_iou'][k]:.3f}, {v:.3f}, "
                          f"{record['held_out_corner_error_px'][k]:.2f} px"
                          for k, v in record["held_out_door_accuracy"].items()))
