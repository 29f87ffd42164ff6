"""The object's pose in the pipeline's room photos: whole photos (the crop stage) against the aimed
look where the whole photos' pose is off the cameras' aim, and always, side by side on the same photos.

    python benchmarks/aimed_look.py --category drawer --objects $(seq 0 99)

For each unseen object of `nfr-drake eval-pipeline --perceive room --object-pose estimated` (seed
`seed`; `pipeline.perception_photos`, nothing fitted) the pose is estimated twice from the
shipped segmenter's masks by `segmentation.crop.room_looks`, as the perception system looks:
- whole photos (`aimed_look` "never"): the crop stage as it ran before the aimed look (the
  carcass's amodal masks looked at again around the box the whole photos give,
  `posed_carcass_look`, the visible masks likewise, `posed_close_look`;
  `estimate_object_pose_carcass_first`; the first look's masks when those give no pose);
- off-aim (the default): the whole photos' pose where its floor box holds the cameras' aim point
  (`aimed_at`), else, or where they give none, the aimed look's (`aimed_looks`: the carcass in the
  crop around where the cameras aim) if it gives one;
- always: the aimed look's, the whole photos' where it gives no pose.
Prints one line per object (position cm, yaw deg, seconds of each) and, per method, the median
errors, how many within 2 cm and 2 degrees, how many more than 10 cm off, and the median time.
This is the estimate before the fitted field refines it (`pose_refine`); the pipeline's CSV
reports the pose after that.
"""

from __future__ import annotations

import datetime
import os
import time
from pathlib import Path

import numpy as np
import tyro

from nfr_drake.perception.object_pose import ObjectPoseError, ObjectPoseEstimate
from nfr_drake.perception.segmentation.crop import room_looks
from nfr_drake.perception.segmentation.model import Segmenter, load_segmenter
from nfr_drake.systems.pipeline import perception_photos
from nfr_drake.systems.scenario import Scenario


def looked(aimed_look: str):
    """The pose `room_looks` gives with that `aimed_look`, None where none."""
    def pose(net: Segmenter, images, X_WCs, cameras, category: str) -> ObjectPoseEstimate | None:
        try:
            return room_looks(net, images, X_WCs, cameras, category, aimed_look=aimed_look).estimate
        except ObjectPoseError:
            return None
    return pose


def pose_error(estimate: ObjectPoseEstimate | None, X_WO: np.ndarray) -> tuple[float, float]:
    """(position error cm in the floor plane, yaw error degrees); inf without a pose."""
    if estimate is None:
        return float("inf"), float("inf")
    yaw = np.arctan2(estimate.X_WO[1, 0], estimate.X_WO[0, 0]) - np.arctan2(X_WO[1, 0], X_WO[0, 0])
    return (float(100.0 * np.linalg.norm(estimate.X_WO[:2, 3] - X_WO[:2, 3])),
            float(abs(np.degrees((yaw + np.pi) % (2 * np.pi) - np.pi))))


METHODS = {"whole photos": looked("never"), "off-aim": looked("off-aim"), "always": looked("always")}


def main(category: str = "drawer", objects: tuple[int, ...] = tuple(range(20)), seed: int = 200,
         segmenter: Path = Path(Scenario.segmenter)) -> None:
    net, _ = load_segmenter(segmenter)
    errors = {name: [] for name in METHODS}
    seconds = {name: [] for name in METHODS}
    for index in objects:
        scenario = Scenario(category=category, model=f"models/{category}", seed=seed, index=index,
                            object_pose="estimated", perceive="room", segmenter=str(segmenter))
        images, X_WCs, cameras = perception_photos(scenario)
        line = [f"{category} {index:3d}"]
        for name, method in METHODS.items():
            started = time.perf_counter()
            estimate = method(net, images, X_WCs, cameras, category)
            seconds[name].append(time.perf_counter() - started)
            errors[name].append(pose_error(estimate, scenario.X_WO.GetAsMatrix4()))
            line.append(f"{name}: {errors[name][-1][0]:6.1f} cm {errors[name][-1][1]:5.1f} deg "
                        f"{seconds[name][-1]:4.1f} s")
        print("  ".join(line), flush=True)
    print(f"\n{category}, seed {seed}, {len(objects)} objects, segmenter {segmenter}; "
          f"{datetime.date.today()}, {os.cpu_count()} CPUs")
    print("| method | position, median (cm) | yaw, median (deg) | within 2 cm and 2 deg "
          "| more than 10 cm off | seconds, median |")
    print("|---|---|---|---|---|---|")
    for name in METHODS:
        e = np.array(errors[name])
        within = int(np.sum((e[:, 0] <= 2.0) & (e[:, 1] <= 2.0)))
        far = [i for i, d in zip(objects, e[:, 0], strict=True) if d > 10.0]
        print(f"| {name} | {np.median(e[:, 0]):.2f} | {np.median(e[:, 1]):.2f} | {within} / {len(e)} | "
              f"{len(far)} ({' '.join(map(str, far))}) | {np.median(seconds[name]):.1f} |")


if __name__ == "__main__":
    tyro.cli(main)
