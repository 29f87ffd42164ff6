"""Open, then place: the paper's last step (its Fig. 1e), planned and simulated on the true object.

The scene: the object, the arm where the opening plan put its base, a small table beside the
arm (`table_beside`) with an item on it (`nfr_drake.world.items`). The opening is simulated
first (`simulate_articulation`, with its further closes, second pull and door turn, then, as in
`run_task`, from a second base where the arm's reach ended it: `pull_on`, `turn_on`), then the
place (`simulate_place`) in a second simulation that starts with the front where the opening left it,
at rest: from the same base with the arm where the opening left it, its fingers on the handle,
or (`MOVE_BASE`: closets) from a second base with the arm at the place's first posture; the
base's drive between the two (the hand letting go, the arm tucking in) is not simulated, and the
table stands beside the place's base.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from pydrake.geometry import (
    AddContactMaterial,
    AddRigidHydroelasticProperties,
    Box,
    CollisionFilterDeclaration,
    GeometrySet,
    Meshcat,
    MeshcatVisualizer,
    ProximityProperties,
)
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from nfr_drake.objects.articulated import ArticulatedObject
from nfr_drake.planning.compartment import (
    InteriorLook,
    compartment_entry,
    compartment_obstacles,
    front_normal,
)
from nfr_drake.planning.place import (
    GRASP_OF,
    PLACE_REACH,
    PlaceConfig,
    PlacePlan,
    PlaceUnreachable,
    fallback_configs,
    place_bases,
    place_problem,
    place_reach_points,
    plan_place,
    ready_posture,
)
from nfr_drake.planning.planner import PlannerConfig, PlanningError, grasp_planner, plan_articulation
from nfr_drake.systems.articulation import (
    SecondPull,
    SimulationConfig,
    SimulationResult,
    StartsInsideObject,
    add_gravity_compensation,
    add_joint_friction,
    couple_fingers,
    hydroelastic_grip,
    joint_error_text,
    rigid_hydroelastic,
    set_arm_gains,
    simulate_articulation,
)
from nfr_drake.systems.interior import look_into_compartment
from nfr_drake.systems.replay import draw_keypoint_trajectory, draw_obstacle, frame_camera, write_replay
from nfr_drake.systems.scene_objects import SceneObject, set_joint_value
from nfr_drake.systems.task import PulledOn, ended_in, pull_on, turn_on
from nfr_drake.world.cloud import SemanticCloud
from nfr_drake.world.items import Item
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.obstacles import distance_to_box, object_obstacles
from nfr_drake.world.plan import ObstacleBox, PlanResult
from nfr_drake.world.robot import (
    FINGER_OPEN,
    HAND_BODIES,
    NUM_ARM_JOINTS,
    TOOL_FRAME,
    add_floor,
    add_panda,
    add_pedestal,
)

TABLE_TOP = (0.3, 0.3)
"""The table top's extent, m."""
TABLE_ABOVE_BASE = 0.35
"""The table top's height above the robot base, m (a level hand reaches the item more easily
there than near the shoulder's height, 0.33 m)."""
_TABLE_BEARINGS_DEG = (90.0, 70.0, 110.0, 50.0, 130.0)
"""Directions of the table from the base tried, from its forward axis, degrees (both sides)."""
ITEM_REACH = {"side": 0.6, "top": 0.5}
"""The item's horizontal distance from the base axis, by grasp, m: a horizontal hand needs room."""
_TABLE_CLEARANCE = 0.08
_TABLE_SIGHT_CLEARANCE = 0.06


