"""The Franka Panda arm and hand and the floor from `sdf/`, resolved as `package://nfr_drake/...`.

Frames: B is the robot base (panda_link0, on the floor or on top of a lift column, `add_pedestal`),
G the tool frame `panda_tool` at the grasp point between the finger pads (+z approach, +y finger
closing axis, +x along the pads).
"""

from __future__ import annotations

from functools import cache

import numpy as np
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, SpatialInertia, default_model_instance

from nfr_drake.parsing import make_parser

PANDA_URL = "package://nfr_drake/panda/panda_arm_hand.sdf"
FLOOR_URL = "package://nfr_drake/scene/floor.sdf"
BASE_FRAME = "panda_link0"
TOOL_FRAME = "panda_tool"
HAND_BODIES = ("panda_hand", "panda_leftfinger", "panda_rightfinger")
ARM_JOINTS = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGER_JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
NUM_ARM_JOINTS = 7

Q_HOME = np.array([0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4])
"""Franka's "ready" configuration of the arm joints, rad, shape (7,)."""
FINGER_OPEN = 0.04
"""Opening of each finger (half the gripper width) when open, m."""
PEDESTAL_HALF_WIDTH = 0.12
"""Half the side of the square lift column under a raised base, m (the base plate is 0.2 m across)."""


def add_panda(plant: MultibodyPlant, X_WB: RigidTransform | None = None,
              model_name: str = "panda") -> ModelInstanceIndex:
    """Add the arm and hand with its base welded at X_WB (default identity); before Finalize()."""
    parser = make_parser(plant, model_name)
    (model,) = parser.AddModels(url=PANDA_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(BASE_FRAME, model),
                     X_WB if X_WB is not None else RigidTransform())
    return model


@cache
def arm_joint_limits() -> tuple[np.ndarray, np.ndarray]:
    """The arm joints' position limits (lower, upper), rad, each (7,) in `ARM_JOINTS` order, as
    the Panda's model states them (read-only arrays)."""
    plant = MultibodyPlant(0.0)
    model = add_panda(plant)
    plant.Finalize()
    joints = [plant.GetJointByName(name, model) for name in ARM_JOINTS]
    lower = np.array([j.position_lower_limits()[0] for j in joints])
    upper = np.array([j.position_upper_limits()[0] for j in joints])
    lower.flags.writeable = upper.flags.writeable = False
    return lower, upper


def add_floor(plant: MultibodyPlant) -> ModelInstanceIndex:
    """Add the floor with its top surface on the world's z = 0 plane; before Finalize()."""
    parser = make_parser(plant)
    (model,) = parser.AddModels(url=FLOOR_URL)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("floor", model))
    return model


PEDESTAL_NAME = "pedestal"
"""The lift column's body and geometry name (`add_pedestal`)."""
PEDESTAL_MASS = 50.0  # kg; welded to the world, it never moves


def add_pedestal(plant: MultibodyPlant, X_WB: RigidTransform) -> None:
    """A lift column from the floor up to a raised base X_WB: a box of side 2 `PEDESTAL_HALF_WIDTH`
    (visual and collision) on a body welded to the world, turned with the base; nothing for a base
    on the floor (z = 0). Before Finalize(). Its own body, not the world body's geometry: in Drake
    1.51's SAP a geometry of the world body pressing into a body whose joints are locked (a
    piece's other fronts, `lock_shut`) crashes the process (Drake issue #24773), and one of a
    welded body does not."""
    height = float(X_WB.translation()[2])
    if height <= 1e-6:
        return
    X_WP = RigidTransform(X_WB.rotation(), X_WB.translation() - [0.0, 0.0, height / 2])
    side = 2 * PEDESTAL_HALF_WIDTH
    body = plant.AddRigidBody(PEDESTAL_NAME, default_model_instance(),
                              SpatialInertia.SolidBoxWithMass(PEDESTAL_MASS, side, side, height))
    plant.WeldFrames(plant.world_frame(), body.body_frame(), X_WP)
    shape = Box(side, side, height)
    plant.RegisterCollisionGeometry(body, RigidTransform(), shape, PEDESTAL_NAME, CoulombFriction(0.8, 0.6))
    plant.RegisterVisualGeometry(body, RigidTransform(), shape, PEDESTAL_NAME,
                                 np.array([0.35, 0.35, 0.38, 1.0]))
