"""One task end to end: read the keypoint trajectory, plan, simulate on the true object, replay."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from pydrake.geometry import Meshcat, MeshcatVisualizer
from pydrake.math import RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.errors import NfrDrakeError
from nfr_drake.planning.grasp import carcass_box, door_panel_box
from nfr_drake.planning.planner import PlannerConfig, PlanningError, plan_articulation
from nfr_drake.planning.scene import build_planning_scene, reach_limit
from nfr_drake.systems.articulation import (
    SimulationConfig,
    SimulationResult,
    StartsInsideObject,
    simulate_articulation,
)
from nfr_drake.systems.corrections import door_turn, felt_door, planned_door_turn
from nfr_drake.systems.keypoints import AddKeypointTrajectorySource
from nfr_drake.systems.replay import draw_keypoint_trajectory, draw_obstacle, frame_camera, write_replay
from nfr_drake.systems.scene_objects import SceneObject, set_joint_value
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.plan import ObstacleBox, PlanResult
from nfr_drake.world.robot import NUM_ARM_JOINTS, add_floor, add_panda, add_pedestal

OPEN_TARGET = {"closet": 0.6, "drawer": 1.0}
"""Default articulation an `open` task reaches (and a `close` task starts from)."""


def task_span(category: str, task: Literal["open", "close"], start_q: float | None = None,
              target_q: float | None = None) -> tuple[float, float]:
    """(start q, target q) of opening or closing a SceneObject of `category`: the given values, by
    default 0 -> OPEN_TARGET to open and OPEN_TARGET -> 0 to close. NfrDrakeError outside [0, 1]."""
    open_q = OPEN_TARGET[category]
    q0 = start_q if start_q is not None else (0.0 if task == "open" else open_q)
    q1 = target_q if target_q is not None else (open_q if task == "open" else 0.0)
    for name, value in (("start_q", q0), ("target_q", q1)):
        if not 0.0 <= value <= 1.0:
            raise NfrDrakeError(f"{name} {value} is outside [0, 1]")
    return q0, q1


@dataclass
class PulledOn:
    """A pull to the stop that the arm's own reach ended (`pull_on`) or a door's turn that ended
    short (`turn_on`), taken on from a second base: why, the second plan (None if planning
    failed) and its error, its simulation and replay."""

    reason: str
    plan: PlanResult | None
    planning_error: str
    simulation: SimulationResult | None
    replay: Path | None

    def details(self) -> str:
        """One line without a verdict: why, and how the pull from the second base ended."""
        then = self.simulation.details() if self.simulation is not None else f"no plan: {self.planning_error}"
        return f"pulled on from a second base ({self.reason}): {then}"


def ended_in(first: SimulationResult | None, pulled_on: PulledOn | None) -> SimulationResult | None:
    """The simulation a part ended in: the second base's where the robot took it on from one
    (and planned there), else `first`."""
    return pulled_on.simulation if pulled_on is not None and pulled_on.simulation is not None else first


@dataclass
class TaskOutcome:
    """Result of `run_task`: the plan (None if planning failed), its error, the simulation, and
    the pull on from a second base where the first base's reach ended it (`pulled_on`)."""

    q_target: float
    keypoints: KeypointTrajectory
    plan: PlanResult | None
    planning_error: str
    planning_seconds: float
    simulation: SimulationResult | None
    replay: Path | None
    pulled_on: PulledOn | None = None

    @property
    def final(self) -> SimulationResult | None:
        """The simulation the object ended in: the second base's, if it pulled on, else the first."""
        return ended_in(self.simulation, self.pulled_on)

    @property
    def success(self) -> bool:
        return self.final is not None and self.final.success

    def summary(self) -> str:
        """One line: the verdict, the first base's outcome and, where it pulled on, the second's."""
        if self.simulation is None:
            return f"FAILURE: planning failed: {self.planning_error}"
        if self.pulled_on is None:
            return self.simulation.summary()
        verdict = "SUCCESS" if self.success else "FAILURE"
        return f"{verdict}: {self.simulation.details()}; {self.pulled_on.details()}"


