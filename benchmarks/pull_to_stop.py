"""The guarded pull to a drawer's stop (`SimulationConfig.guarded_pull`) against none, on the same fit
and plan: each drawer goes through the pipeline once (`run_scenario`, the guarded pull on) and its
plan is simulated again without the guarded pull, so the two outcomes differ by the pull alone.

    python benchmarks/pull_to_stop.py --seed 200 --objects $(seq 0 39) --perceive room \
        --csv-path out/pull_to_stop_room.csv
    python benchmarks/pull_to_stop.py --seed 200 --objects $(seq 0 39) --perceive alone \
        --csv-path out/pull_to_stop_alone.csv

Both with the estimated pose and the fast fit, as `eval-pipeline` runs them in docs/ROOMS.md (in a
room never refused, alone the model's calibrated threshold). Resumable (indices already in the CSV
are skipped). Prints, for each setting, the successes and the largest force on the drawer.
"""

from __future__ import annotations

import csv
import math
from dataclasses import replace
from pathlib import Path
from typing import Literal

import numpy as np
import tyro

from nfr_drake.cpu import set_torch_threads
from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.inference.fit import FitConfig
from nfr_drake.systems.articulation import simulate_articulation
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario
from nfr_drake.systems.scene_objects import SceneObject

FIELDS = ("index", "q_estimate", "handle_path_rmse_cm", "refused", "planned", "grasped",
          "success_guarded", "q_final_guarded", "force_guarded_n", "pulled_past_cm",
          "success_none", "q_final_none", "force_none_n")


def _row(scenario: Scenario) -> dict:
    """One drawer: the pipeline with the guarded pull, then its plan simulated without it."""
    outcome = run_scenario(scenario)
    task = outcome.task
    row = dict(index=scenario.index, q_estimate=outcome.q_estimate,
               handle_path_rmse_cm=outcome.handle_path_rmse_cm, refused=task is None,
               planned=task is not None and task.plan is not None,
               grasped=bool(task and task.simulation and task.simulation.grasped))
    if not row["planned"]:
        return row
    guarded = task.simulation
    obj, part = scenario.sample_piece()
    scene_object = SceneObject.from_articulated_object(obj, scenario.X_WO, scenario.q_start, part)
    none = simulate_articulation(scene_object, task.plan, scenario.q_target, None,
                                 replace(scenario.simulation, grasp=scenario.grasp, guarded_pull=0.0))
    return row | dict(success_guarded=guarded.success, q_final_guarded=guarded.q_final,
                      force_guarded_n=guarded.max_constraint_force, pulled_past_cm=100 * guarded.pulled_past,
                      success_none=none.success, q_final_none=none.q_final,
                      force_none_n=none.max_constraint_force)


def main(objects: tuple[int, ...], csv_path: Path, seed: int = 200,
         perceive: Literal["alone", "room"] = "room", threads: int = 1) -> None:
    """Run the drawers `objects` of capture seed `seed` (resuming from `csv_path`) and print a summary."""
    set_torch_threads(threads)
    base = Scenario(category="drawer", model="models/drawer", seed=seed, q_target=1.0,
                    fit=FitConfig(preset="fast"), min_confidence=0.0 if perceive == "room" else -1.0,
                    object_pose="estimated", perceive=perceive)
    done = {int(r["index"]) for r in csv.DictReader(open(csv_path))} if csv_path.is_file() else set()
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with open(csv_path, "a", newline="") as f:
        writer = csv.DictWriter(f, FIELDS)
        if not done:
            writer.writeheader()
        for index in [i for i in objects if i not in done]:
            writer.writerow(_row(object_scenario(base, index, True)))
            f.flush()
    rows = list(csv.DictReader(open(csv_path)))
    for name in ("guarded", "none"):
        wins = sum(r[f"success_{name}"] == "True" for r in rows)
        forces = [float(r[f"force_{name}_n"]) for r in rows if r["grasped"] == "True"]
        print(f"{name}: {wins} / {len(rows)} opened; largest force on the drawer (grasped): median "
              f"{np.median(forces) if forces else math.nan:.1f} N, max {max(forces, default=math.nan):.1f} N")


if __name__ == "__main__":
    tyro.cli(main)
