"""The posed crop stage's margin and reach against mask IoU on room datasets (choose them on `_val` sets).

    python benchmarks/crop_stage_sweep.py --data data/rooms/closet_val data/rooms/drawer_val

Per dataset and per (margin, reach) of `--margins` x `--reaches`: the mean IoU (p > 0.5) of the
masks of `segmentation.crop.posed_close_look` with those options (the first look's pose shared by
all), beside the first look's; `--rounds 2` also measures a second round (the pose again from the
crop stage's masks, and crops around its box).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import tyro

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.perception.object_pose import ObjectPoseError, estimate_object_pose
from nfr_drake.perception.segmentation.crop import view_boxes
from nfr_drake.perception.segmentation.data import RoomImages
from nfr_drake.perception.segmentation.evaluation import THRESHOLD, mask_iou
from nfr_drake.perception.segmentation.model import load_segmenter


def _ious(masks: list[np.ndarray], trues: list[np.ndarray]) -> list[float]:
    """IoU of each thresholded mask with its true one, views where the object is hidden left out."""
    return [mask_iou(m > THRESHOLD, t) for m, t in zip(masks, trues, strict=True) if t.any()]


def main(data: list[Path], model: Path = Path("models/segmenter"),
         margins: tuple[float, ...] = (0.1, 0.2, 0.3), reaches: tuple[float, ...] = (0.0, 0.25, 0.5),
         rounds: int = 1) -> None:
    net, _ = load_segmenter(model)
    for root in data:
        images = RoomImages([root])
        groups: dict[tuple[str, int], list[int]] = {}
        for i, (rec, a, _) in enumerate(images.index):
            groups.setdefault((str(rec.path), a), []).append(i)
        scores: dict[str, list[float]] = {}
        for members in groups.values():
            rec, a, _ = images.index[members[0]]
            camera = PinholeCamera.from_json(rec.meta["camera"])
            X_WCs = [rec.X_OC[a, images.index[i][2]].astype(float) for i in members]
            cameras = [camera] * len(members)
            rgbs = [images.image(i)[0] for i in members]
            trues = [images.image(i)[1] > 0 for i in members]
            category = images.category[members[0]]

            first = [net.object_mask(rgb) for rgb in rgbs]
            scores.setdefault("first", []).extend(_ious(first, trues))
            try:
                estimate = estimate_object_pose(first, X_WCs, cameras, category=category)
            except ObjectPoseError:
                estimate = None
            for margin, reach in itertools.product(margins, reaches):
                name = f"margin {margin:.2f} reach {reach:.2f}"
                if estimate is None:
                    scores.setdefault(name, []).extend(_ious(first, trues))
                    continue
                shapes = [r.shape[:2] for r in rgbs]
                boxes = view_boxes(estimate.box, X_WCs, cameras, shapes, margin, reach)
                masks = [net.close_look(rgb, b, margin=margin) for rgb, b in zip(rgbs, boxes, strict=True)]
                scores.setdefault(name, []).extend(_ious(masks, trues))
                for round_ in range(2, rounds + 1):
                    try:
                        again = estimate_object_pose(masks, X_WCs, cameras, category=category)
                    except ObjectPoseError:
                        break
                    boxes = view_boxes(again.box, X_WCs, cameras, shapes, margin, reach)
                    masks = [net.close_look(rgb, b, margin=margin)
                             for rgb, b in zip(rgbs, boxes, strict=True)]
                    scores.setdefault(f"{name}, round {round_}", []).extend(_ious(masks, trues))
        for name, values in scores.items():
            print(f"{root}: {name}: mean IoU {np.mean(values):.3f} ({len(values)} images)", flush=True)


if __name__ == "__main__":
    tyro.cli(main)
