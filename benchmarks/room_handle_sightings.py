"""The handle detector's triangulated handle on the pipeline's room photos: whole, or inside the object.

    python benchmarks/room_handle_sightings.py --category drawer --seed 901 --objects $(seq 0 39)
    python benchmarks/room_handle_sightings.py --category closet --seed 901 --objects $(seq 0 29) \
        --csv-path runs/room_sightings_closet.csv

For each object of the seed, shut, the perception cameras of `nfr-drake eval-pipeline --perceive
room --object-pose estimated` photograph it in its held-out room (`pipeline.perception_photos`);
the pipeline's look (`segmentation.crop.room_looks`: the segmenter's masks and the pose estimate)
paints the photos each way the room fit does (`infer.paint_off_object`, every painting of
`PAINTINGS`), and the model's handle detector runs on each painted set. The handle is triangulated
(`locate_handle`) from its maps over the whole photo (before), kept well inside the segmenter's
masks, and kept well inside the pixels the painted photo keeps (`inside_masks`, what `infer` does
on painted room photos), side by side. Per painting and way:
objects with a sighting, the distance from the sighting to the true handle (median, p90), and how
many are within 2 cm and more than 5 cm off. Nothing is fitted.
"""

from __future__ import annotations

import datetime
import math
import platform
from pathlib import Path

import numpy as np
import torch
import tyro

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import CaptureFrame
from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.inference.infer import PAINTINGS, paint_off_object
from nfr_drake.jsonio import write_rows_csv
from nfr_drake.perception.handle_detector.model import DETECTOR_DIR, load_detector
from nfr_drake.perception.handle_triangulation import inside_masks, locate_handle
from nfr_drake.perception.object_pose import ObjectPoseError
from nfr_drake.perception.segmentation.crop import room_looks
from nfr_drake.perception.segmentation.model import load_segmenter
from nfr_drake.systems.pipeline import perception_photos
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.keypoints import KeypointTrajectory

WAYS = ("whole photo", "inside the masks", "inside the kept pixels")


def main(category: str = "drawer", seed: int = 901, objects: tuple[int, ...] = tuple(range(20)),
         segmenter: Path = Path(Scenario.segmenter), csv_path: Path | None = None) -> None:
    """`objects`: indices of the seed's objects (shut, in their held-out rooms)."""
    torch.set_num_threads(1)
    base = Scenario(category=category, model=f"models/{category}", seed=seed, object_pose="estimated",
                    perceive="room", segmenter=str(segmenter))
    net, _ = load_segmenter(segmenter)
    detector, _ = load_detector(Path(base.model) / DETECTOR_DIR)
    rows, no_pose = [], []
    for index in objects:
        scenario = object_scenario(base, index)
        images, X_WCs, cameras = perception_photos(scenario)
        try:
            looks = room_looks(net, images, X_WCs, cameras, category)
        except ObjectPoseError:
            no_pose.append(index)
            continue
        truth = KeypointTrajectory.from_articulated_object(scenario.sample_object(), scenario.X_WO,
                                                           scenario.q_start)
        handle_W = truth.point("handle", truth.q_current)
        frames = frames_in_world(X_WCs, cameras)
        for painting in PAINTINGS:
            painted, kept = paint_off_object(images, looks.masks, X_WCs, cameras, looks.estimate.X_WO,
                                             looks.estimate.size, painting=painting)
            maps = detector.detect(painted)
            for way, used in zip(WAYS, (maps, inside_masks(maps, looks.masks), inside_masks(maps, kept)),
                                 strict=True):
                found = locate_handle(used, frames)
                error = math.nan if found is None else 100.0 * float(np.linalg.norm(found.p_O - handle_W))
                rows.append({"index": index, "painting": painting, "way": way, "error_cm": error})
        errors = [f"{r['painting']} {r['way']} {r['error_cm']:.1f} cm" for r in rows if r["index"] == index]
        print(f"{category} {index}: " + ", ".join(errors), flush=True)
    print(f"\n{datetime.date.today()}, {platform.machine()}, {category}, seed {seed}, {len(objects)} objects "
          f"(no pose: {no_pose or 'none'}), segmenter {segmenter}, detector {base.model}/{DETECTOR_DIR}")
    print("| painting | detector's maps | sighted | error median (cm) | p90 | within 2 cm | over 5 cm |")
    print("|---|---|---|---|---|---|---|")
    for painting in PAINTINGS:
        for way in WAYS:
            errors = np.array([r["error_cm"] for r in rows if r["painting"] == painting and r["way"] == way])
            seen = errors[~np.isnan(errors)]
            median, p90 = (np.median(seen), np.percentile(seen, 90)) if seen.size else (math.nan, math.nan)
            print(f"| {painting} | {way} | {seen.size} / {errors.size} | {median:.2f} | {p90:.2f} "
                  f"| {int((seen < 2).sum())} | {int((seen > 5).sum())} |")
    if csv_path is not None:
        write_rows_csv(csv_path, rows)


def frames_in_world(X_WCs: list[np.ndarray], cameras: list[PinholeCamera]) -> list[CaptureFrame]:
    """The cameras (X_WC (4, 4)) as capture frames whose O is W: triangulated points come out in W."""
    return [CaptureFrame(Path(f"camera_{i}"), X_WC, camera)
            for i, (X_WC, camera) in enumerate(zip(X_WCs, cameras, strict=True))]


if __name__ == "__main__":
    tyro.cli(main)
