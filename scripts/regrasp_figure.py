"""A drawer opened from keypoints placed too far out of its front, with one close and with a
second try after the miss (`SimulationConfig.regrasps`).

    python scripts/regrasp_figure.py --shift 0.035 --out docs/images/regrasp_drawer.png

The drawer is object `--index` of the training domain's seed (the simulation tests' drawer), shut,
at the identity pose; its true keypoints are moved `--shift` m out of its front (+x of its frame,
against the approach) and the plan is made from them. Two runs of the same plan: `regrasps` 0 and
1. Top: the true handle's grip point ahead of the tool along the approach (cm; the fingers catch
it within `capture_half_extents` of 0), bottom: the drawer's articulation; the closes marked.
Prints each run's summary.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib
import tyro

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from pydrake.math import RigidTransform  # noqa: E402

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object  # noqa: E402
from nfr_drake.systems.articulation import SimulationConfig  # noqa: E402
from nfr_drake.systems.scene_objects import SceneObject  # noqa: E402
from nfr_drake.systems.task import read_keypoints, run_task  # noqa: E402


@dataclass
class Args:
    shift: float = 0.035
    """How far out of the drawer's front the keypoints are moved, m."""
    index: int = 3
    out: Path = Path("docs/images/regrasp_drawer.png")


def main(args: Args) -> None:
    obj = SceneObject.from_articulated_object(
        sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, args.index, 0)), RigidTransform(), 0.0)
    keypoints = read_keypoints(obj).shifted([args.shift, 0.0, 0.0])
    fig, (ahead_ax, q_ax) = plt.subplots(2, 1, figsize=(7.5, 5.5), sharex=True)
    config = SimulationConfig()
    for regrasps, colour in ((0, "tab:red"), (1, "tab:blue")):
        outcome = run_task(obj, 1.0, keypoints=keypoints,
                           simulation_config=SimulationConfig(regrasps=regrasps))
        sim, plan = outcome.simulation, outcome.plan
        print(f"regrasps {regrasps}: {sim.summary()}")
        approach = plan.waypoints[0].approach_W
        ahead = (sim.p_W_handle - sim.p_W_tool) @ approach
        label = f"regrasps {regrasps}: {sim.tries} close{'s' if sim.tries > 1 else ''}, " + \
            ("opened" if sim.success else "not opened")
        ahead_ax.plot(sim.times, 100 * ahead, color=colour, label=label)
        q_ax.plot(sim.times, sim.q_object, color=colour, label=label)
        for k in range(sim.tries):
            t_close = plan.t_grasp + k * config.regrasp_time + 0.5 * config.dwell
            for ax in (ahead_ax, q_ax):
                ax.axvline(t_close, color=colour, linestyle=":", linewidth=1)
    half = 100 * config.capture_half_extents[2]
    ahead_ax.axhspan(-half, half, color="0.9", label="caught when the fingers close")
    ahead_ax.set_ylim(-10, 10)
    ahead_ax.set_ylabel("grip point ahead of the tool\nalong the approach, cm")
    ahead_ax.legend(fontsize=8, loc="upper right")
    q_ax.set_ylabel("drawer articulation q")
    q_ax.set_xlabel("time, s (dotted: the fingers close)")
    fig.suptitle(f"Keypoints {100 * args.shift:.1f} cm out of the drawer's front: one close, and a try "
                 f"{100 * config.regrasp_step:.0f} cm deeper", fontsize=10)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(tyro.cli(Args))
