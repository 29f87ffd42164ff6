"""How wide the fitted field says a drawer is, against its true width (docs/PLACE.md, "A drawer's
width from the fitted field").

    python scripts/drawer_width.py --seed 901 --objects 0 1 2 3 4 5

For each drawer of the capture seed: photographed alone by the pipeline's cameras, fitted
(`models/drawer`, 128 px), its `semantic_cloud` rendered; prints the points, the render's time,
`drawer_half_width` and the front's true half width, m.
"""

from __future__ import annotations

import argparse
import time

from nfr_drake.cpu import set_torch_threads
from nfr_drake.planning.compartment import drawer_half_width
from nfr_drake.systems.pipeline import perception_simulator
from nfr_drake.systems.scenario import Scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=901)
    parser.add_argument("--objects", type=int, nargs="+", default=list(range(6)))
    parser.add_argument("--model", default="models/drawer")
    args = parser.parse_args()
    set_torch_threads(1)
    print("index  points  moving  render_s  half_width_m  true_half_width_m  difference_cm")
    for index in args.objects:
        scenario = Scenario(category="drawer", model=args.model, seed=args.seed, index=index, q_target=1.0)
        obj, _ = scenario.sample_piece()
        simulator, perception = perception_simulator(scenario, obj)
        simulator.Initialize()
        context = perception.GetMyContextFromRoot(simulator.get_context())
        kt = perception.get_keypoint_trajectory_output_port().Eval(context)
        started = time.perf_counter()
        cloud = perception.get_semantic_cloud_output_port().Eval(context)
        seconds = time.perf_counter() - started
        half, true_half = drawer_half_width(kt, cloud), obj.params["width"] / 2
        print(f"{index:5d}  {len(cloud.points):6d}  {len(cloud.moving()):6d}  {seconds:8.2f}  {half:12.3f}  "
              f"{true_half:17.3f}  {100 * (half - true_half):13.1f}", flush=True)


if __name__ == "__main__":
    main()