def table_beside(X_WB: RigidTransform, obstacles: list[ObstacleBox], reach: float
                 ) -> tuple[ObstacleBox, RigidTransform]:
    """A table at the robot's side clear of `obstacles` by `_TABLE_CLEARANCE`, its centre `reach`
    from the base axis, the straight line from 0.2 m above the table top on the base axis to the
    item clear of them by `_TABLE_SIGHT_CLEARANCE` (no open door between the arm and the item),
    and the pose X_WI of an item at its centre, its x axis pointing away from the base. Raises
    PlanningError when no spot is clear."""
    z_top = X_WB.translation()[2] + TABLE_ABOVE_BASE
    size = np.array([*TABLE_TOP, z_top])
    yaw = RollPitchYaw(X_WB.rotation()).yaw_angle()
    for bearing in np.radians(_TABLE_BEARINGS_DEG):
        for side in (1.0, -1.0):
            p_BT = reach * np.array([np.cos(bearing), side * np.sin(bearing), 0.0])
            p_WT = X_WB.translation() * [1, 1, 0] + X_WB.rotation() @ p_BT
            X_WT = RigidTransform(RollPitchYaw(0, 0, yaw), p_WT + [0, 0, z_top / 2])
            table = ObstacleBox("table", size, X_WT)
            grid = np.linspace(-1.0, 1.0, 5)
            pts = np.array([[a, b, c] for a in grid for b in grid for c in (-1, 1)]) * size / 2
            pts = (table.X_WB.rotation().matrix() @ pts.T).T + table.X_WB.translation()
            f = np.linspace(0.0, 1.0, 10)[:, None]
            start = X_WB.translation() * [1, 1, 0] + [0, 0, z_top + 0.2]
            sight = (1 - f) * start + f * (p_WT + [0, 0, z_top])
            if all(distance_to_box(box, pts).min() >= _TABLE_CLEARANCE
                   and distance_to_box(box, sight).min() >= _TABLE_SIGHT_CLEARANCE for box in obstacles):
                radial = p_WT - X_WB.translation() * [1, 1, 0]
                X_WI = RigidTransform(RollPitchYaw(0, 0, np.arctan2(radial[1], radial[0])),
                                      [p_WT[0], p_WT[1], z_top])
                return table, X_WI
    raise PlanningError("no spot beside the robot for the table clears the object")


@dataclass
class PlaceSimulationConfig:
    """Options of `simulate_place`; `opening` are those of the opening's simulation
    (`SimulationConfig`: time step, dwell, grasp capture, tolerances, and the grasp: "constraint",
    the hand holding the handle with a ball constraint and the item with a weld, switched on when
    the fingers close on them, or "contact", the fingers squeezing and friction holding)."""

    opening: SimulationConfig = field(default_factory=SimulationConfig)
    release: float = 0.4
    """Time the fingers take to open on the handle, then on the item, s."""
    pick_dwell: float = 0.6
    """Time the hand rests on the item while the fingers close, s."""
    settle: float = 1.0
    """Time after the last motion before the outcome is measured, s."""
    place_tolerance: float = 0.03
    """Largest distance from the item's bottom centre to the goal keypoint, m."""
    rest_speed: float = 0.01
    """The item rests when its speed is below this, m/s."""


@dataclass
class PlaceSimulationResult:
    """What the simulated arm did: the opening before the place (its `SimulationResult`), then
    the place: picked (the item left the table in the hand), item_error (its bottom centre to
    the true goal at the end, m), inside (its centre in the compartment's inner box), resting
    (speed under `rest_speed`), q_final (articulation at the end; `still_open`: within the
    opening's tolerance of the target). times (s, (M,)), q_object ((M,)), p_W_item (m, (M, 3)):
    the samples."""

    opening: SimulationResult = field(repr=False)
    picked: bool
    item_error: float
    inside: bool
    resting: bool
    q_final: float
    still_open: bool
    success: bool
    times: np.ndarray = field(repr=False)
    q_object: np.ndarray = field(repr=False)
    p_W_item: np.ndarray = field(repr=False)

    def summary(self) -> str:
        verdict = "SUCCESS" if self.success else "FAILURE"
        o = self.opening
        return (f"{verdict} ({o.grasp} grasp): opened {o.success} (articulation {o.q_final:.3f}, "
                f"target {o.q_target:.3f}, error {joint_error_text(o.joint_type, o.joint_error)}, "
                f"handle grasped {o.grasped}); item picked {self.picked}, {self.item_error * 100:.1f} cm "
                f"from the goal, inside {self.inside}, resting {self.resting}; front still open "
                f"{self.still_open} (articulation {self.q_final:.3f})")


@dataclass
class _Timeline:
    """Times of the place's run, s: the item's grasp (switched on) and release, the end; the
    hand's backing off (from, duration: the first piece of the segment to the item)."""

    t_item: float
    t_item_release: float
    t_end: float
    t_back: float
    back_duration: float


