"""The place's search over bases and fallback configs, with and without skipping the bases no
fallback can mend, side by side.

    python benchmarks/place_fallbacks.py --closets 26 35 --q-door 0.6

Closet i of capture seed 200 with its door at `q_door`, the true compartment as obstacles
(`true_compartment`, `door_band`) and its scenario's item: the place from the bases in front of it
as `_place_in_front` searches them (each fallback config on every base, a base skipped once it
raised `PlaceUnreachable`), and the same search without the skip (every config on every base, the
search before that skip). Prints per closet each search's outcome (planned: the item's planned
distance from the goal and the plan's duration; else the failure's first words), whether the two
agree (the same plan, or no plan), and each one's planning time.
"""

from __future__ import annotations

import datetime
import platform
import time

import tyro

from nfr_drake.planning.place import (
    GRASP_OF,
    PlaceConfig,
    PlacePlan,
    fallback_configs,
    place_bases,
    place_problem,
    plan_place,
    ready_posture,
)
from nfr_drake.planning.planner import PlanningError
from nfr_drake.systems.place_task import (
    ITEM_REACH,
    _place_in_front,
    door_band,
    table_beside,
    true_compartment,
)
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.keypoints import KeypointTrajectory


def every_base(kt: KeypointTrajectory, q: float, item, obstacles, cfg: PlaceConfig
               ) -> tuple[PlacePlan, object]:
    """The place and its table from the bases in front, every fallback config on every base (no
    skip)."""
    boxes = [*obstacles[0], *obstacles[1]]
    errors = []
    for c in fallback_configs(cfg):
        for X_WB in place_bases(kt, q, boxes):
            try:
                table, X_WI = table_beside(X_WB, boxes, ITEM_REACH[GRASP_OF[kt.category]])
                problem = place_problem(kt, q, item, X_WI, table, obstacles, c, X_WB.translation())
                return plan_place(X_WB, ready_posture(X_WB, X_WI.translation()), problem, c), table
            except PlanningError as err:
                errors.append(str(err))
    raise PlanningError("; ".join(dict.fromkeys(errors)))


def outcome(search, *args) -> tuple[str, float]:
    """What `search(*args)` gave (its plan's place error and duration, or "no plan" and its
    failure's first words) and its seconds."""
    t0 = time.perf_counter()
    try:
        plan, _ = search(*args)
        told = f"planned: item {100 * plan.place_error():.2f} cm from the goal, {plan.duration:.2f} s long"
    except PlanningError as err:
        told = f"no plan ({str(err)[:60]}...)"
    return told, time.perf_counter() - t0


def main(closets: tuple[int, ...] = (26, 35), q_door: float = 0.6, seed: int = 200) -> None:
    for index in closets:
        scenario = Scenario(category="closet", seed=seed, index=index, q_target=q_door)
        obj, _ = scenario.sample_piece()
        item = scenario.sample_item()
        kt = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, 0.0)
        obstacles = door_band(lambda q, obj=obj, X=scenario.X_WO: true_compartment(obj, X, q), q_door)
        cfg = PlaceConfig()
        skipping, t_skip = outcome(_place_in_front, kt, q_door, item, obstacles, cfg)
        every, t_every = outcome(every_base, kt, q_door, item, obstacles, cfg)
        print(f"closet {index}: skipping {skipping}, {t_skip:.0f} s | every base {every}, {t_every:.0f} s "
              f"| same outcome {skipping.split(' (')[0] == every.split(' (')[0]}", flush=True)
    print(f"{datetime.date.today()}, {platform.machine()} CPU, door at q {q_door}, capture seed {seed}")


if __name__ == "__main__":
    tyro.cli(main)
