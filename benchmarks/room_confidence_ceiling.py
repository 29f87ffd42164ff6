"""What the fit confidence would say of a fit that is exactly right, in held-out rooms.

    python benchmarks/room_confidence_ceiling.py --rooms 30 --threads 1
    python benchmarks/room_confidence_ceiling.py --rooms 30 --threads 1 --band 0   # no edge band

For the first `rooms` rooms of each held-out room set of closets and drawers (docs/ROOMS.md;
written as capture sets by `nfr_drake.eval.confidence_rooms`), two features of a perfect fit
need no fit: its silhouette is the target's true one (the room's label image), so its silhouette
IoU against the segmenter's mask (`confidence.fit_features` in a room: the edge band of the sides
the mask touches left out) is what the segmenter allows, and the handle detector either sights a
handle in 3 of the 4 views or not. With the model folder's calibration (`confidence.json`) and its
other terms at the calibration split's mean, the table gives per set the median and 10th
percentile of that worst-view IoU, the rooms with a sighting, and how many such perfect fits would
be refused: as they are, and with the sighting term held at "sighted" (what a feature independent
of the detector's background would leave).
"""

from __future__ import annotations

import datetime
import os
from pathlib import Path

import numpy as np
import tyro

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.capture import read_capture_set
from nfr_drake.eval.confidence_data import SEGMENTER
from nfr_drake.eval.confidence_rooms import room_captures
from nfr_drake.inference.confidence import EDGE_BAND, edge_band, silhouette_iou
from nfr_drake.inference.infer import FittedModel, object_masks
from nfr_drake.perception.handle_triangulation import locate_handle


def perfect_fit(fitted: FittedModel, capture_dir: Path, band: float = EDGE_BAND) -> dict:
    """The room-dependent features of a perfect fit to a room capture (module docstring), the
    silhouettes compared outside the edge band `band` (0: everywhere)."""
    capture = read_capture_set(capture_dir)
    images = capture.load_images()
    labels = np.load(Path(capture.gt["room"]) / "label.npy")[0]
    ious, border = [], []
    for label, prob in zip(labels, object_masks(images, SEGMENTER), strict=True):
        mask = prob > 0.5
        if (label > 0).any():  # a view where the object is wholly hidden has no silhouette
            ious.append(silhouette_iou((label > 0).reshape(-1), mask.reshape(-1),
                                       ~edge_band(mask, band).reshape(-1) if band else
                                       np.ones(mask.size, bool)))
        border.append(np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]]).mean())
    seen = locate_handle(fitted.handle_detector.detect(images), capture.frames)
    return {"silhouette_iou_worst_view": min(ious), "edge_contact": max(border),
            "sighting_missing": float(seen is None), "views": float(len(images))}


def main(rooms: int = 30, rooms_data: Path = Path("data/rooms"), out: Path = Path("data/eval/rooms"),
         threads: int | None = 1, band: float = EDGE_BAND) -> None:
    set_torch_threads(threads)
    print("| set | rooms | worst-view IoU, median (p10) | sighted | perfect fits refused | "
          "refused, sighting term held at sighted |\n|---|---|---|---|---|---|")
    for category in ("closet", "drawer"):
        fitted = FittedModel(Path(f"models/{category}"))
        model = fitted.confidence
        mean = dict(zip([n for n, _ in model.terms], model.mean, strict=True))
        typical = {"image_loss_worst_view": 10 ** mean["image_loss_worst_view"],
                   "code_distance": mean["code_distance"],
                   "sighting_gap_m": (10 ** mean["sighting_gap_m"] - 0.5) / 100.0}
        for name, captures in room_captures(rooms_data, out, category, rooms).items():
            rows = [typical | perfect_fit(fitted, c, band) for c in captures]
            iou = np.array([r["silhouette_iou_worst_view"] for r in rows])
            refused = [model.probability(r) < model.threshold for r in rows]
            sighted = [model.probability(r | {"sighting_missing": 0.0}) < model.threshold for r in rows]
            seen = sum(r["sighting_missing"] == 0.0 for r in rows)
            print(f"| {name} | {len(rows)} | {np.median(iou):.2f} ({np.percentile(iou, 10):.2f}) | "
                  f"{seen} | {sum(refused)} | {sum(sighted)} |")
    print(f"\n{datetime.date.today()}, {os.cpu_count()}-core CPU; calibration: models/C/confidence.json "
          f"(threshold {model.threshold:.2f}); segmenter {SEGMENTER}; edge band {band}")


if __name__ == "__main__":
    tyro.cli(main)
