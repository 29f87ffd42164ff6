"""Grasp-and-articulate motions from a keypoint trajectory: base placement, chained IK, trajectory
optimisation.

The motion over normalised time s in [0, 1]: start at rest (s = 0), pre-grasp (the tool frame
`pregrasp_distance` back from the handle along its own z axis), grasp (at rest, tool frame on the
handle), then the handle keypoints from the current q to the target q (the paper's T waypoints,
evenly spaced in q; then `end_stop_overshoot` past full opening), ending at rest. The
normalised times of these knots and the duration come from the chained IK: each segment gets the
time its joints need at the velocity limits, the approach at least
`pregrasp_distance / approach_speed`, the handle at most `handle_speed`. Only the keypoint
trajectory is used, with obstacle boxes: the floor and the keypoint-derived carcass box, or a true
model's own collision geometry (`nfr_drake.world.obstacles`), and until the grasp an open door's
panel. The base stands on the floor or, for a high handle path, on a lift column the planner raises
(`PlannerConfig.max_lift`). Where nothing plans, a tighter clearance and then a wider approach
cone are tried (`plan_articulation`).
"""

import time
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import BsplineBasis, RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.inverse_kinematics import (
    AngleBetweenVectorsConstraint,
    InverseKinematics,
    MinimumDistanceLowerBoundConstraint,
    OrientationConstraint,
    PositionConstraint,
)
from pydrake.planning import KinematicTrajectoryOptimization
from pydrake.solvers import SnoptSolver, SolverOptions
from pydrake.trajectories import BsplineTrajectory

from nfr_drake.errors import NfrDrakeError
from nfr_drake.planning.grasp import (
    carcass_box,
    door_panel_box,
    handle_tangent,
    handle_waypoints,
)
from nfr_drake.planning.scene import PlanningScene, build_planning_scene
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.obstacles import distance_to_box
from nfr_drake.world.plan import HandleWaypoint, ObstacleBox, PlanResult
from nfr_drake.world.robot import NUM_ARM_JOINTS, PEDESTAL_HALF_WIDTH, Q_HOME

_SPEED_MARGIN = 1.5  # peak over mean joint speed allowed for in the knot timing
_IK_ITERATIONS = 60  # a reachable stage converges in far fewer; fail fast on the rest
_ACCEL_LIMITS = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])  # Panda datasheet, rad/s^2
_Z = np.array([0.0, 0.0, 1.0])
_SHOULDER_HEIGHT = 0.333  # joint 2 above the base, m
_WRIST_REACH = 0.90  # farthest shoulder-to-(nominal) wrist-centre distance kept, m; the cones give slack
_PREFERRED_DISTANCE = 0.62  # base to handle-path centroid, m (most chained IKs succeed there)
_BASE_CLEARANCE = 0.25  # base axis to the moving part's sweep, m
_WRIST_OFFSET = 0.21  # tool point to the wrist centre, back along the approach, m
_MIN_WRIST_RADIUS = 0.2  # wrist centres closer to the base axis than this cramp the arm, m
_COLUMN_RADIUS = PEDESTAL_HALF_WIDTH * np.sqrt(2.0)  # the lift column's (and base plate's) reach, m
_PLACE_SIGHT_HEIGHT = 0.3  # the line from a base to a place goal starts this far above the goal, m
_PLACE_SIGHT_CLEARANCE = 0.1  # ... and clears the obstacles and an open door by this much, m
_PLACE_SIGHT_FRACTION = 0.75  # ... along this fraction of its length
_OBSTACLE_RANGE = 1.3  # obstacles farther than this from the shoulder are out of the arm's reach, m
GRASP_DEPTH = {"constraint": 0.0, "contact": 0.015}
"""`PlannerConfig.grasp_depth` by simulated grasp, m: fingers holding a bar by friction need it
between their pads' middles (the tool point lies 0.9 cm from the fingertips), not at their edge,
where the squeezed bar slips out."""


class PlanningError(NfrDrakeError):
    """No motion satisfies the constraints; the message names those that failed."""