def _desired_states(place: PlacePlan, cfg: PlaceSimulationConfig, finger_start: float,
                    item_half_width: float, finger_item: float) -> tuple[PiecewisePolynomial, _Timeline]:
    """[q; v] of the robot (9 + 9) over the place's run: the arm at the place's first positions
    while the fingers open from `finger_start` (`release`), the segments with the fingers closing
    on the item after the first (to its sides in 70% of the dwell, then to `finger_item`: a
    contact grasp does not hit it) and opening after the second, the settling time."""
    to_pick, carry, retreat = place.segments
    t1 = cfg.release
    t2 = t1 + to_pick.duration
    t3 = t2 + cfg.pick_dwell
    t4 = t3 + carry.duration
    t5 = t4 + cfg.release
    t6 = t5 + retreat.duration
    end = t6 + cfg.settle
    times = np.unique(np.r_[np.arange(0.0, end, 0.01), t1, t2, t3, t4, t5, t6, end])

    def arm(t: float) -> np.ndarray:
        if t < t1:
            return to_pick.value(0.0)
        start, seg = max(((s, g) for s, g in ((t1, to_pick), (t3, carry), (t5, retreat)) if s <= t),
                         key=lambda pair: pair[0])
        return seg.value(min(t - start, seg.duration))

    def fingers(t: float) -> float:
        ramp = lambda a, b, t0, d: a + np.clip((t - t0) / d, 0.0, 1.0) * (b - a)  # noqa: E731
        if t < t2:
            return ramp(finger_start, FINGER_OPEN, 0.0, cfg.release)
        if t < t2 + 0.7 * cfg.pick_dwell:
            return ramp(FINGER_OPEN, item_half_width, t2, 0.7 * cfg.pick_dwell)
        if t < t4:
            return finger_item
        return ramp(finger_item, FINGER_OPEN, t4, cfg.release)

    q = np.array([arm(t) for t in times])
    v = np.gradient(q, times, axis=0)
    q[:, NUM_ARM_JOINTS:] = np.array([fingers(t) for t in times])[:, None]
    v[:, NUM_ARM_JOINTS:] = 0.0
    back = float(to_pick.pieces[0].end_time() - to_pick.pieces[0].start_time())
    timeline = _Timeline(t2 + 0.5 * cfg.pick_dwell, t4, end, t1, back)
    return PiecewisePolynomial.FirstOrderHold(times, np.hstack([q, v]).T), timeline


def _interior(obj: ArticulatedObject, X_WO: RigidTransform, q: float) -> tuple[RigidTransform, np.ndarray]:
    """The compartment's inner box (pose X_WC of its centre, half extents, m) of a closet, or of a
    drawer pulled out to q, from the sampled parameters."""
    p = obj.params
    W, D, H, t = p["width"], p["depth"], p["height"], p["panel_thickness"]
    if obj.category == "closet":
        centre, half = [0.0, 0.0, H / 2], [D / 2 - t, W / 2 - t, H / 2 - t]
    else:
        box_d = p["box_depth"]
        x_front = D / 2 + q * obj.front(0).joint_upper
        centre, half = [x_front - box_d / 2, 0.0, H / 2], [box_d / 2, W / 2 - t, H / 2 - t]
    return X_WO @ RigidTransform(centre), np.array(half)


