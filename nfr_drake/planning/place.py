"""Place: after opening, pick an item from a table beside the robot and put it at the goal keypoint.

The motion starts where the opening plan ends (the hand on the handle at q_target, base unchanged)
or, on a base re-placed in front of the open compartment after the opening (`place_bases`; a
mobile manipulator's base driven to a second spot), from a ready posture (`ready_posture`). It
has three segments of knots, each knot a chained-IK pose; from knot to knot one
`KinematicTrajectoryOptimization` (SNOPT) with minimum-distance constraints at evenly spaced
samples, at rest at both ends:
1. "to pick": back off the handle along its approach (on the opening's base), to the pre-pick
   pose, to the pick pose;
2. "carry": lift, up, over to above the pre-place pose outside the compartment, down to it, in
   along a straight line (the way into the compartment: horizontal through a closet's front, down
   into a drawer) to the place pose: the item's bottom centre `drop_height` above the goal
   keypoint, upright;
3. "retreat": back straight out along the tool's axis until the open fingers are off the item
   (`_straight_out`), then out along the way in (the hand may touch the item it let go of; the
   approach within `approach_cone_deg` of the place's), the item left behind (without
   `PlaceConfig.back_off`, out along the way in at once: `fallback_configs`).
Grasps: a closet's item is held from the side (horizontal approach, finger pads vertical: the
hand fits under a shelf), a drawer's from the top (vertical approach: it is open from above). The
obstacles: those that stay put, those of the moving part at q_target (the hand may touch them
while it backs off the handle), the table, and the item on it (until the pre-pick); the held item
is checked against them all (not against the table while it is lifted off it). The fingers are
open in the plan; the simulation closes them.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
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
from nfr_drake.planning.compartment import compartment_entry, compartment_obstacles, front_normal
from nfr_drake.planning.planner import _ACCEL_LIMITS, PlanningError, _initial_guess
from nfr_drake.planning.scene import PlanningScene, build_planning_scene
from nfr_drake.world.items import Item
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.obstacles import distance_to_box
from nfr_drake.world.plan import HandleWaypoint, ObstacleBox
from nfr_drake.world.robot import FINGER_OPEN, NUM_ARM_JOINTS, Q_HOME, arm_joint_limits

_Z = np.array([0.0, 0.0, 1.0])
_IK_ITERATIONS = 80
_KNOT_SLACK = 0.003  # knots clear obstacles by this much more than the trajectories between them, m
GRASP_OF = {"closet": "side", "drawer": "top"}
"""The grasp of the item by the category it is placed in (module docstring)."""
PLACE_REACH = {"closet": (0.7, 0.8, 0.9), "drawer": (0.5, 0.55, 0.7)}
"""`PlannerConfig.place_reach` values for an opening a place follows, tried in turn (the nearer
base first), by category, m: a closet's goal is reached by a level hand through its front (the
line in, 0.3-0.4 m long, starts that much nearer the base), a drawer's from above, over the
front (a forearm that comes down steeply: the base nearer)."""
_BASE_BEARINGS_DEG = (0.0, 15.0, -15.0, 25.0, -25.0, 40.0, -40.0, 55.0, -55.0)
"""A re-placed base's bearings from the goal, from the front's outward normal, degrees: straight
in front and turned across the front to either side (beside an open door's free edge)."""
_BASE_CLEARANCE = 0.25
"""A re-placed base's axis clears the compartment and the open door by this much, m."""
_SIGHT_HEIGHT = 0.2
"""The sight line to the pre-place point starts this far above it on the base axis, m."""
_SIGHT_CLEARANCE = 0.06
"""The sight line clears the compartment and the open door by this much, m (the forearm's radius)."""
_SIGHT_FRACTION = 0.85
"""How much of the sight line (from the base) must clear them: its end lies at the front."""
_OVER_REACH = 0.12  # a box within this of the carry's line (horizontally) is carried over, m
_OVER_CLEARANCE = 0.05  # a carried item's bottom over the boxes it passes over, m
_OVER_LIMIT = 0.75  # the highest a carried item's bottom is lifted over boxes, above the base, m
WRIST_DIAMETER = 0.10
"""The Panda's wrist (link 7, a 5 cm capsule about the approach, 8-21 cm behind the tool) across,
m: a side-held item goes under a shelf over the goal only with the wrist under it too."""


@dataclass
class PlaceConfig:
    """Options of `plan_place`."""

    retreat_distance: float = 0.10
    """How far the tool backs off the handle along its approach, m."""
    pregrasp_distance: float = 0.08
    """Pre-pick: the tool this far back along its approach from the pick pose, m."""
    lift_height: float = 0.08
    """How far the item is lifted off the table before it is carried, m."""
    carry_clearance: float = 0.05
    """Side grasps: the item is carried from above the table to above the pre-place pose this far
    above the higher of the two, m (top grasps: at the higher of the two)."""
    entry_margin: float = 0.06
    """Closet: the pre-place pose holds the item this far in front of the front plane, m. Drawer:
    this far above the drawer's estimated walls."""
    drop_height: float = 0.015
    """The item's bottom above the goal when released, m (more than `min_distance`)."""
    top_grip_depth: float = 0.02
    """Top grasp: the tool origin this far below the item's top, m."""
    side_grip_height: float = 0.065
    """Side grasp: the tool origin this far above the item's bottom, m (the wrist, 5 cm in radius
    about the approach, clears the surface the item stands on)."""
    position_tolerance: float = 0.004
    upright_tolerance_deg: float = 12.0
    """The held item within this of upright while carried, degrees."""
    release_upright_deg: float = 2.0
    """... and within this at the place, where the arm reaches so (else within
    `upright_tolerance_deg`): released tilted, an item lands on an edge and rocks over (closet 47
    of capture seed 200 was left 4.7 cm from the goal so at 211beb9)."""
    approach_cone_deg: float = 40.0
    """Side grasp at the place: the approach within this of the way into the closet (the hand may
    turn about the vertical)."""
    line_tolerance: float = 0.01
    """The pick's last piece (pre-pick to pick): the pick point within this of the tool's axis, m."""
    line_overshoot: float = 0.006
    """... and the tool at most this past it along its approach, m (the open fingers would push the
    item: 12 cm past it on one plan without this, and the item was nudged off its hold)."""
    back_off: bool = True
    """Whether the tool backs straight off the item after the release (`_straight_out`) before it
    retreats along the way in; False: it retreats at once (the hand may swing and drag the item
    with a finger). Callers plan with it first and without it only where no base plans
    (`fallback_configs`)."""
    back_off_clearance: float = 0.02
    """The back-off ends where the fingertips (1 cm past the tool origin) clear the item's near
    side by this much, m ..."""
    back_off_tolerance: float = 0.004
    """... the release point within this of the tool's axis, m (open fingers clear a 6.7 cm item by
    6.5 mm a side) ..."""
    back_off_turn_deg: float = 3.0
    """... and the tool turned at most this from its orientation at the release, degrees."""
    min_distance: float = 0.01
    collision_samples: int = 12
    """Fewest collision samples per piece (knot to knot); at most four times as many."""
    collision_step: float = 0.03
    """Largest joint move between collision samples (as far as the sample count allows), rad:
    a forearm half a metre out sweeps 1.5 cm, less than a door's thickness."""
    ik_seeds: int = 6
    """Perturbed home postures each knot's IK tries as seeds after the last knot, the home posture
    and the planar postures (`_seeds`; SNOPT is local)."""
    retry_ik_seeds: int = 18
    """Where no base plans with any of the `fallback_configs`, the search runs again with this many
    (a knot's IK can fail from every seed on every base for a door measured a fraction of a
    degree off: closet 81 of capture seed 200, docs/PLACE.md "Results")."""
    deep_seeds: int = 0
    """0: the carry's knots are solved in turn from the pick. Else from the place out
    (`_solve_deepest_first`): the place knot from this many postures drawn across the joint
    ranges too ..."""
    deep_tries: int = 8
    """... and from each of at most this many of its solutions, the way in backwards."""
    retry_deep_seeds: int = 150
    """The `deep_seeds` of the search's last round (`fallback_configs`): where no base plans
    otherwise (low compartments whose goal the arm reaches only on a branch that a chain solved
    from the pick never settles on: closet 74 of capture seed 200, docs/PLACE.md "Results")."""
    num_control_points: int = 10
    velocity_scale: float = 0.5
    acceleration_scale: float = 0.3
    tool_speed: float = 0.12
    """Largest mean speed of the tool on the straight stretches (in and out, lift), m/s."""

    def __post_init__(self) -> None:
        if self.drop_height <= self.min_distance:
            raise NfrDrakeError("place: drop_height must exceed min_distance (the held item clears "
                                "the compartment's floor by min_distance in the plan)")


@dataclass(frozen=True)
class PlaceProblem:
    """What the place planner gets. goal: the goal keypoint at q_target, m, (3,) in W; entry: unit
    direction in W into the compartment (horizontal for a closet, -z for a drawer); entry_depth:
    how far the pre-place pose lies back from the place along the entry, m; fixed, moving:
    obstacle boxes that stay put and those of the moving part at q_target; table: the item's
    support; X_WI: the item's pose on it (frame I: `nfr_drake.world.items`)."""

    grasp: str
    goal: np.ndarray
    entry: np.ndarray
    entry_depth: float
    fixed: list[ObstacleBox]
    moving: list[ObstacleBox]
    table: ObstacleBox
    item: Item
    X_WI: RigidTransform


def place_problem(kt: KeypointTrajectory, q_target: float, item: Item, X_WI: RigidTransform,
                  table: ObstacleBox, obstacles: tuple[list[ObstacleBox], list[ObstacleBox]] | None = None,
                  config: PlaceConfig | None = None, toward: np.ndarray | None = None,
                  floor: float | None = None) -> PlaceProblem:
    """The problem of placing `item` (at X_WI on `table`) at the goal of `kt` opened to q_target:
    a side grasp into a closet, a top grasp into a drawer. obstacles: (fixed, moving) boxes, e.g.
    of a true model; None: from the keypoints (`compartment_obstacles`). toward: the base's
    position (m, (3,) in W) a closet's way in turns toward (`compartment_entry`); None: straight in.
    floor: the compartment floor's height under the goal where measured (m in W; a look inside,
    `InteriorLook`): the goal's height; None: the keypoint's."""
    entry, depth = _entry(kt, q_target, item, config or PlaceConfig(), toward)
    fixed, moving = obstacles if obstacles is not None else compartment_obstacles(kt, q_target)
    goal = kt.point("goal", q_target)
    if floor is not None:
        goal = np.array([goal[0], goal[1], floor])
    return PlaceProblem(GRASP_OF[kt.category], goal, entry, depth, list(fixed), list(moving), table, item,
                        X_WI)


def _entry(kt: KeypointTrajectory, q_target: float, item: Item, cfg: PlaceConfig,
           toward: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The way in (unit, (3,)) and the pre-place point's distance from the place along it, m."""
    entry, opening = compartment_entry(kt, q_target, toward)
    along = item.half_extents[0] if kt.category == "closet" else 0.0
    return entry, opening + along + cfg.entry_margin


def place_bases(kt: KeypointTrajectory, q_target: float, obstacles: list[ObstacleBox],
                heights: tuple[float, ...] = (0.0,)) -> list[RigidTransform]:
    """Poses of a base re-placed after the opening to place in the compartment opened to q_target
    (a mobile manipulator's base driven to a second spot): its goal `PLACE_REACH` away (nearest
    first), at the bearings `_BASE_BEARINGS_DEG` from the front's outward normal (`front_normal`),
    at each of `heights` above the floor (m), facing the goal. Kept when the base's axis clears
    `obstacles` (boxes in W: the compartment and its open front) by `_BASE_CLEARANCE` and the
    straight line from `_SIGHT_HEIGHT` above the pre-place point on that axis to the pre-place
    point (10 cm out of the front along the way in, `compartment_entry` turned toward the base)
    clears them by `_SIGHT_CLEARANCE` (all but its last part, `_SIGHT_FRACTION`): an open door
    between the base and the front turns a base away."""
    goal = kt.point("goal", q_target)
    n = front_normal(kt, q_target)
    f = np.linspace(0.0, _SIGHT_FRACTION, 12)[:, None]
    bases = []
    for height in heights:
        for reach in PLACE_REACH[kt.category]:
            for bearing in np.radians(_BASE_BEARINGS_DEG):
                direction = RotationMatrix.MakeZRotation(bearing) @ n
                p_WB = goal + reach * direction
                p_WB[2] = height
                entry, opening = compartment_entry(kt, q_target, p_WB)
                p_pre = goal - (opening + 0.1) * entry
                column = p_WB + np.outer(np.linspace(0.0, 0.6, 7), _Z)
                sight = (1 - f) * (p_WB * [1, 1, 0] + [0, 0, p_pre[2] + _SIGHT_HEIGHT]) + f * p_pre
                if all(distance_to_box(box, column).min() >= _BASE_CLEARANCE
                       and distance_to_box(box, sight).min() >= _SIGHT_CLEARANCE for box in obstacles):
                    yaw = np.arctan2(*(goal - p_WB)[1::-1])
                    bases.append(RigidTransform(RollPitchYaw(0.0, 0.0, yaw), p_WB))
    return bases


def ready_posture(X_WB: RigidTransform, p_W: np.ndarray) -> np.ndarray:
    """The arm's positions (9,) on a re-placed base X_WB before the place: the home posture turned
    about the base axis to face p_W (m, in W), the fingers open."""
    p_B = X_WB.inverse() @ p_W
    return np.r_[np.arctan2(p_B[1], p_B[0]), Q_HOME[1:], FINGER_OPEN, FINGER_OPEN]


def place_reach_points(kt: KeypointTrajectory, q_target: float, item: Item,
                       config: PlaceConfig | None = None) -> np.ndarray:
    """The held item's origin at the pre-place pose and at the goal, m, (2, 3) in W: what the
    opening plan's base must reach (`plan_articulation`'s `must_reach`)."""
    entry, depth = _entry(kt, q_target, item, config or PlaceConfig())
    goal = kt.point("goal", q_target)
    return np.stack([goal - depth * entry, goal])


@dataclass
class PlaceSegment:
    """One planned segment: trajectories of the planning plant's positions (7 arm joints, 2
    fingers) one after another, each over t in [0, its duration], s, at rest at both ends."""

    name: str
    pieces: list[BsplineTrajectory]

    @property
    def duration(self) -> float:
        return sum(float(p.end_time() - p.start_time()) for p in self.pieces)

    def value(self, t: float) -> np.ndarray:
        """Positions at time t into the segment (clamped to [0, duration]), shape (9,)."""
        for piece in self.pieces:
            if t <= piece.end_time():
                return piece.value(max(t, 0.0)).ravel()
            t -= piece.end_time()
        return self.pieces[-1].value(self.pieces[-1].end_time()).ravel()


@dataclass
class PlacePlan:
    """The planned pick and place. X_GI: the item in the tool frame while held; X_WI_pick: its pose
    on the table; X_WI_place: where the plan leaves it (at release, before the drop), in W."""

    segments: list[PlaceSegment]
    X_WB: RigidTransform
    X_GI: RigidTransform
    X_WI_pick: RigidTransform
    X_WI_place: RigidTransform
    goal: np.ndarray
    seconds: float

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.segments)

    def place_error(self) -> float:
        """Horizontal distance of the planned item's bottom centre from the goal, m."""
        return float(np.linalg.norm((self.X_WI_place.translation() - self.goal)[:2]))


def grasp_in_item(item: Item, grasp: str, cfg: PlaceConfig, flip: bool = False) -> RigidTransform:
    """X_IG: the tool frame G in the item frame I for a "top" or "side" grasp; `flip` turns the
    hand 180 degrees about its approach."""
    e1, e2, e3 = np.eye(3)
    if grasp == "top":  # approach down, pads along the item's x
        R, p = np.column_stack([e1, -e2, -e3]), [0.0, 0.0, item.height - cfg.top_grip_depth]
    elif grasp == "side":  # approach along the item's x, pads vertical
        R, p = np.column_stack([e3, -e2, e1]), [0.0, 0.0, min(cfg.side_grip_height, item.height - 0.015)]
    else:
        raise NfrDrakeError(f"grasp must be top or side, got {grasp!r}")
    X = RigidTransform(RotationMatrix(R), p)
    return X @ RigidTransform(RotationMatrix.MakeZRotation(np.pi)) if flip else X


class _Stage:
    """One knot: named constraints on the tool frame, the scene its IK clears, the tool point it
    aims at (for its timing and IK seeds) and, if known, the tool's approach there (unit, W).
    along: constraints at the inner collision samples of the piece to it, given the scene and the
    tool point it starts from (a straight piece, `_straight_in`, `_straight_out`); None: free."""

    def __init__(self, name: str, scene: str, p_W: np.ndarray, constraints,
                 approach: np.ndarray | None = None,
                 along: Callable[[PlanningScene, np.ndarray], list] | None = None):
        self.name, self.scene, self.p_W, self.constraints = name, scene, np.asarray(p_W), constraints
        self.approach, self.along = approach, along


def _tool_pose(X_WG: RigidTransform, cfg: PlaceConfig, angle_deg: float = 2.0):
    def make(sc: PlanningScene):
        tol = np.full(3, cfg.position_tolerance)
        p = X_WG.translation()
        return [PositionConstraint(sc.plant, sc.plant.world_frame(), p - tol, p + tol, sc.tool_frame,
                                   np.zeros(3), sc.plant_context),
                OrientationConstraint(sc.plant, sc.plant.world_frame(), X_WG.rotation(), sc.tool_frame,
                                      RotationMatrix(), np.radians(angle_deg), sc.plant_context)]
    return make


def _tool_at(p_W: np.ndarray, tol: float):
    def make(sc: PlanningScene):
        return [PositionConstraint(sc.plant, sc.plant.world_frame(), p_W - tol, p_W + tol, sc.tool_frame,
                                   np.zeros(3), sc.plant_context)]
    return make


def _backing_out(p_W: np.ndarray, X_WG: RigidTransform, cfg: PlaceConfig):
    """The tool origin at p_W (within 1 cm), its approach within `approach_cone_deg` of X_WG's."""
    def make(sc: PlanningScene):
        cone = AngleBetweenVectorsConstraint(sc.plant, sc.plant.world_frame(), X_WG.rotation().col(2),
                                             sc.tool_frame, np.array([0.0, 0.0, 1.0]), 0.0,
                                             np.radians(cfg.approach_cone_deg), sc.plant_context)
        return [*_tool_at(p_W, 0.01)(sc), cone]
    return make


def _item_at(p_WI: np.ndarray, X_GI: RigidTransform, entry: np.ndarray, side: bool, cfg: PlaceConfig,
             upright_deg: float | None = None):
    """The held item's origin at p_WI, upright within `upright_deg` (None: the config's
    `upright_tolerance_deg`); a side grasp's approach within the cone of `entry`."""
    upright = cfg.upright_tolerance_deg if upright_deg is None else upright_deg

    def make(sc: PlanningScene):
        W, G, ctx = sc.plant.world_frame(), sc.tool_frame, sc.plant_context
        tol = np.full(3, cfg.position_tolerance)
        out = [PositionConstraint(sc.plant, W, p_WI - tol, p_WI + tol, G, X_GI.translation(), ctx),
               AngleBetweenVectorsConstraint(sc.plant, W, _Z, G, X_GI.rotation().col(2), 0.0,
                                             np.radians(upright), ctx)]
        if side:
            out.append(AngleBetweenVectorsConstraint(sc.plant, W, entry, G, np.array([0.0, 0.0, 1.0]), 0.0,
                                                     np.radians(cfg.approach_cone_deg), ctx))
        return out
    return make


_PLANAR: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []


def _planar_postures() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Postures of the arm in its base's x-z plane (joints 1, 3 and 5 at zero, joint 7 at pi/4) on a
    grid of joints 2, 4 and 6: postures (N, 7), their tool points (N, 3) and approaches (N, 3) in
    the base frame. Computed once per process."""
    if not _PLANAR:
        sc = build_planning_scene(RigidTransform(), [])
        lower, upper = sc.plant.GetPositionLowerLimits(), sc.plant.GetPositionUpperLimits()
        postures, points, approaches = [], [], []
        for q2 in np.linspace(lower[1] + 0.05, upper[1] - 0.05, 15):
            for q4 in np.linspace(lower[3] + 0.05, upper[3] - 0.05, 13):
                for q6 in np.linspace(lower[5] + 0.05, upper[5] - 0.05, 15):
                    q = np.array([0.0, q2, 0.0, q4, 0.0, q6, np.pi / 4])
                    sc.plant.SetPositions(sc.plant_context, np.r_[q, FINGER_OPEN, FINGER_OPEN])
                    X = sc.tool_frame.CalcPoseInWorld(sc.plant_context)
                    postures.append(q)
                    points.append(X.translation())
                    approaches.append(X.rotation().col(2))
        _PLANAR.append((np.array(postures), np.array(points), np.array(approaches)))
    return _PLANAR[0]


def _planar_seeds(sc: PlanningScene, p_W: np.ndarray, approach_W: np.ndarray | None, count: int = 2
                  ) -> list[np.ndarray]:
    """Arm postures (7,) turned about the base axis to face p_W whose tool point lies nearest it
    (in range and height) with the approach nearest `approach_W` (unit, W; None: any)."""
    postures, points, approaches = _planar_postures()
    p_B = sc.X_WB.inverse() @ p_W
    yaw = float(np.arctan2(p_B[1], p_B[0]))
    cost = np.hypot(points[:, 0] - np.hypot(p_B[0], p_B[1]), points[:, 2] - p_B[2])
    if approach_W is not None:
        a = RotationMatrix.MakeZRotation(-yaw) @ (sc.X_WB.rotation().inverse() @ approach_W)
        cost = cost + 0.1 * np.arccos(np.clip(approaches @ a, -1.0, 1.0))
    return [postures[i] + np.r_[yaw, np.zeros(6)] for i in np.argsort(cost)[:count]]


def _seeds(sc: PlanningScene, stage: _Stage, q_prev: np.ndarray, perturbed: int):
    """IK seeds: q_prev, then the home posture turned about the base axis to face the stage's
    point, postures of the arm in that vertical plane nearest the point and the stage's approach
    (`_planar_seeds`, joint 7 also turned a quarter turn either way), then the home posture
    `perturbed` times perturbed (a fixed random stream: plans are repeatable, and more seeds
    start with the same ones); fingers of q_prev."""
    yield q_prev
    fingers = q_prev[NUM_ARM_JOINTS:]
    p_B = sc.X_WB.inverse() @ stage.p_W
    facing = np.r_[np.arctan2(p_B[1], p_B[0]), Q_HOME[1:], fingers]
    yield facing
    for q in _planar_seeds(sc, stage.p_W, stage.approach):
        for turn in (0.0, np.pi / 2, -np.pi / 2):
            yield np.r_[q[:6], q[6] + turn, fingers]
    rng = np.random.default_rng(0)
    for _ in range(perturbed):
        yield facing + np.r_[rng.normal(0.0, 0.5, NUM_ARM_JOINTS), np.zeros(len(q_prev) - NUM_ARM_JOINTS)]


def _knot_solutions(sc: PlanningScene, stage: _Stage, q_prev: np.ndarray, seeds: Iterable[np.ndarray],
                    cfg: PlaceConfig) -> Iterator[np.ndarray]:
    """Each IK solution (9,) of the stage from the seeds in turn: its constraints, the knots'
    clearance, kept close to q_prev, the fingers fixed at q_prev's. A seed whose solve raises
    (FCL's distance query inside SNOPT, on a degenerate pair of capsules: closet 18 of capture
    seed 200 stopped an evaluation so) counts as one that failed."""
    options = SolverOptions()
    options.SetOption(SnoptSolver.id(), "Major iterations limit", _IK_ITERATIONS)
    ik = InverseKinematics(sc.plant, sc.plant_context)
    q = ik.q()
    for c in stage.constraints(sc):
        ik.prog().AddConstraint(c, q)
    ik.AddMinimumDistanceLowerBoundConstraint(cfg.min_distance + _KNOT_SLACK, 0.05)
    fingers = q_prev[NUM_ARM_JOINTS:]
    ik.prog().AddBoundingBoxConstraint(fingers, fingers, q[NUM_ARM_JOINTS:])
    ik.prog().AddQuadraticErrorCost(np.eye(len(q)), q_prev, q)
    for seed in seeds:
        try:
            result = SnoptSolver().Solve(ik.prog(), seed, options)
        except RuntimeError:  # FCL's distance query can fail on a degenerate pair: the next seed
            continue
        if result.is_success():
            yield result.GetSolution(q)


def _nearby(q: np.ndarray, count: int = 4, spread: float = 0.1) -> Iterator[np.ndarray]:
    """q (9,), then `count` postures around it: its arm joints perturbed by `spread` rad (a fixed
    random stream)."""
    yield q
    rng = np.random.default_rng(0)
    for _ in range(count):
        yield q + np.r_[rng.normal(0.0, spread, NUM_ARM_JOINTS), np.zeros(len(q) - NUM_ARM_JOINTS)]


def _solve_chain(scenes: dict[str, PlanningScene], stages: list[_Stage], q0: np.ndarray,
                 cfg: PlaceConfig, on_branch: bool = False) -> tuple[list[np.ndarray] | None, str]:
    """IK of each stage in turn (`_knot_solutions`), seeded by and kept close to the last; fingers
    fixed: (the solutions, "") or (None, the stage that failed). Seeds: `_seeds`; `on_branch`:
    only the last knot's posture and postures near it (`_nearby`), so the arm stays on its branch."""
    q_prev, sols = q0, []
    for stage in stages:
        sc = scenes[stage.scene]
        seeds = _nearby(q_prev) if on_branch else _seeds(sc, stage, q_prev, cfg.ik_seeds)
        q_prev = next(_knot_solutions(sc, stage, q_prev, seeds, cfg), None)
        if q_prev is None:
            return None, stage.name
        sols.append(q_prev)
    return sols, ""


def _solve_deepest_first(scenes: dict[str, PlanningScene], stages: list[_Stage], q0: np.ndarray, deep: int,
                         cfg: PlaceConfig) -> tuple[list[np.ndarray] | None, str]:
    """IK of a chain from its deepest knot out: the stages before its last `deep` in turn from q0
    (`_solve_chain`); the last stage from its usual seeds and `cfg.deep_seeds` postures drawn
    across the joint ranges (a fixed stream), and from each solution found (at most
    `cfg.deep_tries`) the rest of the last `deep` backwards, each seeded by and kept close to the
    one after it, on its branch (`_solve_chain`'s `on_branch`). A chain solved from the pick
    settles on a branch of the arm that may not reach a low compartment's goal (closet 74 of
    capture seed 200: the goal 18.8 cm behind the front, 18 cm under the shelf, docs/PLACE.md)."""
    head, tail = stages[:-deep], stages[-deep:]
    sols, failed = _solve_chain(scenes, head, q0, cfg)
    if sols is None:
        return None, failed
    q_head = sols[-1] if sols else q0
    last = tail[-1]
    sc = scenes[last.scene]
    lower, upper = arm_joint_limits()
    rng = np.random.default_rng(1)
    spread = (np.r_[rng.uniform(lower, upper), q_head[NUM_ARM_JOINTS:]] for _ in range(cfg.deep_seeds))
    seeds = itertools.chain(_seeds(sc, last, q_head, cfg.ik_seeds), spread)
    for q_last in itertools.islice(_knot_solutions(sc, last, q_head, seeds, cfg), cfg.deep_tries):
        back, failed = _solve_chain(scenes, tail[-2::-1], q_last, cfg, on_branch=True)
        if back is not None:
            return [*sols, *back[::-1], q_last], ""
    return None, failed or last.name


def _on_axis(sc: PlanningScene, ahead: np.ndarray, behind: np.ndarray, cfg: PlaceConfig, tol: float
             ) -> list[PositionConstraint]:
    """The tool on the segment between two points (m, (3,) in W), its axis along it: `ahead` on
    the tool's axis (within `tol`) ahead of the tool, `behind` on it behind the tool, neither
    passed by more than `cfg.line_overshoot`."""
    length = float(np.linalg.norm(ahead - behind))
    W, G, ctx = sc.plant.world_frame(), sc.tool_frame, sc.plant_context
    return [PositionConstraint(sc.plant, G, [-tol, -tol, -cfg.line_overshoot], [tol, tol, length + 0.01],
                               W, ahead, ctx),
            PositionConstraint(sc.plant, G, [-tol, -tol, -length - 0.01], [tol, tol, cfg.line_overshoot],
                               W, behind, ctx)]


def _straight_in(p_to: np.ndarray, cfg: PlaceConfig):
    """`_Stage.along` of a piece forward along the tool's axis to p_to (m, (3,) in W), within
    `cfg.line_tolerance` of the line."""
    return lambda sc, p_from: _on_axis(sc, p_to, p_from, cfg, cfg.line_tolerance)


def _straight_out(X_WG: RigidTransform, p_to: np.ndarray, cfg: PlaceConfig):
    """`_Stage.along` of a piece from the tool pose X_WG backwards along the tool's axis to p_to
    (m, (3,) in W), within `cfg.back_off_tolerance` of the line and `cfg.back_off_turn_deg` of
    X_WG's orientation: the open fingers slide off the item they let go of (a retreat free to
    swing dragged closet 3's mug off the goal with one finger: 4.8 cm in the rows of 211beb9)."""
    def along(sc: PlanningScene, _p_from: np.ndarray) -> list:
        return [*_on_axis(sc, X_WG.translation(), p_to, cfg, cfg.back_off_tolerance),
                OrientationConstraint(sc.plant, sc.plant.world_frame(), X_WG.rotation(), sc.tool_frame,
                                      RotationMatrix(), np.radians(cfg.back_off_turn_deg), sc.plant_context)]
    return along


_RESAMPLES = 2
"""How often a piece is optimised again with collision samples added where a check four times as
dense found it closer than half the bound to the scene."""


def _optimise_piece(scenes: dict[str, PlanningScene], stage: _Stage, q_from: np.ndarray, q_to: np.ndarray,
                    p_from: np.ndarray, cfg: PlaceConfig) -> tuple[BsplineTrajectory | None, list[str]]:
    """One trajectory from q_from (exactly) to the stage's constraints, warm-started from the
    straight line to its IK solution q_to, at rest at both ends; the collision samples clear the
    stage's scene. A solution is checked four times as densely: where it passes closer than half
    `min_distance`, those points become samples too and it is optimised again (`_RESAMPLES`
    times: a held item swept 4 mm from a closet's side wall between samples and was knocked out
    of the fingers). Retried once at 1.6 times the duration."""
    sc = scenes[stage.scene]
    plant = sc.plant
    nq = plant.num_positions()
    vmax = cfg.velocity_scale * plant.GetVelocityUpperLimits()
    tau = max(1.5 * float(np.max(np.abs(q_to - q_from)[:NUM_ARM_JOINTS] / vmax[:NUM_ARM_JOINTS])),
              float(np.linalg.norm(stage.p_W - p_from)) / cfg.tool_speed, 0.5)
    check = MinimumDistanceLowerBoundConstraint(plant, cfg.min_distance, sc.plant_context, None, 0.05)
    between = MinimumDistanceLowerBoundConstraint(plant, 0.5 * cfg.min_distance, sc.plant_context, None, 0.05)
    travel = float(np.max(np.abs(q_to - q_from)[:NUM_ARM_JOINTS]))
    samples = int(np.clip(np.ceil(travel / cfg.collision_step), cfg.collision_samples,
                          4 * cfg.collision_samples))
    failed: list[str] = []
    tries = [(scale, extra) for scale in (1.0, 1.6) for extra in range(_RESAMPLES + 1)]
    added: list[float] = []
    for scale, extra in tries:
        if extra == 0:
            added = []
        elif not added:
            continue
        duration = scale * tau
        trajopt = KinematicTrajectoryOptimization(nq, cfg.num_control_points, spline_order=4)
        prog = trajopt.get_mutable_prog()
        trajopt.AddPathEnergyCost(1.0)
        lower, upper = plant.GetPositionLowerLimits().copy(), plant.GetPositionUpperLimits().copy()
        lower[NUM_ARM_JOINTS:] = upper[NUM_ARM_JOINTS:] = q_from[NUM_ARM_JOINTS:]
        trajopt.AddPositionBounds(lower, upper)
        trajopt.AddVelocityBounds(-vmax, vmax)
        amax = np.r_[cfg.acceleration_scale * _ACCEL_LIMITS, np.ones(nq - NUM_ARM_JOINTS)]
        trajopt.AddAccelerationBounds(-amax, amax)
        trajopt.AddDurationConstraint(duration, duration)
        described = [("start configuration", trajopt.AddPathPositionConstraint(q_from, q_from, 0.0))]
        for s in (0.0, 1.0):
            described.append((f"at rest at s={s:.0f}", trajopt.AddPathVelocityConstraint(
                np.zeros(nq), np.zeros(nq), s)))
        described += [(stage.name, trajopt.AddPathPositionConstraint(c, 1.0)) for c in stage.constraints(sc)]
        described += [(f"collision clearance at s={s:.2f} ({stage.scene})",
                       trajopt.AddPathPositionConstraint(check, s))
                      for s in np.r_[np.linspace(0.0, 1.0, samples + 1)[1:], added]]
        if stage.along is not None:
            described += [(f"straight to {stage.name}", trajopt.AddPathPositionConstraint(c, s))
                          for c in stage.along(sc, p_from)
                          for s in np.linspace(0.0, 1.0, samples + 1)[1:-1]]
        for name, binding in described:
            binding.evaluator().set_description(name)
        trajopt.SetInitialGuess(_initial_guess(trajopt, np.array([0.0, 1.0]), np.stack([q_from, q_to]),
                                               duration))
        options = SolverOptions()
        options.SetOption(SnoptSolver.id(), "Major iterations limit", 500)
        try:
            result = SnoptSolver().Solve(prog, None, options)
        except RuntimeError as err:  # FCL's distance query can fail on a degenerate pair of shapes
            added, failed = [], [f"collision query error in the solver ({str(err).splitlines()[0][:80]})"]
            continue
        if result.is_success():
            traj = trajopt.ReconstructTrajectory(result)
            dense = np.linspace(1.0 / samples, 1.0, 4 * samples - 3)  # from the first sample on
            close = [s for s in dense if not between.CheckSatisfied(traj.value(s * duration).ravel())]
            if not close:
                return traj, []
            added = [*added, *close]  # closer than half the bound between samples: sampled there too
            failed = [f"collision clearance between samples ({stage.scene})"]
            continue
        added = []
        failed = sorted(set(result.GetInfeasibleConstraintNames(prog, 1e-4))) or [
            f"solver status {result.get_solution_result()}"]
    return None, failed


def _pieces(scenes: dict[str, PlanningScene], stages: list[_Stage], sols: list[np.ndarray], q: np.ndarray,
            p: np.ndarray, cfg: PlaceConfig) -> tuple[list[BsplineTrajectory] | None, str]:
    """Trajectories (`_optimise_piece`) from the positions q (the tool at p, m, W) through the
    stages' IK solutions in turn: (the pieces, "") or (None, the failure in one line)."""
    pieces = []
    for stage, q_to in zip(stages, sols, strict=True):
        traj, failed = _optimise_piece(scenes, stage, q, q_to, p, cfg)
        if traj is None:
            return None, f"trajectory optimisation to {stage.name}: " + ", ".join(failed)
        pieces.append(traj)
        q, p = traj.value(traj.end_time()).ravel(), stage.p_W
    return pieces, ""


def _over(boxes: list[ObstacleBox], a: np.ndarray, b: np.ndarray, X_WB: RigidTransform) -> float:
    """How high a held item's bottom must pass over the boxes (in W) that the horizontal line
    from a to b (m, (3,)) crosses within `_OVER_REACH`: their highest top plus `_OVER_CLEARANCE`,
    m; -inf when none is crossed or when that lies more than `_OVER_LIMIT` above the base (a tall
    carcass is gone round, not over). Between collision samples a carried item grazed a low
    closet's top edge and was knocked out of the fingers."""
    pts = a + np.linspace(0.0, 1.0, 25)[:, None] * (b - a)
    need = -np.inf
    for box in boxes:
        top = box.top
        level = pts * [1, 1, 0] + [0, 0, top - 1e-3]
        if distance_to_box(box, level).min() <= _OVER_REACH:
            need = max(need, top + _OVER_CLEARANCE)
    return need if need <= X_WB.translation()[2] + _OVER_LIMIT else -np.inf


def free_height(boxes: list[ObstacleBox], p_W: np.ndarray, reach: float = 1.0) -> float:
    """Height of the lowest of `boxes` (in W) over the point p_W (m, (3,)), above it, m (every
    5 mm; `reach` when none lies within that)."""
    z = np.arange(0.005, reach, 0.005)
    column = np.asarray(p_W) + z[:, None] * _Z
    blocked = np.any([distance_to_box(box, column) <= 0.0 for box in boxes], axis=0) if boxes else []
    return float(z[np.argmax(blocked)]) if np.any(blocked) else reach


def side_room_needed(item: Item, cfg: PlaceConfig) -> float:
    """The free height over the goal a side-held item needs, m: the item dropped from
    `drop_height` and the wrist (`WRIST_DIAMETER`) under what lies over it, each with the knots'
    clearance above and below."""
    clearance = cfg.min_distance + _KNOT_SLACK
    return max(item.height + cfg.drop_height + clearance, WRIST_DIAMETER + 2 * clearance)


def _retreat(X_WGplace: RigidTransform, pb: PlaceProblem, cfg: PlaceConfig) -> list[_Stage]:
    """The retreat's knots from the release pose X_WGplace: with `cfg.back_off`, backed straight
    off the item along the tool's axis until the open fingers clear it by `back_off_clearance`
    (`_straight_out`), then out along the way in."""
    approach = X_WGplace.rotation().col(2)
    p_outs = [X_WGplace.translation() - f * pb.entry_depth * pb.entry for f in (0.5, 1.0)]
    outs = [_Stage(f"retreat {k}", "retreat", p, _backing_out(p, X_WGplace, cfg), approach)
            for k, p in enumerate(p_outs, start=1)]
    if not cfg.back_off:
        return outs
    off = X_WGplace.translation() - (pb.item.depth / 2 + 0.01 + cfg.back_off_clearance) * approach
    back_off = _Stage("backing off the item", "retreat", off,
                      _tool_pose(RigidTransform(X_WGplace.rotation(), off), cfg, cfg.back_off_turn_deg),
                      approach, _straight_out(X_WGplace, off, cfg))
    return [back_off, *outs]


class PlaceUnreachable(PlanningError):
    """The place fails from this base whatever the fallback config: `plan_place` failed before the
    retreat for every hand flip (no room under a shelf over the goal, no IK for a knot up to the
    place), or the base has no opening or table. The `fallback_configs` of the same `ik_seeds`
    change only the back-off off the item and the release's tilt, whose IK the first config
    already tries, so on the same base they fail the same: callers skip that base for them (and
    try it again with more seeds, and from the place out)."""


def fallback_configs(cfg: PlaceConfig) -> list[PlaceConfig]:
    """The place's configs to plan with in turn, each on every base before the next: cfg; without
    the back-off off the item (`PlaceConfig.back_off`); and that with the item released within
    the carry's `upright_tolerance_deg` wherever it plans (not only where the level release finds
    no IK: a level release can leave the pieces between the knots no trajectory); then, where
    `retry_ik_seeds` exceeds `ik_seeds`, the three again with that many IK seeds; then, where
    `retry_deep_seeds` exceeds `deep_seeds`, the three solved from the place out with those. A
    place that plans with the first three plans as it would without the rest."""
    free = replace(cfg, back_off=False)
    loose = replace(free, release_upright_deg=max(cfg.release_upright_deg, cfg.upright_tolerance_deg))
    more = [replace(c, ik_seeds=cfg.retry_ik_seeds) for c in (cfg, free, loose)
            if cfg.retry_ik_seeds > cfg.ik_seeds]
    deep = [replace(c, ik_seeds=max(cfg.ik_seeds, cfg.retry_ik_seeds), deep_seeds=cfg.retry_deep_seeds)
            for c in (cfg, free, loose) if cfg.retry_deep_seeds > cfg.deep_seeds]
    configs = []
    for c in (cfg, free, loose, *more, *deep):
        if c not in configs:
            configs.append(c)
    return configs


def _tool_pose_at(sc: PlanningScene, q: np.ndarray) -> RigidTransform:
    sc.plant.SetPositions(sc.plant_context, q)
    return sc.tool_frame.CalcPoseInWorld(sc.plant_context)


def plan_place(X_WB: RigidTransform, q0: np.ndarray, problem: PlaceProblem, config: PlaceConfig | None = None,
               handle: HandleWaypoint | None = None) -> PlacePlan:
    """Plan the pick and place (module docstring) for the arm at base X_WB, from its positions q0
    (9,): the end of the opening plan, the hand on `handle` (it backs off the handle first), or,
    with `handle` None, a base re-placed after the opening (`place_bases`, `ready_posture`).
    Where the pieces to the pick (the last one straight, `_straight_in`) find no trajectory, the
    pre-pick is re-solved from the pick's posture (the arm on one branch: an IK from the previous
    knot may jump to another, which no straight piece joins) and they are optimised again, the
    straight bound unchanged.
    Raises PlanningError when a side-held item has too little room over the goal
    (`side_room_needed`), else naming the stage or the constraints that failed, for each grasp tried
    (the hand either way round about its approach); `PlaceUnreachable` where the fallback configs
    cannot do better (no room, or no IK up to the place for either hand)."""
    cfg = config or PlaceConfig()
    t0 = time.perf_counter()
    pb = problem
    side = pb.grasp == "side"
    if side and (room := free_height(pb.fixed, pb.goal)) < side_room_needed(pb.item, cfg):
        raise PlaceUnreachable(f"{100 * room:.1f} cm free over the goal: a side-held item needs "
                               f"{100 * side_room_needed(pb.item, cfg):.1f} cm (the item, the wrist); "
                               "no other grasp reaches in under a shelf")
    item_box = ObstacleBox("item", 2 * pb.item.half_extents,
                           pb.X_WI @ RigidTransform([0.0, 0.0, pb.item.height / 2]))
    everything = [*pb.fixed, *pb.moving, pb.table]
    base_scenes = {"off handle": build_planning_scene(X_WB, [*pb.fixed, pb.table], touching=pb.moving),
                   "to pre-pick": build_planning_scene(X_WB, [*everything, item_box]),
                   "free": build_planning_scene(X_WB, everything)}
    p_start = _tool_pose_at(base_scenes["free"], q0).translation() if handle is None else handle.p_WH
    off_handle = [] if handle is None else [
        _Stage("backing off the handle", "off handle", handle.p_WH - cfg.retreat_distance * handle.approach_W,
               _tool_at(handle.p_WH - cfg.retreat_distance * handle.approach_W, 0.01), handle.approach_W)]
    p_place = pb.goal + cfg.drop_height * _Z
    failures, reached_place = [], False
    for flip in (False, True):
        X_IG = grasp_in_item(pb.item, pb.grasp, cfg, flip)
        X_GI = X_IG.inverse()
        X_WG = pb.X_WI @ X_IG
        approach = X_WG.rotation().col(2)
        X_WGpre = RigidTransform(X_WG.rotation(), X_WG.translation() - cfg.pregrasp_distance * approach)
        X_WGlift = RigidTransform(X_WG.rotation(), X_WG.translation() + cfg.lift_height * _Z)
        scenes = {**base_scenes,
                  "held off table": build_planning_scene(X_WB, [*pb.fixed, *pb.moving], (pb.item, X_GI)),
                  "held": build_planning_scene(X_WB, everything, (pb.item, X_GI))}
        to_pick = [*off_handle,
                   _Stage("pre-pick", "to pre-pick", X_WGpre.translation(), _tool_pose(X_WGpre, cfg),
                          approach),
                   _Stage("pick", "free", X_WG.translation(), _tool_pose(X_WG, cfg), approach,
                          _straight_in(X_WG.translation(), cfg))]
        sols_a, failed = _solve_chain(scenes, to_pick, q0, cfg)
        if sols_a is None:
            failures.append(f"IK of {failed}")
            continue
        line = [p_place - f * pb.entry_depth * pb.entry for f in (1.0, 2 / 3, 1 / 3, 0.0)]
        p_lift = pb.X_WI.translation() + cfg.lift_height * _Z
        z_high = max(p_lift[2], line[0][2]) + (cfg.carry_clearance if side else 0.0)
        z_high = max(z_high, _over([*pb.fixed, *pb.moving], p_lift, line[0], X_WB))  # the item's bottom
        high = [p_lift * [1, 1, 0] + [0, 0, z_high], line[0] * [1, 1, 0] + [0, 0, z_high]]
        names = ("carry up", "carry over", "pre-place", "entering 1", "entering 2", "place")
        points = [*high, *line]
        keep = [k for k in range(len(points))  # a carry point on the lift or pre-place is left out
                if k >= 2 or min(np.linalg.norm(points[k] - p) for p in (p_lift, line[0])) > 1e-2]
        for release in dict.fromkeys((cfg.release_upright_deg, cfg.upright_tolerance_deg)):  # level first
            carry = [_Stage("lift", "held off table", X_WGlift.translation(), _tool_pose(X_WGlift, cfg),
                            approach)]
            carry += [_Stage(names[k], "held", points[k],
                             _item_at(points[k], X_GI, pb.entry, side, cfg,
                                      release if names[k] == "place" else None),
                             pb.entry if side else -_Z) for k in keep]
            sols_b, failed = (_solve_deepest_first(scenes, carry, sols_a[-1], len(carry) - 1, cfg)
                              if cfg.deep_seeds else _solve_chain(scenes, carry, sols_a[-1], cfg))
            if sols_b is not None:
                break
        if sols_b is None:
            failures.append(f"IK of {failed}")
            continue
        reached_place = True
        X_WGplace = _tool_pose_at(scenes["free"], sols_b[-1])
        X_WIplace = X_WGplace @ X_GI
        placed = ObstacleBox("placed item", 2 * pb.item.half_extents,
                             X_WIplace @ RigidTransform([0.0, 0.0, pb.item.height / 2]))
        scenes["retreat"] = build_planning_scene(X_WB, everything, touching=[placed])
        retreat = _retreat(X_WGplace, pb, cfg)
        sols_c, failed = _solve_chain(scenes, retreat, sols_b[-1], cfg)
        if sols_c is None:
            failures.append(f"IK of {failed}")
            continue
        segments, q, p = [], q0, p_start
        for name, stages, sols in (("to pick", to_pick, sols_a), ("carry", carry, sols_b),
                                   ("retreat", retreat, sols_c)):
            pieces, failed = _pieces(scenes, stages, sols, q, p, cfg)
            if pieces is None and name == "to pick":  # the straight pick: pre-pick on the pick's branch
                pre, _ = _solve_chain(scenes, stages[-2:-1], sols[-1], cfg)
                if pre is not None and not np.allclose(pre[0], sols[-2], atol=1e-3):
                    pieces, again = _pieces(scenes, stages, [*sols[:-2], pre[0], sols[-1]], q, p, cfg)
                    failed = f"{failed}; again from the pick's branch: {again}"
            if pieces is None:
                failures.append(failed)
                break
            segments.append(PlaceSegment(name, pieces))
            q, p = pieces[-1].value(pieces[-1].end_time()).ravel(), stages[-1].p_W
        else:
            carry_end = segments[1].value(segments[1].duration)
            X_WGend = _tool_pose_at(scenes["free"], carry_end)
            return PlacePlan(segments, X_WB, X_GI, pb.X_WI, X_WGend @ X_GI, pb.goal,
                             time.perf_counter() - t0)
    raise (PlanningError if reached_place else PlaceUnreachable)(
        "no feasible pick and place: " + "; ".join(dict.fromkeys(failures)))
