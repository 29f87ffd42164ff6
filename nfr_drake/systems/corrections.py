"""Corrections the robot makes from its own joint positions (forward kinematics of the arm alone):
a joint step for a tool move, a missed close tried again deeper, whether the fingers still hold
a handle, a door turned on by the angle its hand swept short of the keypoints' turn, a door
taken for a drawer turned on as the hand felt it swing (docs/SIMULATION.md). All in the world frame W,
metres and radians; joint vectors are the robot's 9 positions (arm joints 1-7, then the
fingers), steps the 7 arm joints'."""

from dataclasses import replace

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import Solve

from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.robot import NUM_ARM_JOINTS, TOOL_FRAME


def tool_pose_and_jacobian(robot_plant: MultibodyPlant, context, q: np.ndarray
                            ) -> tuple[RigidTransform, np.ndarray]:
    """The tool frame's pose in W at q and its spatial velocity Jacobian (6, NUM_ARM_JOINTS), in
    `robot_plant` (the arm alone) at its `context`."""
    robot_plant.SetPositions(context, q)
    tool = robot_plant.GetFrameByName(TOOL_FRAME)
    J = robot_plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kQDot, tool, np.zeros(3),
                                                robot_plant.world_frame(), robot_plant.world_frame())
    return tool.CalcPoseInWorld(context), J[:, :NUM_ARM_JOINTS]


LIMIT_MARGIN = 0.01
"""A step leaves each arm joint at least this far inside its position limits, rad: the PD
actuators do not reach a command at a limit the plant enforces."""


def bounded_step(robot_plant: MultibodyPlant, q: np.ndarray, J: np.ndarray, error: np.ndarray) -> np.ndarray:
    """The arm joints' least-squares step (NUM_ARM_JOINTS,) for J dq = error (J (6, 7), error (6,))
    that keeps q + dq within `robot_plant`'s position limits less `LIMIT_MARGIN` (a joint already
    past that is brought back to it): a joint whose free step would leave them is held at the
    bound and the others solved again, until none does. Unbounded, a step asks a joint at its
    limit for more, and the arm, held by the handle, settles elsewhere: a door's turn (closet 79
    of capture seed 200, wrist joint 6 at its limit) turned the door back instead of on."""
    q = q[:NUM_ARM_JOINTS]
    lower = robot_plant.GetPositionLowerLimits()[:NUM_ARM_JOINTS] + LIMIT_MARGIN
    upper = robot_plant.GetPositionUpperLimits()[:NUM_ARM_JOINTS] - LIMIT_MARGIN
    dq = np.zeros(NUM_ARM_JOINTS)
    held = (q > upper) | (q < lower)
    dq[held] = np.clip(q, lower, upper)[held] - q[held]
    for _ in range(NUM_ARM_JOINTS):
        free = ~held
        if not free.any():
            break
        dq[free] = np.linalg.lstsq(J[:, free], error - J[:, held] @ dq[held], rcond=None)[0]
        out = free & ((q + dq > upper) | (q + dq < lower))
        if not out.any():
            break
        dq[out] = np.clip(q + dq, lower, upper)[out] - q[out]
        held |= out
    return dq


STEP_STRAY = 0.25
"""A tool step's first-order solution is kept where forward kinematics puts the tool within this
share of the asked translation (plus 1 mm) of its target and turns the hand by at most
`STEP_TURN_DEG`; else the step is solved by inverse kinematics (`tool_step`)."""
STEP_TURN_DEG = 3.0
"""How far a tool step may turn the hand, degrees (`STEP_STRAY`)."""


