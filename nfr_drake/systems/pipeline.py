"""The paper's pipeline in Drake: photograph an unseen object, fit, forward-simulate, plan, open.

Phase 1 (perception): a diagram with the object at X_WO and `NfrPerceptionSystem` fed by RgbdSensors
around it; initialising the simulator runs the fit once, giving the keypoint trajectory in W.
Phase 2 (action): the planner uses that trajectory alone; the arm is simulated on the true object
and an HTML replay shows the predicted (planned-with) and the true keypoint paths.

Between the two, the fit's confidence (`inference.confidence`) is checked: below the scenario's
`min_confidence` (by default the model's calibrated threshold) phase 2 does not run and the outcome
says why (`PipelineOutcome.refused`).

With ground-truth keypoints (`Scenario.keypoints`) phase 1 is skipped: the planner reads the
object's own keypoints.
"""

import math
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution, resolve_framing
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.rooms import Room, RoomDistribution, sample_room
from nfr_drake.errors import NfrDrakeError
from nfr_drake.inference.confidence import refusal
from nfr_drake.inference.infer import check_category
from nfr_drake.nfr.checkpoint import read_model_config
from nfr_drake.objects import ArticulatedObject
from nfr_drake.objects.plant import add_articulated_object, set_articulation
from nfr_drake.perception.object_pose import ObjectPoseError, background_mask
from nfr_drake.planning.planner import grasp_planner
from nfr_drake.systems.model_files import body_box, drawable_meshes
from nfr_drake.systems.perception import AddNfrPerception, NfrPerceptionSystem
from nfr_drake.systems.place_task import PlaceSimulationConfig, PlaceTaskOutcome, run_place_task
from nfr_drake.systems.scenario import Scenario
from nfr_drake.systems.scene_objects import SceneObject, set_joint_value
from nfr_drake.systems.task import TaskOutcome, run_task
from nfr_drake.world.cloud import SemanticCloud
from nfr_drake.world.keypoints import APPROACH_KEYPOINT, KeypointTrajectory
from nfr_drake.world.obstacles import box_corners

_ROOM_STREAM = 203  # the perception room's stream (the cameras use 7, the coarse look 20, the item 23)


@dataclass
class PipelineOutcome:
    """q_estimate / q_true in [0, 1]; keypoint_rmse_cm at the observed state (of a user's model
    file, `Scenario.object_file`, the handle's error alone); handle_path_rmse_cm over [0, 1] (nan
    for a model file, whose q need not span the field's); perception_seconds of the fit; predicted
    and true trajectories in W; the task (None when the fit was refused). Without perception
    (ground-truth keypoints, `perceived` False) the prediction is the truth. confidence: the fit
    result's `confidence` (or None); refused: why the planner did not act on the fit
    (`inference.confidence.refusal`), or on nothing (the object's masks gave no pose: predicted
    None, the errors inf), or ""; pose_error: with an estimated object pose, its position (cm, xy)
    and yaw (degrees) errors."""

    q_estimate: float
    q_true: float
    keypoint_rmse_cm: float
    handle_path_rmse_cm: float
    perception_seconds: float
    predicted: KeypointTrajectory | None
    truth: KeypointTrajectory
    task: TaskOutcome | None
    perceived: bool = True
    confidence: dict | None = None
    refused: str = ""
    pose_error: tuple[float, float] | None = None
    notes: tuple[str, ...] = ()
    """What loading a user's model file found unusual but plannable (`SceneObject.notes`)."""

    def report(self) -> str:
        task = self.task
        p = (self.confidence or {}).get("p_handle_within_2cm")
        confidence = "" if p is None else f"; P(handle within 2 cm) {p:.2f}"
        errors = (f"handle {self.keypoint_rmse_cm:.2f} cm from the model's at the observed state"
                  if math.isnan(self.handle_path_rmse_cm)  # a model file's: the handle alone compared
                  else f"keypoint error {self.keypoint_rmse_cm:.2f} cm RMSE at the observed state, "
                  f"handle path {self.handle_path_rmse_cm:.2f} cm RMSE over q in [0, 1]")
        lines = [f"warning: {note}" for note in self.notes]
        if self.perceived and self.predicted:
            lines.append(f"estimated q {self.q_estimate:.3f} (true {self.q_true:.3f}); {errors}; fit "
                         f"{self.perception_seconds:.1f} s{confidence}")
        if self.pose_error is not None:
            lines.append(f"object pose estimated: {self.pose_error[0]:.2f} cm, "
                         f"{self.pose_error[1]:.2f} deg from the true pose")
        if task is None:
            lines.append(self.refused)
        elif task.plan is None:
            lines.append(f"FAILURE: planning failed: {task.planning_error}")
        else:
            lines.append(f"planning time {task.planning_seconds:.2f} s")
            lines.append(task.simulation.summary() if isinstance(task, PlaceTaskOutcome) else task.summary())
        if isinstance(task, PlaceTaskOutcome) and task.opening_replay is not None:
            lines.append(f"replay of the opening: {task.opening_replay}")
        if task is not None and task.replay is not None:
            lines.append(f"replay: {task.replay}")
        if task is not None and task.pulled_on is not None and task.pulled_on.replay is not None:
            lines.append(f"replay from the second base: {task.pulled_on.replay}")
        return "\n".join(lines)


