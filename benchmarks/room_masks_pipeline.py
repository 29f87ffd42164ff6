"""The segmenter's masks and the object's pose in the pipeline's own room photos: first look against
the crop stage.

    python benchmarks/room_masks_pipeline.py --category drawer --n 20 --seed 200

For objects 0..n-1 of the capture seed, the perception diagram of `nfr-drake eval-pipeline
--perceive room --object-pose estimated` (`pipeline.perception_simulator`; ten 128 px cameras
1.4-1.9 m away around a coarse look, the held-out room; nothing is fitted) photographs the object
in its room and, with the same cameras, alone before the training background, whose pixels off
that background are the true mask (the object's whole silhouette: where the arm or clutter hides
it in the room, the room's true mask would be smaller). Masks per photo: the first look
(`Segmenter.object_mask`), the single-photo second look (`Segmenter.close_look`, the crop around
the photo's own first mask) and the posed crop stage (`segmentation.crop.posed_close_look`, the
crop around the box of the pose from the first masks); for each, the mean IoU (p > 0.5) over the
photos and the pose error of `estimate_object_pose` from those masks, as the pipeline runs it
(the true masks' row for scale). Prints one line per object and the medians; `--csv` writes the
rows. `--extent-only` only measures how large the object is in the photos: the longer side of its true
mask's bounding box over the image side, and its area over the image's, per photo (median and
10th-90th percentiles).
"""

from __future__ import annotations

import datetime
import math
import os
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import tyro

from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.jsonio import write_rows_csv
from nfr_drake.perception.object_pose import ObjectPoseError, background_mask, estimate_object_pose
from nfr_drake.perception.segmentation.crop import posed_close_look
from nfr_drake.perception.segmentation.evaluation import mask_iou
from nfr_drake.perception.segmentation.model import load_segmenter
from nfr_drake.systems.pipeline import perception_photos
from nfr_drake.systems.scenario import Scenario

SETTINGS = ("true", "first", "close", "posed")
"""Masks: the true ones, the first look, the single-photo second look, the posed crop stage."""


def pose_error(masks, X_WCs, cameras, category: str, X_WO: np.ndarray) -> tuple[float, float]:
    """Position (cm) and yaw (degrees) error of the pose from `masks`; inf when none is found."""
    try:
        estimate = estimate_object_pose(masks, X_WCs, cameras, category=category)
    except ObjectPoseError:
        return math.inf, math.inf
    d = np.linalg.inv(X_WO) @ estimate.X_WO
    return 100.0 * float(np.linalg.norm(d[:2, 3])), abs(math.degrees(math.atan2(d[1, 0], d[0, 0])))


def extent(category: str, n: int, seed: int) -> None:
    """Print the object's size in the photos alone (module docstring, `--extent`)."""
    sides, areas = [], []
    for index in range(n):
        scenario = Scenario(category=category, model=f"models/{category}", seed=seed, index=index,
                            object_pose="estimated", perceive="alone")
        for image in perception_photos(scenario)[0]:
            rows, cols = np.nonzero(background_mask(image, DEFAULT_BACKGROUND_RGB) > 0.5)
            sides.append(max(np.ptp(rows), np.ptp(cols)) / max(image.shape[:2]))
            areas.append(rows.size / (image.shape[0] * image.shape[1]))
    p = lambda x: " ".join(f"{v:.2f}" for v in np.percentile(x, [50, 10, 90]))  # noqa: E731
    print(f"{category}, {n} objects of seed {seed}, {len(sides)} photos: bounding box's longer side / image "
          f"side, median p10 p90: {p(sides)}; area / image: {p(areas)}")


def main(category: str = "closet", n: int = 20, seed: int = 200, segmenter: Path = Path(Scenario.segmenter),
         csv_path: Path | None = None, extent_only: bool = False) -> None:
    if extent_only:
        extent(category, n, seed)
        return
    net, _ = load_segmenter(segmenter)
    rows = []
    for index in range(n):
        started = time.perf_counter()
        scenario = Scenario(category=category, model=f"models/{category}", seed=seed, index=index,
                            object_pose="estimated", perceive="room", segmenter=str(segmenter))
        room, X_WCs, cameras = perception_photos(scenario)
        alone, _, _ = perception_photos(replace(scenario, perceive="alone"))
        true = [background_mask(image, DEFAULT_BACKGROUND_RGB) for image in alone]
        masks = {"true": true, "first": [net.object_mask(image) for image in room],
                 "close": [net.close_look(image) for image in room],
                 "posed": posed_close_look(net, room, X_WCs, cameras, category)}
        row = {"index": index}
        for name in SETTINGS:
            row[f"iou_{name}"] = float(np.mean([mask_iou(m > 0.5, t > 0.5) for m, t in zip(masks[name], true,
                                                                                            strict=True)]))
            row[f"cm_{name}"], row[f"deg_{name}"] = pose_error(masks[name], X_WCs, cameras, category,
                                                               scenario.X_WO.GetAsMatrix4())
        rows.append(row)
        print(f"{category} {index}: " + "; ".join(
            f"{name} IoU {row[f'iou_{name}']:.2f} pose {row[f'cm_{name}']:.1f} cm "
            f"{row[f'deg_{name}']:.1f} deg"
            for name in SETTINGS) + f" ({time.perf_counter() - started:.0f} s)", flush=True)
    print(f"{category}, {len(rows)} objects of seed {seed}, medians (IoU: mean over objects):")
    for name in SETTINGS:
        iou = np.mean([r[f"iou_{name}"] for r in rows])
        cm = np.median([r[f"cm_{name}"] for r in rows])
        deg = np.median([r[f"deg_{name}"] for r in rows])
        within = sum(r[f"cm_{name}"] <= 2.0 and r[f"deg_{name}"] <= 2.0 for r in rows)
        print(f"  {name:6s} mask IoU {iou:.3f}; pose {cm:.2f} cm, {deg:.2f} deg; within 2 cm and 2 deg "
              f"{within} / {len(rows)}")
    if csv_path is not None:
        write_rows_csv(csv_path, rows)
    print(f"{datetime.date.today()}, {os.cpu_count()}-core CPU, segmenter {segmenter}")


if __name__ == "__main__":
    tyro.cli(main)
