"""What the robot's corrections from its own joint positions do (docs/SIMULATION.md): the same plan
run with a correction off and on.

    python scripts/corrections_figure.py --case regrasp --error 0.035 --out docs/images/regrasp_drawer.png
    python scripts/corrections_figure.py --case door-turn --error 12 --out docs/images/door_turn_closet.png
    python scripts/corrections_figure.py --case door-as-drawer --error 0.4 \
        --out docs/images/door_as_drawer.png

`regrasp`: the drawer of the simulation tests (training seed, object 3), shut at the identity pose,
planned from its true keypoints moved `--error` m out of its front (+x of its frame, against the
approach); `regrasps` 0 and 1. Top: the true handle's grip point ahead of the tool along the
approach (cm; the fingers catch it within `capture_half_extents` of 0); the closes marked.
`door-turn`: the closet of the simulation tests (object 0), shut, planned from its true keypoints
turned `--error` degrees about the vertical through its handle (the object's yaw off);
`second_turn` off and on. Top: the door's angle from its target (deg), the turn's start marked.
`door-as-drawer`: the same closet planned from drawer keypoints, its handle pulled straight out
along the front's normal by `--error` m (a door the fit took for a drawer); `second_turn` off and
on (the turn as the hand felt it swing). Top as `door-turn`.
Bottom, both: the articulation. Prints each run's summary.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import matplotlib
import numpy as np
import tyro

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from pydrake.math import RigidTransform, RotationMatrix  # noqa: E402

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object  # noqa: E402
from nfr_drake.systems.articulation import SimulationConfig  # noqa: E402
from nfr_drake.systems.scene_objects import SceneObject  # noqa: E402
from nfr_drake.systems.task import run_task  # noqa: E402
from nfr_drake.world.keypoints import KeypointTrajectory  # noqa: E402


@dataclass
class Args:
    case: Literal["regrasp", "door-turn", "door-as-drawer"] = "regrasp"
    error: float = 0.035
    """regrasp: how far out of the drawer's front the keypoints are moved, m; door-turn: how far
    they are turned about the handle, deg; door-as-drawer: how far the straight pull goes, m."""
    out: Path = Path("docs/images/regrasp_drawer.png")


def main(args: Args) -> None:
    drawer = args.case == "regrasp"
    category, index = ("drawer", 3) if drawer else ("closet", 0)
    obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, index, 0))
    truth = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    if drawer:
        keypoints, q_target = truth.shifted([args.error, 0.0, 0.0]), 1.0
        settings = [(f"regrasps {n}", SimulationConfig(regrasps=n)) for n in (0, 1)]
    else:
        p, q_target = truth.point("handle", 0.0), 0.6
        if args.case == "door-turn":
            R = RotationMatrix.MakeZRotation(np.radians(args.error))
            keypoints = KeypointTrajectory.from_articulated_object(obj, RigidTransform(R, p - R @ p), 0.0)
        else:
            q = np.linspace(0.0, 1.0, 11)
            keypoints = KeypointTrajectory("drawer", q, ("handle",),
                                           p + np.outer(args.error * q, [1.0, 0.0, 0.0])[:, None], 0.0)
        turned = "turned on by what the hand swept" if args.case == "door-turn" else \
            "turned on as the hand felt it swing"
        settings = [("planned pull only", SimulationConfig(second_turn=False)), (turned, SimulationConfig())]
    scene_object = SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 5.5), sharex=True)
    config = SimulationConfig()
    styles = ({"color": "tab:red", "linewidth": 4.0, "alpha": 0.45}, {"color": "tab:blue", "linewidth": 1.5})
    for (name, simulation), style in zip(settings, styles, strict=True):  # the same run until the fix
        outcome = run_task(scene_object, q_target, keypoints=keypoints, simulation_config=simulation)
        sim, plan = outcome.simulation, outcome.plan
        print(f"{name}: {sim.summary()}")
        label = f"{name}: " + ("opened" if sim.success else "not opened")
        if drawer:
            top.plot(sim.times, 100 * (sim.p_W_handle - sim.p_W_tool) @ plan.waypoints[0].approach_W,
                     **style, label=f"{label}, {sim.tries} close{'s' if sim.tries > 1 else ''}")
            marks = [plan.t_grasp + k * config.regrasp_time + 0.5 * config.dwell for k in range(sim.tries)]
        else:
            off = np.degrees((sim.q_object - q_target) * obj.front(0).joint_upper)  # the door's span
            top.plot(sim.times, off, **style, label=f"{label}, {off[-1]:+.1f} deg at the end")
            marks = [plan.duration + config.dwell + config.settle] if sim.turned else []
        bottom.plot(sim.times, sim.q_object, **style, label=label)
        for t in marks:
            for ax in (top, bottom):
                ax.axvline(t, color=style["color"], linestyle=":", linewidth=1)
    if drawer:
        half = 100 * config.capture_half_extents[2]
        top.axhspan(-half, half, color="0.9", label="caught when the fingers close")
        top.set_ylim(-10, 10)
        top.set_ylabel("grip point ahead of the tool\nalong the approach, cm")
        bottom.set_xlabel("time, s (dotted: the fingers close)")
        title = (f"Keypoints {100 * args.error:.1f} cm out of the drawer's front: one close, and a try "
                 f"{100 * config.regrasp_step:.0f} cm deeper")
    else:
        tolerance = np.degrees(config.revolute_tolerance)
        top.axhspan(-tolerance, tolerance, color="0.9", label="within the tolerance")
        top.set_ylim(-60 if args.case == "door-as-drawer" else -20, 10)
        top.set_ylabel("door angle from its target, deg")
        bottom.set_xlabel("time, s (dotted: the turn starts)")
        title = (f"Keypoints turned {args.error:.0f} deg about the closet's handle: the planned pull, "
                 "and a turn on" if args.case == "door-turn" else
                 f"The closet's door taken for a drawer, its handle pulled {100 * args.error:.0f} cm "
                 "straight out: the planned pull, and a turn on")
    top.legend(fontsize=8, loc="lower right")
    bottom.set_ylabel("articulation q")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(tyro.cli(Args))