def perceive(scenario: Scenario, obj: ArticulatedObject) -> tuple[KeypointTrajectory, float]:
    """Phase 1: photograph `obj` (at q_start, pose X_WO) with Drake cameras and fit the model.

    Returns the predicted keypoint trajectory in W and the fit's wall time, s.
    """
    trajectory, seconds, _ = perceive_with_confidence(scenario, obj)
    return trajectory, seconds


def perceive_with_confidence(scenario: Scenario, obj: ArticulatedObject
                             ) -> tuple[KeypointTrajectory, float, dict | None]:
    """`perceive`, and the fit's confidence (the perception system's "confidence" port)."""
    perceived = perceive_scene(scenario, obj)
    return perceived.trajectory, perceived.seconds, perceived.confidence


@dataclass
class Perceived:
    """What `perceive_scene` returns: the keypoint trajectory in W, the fit's wall time (s), its
    confidence (the "confidence" port), the object's pose the keypoints were placed with (the
    "X_WO" port), and the fitted field's labelled points in W (the "semantic_cloud" port; None
    unless asked for)."""

    trajectory: KeypointTrajectory
    seconds: float
    confidence: dict | None
    X_WO: RigidTransform
    cloud: SemanticCloud | None = None


def perceive_scene(scenario: Scenario, obj: ArticulatedObject, part: int | None = None,
                   cloud: bool = False) -> Perceived:
    """Photograph `obj` and fit the field (`perception_simulator`): the pose is the scenario's, or
    the estimate with `Scenario.object_pose` "estimated", the cameras then around
    `Scenario.coarse_look`. With `Scenario.perceive` "room" the cameras see the object in
    `perception_room`. A piece of furniture is framed as its captures are (its bounds over every
    articulation in view, `CameraDistribution` "bounds") and the trajectory is that of its part
    `part` (the perception system's `part`). `cloud`: also render the fitted field's points."""
    return _fitted(*perception_simulator(scenario, obj, part), cloud)


def _fitted(simulator: Simulator, perception: NfrPerceptionSystem, cloud: bool = False) -> Perceived:
    """Initialise the perception diagram (the system fits there, once) and read its ports."""
    started = time.perf_counter()
    simulator.Initialize()
    seconds = time.perf_counter() - started
    context = perception.GetMyContextFromRoot(simulator.get_context())
    return Perceived(perception.get_keypoint_trajectory_output_port().Eval(context), seconds,
                     perception.get_confidence_output_port().Eval(context),
                     perception.get_X_WO_output_port().Eval(context),
                     perception.get_semantic_cloud_output_port().Eval(context) if cloud else None)


def _camera_poses(scenario: Scenario, framing: str, X_WA: RigidTransform, p_AT: np.ndarray,
                  bounds_A: tuple[np.ndarray, np.ndarray] | None, camera: PinholeCamera
                  ) -> list[RigidTransform]:
    """The perception cameras' poses X_WC around the look X_WA (`Scenario.coarse_look`), aimed near
    p_AT (A, m, (3,)), framing `bounds_A` (min and max corners in A, m) with framing "bounds",
    drawn from the scenario's seed and index."""
    rng = np.random.default_rng([scenario.seed, scenario.index, 7])
    cameras = CameraDistribution(distance_m=tuple(scenario.distance_m), framing=framing)
    return [X_WA @ RigidTransform(X) for X in cameras.sample(rng, scenario.views, p_AT, bounds_A, camera)]


