"""Open or close a sampled object with ground-truth keypoints: plan, simulate, replay.

    python systems/ground_truth_plan.py systems/ground_truth_open_drawer.yaml

The scenario YAML holds a `Scenario` (fields below, any left out keep their defaults), loaded with
Drake's yaml_load_typed. The diagrams are built by nfr_drake (systems.task.run_task).
"""

import sys
from dataclasses import dataclass, field
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.planner import PlannerConfig
from nfr_drake.systems.articulation import SimulationConfig
from nfr_drake.systems.scene_objects import SceneObject, object_pose
from nfr_drake.systems.task import run_task


@dataclass
class Scenario:
    category: str = "drawer"
    """"closet" or "drawer"."""
    seed: int = 3
    """Object drawn from object_rng(SEED_DOMAIN_TRAIN, seed, 0)."""
    start_q: float = 0.0
    target_q: float = 1.0
    object_xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    object_yaw_deg: float = 0.0
    replay: str = "out/plan/scenario.html"
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    simulation: SimulationConfig = field(default_factory=SimulationConfig)


def run(scenario: Scenario) -> bool:
    """Run the scenario, print the outcome line; True on success."""
    obj = sample_object(scenario.category, object_rng(SEED_DOMAIN_TRAIN, scenario.seed, 0))
    X_WO = object_pose(scenario.object_xyz, scenario.object_yaw_deg)
    outcome = run_task(SceneObject.from_articulated_object(obj, X_WO, scenario.start_q), scenario.target_q,
                       replay=Path(scenario.replay), planner_config=scenario.planner,
                       simulation_config=scenario.simulation)
    if outcome.plan is None:
        print(outcome.planning_error)
        return False
    print(f"{outcome.simulation.summary()}; planning {outcome.planning_seconds:.2f} s; "
          f"replay {outcome.replay}")
    return outcome.success


def main(argv: list[str]) -> int:
    scenario = yaml_load_typed(schema=Scenario, filename=argv[1]) if len(argv) > 1 else Scenario()
    return 0 if run(scenario) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