def simulate_place(obj: ArticulatedObject, X_WO: RigidTransform, opening: SimulationResult, place: PlacePlan,
                   item: Item, table: ObstacleBox, arm_start: np.ndarray | None = None,
                   meshcat: Meshcat | None = None, config: PlaceSimulationConfig | None = None
                   ) -> PlaceSimulationResult:
    """After `opening` (the simulated opening of front 0 of `obj` at X_WO), pick `item` from
    `table` and place it with `place`, in a SAP simulation that starts with the front where the
    opening left it (`opening.q_final`); records into `meshcat` if given. `arm_start`: the
    robot's positions (9,) where the opening ended, its base being the place's (the hand lets go
    of the handle and backs off from where it is, `SimulationResult.q_robot`); None: the base
    moved, the arm starts at the place's first positions with the fingers open."""
    cfg = config or PlaceSimulationConfig()
    sim = cfg.opening
    X_WB = place.X_WB
    scene_object = SceneObject.from_articulated_object(obj, X_WO, opening.q_final)
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=sim.time_step, discrete_contact_approximation="sap"), builder)
    robot = add_panda(plant, X_WB)
    add_floor(plant)
    add_pedestal(plant, X_WB)
    model = scene_object.add_to(plant)
    shape = Box(*table.size)
    world = plant.world_body()
    table_props = ProximityProperties()
    AddContactMaterial(friction=CoulombFriction(0.8, 0.8), properties=table_props)
    AddRigidHydroelasticProperties(0.004, table_props)
    plant.RegisterCollisionGeometry(world, table.X_WB, shape, "table", table_props)
    plant.RegisterVisualGeometry(world, table.X_WB, shape, "table", np.array([0.55, 0.4, 0.3, 1.0]))
    item_body = item.add_to(plant)  # compliant hydroelastic; the object rigid, to rest on
    object_bodies = [plant.get_body(b) for b in plant.GetBodyIndices(model)]
    if sim.contact:
        hydroelastic_grip(plant, scene_graph, [plant.GetBodyByName(name, robot) for name in HAND_BODIES[1:]],
                          object_bodies)
    else:
        rigid_hydroelastic(plant, scene_graph, object_bodies)
    set_arm_gains(plant, robot)
    couple_fingers(plant, robot)
    hand = plant.GetBodyByName("panda_hand", robot)
    X_HT = plant.GetFrameByName(TOOL_FRAME, robot).GetFixedPoseInBodyFrame()
    item_id = None if sim.contact else plant.AddWeldConstraint(hand, X_HT @ place.X_GI, item_body,
                                                               RigidTransform())
    plant.Finalize()

    joint = plant.GetJointByName(scene_object.joint_name, model)
    if not sim.contact:  # the constraints are the grasps: the hand does not touch what it holds
        hand_bodies = [plant.GetBodyByName(name, robot) for name in HAND_BODIES]
        moving = [plant.get_body(b) for b in plant.GetBodiesKinematicallyAffectedBy([joint.index()])]
        hand_set, held = (GeometrySet([g for b in bodies for g in plant.GetCollisionGeometriesForBody(b)])
                          for bodies in (hand_bodies, [*moving, item_body]))
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration().ExcludeBetween(hand_set, held))

    _controller_plant = add_gravity_compensation(builder, plant, robot, X_WB)  # held while the run lasts
    add_joint_friction(builder, plant, joint)
    finger_start = FINGER_OPEN if arm_start is None else sim.finger_target(sim.finger_closed)
    desired, times = _desired_states(place, cfg, finger_start, item.width / 2,
                                     sim.finger_target(item.width / 2))
    source = builder.AddNamedSystem("plan", TrajectorySource(desired))
    let_go = builder.AddNamedSystem("let_go", SecondPull(plant.num_positions(robot)))
    builder.Connect(source.get_output_port(), let_go.get_input_port(0))
    builder.Connect(plant.get_state_output_port(robot), let_go.get_input_port(1))
    builder.Connect(let_go.get_output_port(), plant.get_desired_state_input_port(robot))
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()

    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    ctx = plant.GetMyMutableContextFromRoot(root)
    lower, opened = scene_object.shut_and_open(joint)
    span = opened - lower
    set_joint_value(plant, ctx, joint, lower + opening.q_final * span)
    q_place = desired.value(0.0).ravel()[:plant.num_positions(robot)]
    plant.SetPositions(ctx, robot, q_place if arm_start is None else arm_start)
    if arm_start is not None:  # held where the opening left it, the offset fading as the hand backs off
        let_go.set(root, (arm_start - q_place)[:NUM_ARM_JOINTS], -1.0, 1e-3, times.t_back,
                   times.back_duration)
    plant.SetFreeBodyPose(ctx, item_body, place.X_WI_pick)
    if item_id is not None:
        plant.SetConstraintActiveStatus(ctx, item_id, False)
    if meshcat is not None:
        meshcat.StartRecording(frames_per_second=32.0, set_visualizations_while_recording=False)
    simulator.Initialize()

    tool = plant.GetFrameByName(TOOL_FRAME, robot)
    samples = np.unique(np.r_[np.arange(0.0, times.t_end, sim.sample_period), times.t_item,
                              times.t_item_release, times.t_end])
    p_item, q_object, lifted = [], [], 0.0
    for t in samples:
        simulator.AdvanceTo(t)
        X_WI = plant.EvalBodyPoseInWorld(ctx, item_body)
        if t == times.t_item and item_id is not None:
            X_WT = tool.CalcPoseInWorld(ctx)
            offset = np.linalg.norm((X_WT.inverse() @ X_WI).translation() - place.X_GI.translation())
            if offset <= np.linalg.norm(sim.capture_half_extents):
                plant.SetConstraintActiveStatus(ctx, item_id, True)
        if t == times.t_item_release and item_id is not None:
            plant.SetConstraintActiveStatus(ctx, item_id, False)
        if times.t_item < t <= times.t_item_release:
            lifted = max(lifted, X_WI.translation()[2] - place.X_WI_pick.translation()[2])
        p_item.append(X_WI.translation())
        q_object.append((joint.GetOnePosition(ctx) - lower) / span)
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()

    revolute = joint.type_name() == "revolute"
    tolerance = sim.revolute_tolerance if revolute else sim.prismatic_tolerance
    q_final = q_object[-1]
    X_WI = plant.EvalBodyPoseInWorld(ctx, item_body)
    goal = scene_object.ground_truth.point("goal", q_final)
    item_error = float(np.linalg.norm(X_WI.translation() - goal))
    X_WC, half = _interior(obj, X_WO, q_final)
    inside = bool(np.all(np.abs(X_WC.inverse() @ (X_WI @ [0.0, 0.0, item.height / 2])) <= half))
    resting = float(np.linalg.norm(plant.EvalBodySpatialVelocityInWorld(ctx, item_body).translational())) \
        < cfg.rest_speed
    still_open = abs(q_final - opening.q_target) * abs(span) <= tolerance
    picked = lifted >= 0.5 * PlaceConfig().lift_height
    success = opening.success and picked and inside and resting and still_open \
        and item_error <= cfg.place_tolerance
    return PlaceSimulationResult(opening, picked, item_error, inside, resting, float(q_final), still_open,
                                 success, samples, np.array(q_object), np.array(p_item))


