"""The paper's pipeline in Drake: photograph an unseen object, fit, forward-simulate, plan, open.

Phase 1 (perception): a diagram with the object at X_WO and `NfrPerceptionSystem` fed by RgbdSensors
around it; initialising the simulator runs the fit once, giving the keypoint trajectory in W.
Phase 2 (action): the planner uses that trajectory alone; the arm is simulated on the true object
and an HTML replay shows the predicted (planned-with) and the true keypoint paths.

A `Scenario` is a dataclass loaded from YAML with `yaml_load_typed` (see `systems/*.yaml`); this
module keeps real (not postponed) annotations, which `yaml_load_typed` needs to read field types.
"""

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_load_typed
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import check_category
from nfr_drake.nfr.checkpoint import read_model_config
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, ArticulatedObject, object_rng, sample_object
from nfr_drake.objects.plant import add_articulated_object, set_articulation
from nfr_drake.systems.perception import AddNfrPerception
from nfr_drake.systems.scene_objects import SceneObject, object_pose
from nfr_drake.systems.task import TaskOutcome, run_task
from nfr_drake.world.keypoints import KeypointTrajectory


@dataclass
class Scenario:
    """One run of the pipeline.

    Attributes:
        category: "closet" or "drawer".
        model: neural-field model folder of that category.
        seed: capture seed; the object is `object_rng(SEED_DOMAIN_CAPTURE, seed, index)`, never a
            training object.
        index: object index within the seed.
        q_start: the object's articulation when photographed, in [0, 1].
        q_target: the articulation to reach (1 opens, 0 closes).
        object_xyz: position of the object frame O in W, m.
        object_yaw_deg: rotation of O about W's z, degrees.
        views: perception cameras.
        image_size: square image size of the perception cameras, pixels. 128 by default: the
            models were trained on 64 px images, but the fit takes any resolution, and with the
            shipped models 128 px opens more objects (docs/EVALUATION.md, "The whole pipeline").
        fov_y_deg: their vertical field of view, degrees.
        distance_m: their distance range to the object centre, m.
        restarts: fit starts.
        max_steps: fit steps at most.
        focus_steps: steps of the fit's final close look at the handle (0: none).
        handle_detector: use the model's 2D handle detector, when it ships one.
        keypoints: "head" (the keypoint head, as in the paper; the better of the two on unseen
            objects, docs/EVALUATION.md) or "geometry" (handle and hinge axis read from the
            fitted field's segmentation).
        replay: HTML replay to write ("" for none).
    """

    category: str = "closet"
    model: str = "models/closet"
    seed: int = 100
    index: int = 0
    q_start: float = 0.0
    q_target: float = 1.0
    object_xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    object_yaw_deg: float = 0.0
    views: int = 10
    image_size: int = 128
    fov_y_deg: float = 50.0
    distance_m: list[float] = field(default_factory=lambda: [1.4, 1.9])
    restarts: int = 4
    max_steps: int = 400
    focus_steps: int = FitConfig.focus_steps
    handle_detector: bool = True
    keypoints: str = "head"
    replay: str = ""

    def __post_init__(self):
        if self.category not in ("closet", "drawer"):
            raise ConfigError(f"category must be closet or drawer, got {self.category!r}")
        for name in ("q_start", "q_target"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"{name} must lie in [0, 1]")
        if self.keypoints not in ("geometry", "head"):
            raise ConfigError(f"keypoints must be geometry or head, got {self.keypoints!r}")
        if self.views < 1 or self.image_size < 8:
            raise ConfigError("views must be >= 1 and image_size >= 8")
        object_pose(self.object_xyz, self.object_yaw_deg)  # ConfigError for a non-finite pose

    @classmethod
    def load(cls, path: Path) -> "Scenario":
        return yaml_load_typed(schema=cls, filename=str(path))

    @property
    def X_WO(self) -> RigidTransform:
        return object_pose(self.object_xyz, self.object_yaw_deg)

    def sample_object(self) -> ArticulatedObject:
        return sample_object(self.category, object_rng(SEED_DOMAIN_CAPTURE, self.seed, self.index),
                             name=f"{self.category}_{self.seed}_{self.index}")