@dataclass
class PlannerConfig:
    """Options of `plan_articulation`."""

    num_waypoints: int = 10
    """T: handle waypoints from the current to the target articulation."""
    approach_speed: float = 0.1
    """Speed of the tool from pre-grasp to grasp, m/s."""
    handle_speed: float = 0.12
    """Largest mean speed of the handle while articulating, m/s."""
    pregrasp_distance: float = 0.10
    """How far back along the approach the pre-grasp holds the tool frame, m."""
    grasp_depth: float = 0.0
    """How far past the handle keypoint the tool origin goes along the approach, m: 0 holds the bar
    at the fingertips' grip point (`TOOL_FRAME`), as a grasp by constraint needs; a grasp by
    friction holds it deeper, mid-pad (`GRASP_DEPTH`)."""
    position_tolerance: float = 0.003
    """Half-width of the box the tool origin must lie in at each waypoint, m."""
    path_tolerance: float = 0.004
    """Between consecutive handle waypoints the handle's point of the tool (`grasp_depth` behind
    its origin) stays within this of the straight line joining them, m, at `path_samples` evenly
    spaced times: an arm that holds the handle stiffly must follow its path, not only its
    waypoints (without it the hand swung up to 15 cm off a door's arc between two waypoints)."""
    path_samples: int = 3
    approach_tolerance: float = 0.01
    """From pre-grasp to grasp the handle keypoint stays within this of the tool's z axis (x and
    y in the tool frame), m, at `path_samples` times: the open fingers come in straight over the
    bar, not sideways onto it."""
    rigid_hold: bool = False
    """From the grasp on, the tool keeps its orientation relative to the handle (the one the grasp's
    IK found, turned as the handle's waypoint frame turns), within `rigid_tolerance_deg`, instead of
    turning freely about the bar within `follow_cone_deg`: fingers that hold a bar by friction
    slip when the hand turns on it (`grasp_planner`)."""
    rigid_tolerance_deg: float = 3.0
    bar_tolerance_deg: float = 3.0
    """Allowed angle between the tool's x axis and the handle's bar axis."""
    grasp_cone_deg: float = 30.0
    """Allowed angle between the tool's z axis and the approach at pre-grasp and grasp: the hand may
    come in obliquely about the bar (e.g. from above for a low drawer handle)."""
    follow_cone_deg: float = 35.0
    """Same while following the handle: the hand may turn about the bar (a cylindrical grasp); past
    about 35 degrees the Panda hand's 0.2 m wide palm would touch a door 3 cm behind the bar."""
    min_distance: float = 0.01
    """Clearance between the robot and the floor / carcass box (and itself), m."""
    tight_min_distance: float = 0.005
    """The clearance tried when nothing plans at `min_distance`, m: a bar 7-9 cm above the floor,
    held 1.5 cm deep by contact, leaves the hand's 0.2 m wide palm under 1 cm from the floor
    (docs/PLANNING.md, "A tighter clearance when nothing plans"). At or above `min_distance`: no
    second try."""
    wide_grasp_cone_deg: float = 45.0
    """The approach cone tried when nothing plans at `grasp_cone_deg` at either clearance, degrees:
    a bar about 10 cm above the floor, fitted a centimetre or two low, is reached only by a hand
    that comes in further from above (docs/PLANNING.md, "A wider approach cone when nothing
    plans"). At or below `grasp_cone_deg`: no further try."""
    collision_samples: int = 24
    num_control_points: int = 22
    velocity_scale: float = 0.5
    """Fraction of the datasheet velocity limits the plan may use."""
    acceleration_scale: float = 0.3
    min_duration: float = 2.0
    max_duration: float = 15.0
    max_base_candidates: int = 12
    max_lift: float = 1.0
    """Highest base above the floor, m: the arm stands on a lift column (as on a mobile manipulator;
    a pedestal in simulation). 0 keeps it on the floor."""
    lift_reach: float = 0.9
    """The base is raised only as far as puts the handle path's highest point at most this far
    above it, m; lower paths keep the base on the floor."""
    place_reach: float = 0.7
    """Largest horizontal distance from the base axis to a point the arm must reach later
    (`plan_articulation`'s `must_reach`: a goal to place an item at), m."""
    lift_offsets: tuple[float, ...] = (0.0, 0.1, -0.1)
    """Base heights tried in turn, as offsets from the one `lift_reach` gives (each within
    [0, max_lift]), m: all base positions at one height before the next."""
    end_stop_overshoot: float = 0.03
    """When the target is full opening (q = 1), the handle path goes on this far past the predicted
    end along its tangent, m, so that the object's own stop ends the motion: a predicted travel a few
    cm short of the true one still reaches it. The arm must then be compliant, as it is in
    simulation once grasped (`SimulationConfig.grasped_stiffness`). Closing (q = 0) has no
    overshoot: past the shut position the hand would run into the carcass. 0 stops at the
    prediction."""

    def __post_init__(self) -> None:
        if min(self.approach_speed, self.handle_speed, self.velocity_scale) <= 0.0:
            raise NfrDrakeError("planner: speeds and velocity_scale must be positive")
        if self.num_waypoints < 2:
            raise NfrDrakeError("planner: num_waypoints must be at least 2")
        if self.end_stop_overshoot < 0.0:
            raise NfrDrakeError("planner: end_stop_overshoot must not be negative")
        if self.max_lift < 0.0:
            raise NfrDrakeError("planner: max_lift must not be negative")