def read_keypoints(obj: SceneObject) -> KeypointTrajectory:
    """The object's keypoint trajectory as `KeypointTrajectorySource` outputs it for the object at rest."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, 0.0)
    model = obj.add_to(plant)
    plant.Finalize()
    joint = plant.GetJointByName(obj.joint_name, model)
    shut, opened = obj.shut_and_open(joint)
    source = AddKeypointTrajectorySource(builder, plant, joint, obj.ground_truth, (shut, opened))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    set_joint_value(plant, plant.GetMyMutableContextFromRoot(context), joint,
                    shut + obj.ground_truth.q_current * (opened - shut))
    return source.get_keypoint_trajectory_output_port().Eval(source.GetMyContextFromRoot(context))


def run_task(obj: SceneObject, q_target: float, keypoints: KeypointTrajectory | None = None,
             meshcat: Meshcat | None = None, replay: Path | None = None,
             planner_config: PlannerConfig | None = None,
             simulation_config: SimulationConfig | None = None,
             reference: KeypointTrajectory | None = None) -> TaskOutcome:
    """Plan with `keypoints` (default: read from the object) and simulate on the true object.

    With `replay`, a meshcat (given or made here) records the run and the keypoint paths used by the
    planner and an HTML replay is written there. `reference` (e.g. the true keypoints when the
    planner used predicted ones) is drawn too, under "keypoints_true". Planning with the object's
    own keypoints (`keypoints` None) uses its geometry as obstacles where it has them
    (`SceneObject.obstacles`); given keypoints are planned with keypoint-derived boxes only.
    """
    kt = keypoints if keypoints is not None else read_keypoints(obj)
    obstacles = list(obj.obstacles) if keypoints is None and obj.obstacles is not None else None
    try:
        plan = plan_articulation(kt, q_target, config=planner_config or PlannerConfig(),
                                 obstacles=obstacles)
    except PlanningError as err:
        return TaskOutcome(q_target, kt, None, str(err), float("nan"), None, None)
    if replay is not None and meshcat is None:
        meshcat = Meshcat()
    if meshcat is not None:
        _show_plan(meshcat, kt, plan, q_target, obstacles, reference)
    config = simulation_config or SimulationConfig()
    try:
        simulation = simulate_articulation(obj, plan, q_target, meshcat, config, keypoints=kt)
    except StartsInsideObject as err:
        return TaskOutcome(q_target, kt, None, str(err), plan.seconds["total"], None, None)
    path = write_replay(meshcat, replay) if replay is not None else None
    pulled_on = (pull_on(obj, kt, plan, simulation, obstacles, planner_config or PlannerConfig(), config,
                         meshcat, replay)
                 or turn_on(obj, kt, plan, simulation, obstacles, planner_config or PlannerConfig(), config,
                            meshcat, replay))
    return TaskOutcome(q_target, kt, plan, "", plan.seconds["total"], simulation, path, pulled_on)


def held_handle(plan: PlanResult, q_arm: np.ndarray) -> np.ndarray:
    """Where the handle held by the hand is with the arm at q_arm (7,) rad, as the robot knows it
    (W, m, (3,)): the plan's grip point in the tool frame at the grasp, carried by the tool's pose
    from forward kinematics."""
    scene = build_planning_scene(plan.X_WB, [])
    plant, context, tool = scene.plant, scene.plant_context, scene.tool_frame
    plant.SetPositions(context, scene.robot, plan.trajectory.value(plan.t_grasp).ravel())
    p_TH = tool.CalcPoseInWorld(context).inverse() @ plan.waypoints[0].p_WH
    plant.SetPositions(context, scene.robot, scene.full_q(np.asarray(q_arm)[:NUM_ARM_JOINTS]))
    return tool.CalcPoseInWorld(context) @ p_TH


PULL_ON_REST = 0.005
"""The second base's plan takes the part as open to `PULL_ON_REST` (m of the keypoints' handle
path) short of its predicted end where the hand let go: its pull is then that, the planner's
`end_stop_overshoot` past it and the guarded pull."""


def handle_left_at(kt: KeypointTrajectory, p_WH: np.ndarray, along_W: np.ndarray) -> KeypointTrajectory:
    """The keypoints turned about the vertical (their handle path's horizontal direction onto that
    of unit `along_W`: the line the hand felt) and moved so that their handle lies at p_WH (W, m,
    (3,)), `PULL_ON_REST` short of its end of travel (q 1), their present articulation there: the
    part as the robot takes it when it let go of the handle past the keypoints' predicted end."""
    path = kt.point("handle", kt.q_grid)
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    q_left = float(np.clip(1.0 - PULL_ON_REST / max(length, 1e-9), kt.q_grid[0], 1.0))
    predicted = path[-1] - path[0]
    turn = np.arctan2(along_W[1], along_W[0]) - np.arctan2(predicted[1], predicted[0])
    if not np.isfinite(turn) or np.hypot(*along_W[:2]) < 1e-6 or np.hypot(*predicted[:2]) < 1e-6:
        turn = 0.0
    R = RotationMatrix.MakeZRotation(float(turn)).matrix()
    turned = replace(kt, p_WK=kt.p_WK @ R.T)
    return turned.shifted(np.asarray(p_WH) - turned.point("handle", q_left)).with_current(q_left)


