"""How straight a drawer's pull by contact is, as the robot judges it (docs/SIMULATION.md, "A door
taken for a drawer"), on the random user models of `benchmarks/user_models.py`.

    python scripts/straight_pull_trace.py --seed 1 --models 4 19 25

For each model (its index among `--random 30 --seed S`): `run_task` with the contact grasp's
configs at the model's pose; from the tool's path between the fingers closing and the pull
settling (forward kinematics, W): the chord (m), its bow (`path_bow`), the arc it reads as
(`arc_angle`, degrees), the bow without its ends (`inner_path`, `FELT_JOLT`), and the outcome.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import tyro

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fixtures.user_models import random_models  # noqa: E402

from nfr_drake.planning.planner import PlannerConfig, grasp_planner  # noqa: E402
from nfr_drake.systems.articulation import SimulationConfig  # noqa: E402
from nfr_drake.systems.corrections import FELT_JOLT, arc_angle, inner_path, path_bow  # noqa: E402
from nfr_drake.systems.scene_objects import SceneObject, object_pose  # noqa: E402
from nfr_drake.systems.task import run_task  # noqa: E402


def main(seed: int = 1, models: tuple[int, ...] = (4, 19, 25), count: int = 30) -> None:
    folder = Path(tempfile.mkdtemp(prefix="straight_pull_"))
    for index in models:
        args = random_models(folder, count, seed)[index].plan_args()
        value = {k: args[i + 1] for i, k in enumerate(args) if k.startswith("--")}
        xyz = tuple(float(v) for v in args[args.index("--object-xyz") + 1:][:3])
        obj = SceneObject.from_model_file(Path(value["--object"]), value["--joint"], value["--handle-body"],
                                          object_pose(xyz, float(value["--object-yaw-deg"]), (0, 0, 0)), 0.0)
        config = SimulationConfig(grasp="contact")
        out = run_task(obj, 1.0, planner_config=grasp_planner(PlannerConfig(), "contact"),
                       simulation_config=config)
        sim = out.simulation
        t_pulled = out.plan.duration + config.dwell + config.settle + (sim.tries - 1) * config.regrasp_time
        path = sim.p_W_tool[(sim.times >= sim.felt_from) & (sim.times <= t_pulled + 1e-9)]
        print(f"seed {seed} model {index}: chord {np.linalg.norm(path[-1] - path[0]):.3f} m, bow "
              f"{100 * path_bow(path):.2f} %, arc {np.degrees(abs(arc_angle(path)[0])):.1f} deg, without the "
              f"ends {100 * path_bow(inner_path(path, FELT_JOLT)):.2f} %; {out.summary()}", flush=True)


if __name__ == "__main__":
    tyro.cli(main)
