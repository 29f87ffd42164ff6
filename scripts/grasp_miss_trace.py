"""Where the fitted handle lay against the true one on pipeline pieces the hand missed
(docs/SIMULATION.md, "Trying again after a miss").

    python scripts/grasp_miss_trace.py --seed 200 --objects 12 41 81 90 93

For each piece of `nfr-drake eval-pipeline --category furniture --min-confidence 0` (the same
scenario and part, `object_scenario`) it runs the pipeline once and prints the fitted handle's
error at the observed state (fitted minus true, cm) along the true front's outward normal (the
true handle path's tangent there, made horizontal; negative: the fitted point lies beyond the
bar, seen from the robot), across the front and up; the closes the fingers made, the tool's
distance from the nearest grip point at the last one, and the outcome.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
import tyro

from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.planning.grasp import handle_tangent
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario


@dataclass
class Args:
    seed: int = 200
    objects: list[int] = field(default_factory=lambda: [12])
    model: str = "models/furniture"


def main(args: Args) -> None:
    torch.set_num_threads(1)
    base = Scenario(category="furniture", model=args.model, seed=args.seed, min_confidence=0.0)
    for index in args.objects:
        outcome = run_scenario(object_scenario(base, index, part_target=True))
        truth, fitted, task = outcome.truth, outcome.predicted, outcome.task
        if fitted is None or task is None or task.simulation is None:
            why = outcome.refused or "no plan"
            print(f"seed {args.seed} piece {index}: nothing simulated ({why})", flush=True)
            continue
        out = handle_tangent(truth, truth.q_current)
        out[2] = 0.0
        out /= np.linalg.norm(out)
        across = np.cross([0.0, 0.0, 1.0], out)
        error = fitted.point("handle", fitted.q_current) - truth.point("handle", truth.q_current)
        sim = task.simulation
        print(f"seed {args.seed} piece {index} ({sim.joint_type}): handle error {100 * error @ out:.1f} cm "
              f"along the outward normal, {100 * error @ across:.1f} across, {100 * error[2]:.1f} up; "
              f"{sim.tries} close{'s' if sim.tries > 1 else ''}, the last "
              f"{100 * sim.grasp_offset:.1f} cm from the grip point: "
              f"{'opened' if task.success else 'not opened'}", flush=True)


if __name__ == "__main__":
    main(tyro.cli(Args))
