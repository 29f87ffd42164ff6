"""Obstacle count and planning time with a piece's geometry merged into few boxes or one box per part.

    python benchmarks/furniture_obstacles.py --count 100 --plan-count 10

Piece i of object_rng(SEED_DOMAIN_TRAIN, seed, i), a random part of it (as benchmarks/planning_eval.py
draws it): the boxes of `object_obstacles` (what the planner gets) and of one box per part, over
`count` pieces; the first `plan_count` are planned from shut to their open target with
ground-truth keypoints (no simulation) once with each.
"""

from __future__ import annotations

import datetime
import os
import time

import numpy as np
import tyro
from pydrake.math import RigidTransform

from nfr_drake.planning.planner import PlanningError, plan_articulation
from nfr_drake.systems.scene_objects import sampled_part
from nfr_drake.systems.task import OPEN_TARGET
from nfr_drake.world.obstacles import object_obstacles


def main(count: int = 100, plan_count: int = 10, seed: int = 7) -> None:
    """Print one line per planned piece and two tables: boxes, and planning wall time (s)."""
    boxes = {True: [], False: []}
    plans = {True: [], False: []}
    for i in range(count):
        obj, part, scene_object = sampled_part("furniture", seed, i, RigidTransform())
        line = f"{i:3d} {obj.params['kind']:13s} part {part} {obj.front(part).kind:6s}"
        for merge in (True, False):
            obstacles = object_obstacles(obj, RigidTransform(), 0.0, moving=part, merge=merge)
            boxes[merge].append(len(obstacles))
            if i >= plan_count:
                continue
            t0 = time.perf_counter()
            try:
                plan_articulation(scene_object.ground_truth, OPEN_TARGET[scene_object.category],
                                  obstacles=obstacles)
                planned = True
            except PlanningError:
                planned = False
            seconds = time.perf_counter() - t0
            plans[merge].append((seconds, planned))
            name = "merged" if merge else "per part"
            line += f" | {name}: {len(obstacles):3d} boxes {seconds:6.2f} s {planned}"
        if i < plan_count:
            print(line, flush=True)
    print(f"command: python benchmarks/furniture_obstacles.py --count {count} --plan-count {plan_count} "
          f"--seed {seed}")
    print(f"date: {datetime.date.today()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}")
    print(f"| obstacles | boxes over {count} pieces, median (min-max) | planning s over {plan_count}, "
          "median (max) | planned |")
    print("|---|---|---|---|")
    for merge in (True, False):
        b = np.array(boxes[merge])
        seconds, planned = (np.array(v) for v in zip(*plans[merge], strict=True)) if plans[merge] \
            else (np.full(1, np.nan), np.zeros(0))
        print(f"| {'merged' if merge else 'one per part'} | {np.median(b):.0f} ({b.min()}-{b.max()}) | "
              f"{np.median(seconds):.2f} ({seconds.max():.2f}) | {int(planned.sum())} / {len(planned)} |")


if __name__ == "__main__":
    tyro.cli(main)
