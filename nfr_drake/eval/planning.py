"""Planning with ground-truth keypoints over sampled objects: success rate and planning time.

A piece of furniture is opened at one part (door or drawer) drawn from its own random stream after
the piece, the other parts shut; closets and drawers have one part.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform

from nfr_drake.errors import NfrDrakeError
from nfr_drake.planning.planner import PlannerConfig, grasp_planner
from nfr_drake.systems.articulation import SimulationConfig
from nfr_drake.systems.scene_objects import sampled_part
from nfr_drake.systems.task import OPEN_TARGET, run_task

FIELDS = ("category", "seed", "index", "kind", "part", "part_type", "handle_height", "width", "height",
          "q_target", "planned", "success", "base_height", "planning_seconds", "planning_cpu_seconds",
          "q_final", "joint_error", "max_drift", "max_constraint_force", "error")


@dataclass(frozen=True)
class PlanningEvalConfig:
    """Which objects: `count` per category, object i drawn from object_rng(SEED_DOMAIN_TRAIN, seed, i),
    each opened from q = 0 to its target (the closet target for doors, the drawer target for
    drawers, furniture included)."""

    count: int = 50
    seed: int = 7
    categories: tuple[str, ...] = ("closet", "drawer")
    closet_target: float = OPEN_TARGET["closet"]
    drawer_target: float = OPEN_TARGET["drawer"]
    grasp: str = "constraint"
    """The simulated grasp, "constraint" or "contact" (`SimulationConfig.grasp`; the planner
    follows it, `grasp_planner`); one CSV per grasp."""


def evaluate_one(category: str, seed: int, index: int, targets: dict[str, float],
                 grasp: str = "constraint") -> dict:
    """Open one sampled object (a random part of it) from q = 0 to the target of its part's joint
    (`targets` by SceneObject category, "closet" or "drawer") with the simulated `grasp`; one CSV
    row."""
    obj, part, scene_object = sampled_part(category, seed, index, RigidTransform())
    q_target = targets[scene_object.category]
    outcome = run_task(scene_object, q_target, planner_config=grasp_planner(PlannerConfig(), grasp),
                       simulation_config=SimulationConfig(grasp=grasp))
    sim = outcome.final
    return dict(category=category, seed=seed, index=index, kind=obj.params.get("kind", category),
                part=part, part_type=obj.front(part).kind,
                handle_height=round(float(scene_object.ground_truth.point("handle", 0.0)[2]), 4),
                width=round(obj.params["width"], 4), height=round(obj.params["height"], 4),
                q_target=q_target, planned=outcome.plan is not None, success=outcome.success,
                base_height=round(float(outcome.plan.X_WB.translation()[2]), 3) if outcome.plan else "",
                planning_seconds=round(outcome.planning_seconds, 3),
                planning_cpu_seconds=round(outcome.plan.seconds["cpu"], 3) if outcome.plan else "",
                q_final=round(sim.q_final, 4) if sim else "",
                joint_error=round(sim.joint_error, 4) if sim else "",
                max_drift=round(sim.max_drift, 4) if sim else "",
                max_constraint_force=round(sim.max_constraint_force, 1) if sim else "",
                error=outcome.planning_error[:300])


def evaluate_planning(config: PlanningEvalConfig, csv_path: Path) -> list[dict]:
    """Run (or resume: rows already in `csv_path` are kept) and return all rows.

    A CSV written with other columns (an older version of this evaluation) is refused."""
    csv_path = Path(csv_path)
    rows = []
    if csv_path.is_file():
        with csv_path.open() as f:
            reader = csv.DictReader(f)
            rows = list(reader)
            if rows and tuple(reader.fieldnames or ()) != FIELDS:
                raise NfrDrakeError(f"{csv_path} has the columns {reader.fieldnames}, not {list(FIELDS)}; "
                                    "give another --csv")
    done = {(r["category"], int(r["seed"]), int(r["index"])) for r in rows}
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with csv_path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        if not rows:
            writer.writeheader()
        for category in config.categories:
            for i in range(config.count):
                if (category, config.seed, i) in done:
                    continue
                targets = {"closet": config.closet_target, "drawer": config.drawer_target}
                row = evaluate_one(category, config.seed, i, targets, config.grasp)
                writer.writerow(row)
                f.flush()
                rows.append({k: str(v) for k, v in row.items()})
    return rows


def summarise(rows: list[dict], by: str = "category") -> dict[str, dict[str, float]]:
    """Per value of the column `by` (e.g. "category", "kind", "part_type") and overall: count,
    success rate, planned rate, median and p90 planning wall time, median planning CPU time."""
    out = {}
    for name in sorted({r[by] for r in rows}) + ["all"]:
        sel = [r for r in rows if name == "all" or r[by] == name]
        planned = [float(r["planning_seconds"]) for r in sel if r["planned"] == "True"]
        cpu = [float(r["planning_cpu_seconds"]) for r in sel if r["planned"] == "True"]
        out[name] = dict(count=len(sel), success=np.mean([r["success"] == "True" for r in sel]),
                         planned=np.mean([r["planned"] == "True" for r in sel]),
                         median_s=float(np.median(planned)) if planned else float("nan"),
                         p90_s=float(np.percentile(planned, 90)) if planned else float("nan"),
                         median_cpu_s=float(np.median(cpu)) if cpu else float("nan"))
    return out
