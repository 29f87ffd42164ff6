"""The Panda model in sdf/ against Franka's published kinematics (modified DH table) and poses; the lift
column under a raised base."""

import numpy as np
import pytest
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import RevoluteJoint, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.world.robot import (
    FINGER_OPEN,
    PEDESTAL_HALF_WIDTH,
    PEDESTAL_NAME,
    Q_HOME,
    TOOL_FRAME,
    add_panda,
    add_pedestal,
    arm_joint_limits,
)

# Franka's published modified-DH (Craig) parameters: (a_{i-1}, d_i, alpha_{i-1}) of joints 1-7 and the
# flange (joint 8, fixed), and the hand: rotated -pi/4 about z, tool point 0.1034 m along z.
DH = [(0, 0.333, 0), (0, 0, -np.pi / 2), (0, 0.316, np.pi / 2), (0.0825, 0, np.pi / 2),
      (-0.0825, 0.384, -np.pi / 2), (0, 0, np.pi / 2), (0.088, 0, np.pi / 2), (0, 0.107, 0)]


def _dh(a, d, alpha, theta):
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array([[ct, -st, 0, a], [st * ca, ct * ca, -sa, -d * sa],
                     [st * sa, ct * sa, ca, d * ca], [0, 0, 0, 1]])


def dh_tool_pose(q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    for (a, d, alpha), theta in zip(DH, np.r_[q, 0.0], strict=True):
        T = T @ _dh(a, d, alpha, theta)
    hand = _dh(0, 0, 0, -np.pi / 4)
    hand[2, 3] = 0.1034
    return T @ hand


@pytest.fixture(scope="module")
def panda():
    plant = MultibodyPlant(0.0)
    model = add_panda(plant)
    plant.Finalize()
    return plant, model, plant.CreateDefaultContext()


def _tool_pose(panda, q):
    plant, model, context = panda
    plant.SetPositions(context, model, np.r_[q, FINGER_OPEN, FINGER_OPEN])
    return plant.GetFrameByName(TOOL_FRAME, model).CalcPoseInWorld(context).GetAsMatrix4()


def test_published_poses(panda):
    # Flange at q = 0: (0.088, 0, 0.926) (0.333 + 0.316 + 0.384 - 0.107); tool 0.1034 m below it.
    np.testing.assert_allclose(_tool_pose(panda, np.zeros(7))[:3, 3], [0.088, 0.0, 0.8226], atol=1e-6)
    # libfranka's O_T_EE in the "ready" pose: (0.307, 0, 0.487), tool z pointing down.
    X = _tool_pose(panda, Q_HOME)
    np.testing.assert_allclose(X[:3, 3], [0.3069, 0.0, 0.4869], atol=5e-4)
    np.testing.assert_allclose(X[:3, 2], [0.0, 0.0, -1.0], atol=1e-9)


def test_matches_dh_table(panda):
    plant, model, _ = panda
    lower = plant.GetPositionLowerLimits()[:7]
    upper = plant.GetPositionUpperLimits()[:7]
    rng = np.random.default_rng(0)
    for q in rng.uniform(lower, upper, size=(20, 7)):
        np.testing.assert_allclose(_tool_pose(panda, q), dh_tool_pose(q), rtol=0, atol=1e-7)


def test_datasheet_limits(panda):
    plant, _, _ = panda
    np.testing.assert_allclose(plant.GetPositionUpperLimits()[:7],
                               [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    np.testing.assert_allclose(plant.GetVelocityUpperLimits()[:7], [2.175] * 4 + [2.61] * 3)
    efforts = [plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices()]
    np.testing.assert_allclose(efforts[:7], [87] * 4 + [12] * 3)


def test_arm_joint_limits_are_frankas_published_ones():
    """Read from the model: Franka's datasheet limits (rad), and the ready pose inside them."""
    lower, upper = arm_joint_limits()
    np.testing.assert_allclose(lower, [-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
    np.testing.assert_allclose(upper, [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    assert np.all((lower < Q_HOME) & (Q_HOME < upper))
    with pytest.raises(ValueError):
        lower[0] = 0.0  # the cached arrays are shared: read-only


def test_a_locked_part_pressed_by_the_lift_column_simulates():
    """A raised base's lift column is a body welded to the world: a door on a locked hinge whose
    panel reaches 3 cm into it simulates (as a geometry of the world body it crashed Drake 1.51's
    SAP solver with a segfault) and stays shut."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=0.002, discrete_contact_approximation="sap"), builder)
    add_pedestal(plant, RigidTransform([0.0, 0.0, 0.4]))
    door = plant.AddRigidBody("door", SpatialInertia.SolidBoxWithMass(5.0, 0.4, 0.02, 0.6))
    near_edge = PEDESTAL_HALF_WIDTH - 0.03  # the panel spans x in [near_edge, near_edge + 0.4], hinged at 0
    plant.RegisterCollisionGeometry(door, RigidTransform([near_edge + 0.2, 0.0, 0.3]), Box(0.4, 0.02, 0.6),
                                    "door", CoulombFriction(0.8, 0.6))
    hinge = plant.AddJoint(RevoluteJoint("hinge", plant.world_frame(), door.body_frame(), [0.0, 0.0, 1.0]))
    plant.Finalize()
    assert plant.GetBodyByName(PEDESTAL_NAME) in plant.GetBodiesWeldedTo(plant.world_body())
    simulator = Simulator(builder.Build())
    context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    query = scene_graph.get_query_output_port().Eval(
        scene_graph.GetMyContextFromRoot(simulator.get_context()))
    assert max(p.depth for p in query.ComputePointPairPenetration()) == pytest.approx(0.03, abs=1e-6)
    hinge.Lock(context)
    simulator.AdvanceTo(0.05)
    assert hinge.get_angle(context) == pytest.approx(0.0, abs=1e-9)
