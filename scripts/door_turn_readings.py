"""How far a door would end from its target with each reading of the fit planning its turn
(docs/SIMULATION.md, "The turn planned from two readings of the fit").

    python scripts/door_turn_readings.py --seed 901 --objects $(seq 0 59)

For each closet of `nfr-drake eval-pipeline --category closet --object-pose estimated --perceive
room --min-confidence 0` (the same scenario, `object_scenario`) it runs the pipeline once and
prints the fit's articulation, the turn from it to the target that the keypoints read (the handle
about their hinge, `handle_turns`), the one the articulation reads ((q_target - q) x
`turn_per_q`), the one planned (`planned_door_turn`: their mean) and where the door ended.
Degrees. The robot turns the door until its hand has swept the planned turn, so a door planned
with another reading would have ended by the difference elsewhere (the hand's own shortfall
kept); the summary counts the doors grasped that each reading leaves within the task's 5
degrees, with the median and 90th percentile of their end errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
import tyro

from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.systems.corrections import handle_turns, planned_door_turn
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario


@dataclass
class Args:
    seed: int = 901
    objects: list[int] = field(default_factory=lambda: list(range(60)))
    perceive: str = "room"
    model: str = "models/closet"


def main(args: Args) -> None:
    torch.set_num_threads(1)
    base = Scenario(category="closet", model=args.model, seed=args.seed, min_confidence=0.0,
                    object_pose="estimated", perceive=args.perceive)
    ends = {"keypoints": [], "articulation": [], "mean": []}
    for index in args.objects:
        outcome = run_scenario(object_scenario(base, index, part_target=True))
        task = outcome.task
        if task is None or task.simulation is None or not task.final.grasped:
            print(f"closet {index}: not grasped", flush=True)
            continue
        kt, sim = task.keypoints, task.final
        target = np.degrees(sim.q_target * kt.turn_per_q)
        readings = {"keypoints": abs(np.degrees(handle_turns(kt, np.array([sim.q_target]))[0][0])),
                    "articulation": np.degrees((sim.q_target - kt.q_current) * kt.turn_per_q)}
        planned = abs(np.degrees(planned_door_turn(kt, sim.q_target)[0]))
        readings["mean"] = planned
        end = np.degrees(sim.q_final * kt.turn_per_q)
        for name, turn in readings.items():
            ends[name].append(abs(end + turn - planned - target))
        print(f"closet {index}: fit q {np.degrees(kt.q_current * kt.turn_per_q):.1f}, turns read by the "
              f"keypoints {readings['keypoints']:.1f}, by the articulation {readings['articulation']:.1f}, "
              f"planned {planned:.1f}; ended at {end:.1f} (target {target:.1f})"
              f"{', from a second base' if task.pulled_on else ''}", flush=True)
    for name, errors in ends.items():
        errors = np.array(errors)
        print(f"{name}: {np.sum(errors <= 5.0)} of {len(errors)} grasped within 5 degrees, end error median "
              f"{np.median(errors):.2f}, p90 {np.percentile(errors, 90):.2f}")


if __name__ == "__main__":
    main(tyro.cli(Args))