def grasp_planner(config: PlannerConfig, grasp: str) -> PlannerConfig:
    """`config` for a simulated grasp ("constraint" or "contact"): a grasp by contact holds the
    bar deeper (`GRASP_DEPTH`), keeps the hand still on the handle (`rigid_hold`) and stops at the
    predicted end (no `end_stop_overshoot`: a stiff arm pulling past the stop drags the bar out of
    the fingers)."""
    if grasp == "contact":
        return replace(config, grasp_depth=GRASP_DEPTH[grasp], rigid_hold=True, end_stop_overshoot=0.0)
    return replace(config, grasp_depth=GRASP_DEPTH[grasp])


def _swept_points(kt: KeypointTrajectory, waypoints: list[HandleWaypoint]) -> np.ndarray:
    """Points on the moving part's sweep, m, shape (M, 3): the handle path and, for a door, the
    segments from the hinge axis to the handle."""
    pts = [w.p_WH for w in waypoints]
    if kt.category == "closet":
        for w in waypoints:
            a = kt.point("hinge_bottom", w.q)
            axis = kt.point("hinge_top", w.q) - a
            axis /= np.linalg.norm(axis)
            foot = a + ((w.p_WH - a) @ axis) * axis
            pts += [foot + f * (w.p_WH - foot) for f in np.linspace(0.0, 1.0, 8)]
    return np.array(pts)


def _base_heights(waypoints: list[HandleWaypoint], cfg: PlannerConfig) -> list[float]:
    """Heights of the base above the floor to try, m: the least that puts the highest handle
    waypoint at most `lift_reach` above it, then `lift_offsets` from it, each within [0, max_lift]."""
    top = max(w.p_WH[2] for w in waypoints)
    first = top - cfg.lift_reach
    heights = [float(np.clip(first + d, 0.0, cfg.max_lift)) for d in cfg.lift_offsets]
    return list(dict.fromkeys(heights))


def _base_candidates(kt: KeypointTrajectory, waypoints: list[HandleWaypoint], obstacles: list[ObstacleBox],
                     cfg: PlannerConfig, z_B: float, must_reach: np.ndarray) -> list[RigidTransform]:
    """Robot base poses facing the handle path with the base `z_B` above the floor (m), most
    reachable first, within `cfg.place_reach` (horizontally) of the points `must_reach` (m, (M, 3)).

    Candidates lie on rings around the path's centroid. One is kept when its base clears the moving
    part's sweep by `_BASE_CLEARANCE`, its column (floor to shoulder) clears every obstacle by
    `_COLUMN_RADIUS` (the planner's collision checks ignore the base link and the column, which are
    welded to the world as the obstacles are), and the wrist centre of every waypoint (`_WRIST_OFFSET`
    back along the approach) is within `_WRIST_REACH` of the shoulder and `_MIN_WRIST_RADIUS` off the
    base axis. Ranked by closeness to `_PREFERRED_DISTANCE` from the centroid (nearer bases cramp the
    arm), then by the farthest wrist reach.
    """
    p = np.array([w.p_WH for w in waypoints])
    wrists = p - _WRIST_OFFSET * np.array([w.approach_W for w in waypoints])
    door = door_panel_box(kt.with_current(waypoints[-1].q)) if len(must_reach) else None
    in_sight_of = [*obstacles, door] if door is not None else obstacles
    swept = _swept_points(kt, waypoints)
    c = p.mean(axis=0)
    column = np.linspace(0.0, z_B + _SHOULDER_HEIGHT, 8)
    scored = []
    for rho in np.arange(0.3, 1.01, 0.1):
        for phi in np.radians(np.arange(0.0, 360.0, 15.0)):
            p_WB = np.array([c[0] + rho * np.cos(phi), c[1] + rho * np.sin(phi), z_B])
            if np.min(np.linalg.norm((swept - p_WB)[:, :2], axis=1)) < _BASE_CLEARANCE:
                continue
            axis = np.column_stack([np.full(8, p_WB[0]), np.full(8, p_WB[1]), column])
            if any(distance_to_box(box, axis).min() < _COLUMN_RADIUS for box in obstacles):
                continue
            reach = np.linalg.norm(wrists - (p_WB + [0, 0, _SHOULDER_HEIGHT]), axis=1)
            radius = np.linalg.norm((wrists - p_WB)[:, :2], axis=1)
            if reach.max() > _WRIST_REACH or radius.min() < _MIN_WRIST_RADIUS:
                continue
            if len(must_reach) and not _sees(p_WB, must_reach, in_sight_of, cfg):
                continue
            yaw = np.arctan2(*(c - p_WB)[1::-1])
            score = abs(rho - _PREFERRED_DISTANCE) + 0.1 * reach.max()
            scored.append((score, RigidTransform(RollPitchYaw(0, 0, yaw), p_WB)))
    scored.sort(key=lambda item: item[0])
    return [X for _, X in scored[:cfg.max_base_candidates]]