@dataclass
class PlaceTaskOutcome:
    """Result of `run_place_task`: the opening plan and the place plan (None where planning
    failed, `planning_error` then says why), their planning time (s), the simulation (None
    without both plans), the replay's path, and the opening's simulation (where it ran: also when
    the place, planned after it from a moved base, then found no plan) and its replay's path."""

    q_target: float
    keypoints: KeypointTrajectory
    plan: PlanResult | None
    place: PlacePlan | None
    planning_error: str
    planning_seconds: float
    simulation: PlaceSimulationResult | None
    replay: Path | None
    opening: SimulationResult | None = None
    opening_replay: Path | None = None
    pulled_on: PulledOn | None = None
    """The opening taken on from a second base (`systems.task.pull_on`, `turn_on`), where it was."""

    @property
    def opened(self) -> SimulationResult | None:
        """The simulation the opening ended in: the second base's where it pulled on, else the first."""
        return ended_in(self.opening, self.pulled_on)

    @property
    def success(self) -> bool:
        return self.simulation is not None and self.simulation.success


def true_compartment(obj: ArticulatedObject, X_WO: RigidTransform, q: float
                     ) -> tuple[list[ObstacleBox], list[ObstacleBox]]:
    """The true model's boxes, one per part (`object_obstacles` unmerged: the compartment stays
    hollow), at articulation q: those that stay put and those of front 0 (the moving one)."""
    boxes = object_obstacles(obj, X_WO, q, moving=-1, merge=False)
    moving = [b for b in boxes if b.name.startswith("front0_")]
    return [b for b in boxes if not b.name.startswith("front0_")], moving


MOVE_BASE = {"closet": True, "drawer": False}
"""Whether the base moves between the opening and the place, by category: a closet's door must be
opened from where its sweep allows and its floor reached through the open front from in front
of it, which one base seldom does; a drawer's box is reached from where its handle was pulled
(there the base moves only when no one base serves both)."""


