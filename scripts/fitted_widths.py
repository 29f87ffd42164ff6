"""How wide (and, for a closet, how tall) the fitted field says a part is, against the truth
(docs/PLACE.md, "The moving part's width from the fitted field").

    python scripts/fitted_widths.py --category drawer --seed 901 --objects 0 1 2 3 4 5
    python scripts/fitted_widths.py --category closet --seed 901 --objects 0 1 2 3 4 5

For each object of the capture seed: photographed alone by the pipeline's cameras, fitted
(`models/CATEGORY`, 128 px), its `semantic_cloud` rendered; prints the points, the render's time,
the measured width (a drawer front's half width about its goal, `drawer_half_width`; a door's
width from its hinge line, `door_width`) and the true one (half the carcass's width; the
carcass's width), m. For a closet also the open door's top edge, as the keypoints give it
(`hinge_top`) and as the fitted field's points of the moving part give it (`part_top`: their
0.98 quantile of height), against the true door's top, and the carcass's top from its points, cm
from the truth (docs/PLACE.md, "The tops from the fitted field"); and the half width the
keypoints give the carcass (`closet_half_width`) and its points (`carcass_half_width`) less the
true one, cm.
"""

from __future__ import annotations

import argparse
import time

from nfr_drake.cpu import set_torch_threads
from nfr_drake.planning.compartment import (
    carcass_half_width,
    closet_half_width,
    door_width,
    drawer_half_width,
    part_top,
)
from nfr_drake.systems.pipeline import perception_simulator
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.obstacles import object_obstacles


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--category", choices=("closet", "drawer"), default="drawer")
    parser.add_argument("--seed", type=int, default=901)
    parser.add_argument("--objects", type=int, nargs="+", default=list(range(6)))
    args = parser.parse_args()
    set_torch_threads(1)
    drawer = args.category == "drawer"
    closet_columns = ("  door_top_m  keypoints_cm  points_cm  carcass_top_m  points_cm  half_width_cm"
                      "  points_cm")
    print("index  points  moving  render_s  width_m  true_width_m  difference_cm"
          + ("" if drawer else closet_columns))
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
        line = (f"{index:5d}  {len(cloud.points):6d}  {len(cloud.moving()):6d}  {seconds:8.2f}  "
                f"{width:7.3f}  {truth:12.3f}  {100 * (width - truth):13.1f}")
        if not drawer:
            boxes = object_obstacles(obj, scenario.X_WO, cloud.q, moving=-1, merge=False)
            tops = {b.name: b.top for b in boxes}
            door = max(v for k, v in tops.items() if k.startswith("front0_"))
            carcass = max(v for k, v in tops.items() if not k.startswith("front0_"))
            seen = [part_top(p) for p in (cloud.moving(), cloud.static())]
            line += (f"  {door:10.3f}  {100 * (kt.point('hinge_top', cloud.q)[2] - door):12.1f}"
                     f"  {100 * (seen[0] - door):9.1f}  {carcass:13.3f}  {100 * (seen[1] - carcass):9.1f}"
                     f"  {100 * (closet_half_width(kt, cloud.q) - obj.params['width'] / 2):13.1f}"
                     f"  {100 * (carcass_half_width(kt, cloud, cloud.q) - obj.params['width'] / 2):9.1f}")
        print(line, flush=True)


if __name__ == "__main__":
    main()