def _sees(p_WB: np.ndarray, points: np.ndarray, boxes: list[ObstacleBox], cfg: PlannerConfig) -> bool:
    """Whether a base at p_WB has `points` (m, (M, 3)) within `cfg.place_reach` horizontally, and
    the straight line to the first (from `_PLACE_SIGHT_HEIGHT` above it; all but its last quarter,
    which ends beside the compartment) clears `boxes` by `_PLACE_SIGHT_CLEARANCE`."""
    if np.linalg.norm((points - p_WB)[:, :2], axis=1).max() > cfg.place_reach:
        return False
    f = np.linspace(0.0, _PLACE_SIGHT_FRACTION, 10)[:, None]
    line = (1 - f) * np.r_[p_WB[:2], points[0, 2] + _PLACE_SIGHT_HEIGHT] + f * points[0]
    return all(distance_to_box(box, line).min() >= _PLACE_SIGHT_CLEARANCE for box in boxes)


def _within_reach(obstacles: list[ObstacleBox], X_WB: RigidTransform) -> list[ObstacleBox]:
    """The obstacles within `_OBSTACLE_RANGE` of the shoulder of a base at X_WB."""
    shoulder = X_WB @ np.array([0.0, 0.0, _SHOULDER_HEIGHT])
    return [box for box in obstacles if distance_to_box(box, shoulder[None])[0] <= _OBSTACLE_RANGE]


@dataclass
class _Scenes:
    """The planning scenes of one base pose: `approach` (up to the grasp: also an open door's
    panel, `grasp.door_panel_box`), `follow` (once grasped: the door moves with the hand) and
    `end` (the last waypoint: also a door at the target, which the hand holding its handle may
    touch and the rest of the arm must clear: the door swings towards the arm as it opens, and
    the follow scene has no door; a drawer's is `follow`)."""

    approach: PlanningScene
    follow: PlanningScene
    end: PlanningScene


class _Stage:
    """One IK target: the point `p_GQ` of the tool frame G at `p_WQ`, and the tool's orientation."""

    def __init__(self, name: str, p_WQ: np.ndarray, p_GQ: np.ndarray, wp: HandleWaypoint, cone_deg: float,
                 flip: bool):
        self.name, self.p_WQ, self.p_GQ, self.wp = name, p_WQ, p_GQ, wp
        self.cone, self.flip = np.radians(cone_deg), flip
        self.R_WG: RotationMatrix | None = None
        """The tool's orientation, once fixed (`PlannerConfig.rigid_hold`); else the cones."""

    def bar_W(self) -> np.ndarray:
        return -self.wp.bar_W if self.flip else self.wp.bar_W


def _constraints(scene: PlanningScene, stage: _Stage, cfg: PlannerConfig):
    """(description, constraint) pairs fixing the tool frame for `stage`."""
    plant, ctx, W, G = scene.plant, scene.plant_context, scene.plant.world_frame(), scene.tool_frame
    tol = np.full(3, cfg.position_tolerance)
    position = (f"{stage.name} position", PositionConstraint(plant, W, stage.p_WQ - tol, stage.p_WQ + tol,
                                                             G, stage.p_GQ, ctx))
    if stage.R_WG is not None:
        return [position, _held_orientation(scene, stage.R_WG, stage.name, cfg)]
    return [
        position,
        (f"{stage.name} bar alignment", AngleBetweenVectorsConstraint(
            plant, W, stage.bar_W(), G, np.array([1.0, 0, 0]), 0.0, np.radians(cfg.bar_tolerance_deg), ctx)),
        (f"{stage.name} approach cone", AngleBetweenVectorsConstraint(
            plant, W, stage.wp.approach_W, G, np.array([0, 0, 1.0]), 0.0, stage.cone, ctx)),
    ]


def _held_orientation(scene: PlanningScene, R_WG: RotationMatrix, name: str, cfg: PlannerConfig):
    """(description, constraint): the tool frame at R_WG within `rigid_tolerance_deg`."""
    return (f"{name} held orientation", OrientationConstraint(
        scene.plant, scene.plant.world_frame(), R_WG, scene.tool_frame, RotationMatrix(),
        np.radians(cfg.rigid_tolerance_deg), scene.plant_context))