def _first_that_plans(place_config: PlaceConfig, candidates: list, attempt: Callable, label: Callable,
                      failed: str = "") -> tuple:
    """`attempt(cfg, candidate)` with each of the place's `fallback_configs` on every candidate (a
    base, or a reach) before the next config; the first result. A candidate where it raised
    `PlaceUnreachable` is not tried again with the same IK seeds (`PlaceConfig.ik_seeds`,
    `deep_seeds`): the fallbacks change only the back-off off the item and the release's tilt,
    and would fail there the same. Raises PlanningError: `failed`, then each failure after
    `label(candidate)`."""
    errors, unreachable = [], set()
    for cfg in fallback_configs(place_config):
        for k, candidate in enumerate(candidates):
            if (cfg.ik_seeds, cfg.deep_seeds, k) in unreachable:
                continue
            try:
                return attempt(cfg, candidate)
            except PlaceUnreachable as err:
                unreachable.add((cfg.ik_seeds, cfg.deep_seeds, k))
                errors.append(f"{label(candidate)}{err}")
            except PlanningError as err:
                errors.append(f"{label(candidate)}{err}")
    raise PlanningError(failed + ("; ".join(dict.fromkeys(errors)) or "none clears it"))


def _one_base(kt: KeypointTrajectory, q_target: float, item: Item, obstacles, config: PlannerConfig,
              place_config: PlaceConfig) -> tuple[PlanResult, PlacePlan, ObstacleBox]:
    """The opening and the place from one base, sought nearest the goal first (`PLACE_REACH`,
    `_first_that_plans`; the opening planned once per base: what it must reach,
    `place_reach_points`, is the same for every config, and so is a base without one or without
    a table: it is not tried again)."""
    openings: dict[float, PlanResult | PlanningError] = {}

    def attempt(cfg: PlaceConfig, reach: float) -> tuple[PlanResult, PlacePlan, ObstacleBox]:
        try:
            if reach not in openings:
                try:
                    openings[reach] = plan_articulation(
                        kt, q_target, config=replace(config, place_reach=reach),
                        must_reach=place_reach_points(kt, q_target, item, place_config))
                except PlanningError as err:
                    openings[reach] = err
            plan = openings[reach]
            if isinstance(plan, PlanningError):
                raise plan
            table, X_WI = table_beside(plan.X_WB, [*obstacles[0], *obstacles[1]],
                                       ITEM_REACH[GRASP_OF[kt.category]])
            problem = place_problem(kt, q_target, item, X_WI, table, obstacles, cfg)
        except PlanningError as err:  # the same for every config
            raise PlaceUnreachable(str(err)) from err
        q_end = plan.trajectory.value(plan.trajectory.end_time()).ravel()
        return plan, plan_place(plan.X_WB, q_end, problem, cfg, plan.waypoints[-1]), table

    return _first_that_plans(place_config, PLACE_REACH[kt.category], attempt,
                             lambda reach: f"base within {reach:.2f} m of the goal: ")


DOOR_MARGIN = 0.03
"""Where the base moved, the place avoids the moving part at its measured articulation and this
much (a fraction of its range) to either side: the hand's nudge and the measure's error."""


def measured_articulation(kt: KeypointTrajectory, opening: SimulationResult) -> float:
    """The moving part's articulation (kt's) where the opening let go of it: the articulation at
    which kt's handle passes nearest the held point of the handle at the end of the opening (the
    hand's pose and its hold, `SimulationResult.p_W_handle`)."""
    return kt.nearest_q("handle", opening.p_W_handle[-1])


def door_band(obstacles_at, q: float, margin: float = DOOR_MARGIN
              ) -> tuple[list[ObstacleBox], list[ObstacleBox]]:
    """`obstacles_at(q)`'s (fixed, moving) boxes, the moving ones also at q - margin and q + margin
    (within [0, 1]; renamed `*_less`, `*_more`): the part where it was measured and either side."""
    fixed, moving = obstacles_at(q)
    band = list(moving)
    for suffix, q_side in (("less", max(q - margin, 0.0)), ("more", min(q + margin, 1.0))):
        band += [ObstacleBox(f"{b.name}_{suffix}", b.size, b.X_WB) for b in obstacles_at(q_side)[1]]
    return list(fixed), band