def _perception_camera(scenario: Scenario) -> PinholeCamera:
    return PinholeCamera.from_fov(scenario.image_size, scenario.image_size, math.radians(scenario.fov_y_deg))


def _with_perception(builder: DiagramBuilder, plant, scene_graph, model, scenario: Scenario,
                     X_WCs: list[RigidTransform], camera: PinholeCamera, known: RigidTransform | None,
                     lighting=None, part: int | None = None) -> tuple[Simulator, NfrPerceptionSystem]:
    """The perception cameras at X_WCs and `NfrPerceptionSystem` (the object `model`, its pose
    `known` or None to estimate it) added to the finalised plant's diagram, built into a Simulator
    not yet initialised."""
    perception = AddNfrPerception(builder, plant, scene_graph, Path(scenario.model), model, known,
                                  X_WCs, camera, scenario.fit, lighting, scenario.keypoints,
                                  scenario.perceive, Path(scenario.segmenter), part,
                                  room_loss=scenario.room_loss, mask_crop=scenario.mask_crop,
                                  aimed_look=scenario.aimed_look, look_again=scenario.look_again,
                                  paintings=tuple(scenario.paintings), refine_masks=scenario.refine_masks)
    return Simulator(builder.Build()), perception


def perception_simulator(scenario: Scenario, obj: ArticulatedObject, part: int | None = None
                         ) -> tuple[Simulator, NfrPerceptionSystem]:
    """The diagram `perceive_scene` photographs `obj` with (the object at X_WO and q_start, the
    perception cameras, named `nfr_camera_{i}`, and `NfrPerceptionSystem`) in a Simulator not yet
    initialised, so nothing is fitted until `Initialize`."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    X_WO = scenario.X_WO
    model = add_articulated_object(plant, obj, X_WO)
    camera = _perception_camera(scenario)
    framing = resolve_framing("auto", obj.category)
    X_WCs = _camera_poses(scenario, framing, scenario.coarse_look(),
                          *CameraDistribution(framing=framing).target_of(obj), camera)
    lighting = None
    if scenario.perceive == "room":
        room = perception_room(scenario, obj, X_WCs)
        room.add_to(plant, X_WO.GetAsMatrix4())
        lighting = room.lighting.moved(X_WO.GetAsMatrix4())
    plant.Finalize()
    known = X_WO if scenario.object_pose == "given" else None
    simulator, perception = _with_perception(builder, plant, scene_graph, model, scenario, X_WCs, camera,
                                             known, lighting, part)
    set_articulation(plant, plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()),
                     obj, model, scenario.q_start)
    return simulator, perception


def canonical_part(plant, scene_graph, model, scene_object: SceneObject, X_WO: RigidTransform) -> int:
    """The index of a model file's door or drawer among its fronts in the furniture field's
    canonical order (docs/FURNITURE.md, "Part order": by the left edge of what each one-dof joint
    moves, seen from the front, to the millimetre, then by its top edge, highest first), all shut,
    in frame O (`SceneObject.category_frame`). The plant is finalised, its joints at 0."""
    inspector = scene_graph.model_inspector()
    context = plant.CreateDefaultContext()
    X_OW = X_WO.inverse()
    edges = {}
    for name in (scene_object.joint_name, *scene_object.locked_joints):
        joint = plant.GetJointByName(name, model)
        if name == scene_object.joint_name:
            set_joint_value(plant, context, joint, scene_object.shut_and_open(joint)[0])
        corners = []
        for index in plant.GetBodiesKinematicallyAffectedBy([joint.index()]):
            box = body_box(plant, inspector, plant.get_body(index))
            if box is not None:
                X_OB = X_OW @ plant.EvalBodyPoseInWorld(context, plant.get_body(index))
                corners.append(box_corners(X_OB @ RigidTransform((box[0] + box[1]) / 2), box[1] - box[0]))
        if corners:
            p_O = np.concatenate(corners)
            edges[name] = (round(float(p_O[:, 1].min()), 3), -float(p_O[:, 2].max()))
    return sorted(edges, key=edges.get).index(scene_object.joint_name)


def model_file_perception_simulator(scenario: Scenario, scene_object: SceneObject,
                                    frame: tuple[RigidTransform, tuple[np.ndarray, np.ndarray]]
                                    ) -> tuple[Simulator, NfrPerceptionSystem, list[str]]:
    """`perception_simulator` for a user's model file (`Scenario.object_file`, loaded as
    `scene_object`): the model as its file and pose place it, the door or drawer at q_start and
    its other joints shut, the cameras framing its shut bounds (framing "bounds", as furniture's)
    around its frame O (`frame`: X_WO and the shut bounds in O, `SceneObject.category_frame`; or a
    coarse look at it when the pose is estimated); the fit is given that O with
    `Scenario.object_pose` "given". Also the notes of `drawable_meshes` (visual meshes the cameras
    see a copy of)."""
    X_WO, bounds_O = frame
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    model = scene_object.add_to(plant)
    notes = drawable_meshes(plant, scene_graph, model, Path(tempfile.gettempdir()) / "nfr_drake_meshes")
    plant.Finalize()
    camera = _perception_camera(scenario)
    X_WCs = _camera_poses(scenario, "bounds", scenario.coarse_look(X_WO), (bounds_O[0] + bounds_O[1]) / 2,
                          bounds_O, camera)
    furniture = read_model_config(Path(scenario.model)).get("category") == "furniture"
    part = canonical_part(plant, scene_graph, model, scene_object, X_WO) if furniture else None
    simulator, perception = _with_perception(builder, plant, scene_graph, model, scenario, X_WCs, camera,
                                             X_WO if scenario.object_pose == "given" else None, part=part)
    context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    joint = plant.GetJointByName(scene_object.joint_name, model)
    shut, opened = scene_object.shut_and_open(joint)
    set_joint_value(plant, context, joint, shut + scenario.q_start * (opened - shut))
    for name in scene_object.locked_joints:
        set_joint_value(plant, context, plant.GetJointByName(name, model), 0.0)
    return simulator, perception, notes


def perception_photos(scenario: Scenario) -> tuple[list[np.ndarray], list[np.ndarray], list[PinholeCamera]]:
    """What the scenario's perception cameras see of its object (`perception_simulator`; nothing
    is fitted): uint8 RGB photos (H, W, 3), the cameras' poses X_WC (4, 4) in W and intrinsics."""
    images, _, X_WCs, cameras = _shots(scenario, depth=False)
    return images, X_WCs, cameras