def _hold_rigidly(kt: KeypointTrajectory, stages: list[_Stage], R_WG_grasp: RotationMatrix) -> None:
    """Fix the orientation of the grasp (stage 1) and of every later stage: R_WG_grasp turned as
    the handle turns from the grasp's articulation to the stage's (`_handle_turn`)."""
    for stage in stages[1:]:
        stage.R_WG = _handle_turn(kt, stages[1].wp.q, stage.wp.q) @ R_WG_grasp


def _handle_turn(kt: KeypointTrajectory, q0: float, q: float) -> RotationMatrix:
    """The handle's rotation in W from articulation q0 to q: a door's about its hinge axis (the
    hinge keypoints), by the angle its handle swept about it; none for a drawer. From the
    handle's path and the axis rather than the waypoints' approach directions, which a fitted
    field's keypoints make jitter by more than the hold's tolerance."""
    if kt.category != "closet":
        return RotationMatrix()
    bottom = kt.point("hinge_bottom", q0)
    axis = kt.point("hinge_top", q0) - bottom
    axis = axis / np.linalg.norm(axis)
    r0, r = (kt.point("handle", x) - bottom for x in (q0, q))
    r0, r = r0 - (r0 @ axis) * axis, r - (r @ axis) * axis
    return RotationMatrix(AngleAxis(float(np.arctan2(axis @ np.cross(r0, r), r0 @ r)), axis))


def _stages(waypoints: list[HandleWaypoint], cfg: PlannerConfig, flip: bool) -> list[_Stage]:
    """Pre-grasp (the point `pregrasp_distance` ahead of the tool along its z on the handle), grasp,
    then the handle waypoints (the point `grasp_depth` behind the tool origin on the handle)."""
    first, origin = waypoints[0], np.array([0.0, 0.0, -cfg.grasp_depth])
    ahead = np.array([0.0, 0.0, cfg.pregrasp_distance])
    stages = [_Stage("pre-grasp", first.p_WH, ahead, first, cfg.grasp_cone_deg, flip),
              _Stage("grasp", first.p_WH, origin, first, cfg.grasp_cone_deg, flip)]
    stages += [_Stage(f"handle waypoint {i} (q={w.q:.2f})", w.p_WH, origin, w, cfg.follow_cone_deg, flip)
               for i, w in enumerate(waypoints[1:], start=1)]
    return stages


def _chained_ik(kt: KeypointTrajectory, scenes: _Scenes, stages: list[_Stage], q_start: np.ndarray,
                cfg: PlannerConfig) -> tuple[list[np.ndarray] | None, str]:
    """Solve the stages in order, each seeded by and kept close to the last; (solutions, failed stage).
    Pre-grasp and grasp keep clear of the approach obstacles too."""
    scene = scenes.follow
    solver = SnoptSolver()
    q_prev = scene.full_q(q_start)
    # First seed: the home posture turned to face the handle.
    p_BH = scene.X_WB.inverse() @ stages[1].p_WQ
    q_seed = scene.full_q(np.r_[np.arctan2(p_BH[1], p_BH[0]), Q_HOME[1:]])
    ik_options = SolverOptions()
    ik_options.SetOption(SnoptSolver.id(), "Major iterations limit", _IK_ITERATIONS)
    sols = []
    for k, stage in enumerate(stages):
        stage_scene = scenes.approach if k < 2 else scenes.end if k == len(stages) - 1 else scenes.follow
        ik = InverseKinematics(stage_scene.plant, stage_scene.plant_context)
        q = ik.q()
        for _, c in _constraints(stage_scene, stage, cfg):
            ik.prog().AddConstraint(c, q)
        ik.AddMinimumDistanceLowerBoundConstraint(cfg.min_distance, 0.05)
        ik.prog().AddBoundingBoxConstraint(q_prev[NUM_ARM_JOINTS:], q_prev[NUM_ARM_JOINTS:],
                                           q[NUM_ARM_JOINTS:])
        ik.prog().AddQuadraticErrorCost(np.eye(len(q)), q_prev, q)
        result = solver.Solve(ik.prog(), q_seed, ik_options)
        if not result.is_success():
            return None, stage.name
        q_prev = q_seed = result.GetSolution(q)
        sols.append(q_prev)
        if k == 1 and cfg.rigid_hold:
            plant, context = stage_scene.plant, stage_scene.plant_context
            plant.SetPositions(context, q_prev)
            _hold_rigidly(kt, stages, stage_scene.tool_frame.CalcPoseInWorld(context).rotation())
    return sols, ""


