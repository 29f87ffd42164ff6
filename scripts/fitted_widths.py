"""How wide the fitted field says a moving part is, against the truth (docs/PLACE.md, "The moving
part's width from the fitted field").

    python scripts/fitted_widths.py --category drawer --seed 901 --objects 0 1 2 3 4 5
    python scripts/fitted_widths.py --category closet --seed 901 --objects 0 1 2 3 4 5

For each object of the capture seed: photographed alone by the pipeline's cameras, fitted
(`models/CATEGORY`, 128 px), its `semantic_cloud` rendered; prints the points, the render's time,
the measured width (a drawer front's half width about its goal, `drawer_half_width`; a door's
width from its hinge line, `door_width`) and the true one (half the carcass's width; the
carcass's width), m.
"""

from __future__ import annotations

import argparse
import time

from nfr_drake.cpu import set_torch_threads
from nfr_drake.planning.compartment import door_width, drawer_half_width
from nfr_drake.systems.pipeline import perception_simulator
from nfr_drake.systems.scenario import Scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--category", choices=("closet", "drawer"), default="drawer")
    parser.add_argument("--seed", type=int, default=901)
    parser.add_argument("--objects", type=int, nargs="+", default=list(range(6)))
    args = parser.parse_args()
    set_torch_threads(1)
    drawer = args.category == "drawer"
    print("index  points  moving  render_s  width_m  true_width_m  difference_cm")
    for index in args.objects:
        scenario = Scenario(category=args.category, model=f"models/{args.category}", seed=args.seed,
                            index=index, q_target=1.0 if drawer else 0.6)
        obj, _ = scenario.sample_piece()
        simulator, perception = perception_simulator(scenario, obj)
        simulator.Initialize()
        context = perception.GetMyContextFromRoot(simulator.get_context())
        kt = perception.get_keypoint_trajectory_output_port().Eval(context)
        started = time.perf_counter()
        cloud = perception.get_semantic_cloud_output_port().Eval(context)
        seconds = time.perf_counter() - started
        width = drawer_half_width(kt, cloud) if drawer else door_width(kt, cloud)
        truth = obj.params["width"] / (2 if drawer else 1)
        print(f"{index:5d}  {len(cloud.points):6d}  {len(cloud.moving()):6d}  {seconds:8.2f}  {width:7.3f}  "
              f"{truth:12.3f}  {100 * (width - truth):13.1f}", flush=True)


if __name__ == "__main__":
    main()