def perception_photos_and_depths(scenario: Scenario) -> tuple[list[np.ndarray], list[np.ndarray],
                                                                list[np.ndarray], list[PinholeCamera]]:
    """`perception_photos` with each camera's depth image (H, W) float32, m (inf where nothing is
    within its range): photos, depths, X_WCs, intrinsics."""
    return _shots(scenario, depth=True)


def _shots(scenario: Scenario, depth: bool) -> tuple[list[np.ndarray], list[np.ndarray],
                                                     list[np.ndarray], list[PinholeCamera]]:
    """Photos, depths (rendered only with `depth`, else an empty list), X_WCs and intrinsics of the
    scenario's perception cameras."""
    simulator, perception = perception_simulator(scenario, scenario.sample_object())
    diagram, context = simulator.get_system(), simulator.get_context()
    images, depths = [], []
    for i in range(len(perception.cameras)):
        sensor = diagram.GetSubsystemByName(f"nfr_camera_{i}")
        sensor_context = sensor.GetMyContextFromRoot(context)
        images.append(sensor.color_image_output_port().Eval(sensor_context).data[..., :3].copy())
        if depth:
            depths.append(sensor.depth_image_32F_output_port().Eval(sensor_context).data[..., 0].copy())
    return images, depths, [X.GetAsMatrix4() for X in perception.camera_poses], perception.cameras


VISIBLE_DEPTH_M = 0.02
"""A pixel of the object's silhouette is visible in the room when the room's depth there is within
this of the object's depth alone."""


def visible_silhouettes(alone: list[np.ndarray], alone_depths: list[np.ndarray],
                        room_depths: list[np.ndarray]) -> list[np.ndarray]:
    """The object's true visible mask (H, W) bool per view, from the same cameras' photos of it
    alone (uint8 RGB before the training background) and their depths alone and in its room (m):
    its silhouette (the pixels off that background) where nothing of the room (the arm, clutter)
    lies in front of it."""
    return [(background_mask(image, DEFAULT_BACKGROUND_RGB) > 0.5)
            & (np.abs(d_room - d_alone) < VISIBLE_DEPTH_M)
            for image, d_alone, d_room in zip(alone, alone_depths, room_depths, strict=True)]


