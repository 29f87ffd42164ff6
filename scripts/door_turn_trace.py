"""Where a door's turn after the planned pull comes from, on the pipeline's own runs
(docs/SIMULATION.md, "Turning a door by what the hand swept" and "A door taken for a drawer").

    python scripts/door_turn_trace.py --seed 200 --objects 46
    python scripts/door_turn_trace.py --seed 901 --objects 8
    python scripts/door_turn_trace.py --category closet --grasp contact --objects 43

For each piece of `nfr-drake eval-pipeline --category C --min-confidence 0 [--grasp G]` (the same
scenario, part and target, `object_scenario`) it runs the pipeline once and prints, from
the simulation's samples: the fit's articulation of the part; the largest articulation between the
fingers closing and the pull starting (a grasp's jolt); the angle the held hand swept about the
circle through its path until the pull settled, measured from the path's first sample and from its
point furthest back (`corrections.arc_angle`, today's measure); the articulation then; the turn
the robot asked for (`SimulationResult.turned`) and the turn the door made; the final
articulation; and where the turn was taken on from a second base (`systems.task.turn_on`), how
that ended. Angles in degrees (generated doors: a quarter turn per unit of q); a drawer is named
and skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
import tyro

from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.systems.corrections import arc_angle
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario


@dataclass
class Args:
    seed: int = 200
    objects: list[int] = field(default_factory=lambda: [46])
    category: str = "furniture"
    """furniture, or closet (`models/closet`)."""
    grasp: str = "constraint"


def first_sample_sweep(points: np.ndarray) -> float:
    """The angle (rad) from the first of `points` (N, 3) to the last about the circle through them,
    the sign of `arc_angle`'s (the measure before it took the point furthest back)."""
    swept, centre, axis = arc_angle(points)
    e1 = points[0] - centre
    e1 -= (e1 @ axis) * axis
    e2 = np.cross(axis, e1)
    last = points[-1] - centre
    return float(np.arctan2(last @ e2, last @ e1))


def main(args: Args) -> None:
    torch.set_num_threads(1)
    base = Scenario(category=args.category, model=f"models/{args.category}", seed=args.seed,
                    min_confidence=0.0, grasp=args.grasp)
    for index in args.objects:
        scenario = object_scenario(base, index, part_target=True)
        outcome = run_scenario(scenario)
        task, config = outcome.task, scenario.simulation
        sim, plan = task.simulation, task.plan
        if sim.joint_type != "revolute":
            print(f"seed {args.seed} piece {index}: part {scenario.part} is a drawer, no turn", flush=True)
            continue
        span = 90.0  # degrees per unit of q
        delay = (sim.tries - 1) * config.regrasp_time
        t_close, t_pull = plan.t_grasp + delay + 0.5 * config.dwell, sim.felt_from
        t_pulled = plan.duration + config.dwell + config.settle + delay
        held = (sim.times >= t_pull) & (sim.times < t_pulled)
        jolt = sim.q_object[(sim.times >= t_close) & (sim.times <= t_pull)].max(initial=0.0)
        print(f"seed {args.seed} piece {index}, part {scenario.part} ({sim.joint_type}): "
              f"fit q {span * outcome.q_estimate:.1f}, jolt to {span * jolt:.1f}, "
              f"swept from the first sample {abs(np.degrees(first_sample_sweep(sim.p_W_tool[held]))):.1f} "
              f"and from the point furthest back {abs(np.degrees(arc_angle(sim.p_W_tool[held])[0])):.1f}, "
              f"pulled to {span * sim.q_pulled:.1f}, turn asked {abs(np.degrees(sim.turned)):.1f}, "
              f"made {span * (sim.q_final - sim.q_pulled):.1f}, final {span * sim.q_final:.1f} "
              f"(target {span * sim.q_target:.1f}): {'opened' if sim.success else 'not opened'}", flush=True)
        if task.pulled_on is not None:
            print(f"  {task.pulled_on.details()}: {'opened' if task.success else 'not opened'}", flush=True)


if __name__ == "__main__":
    main(tyro.cli(Args))
