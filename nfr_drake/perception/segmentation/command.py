"""`nfr-drake train-segmenter` and `nfr-drake eval-segmenter`."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from nfr_drake.perception.segmentation.evaluation import Crop
from nfr_drake.perception.segmentation.model import SegmenterConfig
from nfr_drake.perception.segmentation.training import SegmenterTrainConfig


def train_segmenter_command(data: list[Path], out: Path,
                            steps: int = SegmenterTrainConfig.steps,
                            batch: int = SegmenterTrainConfig.batch,
                            crop: int = SegmenterTrainConfig.crop,
                            lr: float = SegmenterTrainConfig.lr,
                            channels: int = SegmenterConfig.channels,
                            checkpoint_every: int = SegmenterTrainConfig.checkpoint_every,
                            threads: int | None = None, resume: bool = False,
                            init_from: Path | None = None) -> None:
    """Train the 2D object segmenter on room datasets (`nfr-drake generate-rooms`).

    Args:
        data: room dataset folders (any categories and image sizes).
        out: output folder: a model folder (model.safetensors, config.json) and checkpoint/.
        steps: optimiser steps.
        batch: augmented crops per step.
        crop: crop size, px.
        lr: learning rate (cosine decay to 0).
        channels: channels of the first stage (doubling per stage, at most 4x).
        checkpoint_every: steps between checkpoints.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
        resume: continue a stopped run from OUT/checkpoint/.
        init_from: a segmenter folder (`models/segmenter`) to start from, its architecture
            (`--channels` unused): a fine-tune.
    """
    from nfr_drake.perception.segmentation.training import train_segmenter

    config = SegmenterTrainConfig(steps=steps, batch=batch, crop=crop, lr=lr,
                                  checkpoint_every=checkpoint_every, threads=threads)
    command = "nfr-drake train-segmenter " + " ".join(sys.argv[2:])
    record = train_segmenter(list(data), out, config, SegmenterConfig(channels=channels), resume=resume,
                             command=command, init_from=init_from)
    print(f"segmenter written to {out}: {record['images']} images, {config.steps} steps in "
          f"{record['seconds'] / 60:.1f} min, final loss {record['final_loss']:.3f}")


def eval_segmenter_command(model: Path, data: list[Path], out: Path | None = None,
                           figure: Path | None = None, figure_images: int = 2,
                           threads: int | None = None, crop: Crop = "none") -> None:
    """Mask IoU of a segmenter on room datasets (per dataset: mean, median, pooled, on images
    where the image edge cuts the object and where it does not, false-positive area).

    Args:
        model: segmenter folder (`models/segmenter`).
        data: room dataset folders.
        out: JSON file for the measures (printed either way).
        figure: PNG of photos with true (green) and predicted (magenta) masks.
        figure_images: images per dataset in the figure.
        threads: torch CPU threads (default: the free cores).
        crop: the masks measured: the first look ("none"), the second look at the crop around
            each photo's first mask ("mask"), or the crop stage over the views of one articulation,
            the crop around the box of the pose from their first masks ("posed"; docs/ROOMS.md).
    """
    from nfr_drake.cpu import set_torch_threads
    from nfr_drake.perception.segmentation.evaluation import evaluate_dataset, mask_figure
    from nfr_drake.perception.segmentation.model import load_segmenter

    set_torch_threads(threads)
    net, _ = load_segmenter(model)
    results = []
    for root in data:
        r = evaluate_dataset(net, root, crop)
        results.append(r)
        cut = "-" if r["iou_mean_cut"] is None else f"{r['iou_mean_cut']:.3f}"
        print(f"{root}: {r['category']} {r['style']}, crop {crop}, {r['images']} images: "
              f"IoU mean {r['iou_mean']:.3f} "
              f"median {r['iou_median']:.3f} pooled {r['iou_pooled']:.3f}; cut by the edge "
              f"({r['cut_images']}) {cut}; false-positive area {r['false_positive_area']:.3f}; centre box "
              f"{r['iou_mean_centre_box']:.3f}"
              + (f"; amodal carcass IoU mean {r['amodal_iou_mean']:.3f} median {r['amodal_iou_median']:.3f} "
                 f"pooled {r['amodal_iou_pooled']:.3f}" if "amodal_iou_mean" in r else ""))
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(json.dumps({"model": str(model), "results": results}, indent=2) + "\n")
    if figure is not None:
        mask_figure(net, list(data), figure_images, figure, crop=crop)