def _initial_guess(trajopt: KinematicTrajectoryOptimization, s_knots: np.ndarray, q_knots: np.ndarray,
                   duration: float) -> BsplineTrajectory:
    """A B-spline over [0, duration] whose control points follow the piecewise-linear path through
    (s_knots, q_knots)."""
    n = trajopt.num_control_points()
    s_cp = np.linspace(0.0, 1.0, n)
    cps = np.stack([np.interp(s_cp, s_knots, q_knots[:, j]) for j in range(q_knots.shape[1])])
    basis = trajopt.basis()
    return BsplineTrajectory(BsplineBasis(basis.order(), np.asarray(basis.knots()) * duration), cps)


def _on_segment(scene: PlanningScene, p_WA: np.ndarray, p_WB: np.ndarray, p_GQ: np.ndarray, tol: float
                ) -> PositionConstraint:
    """The tool's point p_GQ within `tol` (m) of the segment from p_WA to p_WB (m, in W): a box
    along it, `tol` wider at its ends."""
    along = p_WB - p_WA
    length = float(np.linalg.norm(along))
    x = along / length if length > 1e-9 else np.array([1.0, 0.0, 0.0])
    R_WS = RotationMatrix.MakeFromOneVector(x, 0)
    return PositionConstraint(scene.plant, scene.plant.world_frame(), RigidTransform(R_WS, p_WA),
                              np.array([-tol, -tol, -tol]), np.array([length + tol, tol, tol]),
                              scene.tool_frame, p_GQ, scene.plant_context)


def _knot_times(stages: list[_Stage], q_knots: np.ndarray, vmax: np.ndarray, cfg: PlannerConfig
                ) -> tuple[np.ndarray, float]:
    """Normalised times of the knots (start, then each stage), shape (len(stages) + 1,), and the duration.

    Each segment takes the longest of: its joints' displacement at `vmax / _SPEED_MARGIN` (a cubic
    B-spline's peak speed exceeds its mean), the approach at `approach_speed`, the handle's move at
    `handle_speed`.
    """
    dq = np.abs(np.diff(q_knots, axis=0))[:, :NUM_ARM_JOINTS]
    tau = np.max(dq / vmax[:NUM_ARM_JOINTS], axis=1) * _SPEED_MARGIN
    tau[1] = max(tau[1], cfg.pregrasp_distance / cfg.approach_speed)
    handle_steps = np.linalg.norm(np.diff([st.p_WQ for st in stages[1:]], axis=0), axis=1)
    tau[2:] = np.maximum(tau[2:], handle_steps / cfg.handle_speed)
    tau = np.maximum(tau, 0.05)
    duration = float(np.clip(tau.sum(), cfg.min_duration, cfg.max_duration))
    s_knots = np.r_[0.0, np.cumsum(tau)] / tau.sum()
    s_knots[-1] = 1.0
    return s_knots, duration


def _optimise(scenes: _Scenes, stages: list[_Stage], ik_sols: list[np.ndarray], q_start: np.ndarray,
              cfg: PlannerConfig) -> tuple[BsplineTrajectory | None, float, list[str]]:
    """KinematicTrajectoryOptimization at a fixed duration (velocity and acceleration bounds are then
    linear), warm-started from the chained IK; retried once at 1.6 times the duration.

    Returns the trajectory (None on failure), the grasp's normalised time, the failed constraints.
    """
    q0 = scenes.follow.full_q(q_start)
    q_knots = np.stack([q0, *ik_sols])
    vmax = cfg.velocity_scale * scenes.follow.plant.GetVelocityUpperLimits()
    s_knots, duration = _knot_times(stages, q_knots, vmax, cfg)
    failed = []
    for scale in (1.0, 1.6):
        T = min(scale * duration, cfg.max_duration)
        traj, failed = _optimise_at(scenes, stages, s_knots, q_knots, T, cfg)
        if traj is not None:
            break
    return traj, float(s_knots[2]), failed