@dataclass
class PipelineOutcome:
    """q_estimate / q_true in [0, 1]; keypoint_rmse_cm at the observed state; handle_path_rmse_cm
    over [0, 1]; perception_seconds of the fit; predicted and true trajectories in W; the task."""

    q_estimate: float
    q_true: float
    keypoint_rmse_cm: float
    handle_path_rmse_cm: float
    perception_seconds: float
    predicted: KeypointTrajectory
    truth: KeypointTrajectory
    task: TaskOutcome

    def report(self) -> str:
        task = self.task
        lines = [f"estimated q {self.q_estimate:.3f} (true {self.q_true:.3f}); keypoint error "
                 f"{self.keypoint_rmse_cm:.2f} cm RMSE at the observed state, handle path "
                 f"{self.handle_path_rmse_cm:.2f} cm RMSE over q in [0, 1]; fit "
                 f"{self.perception_seconds:.1f} s"]
        if task.plan is None:
            lines.append(f"FAILURE: planning failed: {task.planning_error}")
        else:
            lines.append(f"planning time {task.planning_seconds:.2f} s")
            lines.append(task.simulation.summary())
        if task.replay is not None:
            lines.append(f"replay: {task.replay}")
        return "\n".join(lines)


def perceive(scenario: Scenario, obj: ArticulatedObject) -> tuple[KeypointTrajectory, float]:
    """Phase 1: photograph `obj` (at q_start, pose X_WO) with Drake cameras and fit the model.

    Returns the predicted keypoint trajectory in W and the fit's wall time, s.
    """
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    X_WO = scenario.X_WO
    model = add_articulated_object(plant, obj, X_WO)
    plant.Finalize()
    rng = np.random.default_rng([scenario.seed, scenario.index, 7])
    cameras = CameraDistribution(distance_m=tuple(scenario.distance_m))
    X_WCs = [X_WO @ RigidTransform(X) for X in cameras.sample(rng, scenario.views,
                                                               obj.look_at_target())]
    camera = PinholeCamera.from_fov(scenario.image_size, scenario.image_size,
                                    math.radians(scenario.fov_y_deg))
    perception = AddNfrPerception(builder, plant, scene_graph, Path(scenario.model), model, X_WO,
                                  X_WCs, camera,
                                  FitConfig.budget(scenario.restarts, scenario.max_steps,
                                                   focus_steps=scenario.focus_steps,
                                                   sightings=scenario.handle_detector),
                                  keypoint_source=scenario.keypoints)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    set_articulation(plant, plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()),
                     obj, model, scenario.q_start)
    started = time.perf_counter()
    simulator.Initialize()  # the perception system fits here, once
    seconds = time.perf_counter() - started
    context = perception.GetMyContextFromRoot(simulator.get_context())
    return perception.get_keypoint_trajectory_output_port().Eval(context), seconds


def _rmse_cm(a: np.ndarray, b: np.ndarray) -> float:
    return float(100.0 * np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def run_scenario(scenario: Scenario) -> PipelineOutcome:
    """Both phases; the replay (if asked for) draws the predicted and the true keypoint paths.
    NfrDrakeError first when the model is not of the scenario's category."""
    check_category(Path(scenario.model), read_model_config(Path(scenario.model)).get("category"),
                   scenario.category, "scenario", "object")
    obj = scenario.sample_object()
    predicted, seconds = perceive(scenario, obj)
    truth = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, scenario.q_start)
    names = [n for n in truth.names if n in predicted.names]
    now = lambda kt: np.stack([kt.point(n, kt.q_current) for n in names])  # noqa: E731
    grid = truth.q_grid
    scene_object = SceneObject.from_articulated_object(obj, scenario.X_WO, scenario.q_start)
    task = run_task(scene_object, scenario.q_target, keypoints=predicted,
                    replay=Path(scenario.replay) if scenario.replay else None, reference=truth)
    return PipelineOutcome(
        q_estimate=predicted.q_current, q_true=scenario.q_start,
        keypoint_rmse_cm=_rmse_cm(now(predicted), now(truth)),
        handle_path_rmse_cm=_rmse_cm(predicted.point("handle", grid), truth.point("handle", grid)),
        perception_seconds=seconds, predicted=predicted, truth=truth, task=task)