def pull_on(obj: SceneObject, kt: KeypointTrajectory, plan: PlanResult, first: SimulationResult,
            obstacles: list[ObstacleBox] | None, planner_config: PlannerConfig, config: SimulationConfig,
            meshcat: Meshcat | None, replay: Path | None) -> PulledOn | None:
    """The pull to the stop taken on from a second base, where the arm's own reach ended the
    guarded pull of `first` (`SimulationConfig.pull_on`: the pull stopped short of its distance,
    and at its last joint positions the arm cannot move on along the line it pulled along,
    `SimulationResult.pull_line`, `reach_limit`); None where it did not. The handle is taken where
    the hand let go of it, the keypoints' path along the line it pulled along (`held_handle`,
    `handle_left_at`); `from_a_second_base` goes on."""
    if not (config.pull_on and config.pulls_to_stop(plan) and first.grasped
            and first.pulled_past < config.guarded_pull):
        return None
    reason = reach_limit(plan.X_WB, first.q_robot, first.pull_line)
    if reason is None:
        return None
    kt_on = handle_left_at(kt, held_handle(plan, first.q_robot), first.pull_line)
    return from_a_second_base(obj, kt, kt_on, reason, first, obstacles, planner_config, config, meshcat,
                              replay)


TURN_ON_MIN = float(np.radians(3.0))
"""The least angle (rad) a door's turn must end short of its target, as the robot measures it
(`door_turn` over its hand's whole held path), for it to turn on from a second base
(`turn_on`): over the second turn's 1 degree, under the task's 5."""


def turn_on(obj: SceneObject, kt: KeypointTrajectory, plan: PlanResult, first: SimulationResult,
            obstacles: list[ObstacleBox] | None, planner_config: PlannerConfig, config: SimulationConfig,
            meshcat: Meshcat | None, replay: Path | None) -> PulledOn | None:
    """A door's turn taken on from a second base where `first` ended at least `TURN_ON_MIN` short
    of the keypoints' turn to the target as the robot measures it: the angle its hand swept
    about the circle through its held path (`door_turn`; the arm's reach, a joint at its limit,
    or the second turn's largest step ended it; `SimulationConfig.pull_on`); None where it did
    not. The door is taken as the hand felt it (`felt_door`: about the felt hinge, the handle
    where the hand let go of it, turned by the angle swept); `from_a_second_base` goes on. The
    reason names the arm's limit where `reach_limit` finds one along the turn's way."""
    if not (config.pull_on and config.turns_again(plan, kt) and first.grasped):
        return None
    felt = first.p_W_tool[first.times >= first.felt_from]
    if len(felt) < 3:
        return None
    planned, planned_axis = planned_door_turn(kt, first.q_target)
    opening = 1.0 if planned >= 0.0 else -1.0  # the sign of the door's opening about the axis
    left, centre, axis = door_turn(felt, planned, planned_axis)
    if opening * left < TURN_ON_MIN:
        return None
    p_WH = held_handle(plan, first.q_robot)
    way = opening * np.cross(axis, p_WH - centre)
    reason = (reach_limit(plan.X_WB, first.q_robot, way / np.linalg.norm(way))
              or f"the turn ended {np.degrees(abs(left)):.0f} deg short")
    kt_on = felt_door(kt, felt, p_WH)
    return from_a_second_base(obj, kt, kt_on, reason, first, obstacles, planner_config, config, meshcat,
                              replay)