def look_inside(obj: ArticulatedObject, X_WO: RigidTransform, q_true: float, kt: KeypointTrajectory,
                q: float) -> InteriorLook:
    """The floor and the ceiling over kt's goal at articulation q, seen in `obj` opened to q_true
    (in [0, 1]) by a camera held low in front of the front kt's keypoints give
    (`look_into_compartment`)."""
    _, opening = compartment_entry(kt, q)
    return look_into_compartment(obj, X_WO, q_true, kt.point("goal", q), front_normal(kt, q), opening)


def _place_in_front(kt: KeypointTrajectory, q: float, item: Item, obstacles, place_config: PlaceConfig,
                    floor: float | None = None) -> tuple[PlacePlan, ObstacleBox]:
    """The place from a base re-placed in front of the compartment opened to q (`place_bases`,
    the first that plans, `_first_that_plans`; a base without a table is not tried again), and its
    table; `floor`: the goal's height where measured (m in W; `place_problem`)."""
    boxes = [*obstacles[0], *obstacles[1]]

    def attempt(cfg: PlaceConfig, X_WB: RigidTransform) -> tuple[PlacePlan, ObstacleBox]:
        try:
            table, X_WI = table_beside(X_WB, boxes, ITEM_REACH[GRASP_OF[kt.category]])
            problem = place_problem(kt, q, item, X_WI, table, obstacles, cfg, X_WB.translation(), floor)
        except PlanningError as err:  # the same for every config
            raise PlaceUnreachable(str(err)) from err
        return plan_place(X_WB, ready_posture(X_WB, X_WI.translation()), problem, cfg), table

    return _first_that_plans(place_config, place_bases(kt, q, boxes), attempt, lambda X_WB: "",
                             "no base in front of the open compartment plans the place: ")


