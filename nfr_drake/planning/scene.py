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
from nfr_drake.world.robot import FINGER_OPEN, HAND_BODIES, TOOL_FRAME, add_floor, add_panda, add_pedestal


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