def perception_room(scenario: Scenario, obj: ArticulatedObject, X_WCs: list[RigidTransform]) -> Room:
    """The room the perception cameras at X_WCs see `obj` in (frame W of the room = O): drawn from
    the scenario's seed and index (`sample_room`, held-out textures and lights, the cameras'
    framing unused: they are given), kept clear of the cameras."""
    X_OW = scenario.X_WO.inverse()
    p_OC = np.stack([(X_OW @ X_WC).translation() for X_WC in X_WCs])
    rng = np.random.default_rng([scenario.seed, scenario.index, _ROOM_STREAM])
    return sample_room(rng, obj, p_OC, RoomDistribution(style="heldout"))


def _pose_error(X_WO: RigidTransform, X_WO_estimated: RigidTransform) -> tuple[float, float]:
    """How far an estimated object pose is from the true one: position on the floor (cm) and yaw
    (degrees)."""
    error = X_WO.inverse() @ X_WO_estimated
    return (100.0 * float(np.linalg.norm(error.translation()[:2])),
            abs(math.degrees(RollPitchYaw(error.rotation()).yaw_angle())))


def _rmse_cm(a: np.ndarray, b: np.ndarray) -> float:
    return float(100.0 * np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def _run(scenario: Scenario, obj: ArticulatedObject | None, scene_object: SceneObject,
         keypoints: KeypointTrajectory | None, reference: KeypointTrajectory | None,
         replay: Path | None, cloud: SemanticCloud | None = None) -> TaskOutcome | PlaceTaskOutcome:
    """Phase 2: the scenario's task planned with `keypoints` (None: the object's own; `cloud`: the
    fitted field's points they came with, which size the moving part's obstacles for the place).
    `obj` (the generated object) is read by the place task only: a model file's is None."""
    simulation = replace(scenario.simulation, grasp=scenario.grasp)
    planner = grasp_planner(scenario.planner, scenario.grasp)
    if scenario.task == "open-and-place":
        return run_place_task(obj, scenario.X_WO, scenario.q_start, scenario.q_target, scenario.sample_item(),
                              keypoints=keypoints, reference=reference, replay=replay, planner_config=planner,
                              simulation_config=PlaceSimulationConfig(opening=simulation), cloud=cloud)
    return run_task(scene_object, scenario.q_target, keypoints=keypoints, replay=replay, reference=reference,
                    planner_config=planner, simulation_config=simulation)


def run_scenario(scenario: Scenario) -> PipelineOutcome:
    """Both phases (the first only when the scenario perceives); the replay (if asked for) draws
    the keypoint paths the planner used and, with perception, the true ones. A piece of furniture
    is opened at its part `Scenario.sample_piece` names, the others held shut. NfrDrakeError first
    when the model is not of the scenario's category."""
    if scenario.object_file:
        return _run_model_file(scenario)
    if scenario.perceives:
        check_category(Path(scenario.model), read_model_config(Path(scenario.model)).get("category"),
                       scenario.category, "scenario", "object")
    obj, part = scenario.sample_piece()
    scene_object = SceneObject.from_articulated_object(obj, scenario.X_WO, scenario.q_start, part)
    replay = Path(scenario.replay) if scenario.replay else None
    if not scenario.perceives:
        task = _run(scenario, obj, scene_object, None, None, replay)
        return PipelineOutcome(q_estimate=scenario.q_start, q_true=scenario.q_start,
                               keypoint_rmse_cm=0.0, handle_path_rmse_cm=0.0, perception_seconds=0.0,
                               predicted=task.keypoints, truth=task.keypoints, task=task,
                               perceived=False)
    truth = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, scenario.q_start, part=part)
    try:
        perceived = perceive_scene(scenario, obj, part if scenario.category == "furniture" else None,
                                   cloud=scenario.task == "open-and-place")
    except ObjectPoseError as err:
        return PipelineOutcome(q_estimate=math.nan, q_true=scenario.q_start, keypoint_rmse_cm=math.inf,
                               handle_path_rmse_cm=math.inf, perception_seconds=math.nan, predicted=None,
                               truth=truth, task=None, refused=f"nothing planned: {err}",
                               pose_error=(math.inf, math.inf))
    predicted, confidence = perceived.trajectory, perceived.confidence
    pose_error = _pose_error(scenario.X_WO, perceived.X_WO) if scenario.object_pose == "estimated" else None
    names = [n for n in truth.names if n in predicted.names]
    now = lambda kt: np.stack([kt.point(n, kt.q_current) for n in names])  # noqa: E731
    grid = truth.q_grid
    refused = refusal(confidence, None if scenario.min_confidence < 0 else scenario.min_confidence)
    task = None if refused else _run(scenario, obj, scene_object, predicted, truth, replay, perceived.cloud)
    return PipelineOutcome(
        q_estimate=predicted.q_current, q_true=scenario.q_start,
        keypoint_rmse_cm=_rmse_cm(now(predicted), now(truth)),
        handle_path_rmse_cm=_rmse_cm(predicted.point("handle", grid), truth.point("handle", grid)),
        perception_seconds=perceived.seconds, predicted=predicted, truth=truth, task=task,
        confidence=confidence, refused=refused or "", pose_error=pose_error)