def tool_step(robot_plant: MultibodyPlant, q: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The arm joints' step (NUM_ARM_JOINTS,) at q (9,) that moves the tool frame's origin by
    `translation` ((3,), W, m), the hand's orientation kept, within the joint limits;
    `robot_plant` is the arm alone. First the least-squares step (`bounded_step`); where forward
    kinematics shows it strays (`STEP_STRAY`: with a joint held at its limit the others can be
    near a singularity, and a 4.5 cm pull of a sliding door's handle, solved so, swung the tool
    22 cm down and dragged the door 20 cm back), the step nearest q that inverse kinematics finds
    for the tool's pose within 2 mm along each axis and `STEP_TURN_DEG`, within the limits less
    `LIMIT_MARGIN`; no step where it finds none."""
    context = robot_plant.CreateDefaultContext()
    X_WT, J = tool_pose_and_jacobian(robot_plant, context, q)
    dq = bounded_step(robot_plant, q, J, np.r_[np.zeros(3), translation])
    target = RigidTransform(X_WT.rotation(), X_WT.translation() + translation)
    stepped = np.r_[q[:NUM_ARM_JOINTS] + dq, q[NUM_ARM_JOINTS:]]
    reached, _ = tool_pose_and_jacobian(robot_plant, context, stepped)
    strays = np.linalg.norm(reached.translation() - target.translation())
    turns = reached.rotation().InvertAndCompose(target.rotation()).ToAngleAxis().angle()
    if strays <= STEP_STRAY * np.linalg.norm(translation) + 1e-3 and np.degrees(turns) <= STEP_TURN_DEG:
        return dq
    return _tool_step_by_ik(robot_plant, q, target)


def _tool_step_by_ik(robot_plant: MultibodyPlant, q: np.ndarray, target: RigidTransform) -> np.ndarray:
    """The arm joints' step (NUM_ARM_JOINTS,) nearest q (9,) that puts the tool at `target` (W)
    within 2 mm along each axis and `STEP_TURN_DEG`, the arm within its limits less
    `LIMIT_MARGIN` and the fingers where they are; zeros where the solver finds none."""
    ik = InverseKinematics(robot_plant)
    world, tool = robot_plant.world_frame(), robot_plant.GetFrameByName(TOOL_FRAME)
    p = target.translation()
    ik.AddPositionConstraint(tool, np.zeros(3), world, p - 2e-3, p + 2e-3)
    ik.AddOrientationConstraint(world, target.rotation(), tool, RotationMatrix(), np.radians(STEP_TURN_DEG))
    x = ik.q()
    lower = robot_plant.GetPositionLowerLimits()[:NUM_ARM_JOINTS] + LIMIT_MARGIN
    upper = robot_plant.GetPositionUpperLimits()[:NUM_ARM_JOINTS] - LIMIT_MARGIN
    ik.prog().AddBoundingBoxConstraint(lower, upper, x[:NUM_ARM_JOINTS])
    ik.prog().AddBoundingBoxConstraint(q[NUM_ARM_JOINTS:], q[NUM_ARM_JOINTS:], x[NUM_ARM_JOINTS:])
    ik.prog().AddQuadraticErrorCost(np.eye(len(q)), q, x)
    result = Solve(ik.prog(), np.clip(q, np.r_[lower, q[NUM_ARM_JOINTS:]], np.r_[upper, q[NUM_ARM_JOINTS:]]))
    if not result.is_success():
        return np.zeros(NUM_ARM_JOINTS)
    return result.GetSolution(x)[:NUM_ARM_JOINTS] - q[:NUM_ARM_JOINTS]


def regrasp_step(robot_plant: MultibodyPlant, q_grasp: np.ndarray, step: float) -> np.ndarray:
    """The arm joints' step that moves the tool `step` m further along its approach (its z axis)
    from `q_grasp`, where the fingers missed."""
    X_WT, _ = tool_pose_and_jacobian(robot_plant, robot_plant.CreateDefaultContext(), q_grasp)
    return tool_step(robot_plant, q_grasp, step * X_WT.rotation().col(2))


FINGERS_EMPTY = 0.002
"""Fingers closed to under this opening (m, the two together) hold nothing (`fingers_hold`):
empty, the squeeze closes them to their stop at 0; on a 1.4 cm bar a 40 N squeeze sinks each
pad about 1 mm, so a handle under about 4 mm thick would read as lost."""


def fingers_hold(q_now: np.ndarray) -> bool:
    """Whether fingers closed on a handle still hold it, by their opening as a gripper senses it:
    the robot's positions (9,), the two fingers' last. A handle lost from between them lets the
    squeeze close them on nothing (`FINGERS_EMPTY`)."""
    return float(np.sum(q_now[NUM_ARM_JOINTS:])) >= FINGERS_EMPTY


FELT_LINE_MIN = 0.05
"""The least travel (m) of the held handle from which the robot takes its direction as the
drawer's slide (`felt_line`)."""


def felt_line(tool_path: np.ndarray, planned: np.ndarray) -> np.ndarray:
    """The unit direction (3,) to pull a drawer on along: the tool's travel over `tool_path` (N, 3;
    forward kinematics since the fingers closed on the handle: the slide guided the held hand)
    where it went at least `FELT_LINE_MIN` and forward along unit `planned` (the plan's line);
    else `planned`."""
    travel = tool_path[-1] - tool_path[0]
    length = float(np.linalg.norm(travel))
    if length < FELT_LINE_MIN or travel @ planned <= 0.0:
        return planned
    return travel / length


def arc_angle(points: np.ndarray, fit: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """The circle through `points` (N, 3; N >= 3, not on a line), or through `fit` (M, 3; M >= 3)
    where given: the signed angle `points` sweep about it to the last point from the point
    furthest back against the way the path went (first to last; rad, within +-pi), its centre
    (3,) and unit axis (3,), the angle positive about the axis. Plane by SVD, circle by linear
    least squares in it. From the furthest point back, not from the first:
    a grasp can jolt a door open and let it swing back before the pull, so the path's first
    point can lie ahead of where the door was held shut (pipeline door 46 of seed 200 was
    thrown 30 degrees open and back as the hand took it, and its turn measured from there came
    out 19 degrees short of its swept 51)."""
    fit = points if fit is None else fit
    mean = fit.mean(axis=0)
    e1, e2 = np.linalg.svd(fit - mean)[2][:2]
    axis = np.cross(e1, e2)
    uv = (fit - mean) @ np.c_[e1, e2]
    centre_uv = np.linalg.lstsq(np.c_[2.0 * uv, np.ones(len(uv))], (uv ** 2).sum(axis=1), rcond=None)[0][:2]
    rel = (points - mean) @ np.c_[e1, e2] - centre_uv
    turned = np.unwrap(np.arctan2(rel[:, 1], rel[:, 0]))  # each point's angle, continuous along the path
    way = np.sign(turned[-1] - turned[0]) or 1.0
    swept = float(turned[-1] - (turned.min() if way > 0 else turned.max()))
    return float(np.clip(swept, -np.pi, np.pi)), mean + centre_uv @ np.r_[[e1], [e2]], axis


def handle_turns(keypoints: KeypointTrajectory, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The angles a door's keypoints turn the handle by from their present articulation to each
    of `qs` (M,), about their hinge (rad, (M,), signed about the returned unit axis, hinge_bottom
    to hinge_top at the present articulation)."""
    bottom, top = (keypoints.point(name, keypoints.q_current) for name in ("hinge_bottom", "hinge_top"))
    axis = (top - bottom) / np.linalg.norm(top - bottom)
    a = keypoints.point("handle", keypoints.q_current) - bottom
    a = a - (a @ axis) * axis
    b = keypoints.point("handle", np.atleast_1d(qs)) - bottom
    b = b - np.outer(b @ axis, axis)
    return np.arctan2(np.cross(a, b) @ axis, b @ a), axis


def door_turns(keypoints: KeypointTrajectory, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The angles a door turns by from the keypoints' present articulation to each of `qs` (M,),
    as the robot plans its turn (rad, (M,), signed about the returned unit axis): the mean of two
    readings of one fit, the keypoints' own turn of the handle about their hinge
    (`handle_turns`) and the articulation's, (q - q_current) times `turn_per_q` the way the handle
    turns as q grows; the keypoints' alone where `turn_per_q` is unknown. The first errs where the
    fitted hinge or handle path is off, the second where the fit's q is (docs/SIMULATION.md,
    "The turn planned from two readings of the fit")."""
    angles, axis = handle_turns(keypoints, qs)
    if keypoints.turn_per_q is None:
        return angles, axis
    ends = handle_turns(keypoints, keypoints.q_grid[[0, -1]])[0]
    way = 1.0 if ends[1] >= ends[0] else -1.0
    return 0.5 * (angles + way * (np.atleast_1d(qs) - keypoints.q_current) * keypoints.turn_per_q), axis


def planned_door_turn(keypoints: KeypointTrajectory, q_target: float) -> tuple[float, np.ndarray]:
    """The angle a door turns by from the keypoints' present articulation to `q_target` as the
    robot plans it (rad, signed about the returned unit axis, hinge_bottom to hinge_top:
    `door_turns`). About the hinge, not about a circle through the handle's path: a fitted path's
    curvature can be off where its ends are right."""
    angles, axis = door_turns(keypoints, np.array([q_target]))
    return float(angles[0]), axis


MOVES_WITH_THE_DOOR = 1e-3
"""The least path (m) a keypoint travels over a door's articulation to move with it."""


def felt_door(keypoints: KeypointTrajectory, tool_path: np.ndarray, p_WH: np.ndarray) -> KeypointTrajectory:
    """A door's keypoints as the robot holding its handle takes them (W, m): `keypoints`' grid and
    names, about the hinge its hand felt (the circle through `tool_path`, (N, 3), the tool's path
    by forward kinematics since the fingers closed, `arc_angle`), the handle where the hand holds
    it (`p_WH`, (3,)), and the present articulation where `keypoints`' turn from theirs
    (`door_turns`) equals the angle the hand swept. The hinge keypoints lie on the felt axis
    at their own heights along it; the others that move with the door keep their offsets from the
    handle, turned by the angle between the two hinges' directions to the handle, and turn with
    the handle about the felt axis by the `door_turns` angles; those that do not (the goal) stay.
    What the robot plans a door's turn from a second base with (`systems.task.turn_on`)."""
    angles, planned_axis = door_turns(keypoints, keypoints.q_grid)
    swept, centre, axis = arc_angle(tool_path)
    if axis @ planned_axis < 0.0:
        swept, axis = -swept, -axis
    if angles[-1] < angles[0]:  # told about the axis the door opens positively about
        angles, swept, axis = -angles, -swept, -axis
    angles = np.maximum.accumulate(angles)  # a fitted path's small wiggles: one angle per q
    q_now = float(np.interp(swept, angles, keypoints.q_grid))
    now = keypoints.at(q_now)
    handle = keypoints.names.index("handle")

    def across(p: np.ndarray, on_axis: np.ndarray) -> np.ndarray:  # from the axis, across it
        r = p - on_axis
        return r - (r @ axis) * axis

    hinge_kt = keypoints.point("hinge_bottom", q_now)
    a, b = across(now[handle], hinge_kt), across(p_WH, centre)
    to_felt = RotationMatrix(AngleAxis(float(np.arctan2(np.cross(a, b) @ axis, a @ b)), axis)).matrix()
    travel = np.linalg.norm(np.diff(keypoints.p_WK, axis=0), axis=2).sum(axis=0)  # (K,)
    p_WK = np.repeat(now[None], len(keypoints.q_grid), axis=0)
    for k, name in enumerate(keypoints.names):
        if name.startswith("hinge_"):
            p_WK[:, k] = centre + ((now[k] - centre) @ axis) * axis
        elif travel[k] >= MOVES_WITH_THE_DOOR:
            p_k = p_WH + to_felt @ (now[k] - now[handle]) - centre
            p_WK[:, k] = centre + np.stack([RotationMatrix(AngleAxis(float(t), axis)).matrix() @ p_k
                                            for t in angles - swept])
    return replace(keypoints, p_WK=p_WK, q_current=q_now)


def door_turn(tool_path: np.ndarray, planned: float, planned_axis: np.ndarray
              ) -> tuple[float, np.ndarray, np.ndarray]:
    """How much further to turn a door, rad: the `planned` turn (rad about `planned_axis`,
    `planned_door_turn`) less the angle the tool swept (`tool_path`, (N, 3), from its joint
    positions) about the circle through its path; with that circle's centre and axis (the door's
    hinge as the hand felt it, turned to agree with the plan's)."""
    swept, centre, axis = arc_angle(tool_path)
    if axis @ planned_axis < 0.0:
        swept, axis = -swept, -axis
    return planned - swept, centre, axis


def turn_step(robot_plant: MultibodyPlant, q: np.ndarray, centre: np.ndarray, axis: np.ndarray,
              angle: float, iterations: int = 8) -> np.ndarray:
    """The arm joints' step from q that turns the tool frame by `angle` (rad) about the line through
    `centre` along unit `axis` (a door's hinge, carrying the hand on the handle), by Gauss-Newton
    on the tool's pose, each step within the joint limits (`bounded_step`)."""
    context = robot_plant.CreateDefaultContext()
    X_WT, _ = tool_pose_and_jacobian(robot_plant, context, q)
    turn = RotationMatrix(AngleAxis(angle, axis / np.linalg.norm(axis)))
    goal = RigidTransform(turn @ X_WT.rotation(), centre + turn @ (X_WT.translation() - centre))
    q_now = q.copy()
    for _ in range(iterations):
        X_WT, J = tool_pose_and_jacobian(robot_plant, context, q_now)
        rotation = (goal.rotation() @ X_WT.rotation().inverse()).ToAngleAxis()
        error = np.r_[rotation.angle() * rotation.axis(), goal.translation() - X_WT.translation()]
        q_now[:NUM_ARM_JOINTS] += bounded_step(robot_plant, q_now, J, error)
    return (q_now - q)[:NUM_ARM_JOINTS]


def hinge_gap(centre: np.ndarray, keypoints: KeypointTrajectory) -> float:
    """The horizontal distance from a felt hinge's point `centre` ((3,), m) to the keypoints' hinge
    line (hinge_bottom to hinge_top at their present articulation) at the centre's height, m."""
    bottom, top = (keypoints.point(name, keypoints.q_current) for name in ("hinge_bottom", "hinge_top"))
    on_line = bottom + (centre[2] - bottom[2]) / (top[2] - bottom[2]) * (top - bottom)
    return float(np.linalg.norm((centre - on_line)[:2]))


def door_turn_offset(robot_plant: MultibodyPlant, tool_path: np.ndarray, keypoints: KeypointTrajectory,
                     q_target: float, q_now: np.ndarray, q_command: np.ndarray, smallest: float,
                     largest: float, largest_gap: float = np.inf) -> tuple[np.ndarray, float, float]:
    """The offset to add to the arm's command `q_command` (the plan's last) that turns the hand,
    now at `q_now` (measured), on about the door's felt hinge by `door_turn`'s angle for the turn
    `keypoints` plan to `q_target`, clipped to +-`largest` (rad), that angle, and the felt hinge's
    gap to the keypoints' (`hinge_gap`, m); no offset and angle 0 when the angle is under
    `smallest` or the gap over `largest_gap` (the keypoints' hinge, whose turn the angle comes
    from, is not the door's), and gap nan when the tool's path has under 3 points."""
    if len(tool_path) < 3:
        return np.zeros(NUM_ARM_JOINTS), 0.0, float("nan")
    angle, centre, axis = door_turn(tool_path, *planned_door_turn(keypoints, q_target))
    gap = hinge_gap(centre, keypoints)
    if abs(angle) < smallest or gap > largest_gap:
        return np.zeros(NUM_ARM_JOINTS), 0.0, gap
    return (*_turn_offset(robot_plant, q_now, q_command, centre, axis, angle, largest), gap)


def _turn_offset(robot_plant: MultibodyPlant, q_now: np.ndarray, q_command: np.ndarray, centre: np.ndarray,
                 axis: np.ndarray, angle: float, largest: float) -> tuple[np.ndarray, float]:
    """The offset to add to the arm's command `q_command` that turns the hand, now at `q_now`, by
    `angle` clipped to +-`largest` (rad) about the line through `centre` along `axis`, and that
    clipped angle."""
    angle = float(np.clip(angle, -largest, largest))
    return (q_now - q_command)[:NUM_ARM_JOINTS] + turn_step(robot_plant, q_now, centre, axis, angle), angle


FELT_ARC_MIN = float(np.radians(10.0))
"""The least angle (rad) the held hand must sweep about the circle through its path, on a pull
planned along a line, for the robot to take the part for a door (`felt_arc`): a
drawer's slide guides the hand along a line (the drawer of the simulation tests pulled to 0.6 is
not turned), and the doors the furniture pipeline took for drawers swung 27-42 degrees open
before the arm's pull ended (docs/SIMULATION.md, "A door taken for a drawer")."""


def path_bow(points: np.ndarray) -> float:
    """How far `points` (N, 3) stray from the line through the first and the last, at most, over
    the distance between those two (0 for a straight path; an arc of angle a bows tan(a / 4) / 2);
    inf where the two coincide."""
    chord = points[-1] - points[0]
    length = float(np.linalg.norm(chord))
    if length == 0.0:
        return float("inf")
    return float(np.linalg.norm(np.cross(points - points[0], chord / length), axis=1).max() / length)


FELT_JOLT = 0.02
"""The held hand's path within this of either of its ends (m) is left out where the robot judges
whether a straight pull swept an arc (`felt_arc`): as the pull takes the load and as
the part meets its stop, fingers that hold a bar by friction let it jump across them by up to a
centimetre, which bows a straight path like an arc (docs/SIMULATION.md, "A door taken for a
drawer")."""


def inner_path(points: np.ndarray, margin: float) -> np.ndarray:
    """The points of a path (N, 3) farther than `margin` (m) from both its first and its last
    point, in order."""
    far = (np.linalg.norm(points - points[0], axis=1) > margin) & \
        (np.linalg.norm(points - points[-1], axis=1) > margin)
    return points[far]


def felt_arc(tool_path: np.ndarray) -> tuple[float, np.ndarray, np.ndarray] | None:
    """The arc a held hand swept on a pull planned along a line (`tool_path` (N, 3), forward
    kinematics since the fingers closed): the angle (rad, > 0), the centre (3,) and the unit axis
    (3,) about which it is positive of the circle through the path (`arc_angle`); None where it
    swept none, a drawer's line. The path's shape is judged, and its circle fitted, without its
    ends' jolts (`inner_path`, `FELT_JOLT`); the angle is the whole path's. None where the inner
    path has under 3 points or bows off the line between its ends less than an arc of
    `FELT_ARC_MIN` would (`path_bow`: a circle fitted to a nearly straight path is any circle, and
    a sliding door pulled 45 cm straight to its stop was turned on as a door), or where the path
    sweeps under `FELT_ARC_MIN`."""
    inner = inner_path(tool_path, FELT_JOLT)
    if len(inner) < 3 or path_bow(inner) < np.tan(FELT_ARC_MIN / 4.0) / 2.0:
        return None
    swept, centre, axis = arc_angle(tool_path, fit=inner)
    if abs(swept) < FELT_ARC_MIN:
        return None
    return (swept, centre, axis) if swept > 0.0 else (-swept, centre, -axis)


def felt_door_turn_offset(robot_plant: MultibodyPlant, tool_path: np.ndarray, target: float,
                          q_now: np.ndarray, q_command: np.ndarray, smallest: float, largest: float
                          ) -> tuple[np.ndarray, float]:
    """A pull planned along a line whose held hand swept an arc (`tool_path` (N, 3), forward
    kinematics since the fingers closed; `felt_arc`): a door taken for a drawer. The offset to
    add to the arm's command `q_command` (the plan's last) that turns the hand, now at `q_now`, on
    about that arc's circle (the hinge as the hand felt it) until it has swept `target` rad,
    clipped to +-`largest` (a turn in one joint step strains the hinge more the larger it is), and
    that angle; no offset and angle 0 where the hand swept no arc or the turn is under
    `smallest`."""
    none = np.zeros(NUM_ARM_JOINTS), 0.0
    arc = felt_arc(tool_path)
    if arc is None or abs(target - arc[0]) < smallest:
        return none
    swept, centre, axis = arc
    return _turn_offset(robot_plant, q_now, q_command, centre, axis, target - swept, largest)