def from_a_second_base(obj: SceneObject, kt: KeypointTrajectory, kt_on: KeypointTrajectory, reason: str,
                       first: SimulationResult, obstacles: list[ObstacleBox] | None,
                       planner_config: PlannerConfig, config: SimulationConfig, meshcat: Meshcat | None,
                       replay: Path | None) -> PulledOn:
    """The task taken on from a second base, `reason` why: the base placed again for the part
    as the robot takes it when it let go (`kt_on`) as for any task (the obstacles those of the
    first plan: `obstacles`, else `kt`'s carcass box), and the second simulation starting with
    the part where `first` left it, the arm at home; the drive between the bases is not
    simulated. With `replay`, its replay goes beside it (`*_pulled_on.html`)."""
    try:
        plan_on = plan_articulation(kt_on, first.q_target, config=planner_config,
                                    obstacles=obstacles if obstacles is not None else [carcass_box(kt)])
    except PlanningError as err:
        return PulledOn(reason, None, str(err), None, None)
    obj_on = replace(obj, ground_truth=obj.ground_truth.with_current(first.q_final))
    if meshcat is not None:
        _show_plan(meshcat, kt_on, plan_on, first.q_target, obstacles, None)
    try:
        simulation = simulate_articulation(obj_on, plan_on, first.q_target, meshcat, config, keypoints=kt_on)
    except StartsInsideObject as err:
        return PulledOn(reason, None, str(err), None, None)
    path = None
    if replay is not None and meshcat is not None:
        path = write_replay(meshcat, replay.with_name(f"{replay.stem}_pulled_on{replay.suffix}"))
    return PulledOn(reason, plan_on, "", simulation, path)


def _show_plan(meshcat: Meshcat, kt: KeypointTrajectory, plan: PlanResult, q_target: float,
               obstacles: list[ObstacleBox] | None, reference: KeypointTrajectory | None) -> None:
    """Clear `meshcat`, draw the keypoint paths the planner used (and `reference`'s, under
    "keypoints_true") and its obstacle boxes, and look at the handle path and the robot from the
    side, from above."""
    meshcat.Delete()
    meshcat.DeleteRecording()
    draw_keypoint_trajectory(meshcat, kt, "keypoints", (kt.q_current, q_target))
    if reference is not None:
        draw_keypoint_trajectory(meshcat, reference, "keypoints_true",
                                 (reference.q_current, q_target), line_width=2.0)
    for box in (*(obstacles if obstacles is not None else [carcass_box(kt)]), door_panel_box(kt)):
        if box is not None:
            draw_obstacle(meshcat, box)
    p_handle = kt.point("handle", (kt.q_current + q_target) / 2)
    p_base = plan.X_WB.translation()
    centre = (p_handle + p_base) / 2 + [0.0, 0.0, 0.2]
    away = p_base - p_handle
    away[2] = 0.0
    away = away / np.linalg.norm(away)
    side = np.cross([0.0, 0.0, 1.0], away)
    frame_camera(meshcat, centre, centre + 0.3 * away + 1.2 * side + [0.0, 0.0, 0.8])


def replay_plan(kt: KeypointTrajectory, plan: PlanResult, q_target: float, replay: Path,
                meshcat: Meshcat | None = None, frames_per_second: float = 32.0) -> Path:
    """The planned motion alone as an HTML replay written to `replay`: the arm on its base (and lift
    column) following `plan.trajectory`, with the keypoint paths and the planner's boxes; nothing
    is simulated (keypoints without a model of the object, e.g. a fit to photos). Returns the path."""
    meshcat = meshcat or Meshcat()
    _show_plan(meshcat, kt, plan, q_target, None, None)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    robot = add_panda(plant, plan.X_WB)
    add_floor(plant)
    add_pedestal(plant, plan.X_WB)
    plant.Finalize()
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    meshcat.StartRecording(frames_per_second=frames_per_second, set_visualizations_while_recording=False)
    for t in np.r_[np.arange(0.0, plan.duration, 1.0 / frames_per_second), plan.duration]:
        context.SetTime(t)
        plant.SetPositions(plant_context, robot, plan.trajectory.value(t).ravel())
        diagram.ForcedPublish(context)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    return write_replay(meshcat, replay)
