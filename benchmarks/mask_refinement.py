"""The pixels a painted room photo keeps, with and without the masks refined by the photo's colours.

    python benchmarks/mask_refinement.py --category closet --n 20 --seed 901

For objects 0..n-1 of the capture seed, the perception cameras of `nfr-drake eval-pipeline
--perceive room --object-pose estimated` (`pipeline.perception_photos_and_depths`: ten 128 px
photos of the object in its held-out room) and the same cameras on the object alone before the
training background; the true mask is the object's visible silhouette
(`pipeline.visible_silhouettes`: its pixels off that background where the room's depth agrees
with its own, not hidden by the arm or clutter). The pipeline's masks and pose
(`segmentation.crop.room_looks`) give, per painting of `infer.painting_thresholds` ("region",
"fronts", "sure"), the pixels the painted photo keeps, from the segmenter's masks as they are and
refined (`segmentation.refine.refine_masks`). Per photo: IoU of the kept pixels with the true
mask, spill (kept pixels off it, over its area) and missed (its pixels not kept, over its area).
Prints medians and means over the photos (spill's mean is dominated by the few photos where the
mask runs onto a neighbour) and the refinement's time per photo; `--csv-path` writes one row per
photo, painting and method. `--figure`: a PNG of the objects `--figure-objects`, views
`--figure-views`, one row per view: the photo, then the photo painted in the training background
off the kept pixels of the "region" painting from the segmenter's masks and from the refined ones,
the visible silhouette outlined in green.
"""

from __future__ import annotations

import datetime
import os
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import tyro

from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.visualize import image_grid
from nfr_drake.inference.infer import PAINTINGS, painting_thresholds
from nfr_drake.jsonio import write_rows_csv
from nfr_drake.perception.object_pose import ObjectPoseError
from nfr_drake.perception.segmentation.crop import room_looks
from nfr_drake.perception.segmentation.model import load_segmenter
from nfr_drake.perception.segmentation.refine import refine_masks
from nfr_drake.systems.pipeline import perception_photos_and_depths, visible_silhouettes
from nfr_drake.systems.scenario import Scenario

METHODS = ("segmenter", "refined")


def kept_stats(kept: np.ndarray, true: np.ndarray) -> tuple[float, float, float]:
    """IoU of the kept pixels (H, W) bool with the true mask (H, W) bool, and the spill and the
    missed pixels over the true mask's area."""
    area = max(int(true.sum()), 1)
    return (float((kept & true).sum() / max(int((kept | true).sum()), 1)),
            float((kept & ~true).sum() / area), float((true & ~kept).sum() / area))


def outlined(image: np.ndarray, kept: np.ndarray | None, true: np.ndarray) -> np.ndarray:
    """The photo (H, W, 3) painted in the training background off `kept` (H, W) bool (None: as it
    is), the true mask (H, W) bool outlined in green."""
    out = image.copy()
    if kept is not None:
        out[~kept] = np.round(255 * np.asarray(DEFAULT_BACKGROUND_RGB)).astype(np.uint8)
    contours, _ = cv2.findContours(true.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return cv2.drawContours(out, contours, -1, (0, 255, 0), 1)


def main(category: str = "closet", n: int = 20, seed: int = 901, segmenter: Path = Path(Scenario.segmenter),
         csv_path: Path | None = None, figure: Path | None = None, figure_objects: tuple[int, ...] = (0,),
         figure_views: tuple[int, ...] = (0, 3, 6, 9)) -> None:
    net, _ = load_segmenter(segmenter)
    rows, seconds, panels = [], [], []
    for index in range(n):
        scenario = Scenario(category=category, model=f"models/{category}", seed=seed, index=index,
                            object_pose="estimated", perceive="room", segmenter=str(segmenter))
        room, room_depths, X_WCs, cameras = perception_photos_and_depths(scenario)
        alone, alone_depths, _, _ = perception_photos_and_depths(replace(scenario, perceive="alone"))
        true = visible_silhouettes(alone, alone_depths, room_depths)
        try:
            looks = room_looks(net, room, X_WCs, cameras, category)
        except ObjectPoseError:
            print(f"{category} {index}: no pose, left out", flush=True)
            continue
        started = time.perf_counter()
        masks = {"segmenter": looks.masks, "refined": refine_masks(room, looks.masks)}
        seconds.append((time.perf_counter() - started) / len(room))
        shapes = [image.shape[:2] for image in room]
        for painting in PAINTINGS:
            thresholds = painting_thresholds(painting, X_WCs, cameras, shapes, looks.estimate.X_WO,
                                             looks.estimate.size)
            if painting == "region" and index in figure_objects:
                panels += [[outlined(room[v], None, true[v]),
                            *(outlined(room[v], masks[m][v] > thresholds[v], true[v]) for m in METHODS)]
                           for v in figure_views]
            for method in METHODS:
                for view, (m, t, truth) in enumerate(zip(masks[method], thresholds, true, strict=True)):
                    if truth.any():
                        iou, spill, missed = kept_stats(m > t, truth)
                        rows.append({"index": index, "view": view, "painting": painting, "method": method,
                                     "iou": iou, "spill": spill, "missed": missed})
        region = {method: [r["iou"] for r in rows
                           if (r["index"], r["painting"], r["method"]) == (index, "region", method)]
                  for method in METHODS}
        print(f"{category} {index}: kept pixels' IoU, region painting, median over the views: "
              + ", ".join(f"{method} {np.median(ious):.3f}" for method, ious in region.items()), flush=True)
    print(f"{category}, objects 0-{n - 1} of seed {seed}, kept pixels against the true mask, per photo:")
    for painting in PAINTINGS:
        for method in METHODS:
            sub = [r for r in rows if r["painting"] == painting and r["method"] == method]
            stat = {k: np.array([r[k] for r in sub]) for k in ("iou", "spill", "missed")}
            print(f"  {painting:6s} {method:9s} IoU median {np.median(stat['iou']):.3f} mean "
                  f"{stat['iou'].mean():.3f}; spill median {np.median(stat['spill']):.3f} mean "
                  f"{stat['spill'].mean():.3f}; missed median {np.median(stat['missed']):.3f} mean "
                  f"{stat['missed'].mean():.3f} ({len(sub)} photos)")
    print(f"refinement: {1000 * np.median(seconds):.0f} ms per photo (median)")
    if csv_path is not None:
        write_rows_csv(csv_path, rows)
    if figure is not None and panels:
        figure.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(figure), image_grid(panels, scale=2)[..., ::-1])
    print(f"{datetime.date.today()}, {os.cpu_count()}-core CPU, segmenter {segmenter}")


if __name__ == "__main__":
    tyro.cli(main)
