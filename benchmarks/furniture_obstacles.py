"""Planning time and obstacle count with a piece's geometry merged into few boxes or one box per part.

    python benchmarks/furniture_obstacles.py --count 10

Piece i of object_rng(SEED_DOMAIN_TRAIN, seed, i), a random part of it (as benchmarks/planning_eval.py
draws it), planned from shut to its open target with ground-truth keypoints (no simulation), once
with `object_obstacles(merge=True)` (what the planner gets) and once with one box per part.
"""

from __future__ import annotations

import datetime
import os
import time

import numpy as np
import tyro
from pydrake.math import RigidTransform

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.planner import PlanningError, plan_articulation
from nfr_drake.systems.scene_objects import SceneObject, random_part
from nfr_drake.systems.task import OPEN_TARGET
from nfr_drake.world.obstacles import object_obstacles


def main(count: int = 10, seed: int = 7) -> None:
    """Print one line per piece and a summary: boxes, planning wall time (s), planned or not."""
    results = {True: [], False: []}
    for i in range(count):
        rng = object_rng(SEED_DOMAIN_TRAIN, seed, i)
        obj = sample_object("furniture", rng)
        part = random_part(obj, rng)
        scene_object = SceneObject.from_articulated_object(obj, RigidTransform(), 0.0, part=part)
        line = f"{i:3d} {obj.params['kind']:13s} part {part} {obj.front(part).kind:6s}"
        for merge in (True, False):
            boxes = object_obstacles(obj, RigidTransform(), 0.0, moving=part, merge=merge)
            t0 = time.perf_counter()
            try:
                plan_articulation(scene_object.ground_truth, OPEN_TARGET[scene_object.category],
                                  obstacles=boxes)
                planned = True
            except PlanningError:
                planned = False
            seconds = time.perf_counter() - t0
            results[merge].append((len(boxes), seconds, planned))
            name = "merged" if merge else "per part"
            line += f" | {name}: {len(boxes):3d} boxes {seconds:6.2f} s {planned}"
        print(line, flush=True)
    print(f"command: python benchmarks/furniture_obstacles.py --count {count} --seed {seed}")
    print(f"date: {datetime.date.today()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    print("| obstacles | boxes, median (max) | planning s, median (max) | planned |")
    print("|---|---|---|---|")
    for merge in (True, False):
        boxes, seconds, planned = (np.array(v) for v in zip(*results[merge], strict=True))
        print(f"| {'merged' if merge else 'one per part'} | {np.median(boxes):.0f} ({boxes.max()}) | "
              f"{np.median(seconds):.2f} ({seconds.max():.2f}) | {int(planned.sum())} / {len(planned)} |")


if __name__ == "__main__":
    tyro.cli(main)