def _optimise_at(scenes: _Scenes, stages: list[_Stage], s_knots: np.ndarray, q_knots: np.ndarray,
                 duration: float, cfg: PlannerConfig) -> tuple[BsplineTrajectory | None, list[str]]:
    scene = scenes.follow
    plant = scene.plant
    nq = plant.num_positions()
    trajopt = KinematicTrajectoryOptimization(nq, cfg.num_control_points, spline_order=4)
    prog = trajopt.get_mutable_prog()
    trajopt.AddPathEnergyCost(1.0)
    q0 = q_knots[0]
    lower, upper = plant.GetPositionLowerLimits().copy(), plant.GetPositionUpperLimits().copy()
    lower[NUM_ARM_JOINTS:] = upper[NUM_ARM_JOINTS:] = q0[NUM_ARM_JOINTS:]
    trajopt.AddPositionBounds(lower, upper)
    vmax = cfg.velocity_scale * plant.GetVelocityUpperLimits()
    trajopt.AddVelocityBounds(-vmax, vmax)
    amax = np.r_[cfg.acceleration_scale * _ACCEL_LIMITS, np.ones(nq - NUM_ARM_JOINTS)]
    trajopt.AddAccelerationBounds(-amax, amax)
    trajopt.AddDurationConstraint(duration, duration)

    described = []
    b = trajopt.AddPathPositionConstraint(q0, q0, 0.0)
    described.append(("start configuration", b))
    zeros = np.zeros(nq)
    for s, what in ((0.0, "start"), (s_knots[2], "grasp"), (1.0, "end")):
        described.append((f"at rest at {what}", trajopt.AddPathVelocityConstraint(zeros, zeros, s)))
    for stage, s in zip(stages, s_knots[1:], strict=True):
        for name, c in _constraints(scene, stage, cfg):
            described.append((name, trajopt.AddPathPositionConstraint(c, s)))
    first = stages[1]
    in_line = np.array([cfg.approach_tolerance, cfg.approach_tolerance, 0.0])
    straight_in = PositionConstraint(plant, scene.tool_frame, -in_line + [0.0, 0.0, first.p_GQ[2] - 0.01],
                                     in_line + [0.0, 0.0, stages[0].p_GQ[2] + 0.01], plant.world_frame(),
                                     first.p_WQ, scene.plant_context)
    for f in np.arange(1, cfg.path_samples + 1) / (cfg.path_samples + 1):
        s = s_knots[1] + f * (s_knots[2] - s_knots[1])
        described.append(("straight approach", trajopt.AddPathPositionConstraint(straight_in, s)))
    for k in range(2, len(stages)):  # the handle's path, from the grasp (stage 1) on
        a, b = stages[k - 1], stages[k]
        on_line = _on_segment(scene, a.p_WQ, b.p_WQ, b.p_GQ, cfg.path_tolerance)
        for f in np.arange(1, cfg.path_samples + 1) / (cfg.path_samples + 1):
            s = s_knots[k] + f * (s_knots[k + 1] - s_knots[k])
            described.append((f"handle path from {a.name} to {b.name}", trajopt.AddPathPositionConstraint(
                on_line, s)))
            if a.R_WG is not None and b.R_WG is not None:
                R_ab = (a.R_WG.inverse() @ b.R_WG).ToAngleAxis()
                R_s = a.R_WG @ RotationMatrix(AngleAxis(f * R_ab.angle(), R_ab.axis()))
                name, held = _held_orientation(scene, R_s, f"handle path from {a.name} to {b.name}", cfg)
                described.append((name, trajopt.AddPathPositionConstraint(held, s)))
    collision = {name: MinimumDistanceLowerBoundConstraint(sc.plant, cfg.min_distance, sc.plant_context,
                                                           None, 0.05)
                 for name, sc in (("approach", scenes.approach), ("follow", scene), ("end", scenes.end))}
    for s in np.linspace(0.0, 1.0, cfg.collision_samples + 1)[1:]:
        which = "approach" if s <= s_knots[2] else "end" if s == 1.0 else "follow"
        binding = trajopt.AddPathPositionConstraint(collision[which], s)
        described.append((f"collision clearance at s={s:.2f}", binding))
    for name, binding in described:
        binding.evaluator().set_description(name)

    trajopt.SetInitialGuess(_initial_guess(trajopt, s_knots, q_knots, duration))
    options = SolverOptions()
    options.SetOption(SnoptSolver.id(), "Major iterations limit", 400)
    result = SnoptSolver().Solve(prog, None, options)
    if not result.is_success():
        failed = result.GetInfeasibleConstraintNames(prog, 1e-4)
        return None, sorted(set(failed)) or [f"solver status {result.get_solution_result()}"]
    return trajopt.ReconstructTrajectory(result), []