def _run_model_file(scenario: Scenario) -> PipelineOutcome:
    """`run_scenario` on a user's model file (`Scenario.object_file`): photographed alone and fitted
    (`model_file_perception_simulator`) with `Scenario.model` or, left empty, models/furniture
    (which fits every front and gives the joint's, `canonical_part`; a closet or drawer model must
    be of the joint's kind), planned with the fitted keypoints and simulated on the model. The
    error is the handle's alone: the hinge keypoints of a model's joint lie on its axis either side
    of the handle, the field's at the door's top and bottom edges. NfrDrakeError for a sliding door
    (no model of them) or a model of another kind than the joint's."""
    scene_object = scenario.model_file_object()
    if APPROACH_KEYPOINT in scene_object.ground_truth.names:
        raise NfrDrakeError(f"joint {scenario.joint!r} slides sideways (a sliding door): no neural field "
                            "model of sliding doors; plan with its own keypoints (nfr-drake plan --object)")
    truth = scene_object.ground_truth
    replay = Path(scenario.replay) if scenario.replay else None
    if not scenario.perceives:
        task = _run(scenario, None, scene_object, None, None, replay)
        return PipelineOutcome(q_estimate=scenario.q_start, q_true=scenario.q_start, keypoint_rmse_cm=0.0,
                               handle_path_rmse_cm=0.0, perception_seconds=0.0, predicted=truth, truth=truth,
                               task=task, perceived=False, notes=scene_object.notes)
    model = Path(scenario.model or "models/furniture")
    model_category = read_model_config(model).get("category")
    if model_category != "furniture":  # a furniture model has doors and drawers
        check_category(model, model_category, scene_object.category,
                       f"{scenario.object_file}: joint {scenario.joint!r}",
                       "door" if scene_object.category == "closet" else "drawer")
    scenario = replace(scenario, model=str(model))
    frame = scene_object.category_frame()
    simulator, perception, drawn = model_file_perception_simulator(scenario, scene_object, frame)
    notes = (*scene_object.notes, *drawn)
    try:
        perceived = _fitted(simulator, perception)
    except ObjectPoseError as err:
        return PipelineOutcome(q_estimate=math.nan, q_true=scenario.q_start, keypoint_rmse_cm=math.inf,
                               handle_path_rmse_cm=math.inf, perception_seconds=math.nan, predicted=None,
                               truth=truth, task=None, refused=f"nothing planned: {err}", notes=notes)
    predicted, confidence = scene_object.in_joint_units(perceived.trajectory), perceived.confidence
    pose_error = _pose_error(frame[0], perceived.X_WO) if scenario.object_pose == "estimated" else None
    handle_error = 100.0 * float(np.linalg.norm(predicted.point("handle", predicted.q_current)
                                                - truth.point("handle", truth.q_current)))
    refused = refusal(confidence, None if scenario.min_confidence < 0 else scenario.min_confidence)
    task = None if refused else _run(scenario, None, scene_object, predicted, truth, replay)
    return PipelineOutcome(
        q_estimate=predicted.q_current, q_true=scenario.q_start, keypoint_rmse_cm=handle_error,
        handle_path_rmse_cm=math.nan, perception_seconds=perceived.seconds, predicted=predicted, truth=truth,
        task=task, confidence=confidence, refused=refused or "", pose_error=pose_error, notes=notes)