def run_place_task(obj: ArticulatedObject, X_WO: RigidTransform, q_start: float, q_target: float, item: Item,
                   keypoints: KeypointTrajectory | None = None, reference: KeypointTrajectory | None = None,
                   replay: Path | None = None, planner_config: PlannerConfig | None = None,
                   place_config: PlaceConfig | None = None,
                   simulation_config: PlaceSimulationConfig | None = None,
                   cloud: SemanticCloud | None = None) -> PlaceTaskOutcome:
    """Open front 0 of `obj` (a closet or a drawer at X_WO, at q_start) to q_target and place
    `item` (standing on a table beside the robot) at the goal keypoint, planned with `keypoints`
    (default: the object's own, with its true geometry as obstacles; given keypoints are planned
    with keypoint-derived boxes only), then simulated on the true object: the opening
    (`simulate_articulation`), then the place (`simulate_place`). A drawer's place is planned
    with its opening, from one base (`_one_base`). A closet's (or a drawer's where no one base
    serves both) from a base re-placed after the opening (`MOVE_BASE`): the opening is planned
    and simulated first, then the place planned around the front where the opening left it
    (`measured_articulation`, `door_band`; with given keypoints, a closet's floor and the shelf
    over the goal where a look inside sees them, `look_inside`, the goal at the floor's height).
    Where the opening is taken on from a second base (`pull_on`, `turn_on`), the place is
    planned from a base placed after it, as a closet's. `replay`: an HTML replay of the place,
    with the keypoint paths used (and `reference`'s under "keypoints_true"), the opening's beside
    it (`*_opening.html`, and the second base's `*_opening_pulled_on.html`). `cloud`: the fitted field's
    points that came with `keypoints`; the moving part's obstacles then have its measured width
    (`compartment_obstacles`)."""
    started = time.perf_counter()
    place_config = place_config or PlaceConfig()
    if keypoints is None:
        kt = KeypointTrajectory.from_articulated_object(obj, X_WO, q_start)
        obstacles_at = lambda q: true_compartment(obj, X_WO, q)  # noqa: E731
    else:
        kt, obstacles_at = keypoints, lambda q: compartment_obstacles(keypoints, q, cloud=cloud)  # noqa: E731
    obstacles = obstacles_at(q_target)
    simulation_config = simulation_config or PlaceSimulationConfig()
    config = grasp_planner(planner_config or PlannerConfig(), simulation_config.opening.grasp)
    failed = lambda why, seconds=float("nan"), opening=None, opening_replay=None, on=None: (  # noqa: E731
        PlaceTaskOutcome(q_target, kt, None, None, why, seconds, None, None, opening, opening_replay, on))
    errors, plan = [], None
    if not MOVE_BASE[kt.category]:
        try:
            plan, place, table = _one_base(kt, q_target, item, obstacles, config, place_config)
        except PlanningError as err:
            errors.append(str(err))
            plan = None
    moved = plan is None
    if moved:
        try:
            plan = plan_articulation(kt, q_target, config=config)
        except PlanningError as err:
            return failed("; ".join([*errors, f"base moved after the opening: {err}"]))
    seconds = time.perf_counter() - started
    meshcats = [Meshcat() if replay is not None else None for _ in range(2)]
    scene_object = SceneObject.from_articulated_object(obj, X_WO, q_start)
    try:
        opening = simulate_articulation(scene_object, plan, q_target, meshcats[1],
                                        simulation_config.opening, kt)
    except StartsInsideObject as err:
        return failed("; ".join([*errors, str(err)]), seconds)
    opening_replay = None if replay is None else write_replay(
        meshcats[1], replay.with_name(f"{replay.stem}_opening{replay.suffix}"))
    started_on = time.perf_counter()  # as `run_task`: the opening taken on from a second base
    true_geometry = list(scene_object.obstacles) if keypoints is None and scene_object.obstacles else None
    pulled_on = (pull_on(scene_object, kt, plan, opening, true_geometry, config, simulation_config.opening,
                         meshcats[1], opening_replay)
                 or turn_on(scene_object, kt, plan, opening, true_geometry, config, simulation_config.opening,
                            meshcats[1], opening_replay))
    seconds += time.perf_counter() - started_on
    opened = ended_in(opening, pulled_on)
    moved = moved or opened is not opening  # after a second base the place goes from a base placed anew
    if moved:
        q_door = measured_articulation(kt, opened)
        look = None
        if keypoints is not None and kt.category == "closet":  # look in for the floor and the shelf
            look = look_inside(obj, X_WO, opened.q_final, kt, q_door)
            obstacles_at = lambda q: compartment_obstacles(keypoints, q, look, cloud)  # noqa: E731
        obstacles = door_band(obstacles_at, q_door)
        planned = time.perf_counter()
        try:
            place, table = _place_in_front(kt, q_door, item, obstacles, place_config,
                                           None if look is None else look.floor)
        except PlanningError as err:
            return failed("; ".join([*errors, f"base moved after the opening (front measured at "
                                     f"{q_door:.3f}): {err}"]), seconds + time.perf_counter() - planned,
                          opening, opening_replay, pulled_on)
        seconds += time.perf_counter() - planned
    for meshcat in meshcats[:1] if replay is not None else []:
        draw_keypoint_trajectory(meshcat, kt, "keypoints", (kt.q_current, q_target))
        if reference is not None:
            draw_keypoint_trajectory(meshcat, reference, "keypoints_true", (reference.q_current, q_target),
                                     line_width=2.0)
        for box in (*obstacles[0], *obstacles[1]):
            draw_obstacle(meshcat, box)
        goal = kt.point("goal", q_target)
        centre = (goal + place.X_WB.translation()) / 2 + [0.0, 0.0, 0.3]
        away = place.X_WB.translation() - goal
        away[2] = 0.0
        side = np.cross([0.0, 0.0, 1.0], away / np.linalg.norm(away))
        frame_camera(meshcat, centre, centre + 0.6 * away + 1.2 * side + [0.0, 0.0, 0.9])
    simulation = simulate_place(obj, X_WO, opened, place, item, table, None if moved else opening.q_robot,
                                meshcats[0], simulation_config)
    path = write_replay(meshcats[0], replay) if replay is not None else None
    return PlaceTaskOutcome(q_target, kt, plan, place, "", seconds, simulation, path, opening, opening_replay,
                            pulled_on)
