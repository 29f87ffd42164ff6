"""The planner's world: the arm at a base pose, the floor and keypoint-derived obstacles.

It never holds the object's model: obstacles come from `grasp.carcass_box` and
`grasp.door_proxy` (keypoints only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, CollisionFilterDeclaration, GeometrySet, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    FixedOffsetFrame,
    ModelInstanceIndex,
    RevoluteJoint,
    SpatialInertia,
)
from pydrake.planning import RobotDiagram, RobotDiagramBuilder
from pydrake.systems.framework import Context

from nfr_drake.planning.grasp import DoorProxy, ObstacleBox
from nfr_drake.systems.robot import (
    ARM_JOINTS,
    FINGER_JOINTS,
    FINGER_OPEN,
    HAND_BODIES,
    TOOL_FRAME,
    add_floor,
    add_panda,
)


@dataclass
class PlanningScene:
    """A built planning diagram and its contexts (kept alive for the constraints that use them).

    Positions q of `plant`: the robot's 9 (7 arm joints, 2 fingers) at `robot_indices` and, with a
    door proxy, its joint at `proxy_index`.
    """

    diagram: RobotDiagram
    plant: MultibodyPlant
    robot: ModelInstanceIndex
    context: Context
    plant_context: Context
    X_WB: RigidTransform
    robot_indices: np.ndarray
    proxy_index: int | None

    @property
    def tool_frame(self):
        return self.plant.GetFrameByName(TOOL_FRAME, self.robot)

    def full_q(self, q_arm: np.ndarray, proxy_value: float = 0.0) -> np.ndarray:
        """Arm joints (7,) with the fingers open and the proxy at `proxy_value`, shape (nq,)."""
        q = np.zeros(self.plant.num_positions())
        q[self.robot_indices] = np.r_[q_arm, FINGER_OPEN, FINGER_OPEN]
        if self.proxy_index is not None:
            q[self.proxy_index] = proxy_value
        return q


def build_planning_scene(X_WB: RigidTransform, obstacles: list[ObstacleBox],
                         proxy: DoorProxy | None = None) -> PlanningScene:
    """The arm with base pose X_WB, the floor, `obstacles` welded to the world and, optionally, a
    door proxy on its hinge joint (it collides with the arm only, not with the hand)."""
    builder = RobotDiagramBuilder(time_step=0.0)
    plant = builder.plant()
    robot = add_panda(plant, X_WB)
    add_floor(plant)
    for box in obstacles:
        plant.RegisterCollisionGeometry(plant.world_body(), box.X_WB, Box(*box.size),
                                        f"obstacle_{box.name}", ProximityProperties())
    proxy_joint = None
    if proxy is not None:
        proxy_model = plant.AddModelInstance("door_proxy")
        body = plant.AddRigidBody("proxy", proxy_model, SpatialInertia.SolidBoxWithMass(1.0, *proxy.size))
        plant.RegisterCollisionGeometry(body, RigidTransform(proxy.p_JS), Box(*proxy.size), "proxy",
                                        ProximityProperties())
        J = plant.AddFrame(FixedOffsetFrame("proxy_joint_frame", plant.world_frame(), proxy.X_WJ))
        proxy_joint = plant.AddJoint(RevoluteJoint("proxy_joint", J, body.body_frame(), [0.0, 0.0, 1.0]))
    plant.Finalize()
    if proxy_joint is not None:
        proxy_set = GeometrySet(plant.GetCollisionGeometriesForBody(proxy_joint.child_body()))
        others = [plant.world_body(), plant.GetBodyByName("floor")]
        others += [plant.GetBodyByName(name, robot) for name in HAND_BODIES]
        builder.scene_graph().collision_filter_manager().Apply(CollisionFilterDeclaration().ExcludeBetween(
            proxy_set, GeometrySet([g for b in others for g in plant.GetCollisionGeometriesForBody(b)])))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    robot_indices = np.array([plant.GetJointByName(name, robot).position_start()
                              for name in (*ARM_JOINTS, *FINGER_JOINTS)])
    return PlanningScene(diagram, plant, robot, context, plant.GetMyMutableContextFromRoot(context), X_WB,
                         robot_indices, proxy_joint.position_start() if proxy_joint is not None else None)