def plan_articulation(kt: KeypointTrajectory, q_target: float, q_start: np.ndarray = Q_HOME,
                      config: PlannerConfig | None = None,
                      obstacles: list[ObstacleBox] | None = None,
                      must_reach: np.ndarray | None = None) -> PlanResult:
    """Plan grasping the handle and moving it from `kt.q_current` to `q_target`.

    q_start: the arm's joint positions at t = 0, rad, shape (7,). obstacles: boxes in W that stay
    put (a true model's geometry without the moving part); None: the keypoint-derived carcass box.
    must_reach: points in W (m, (M, 3)) the base must stay within `config.place_reach` of
    (horizontally), for a motion after this one, the first in sight past the obstacles and the
    door open at q_target (a place: the pre-place point, then the goal). A door's plan ends with
    the arm clear of the door at q_target (the hand may touch it). Where nothing plans, the
    fallbacks of `_fallbacks` are tried in turn. Raises PlanningError naming the constraints that
    failed at each try.
    """
    config = config or PlannerConfig()
    if not 0.0 <= q_target <= 1.0:
        raise NfrDrakeError(f"target articulation {q_target} is outside [0, 1]")
    failures = []
    for label, tried in _fallbacks(config):
        try:
            return _plan(kt, q_target, q_start, tried, obstacles, must_reach)
        except PlanningError as err:
            failures.append(str(err) if not failures else f"{label}: {str(err).split(': ', 1)[1]}")
    raise PlanningError("; ".join(failures))


def _fallbacks(config: PlannerConfig) -> list[tuple[str, PlannerConfig]]:
    """The configurations `plan_articulation` tries in turn, each with the words that name its
    failure: `config`, then at `tight_min_distance`, then with `wide_grasp_cone_deg` at either
    clearance (each only where it differs from `config`)."""
    clearances = [config.min_distance]
    if config.tight_min_distance < config.min_distance:
        clearances.append(config.tight_min_distance)
    tries = [(f"with {100 * c:.1f} cm of clearance", replace(config, min_distance=c)) for c in clearances]
    if config.wide_grasp_cone_deg > config.grasp_cone_deg:
        cone = config.wide_grasp_cone_deg
        tries += [(f"with a {cone:g} deg approach cone and {100 * c:.1f} cm of clearance",
                   replace(config, min_distance=c, grasp_cone_deg=cone)) for c in clearances]
    return tries


def _plan(kt: KeypointTrajectory, q_target: float, q_start: np.ndarray, config: PlannerConfig,
          obstacles: list[ObstacleBox] | None, must_reach: np.ndarray | None) -> PlanResult:
    """`plan_articulation` at `config`'s clearance and approach cone, without fallbacks."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    q_values = np.linspace(kt.q_current, q_target, config.num_waypoints)
    waypoints = handle_waypoints(kt, q_values)
    if q_target == 1.0 and kt.q_current < 1.0 and config.end_stop_overshoot > 0.0:
        end = waypoints[-1]
        onward = config.end_stop_overshoot * handle_tangent(kt, 1.0)
        waypoints.append(replace(end, p_WH=end.p_WH + onward))
    obstacles, door = list(obstacles) if obstacles is not None else [carcass_box(kt)], door_panel_box(kt)
    door_end = door_panel_box(kt.with_current(q_target))
    failures = []
    bases = [X for z_B in _base_heights(waypoints, config)
             for X in _base_candidates(kt, waypoints, obstacles, config, z_B,
                                       np.zeros((0, 3)) if must_reach is None else np.atleast_2d(must_reach))]
    for X_WB in bases:
        near = _within_reach(obstacles, X_WB)
        follow = build_planning_scene(X_WB, near)
        end = build_planning_scene(X_WB, near, touching=[door_end]) if door_end else follow
        scenes = _Scenes(build_planning_scene(X_WB, [*near, door]) if door else follow, follow, end)
        for flip in (True, False):
            stages = _stages(waypoints, config, flip)
            sols, failed = _chained_ik(kt, scenes, stages, q_start, config)
            if sols is None:
                failures.append(f"IK of {failed}")
                continue
            t1 = time.perf_counter()
            traj, s_grasp, failed_constraints = _optimise(scenes, stages, sols, q_start, config)
            t2 = time.perf_counter()
            if traj is None:
                failures.append("trajectory optimisation: " + ", ".join(failed_constraints))
                continue
            return PlanResult(traj, X_WB, s_grasp, waypoints, flip,
                              {"placement": t1 - t0, "trajopt": t2 - t1, "total": t2 - t0,
                               "cpu": time.process_time() - cpu0})
    summary = "; ".join(dict.fromkeys(failures)) or (
        "no robot base position both reaches every handle waypoint (the base raised at most "
        f"{config.max_lift:.2f} m) and clears the moving part's sweep and the obstacles"
        + (f", within {config.place_reach:.2f} m of the place goal" if must_reach is not None else ""))
    raise PlanningError(f"no feasible motion from q={kt.q_current:.2f} to q={q_target:.2f}: {summary}")
