"""Predicted against true door motion in the pipeline: hinge, radius and the angle swept to q_target.

Usage: python benchmarks/door_sweep.py --indices 1 6 8 15 16 [--seed 200] [--q-target 0.6]
       [--model models/closet]
Runs the pipeline's perception (`nfr_drake.systems.pipeline.perceive`: ten Drake cameras at 128 px,
the default fit) on shut closets of the capture seed, and prints per object the hinge position
error, the handle's distance from the hinge axis (radius), and the angle the handle path sweeps about
its own hinge axis from q = 0 to q_target, predicted and true, as a markdown table.
"""

from __future__ import annotations

import argparse
import platform
from datetime import date

import numpy as np
import torch

from nfr_drake.systems.pipeline import perceive
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.keypoints import KeypointTrajectory


def radius_and_sweep(kt: KeypointTrajectory, q0: float, q1: float) -> tuple[float, float]:
    """Handle distance from the hinge axis at q0 (m) and the angle (deg) it sweeps to q1."""
    bottom, top = kt.point("hinge_bottom", q0), kt.point("hinge_top", q0)
    axis = (top - bottom) / np.linalg.norm(top - bottom)
    arms = []
    for q in (q0, q1):
        arm = kt.point("handle", q) - bottom
        arms.append(arm - axis * (arm @ axis))
    cos = arms[0] @ arms[1] / (np.linalg.norm(arms[0]) * np.linalg.norm(arms[1]))
    return float(np.linalg.norm(arms[0])), float(np.degrees(np.arccos(np.clip(cos, -1, 1))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--indices", type=int, nargs="+", required=True)
    parser.add_argument("--seed", type=int, default=200)
    parser.add_argument("--q-target", type=float, default=0.6)
    parser.add_argument("--model", default="models/closet")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"{date.today()}, {platform.processor() or platform.machine()}, {args.model}")
    print("| object | hinge error (cm) | radius true / predicted (cm) | sweep to q_target true / "
          "predicted (deg) |")
    print("|---|---|---|---|")
    for index in args.indices:
        scenario = Scenario(category="closet", model=args.model, seed=args.seed, index=index,
                            q_start=0.0, q_target=args.q_target)
        obj = scenario.sample_object()
        predicted, _ = perceive(scenario, obj)
        truth = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, 0.0)
        hinge = np.linalg.norm(predicted.point("hinge_bottom", 0.0) - truth.point("hinge_bottom", 0.0))
        r_true, s_true = radius_and_sweep(truth, 0.0, args.q_target)
        r_pred, s_pred = radius_and_sweep(predicted, 0.0, args.q_target)
        print(f"| {index} | {100 * hinge:.1f} | {100 * r_true:.1f} / {100 * r_pred:.1f} | "
              f"{s_true:.1f} / {s_pred:.1f} |")


if __name__ == "__main__":
    main()
