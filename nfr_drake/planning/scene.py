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
from pydrake.multibody.tree import ModelInstanceIndex
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


def reach_limit(X_WB: RigidTransform, q_arm: np.ndarray) -> str | None:
    """Why the arm on a base at X_WB, at joint positions q_arm (7,) rad, can move on no further, as
    the robot's own model tells: a joint within `REACH_JOINT_MARGIN` of a limit ("panda_joint6 at
    its upper limit"), or two of its links (or a link and the pedestal or the floor) within
    `REACH_CLEARANCE` ("panda_link2 and panda_link4 touch"); None when neither."""
    q_arm = np.asarray(q_arm, dtype=float)[:NUM_ARM_JOINTS]
    lower, upper = arm_joint_limits()
    for i, (q, low, high) in enumerate(zip(q_arm, lower, upper, strict=True)):
        if q <= low + REACH_JOINT_MARGIN:
            return f"panda_joint{i + 1} at its lower limit"
        if q >= high - REACH_JOINT_MARGIN:
            return f"panda_joint{i + 1} at its upper limit"
    scene = build_planning_scene(X_WB, [])
    scene.plant.SetPositions(scene.plant_context, scene.robot, scene.full_q(q_arm))
    query = scene.plant.get_geometry_query_input_port().Eval(scene.plant_context)
    inspector = query.inspector()
    robot_bodies = set(scene.plant.GetBodyIndices(scene.robot))
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(REACH_CLEARANCE):
        bodies = [scene.plant.GetBodyFromFrameId(inspector.GetFrameId(g)) for g in (pair.id_A, pair.id_B)]
        if pair.distance <= REACH_CLEARANCE and any(b.index() in robot_bodies for b in bodies):
            return f"{bodies[0].name()} and {bodies[1].name()} touch"
    return None
