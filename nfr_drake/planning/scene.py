"""The planner's world: the arm at a base pose (on a pedestal if raised), the floor, obstacle boxes.

It never holds the object's model: obstacles are boxes, from keypoints (`grasp.carcass_box`) or,
for a true model, from its collision geometry (`nfr_drake.world.obstacles`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, CollisionFilterDeclaration, GeometrySet, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable, ModelInstanceIndex
from pydrake.planning import RobotDiagram
from pydrake.systems.framework import Context

from nfr_drake.parsing import make_robot_diagram_builder
from nfr_drake.world.items import Item
from nfr_drake.world.plan import ObstacleBox
from nfr_drake.world.robot import (
    FINGER_OPEN,
    HAND_BODIES,
    NUM_ARM_JOINTS,
    TOOL_FRAME,
    add_floor,
    add_panda,
    add_pedestal,
    arm_joint_limits,
)


@dataclass
class PlanningScene:
    """A built planning diagram and its contexts (kept alive for the constraints that use them).

    Positions q of `plant`: 7 arm joints then 2 finger joints, shape (9,).
    """

    diagram: RobotDiagram
    plant: MultibodyPlant
    robot: ModelInstanceIndex
    context: Context
    plant_context: Context
    X_WB: RigidTransform

    @property
    def tool_frame(self):
        return self.plant.GetFrameByName(TOOL_FRAME, self.robot)

    def full_q(self, q_arm: np.ndarray) -> np.ndarray:
        """Arm joints (7,) with the fingers open, shape (9,)."""
        return np.r_[q_arm, FINGER_OPEN, FINGER_OPEN]


def build_planning_scene(X_WB: RigidTransform, obstacles: list[ObstacleBox],
                         held: tuple[Item, RigidTransform] | None = None,
                         touching: list[ObstacleBox] = ()) -> PlanningScene:
    """The arm with base pose X_WB (on a pedestal if raised), the floor, and `obstacles` welded to
    the world; `held` (an item and its pose X_GI in the tool frame G) adds the item's shapes to the
    hand, clear of the obstacles but not of the hand that holds it; `touching` are obstacles too,
    but the hand (palm and fingers) may touch them (the door behind a handle the hand lets go of)."""
    builder = make_robot_diagram_builder(time_step=0.0)
    plant = builder.plant()
    robot = add_panda(plant, X_WB)
    add_floor(plant)
    add_pedestal(plant, X_WB)
    box_ids = [plant.RegisterCollisionGeometry(plant.world_body(), box.X_WB, Box(*box.size),
                                               f"obstacle_{box.name}", ProximityProperties())
               for box in [*obstacles, *touching]]
    hand = GeometrySet([g for name in HAND_BODIES
                        for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName(name, robot))])
    filters = builder.scene_graph().collision_filter_manager()
    if touching:
        touched = GeometrySet(box_ids[len(obstacles):])
        filters.Apply(CollisionFilterDeclaration().ExcludeBetween(hand, touched))
    if held is not None:
        item, X_GI = held
        X_HI = plant.GetFrameByName(TOOL_FRAME, robot).GetFixedPoseInBodyFrame() @ X_GI
        ids = [plant.RegisterCollisionGeometry(plant.GetBodyByName("panda_hand", robot), X_HI @ X_IS, shape,
                                               f"held_{name}", ProximityProperties())
               for name, shape, X_IS in item.shapes()]
        filters.Apply(CollisionFilterDeclaration().ExcludeBetween(GeometrySet(ids), hand))
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    return PlanningScene(diagram, plant, robot, context, plant.GetMyMutableContextFromRoot(context), X_WB)


REACH_JOINT_MARGIN = 0.02
"""A joint this close to a limit (rad) is at it, for `reach_limit`."""

REACH_CLEARANCE = 0.005
"""Two parts of the arm (or the arm and its pedestal or the floor) this close (m) touch, for
`reach_limit`."""

_REACH_STEP = 0.01
"""How far on along the line `reach_limit` looks, m."""


def reach_limit(X_WB: RigidTransform, q_arm: np.ndarray, toward_W: np.ndarray) -> str | None:
    """Why the arm on a base at X_WB, at joint positions q_arm (7,) rad, cannot move its tool on
    along unit toward_W (W) with its orientation held, as the robot's own model tells: a joint
    within `REACH_JOINT_MARGIN` of a limit that the motion drives it further into ("panda_joint6 at
    its upper limit"), or two of its links (or a link and the pedestal or the floor) within
    `REACH_CLEARANCE` that the motion brings closer ("panda_link2 and panda_link4 touch"); None
    when neither. The motion: the least-squares joint rates for the tool's velocity along
    toward_W, as the guarded pull commands it (`systems.articulation.PullToStop`)."""
    q_arm = np.asarray(q_arm, dtype=float)[:NUM_ARM_JOINTS]
    scene = build_planning_scene(X_WB, [])
    plant, context, tool = scene.plant, scene.plant_context, scene.tool_frame
    plant.SetPositions(context, scene.robot, scene.full_q(q_arm))
    J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, tool, np.zeros(3),
                                          plant.world_frame(), plant.world_frame())[:, :NUM_ARM_JOINTS]
    rate = np.linalg.lstsq(J, np.r_[np.zeros(3), toward_W], rcond=None)[0]  # rad per m along the line
    lower, upper = arm_joint_limits()
    for i in range(NUM_ARM_JOINTS):
        if q_arm[i] <= lower[i] + REACH_JOINT_MARGIN and rate[i] < 0.0:
            return f"panda_joint{i + 1} at its lower limit"
        if q_arm[i] >= upper[i] - REACH_JOINT_MARGIN and rate[i] > 0.0:
            return f"panda_joint{i + 1} at its upper limit"
    distance, names = _arm_clearance(scene)
    if distance <= REACH_CLEARANCE:
        plant.SetPositions(context, scene.robot, scene.full_q(q_arm + _REACH_STEP * rate))
        if _arm_clearance(scene)[0] < distance:
            return f"{names[0]} and {names[1]} touch"
    return None


def _arm_clearance(scene: PlanningScene) -> tuple[float, tuple[str, str]]:
    """The smallest distance (m) between a part of the arm and anything else of `scene` (another
    part, the pedestal, the floor) within `REACH_CLEARANCE`, with the two bodies' names; (inf, ())
    when none is that close."""
    query = scene.plant.get_geometry_query_input_port().Eval(scene.plant_context)
    inspector = query.inspector()
    robot = set(scene.plant.GetBodyIndices(scene.robot))
    best = (np.inf, ())
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(REACH_CLEARANCE):
        bodies = [scene.plant.GetBodyFromFrameId(inspector.GetFrameId(g)) for g in (pair.id_A, pair.id_B)]
        if pair.distance < best[0] and any(b.index() in robot for b in bodies):
            best = (float(pair.distance), (bodies[0].name(), bodies[1].name()))
    return best
