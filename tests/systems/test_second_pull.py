"""The second pull: a drawer pulled by contact, measured by the arm's own joints, pulled again."""

from types import SimpleNamespace

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.planner import PlannerConfig, grasp_planner
from nfr_drake.systems.articulation import (
    SecondPull,
    SimulationConfig,
    second_pull_offset,
    straight_pull,
)
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.systems.task import run_task
from nfr_drake.world.robot import FINGER_OPEN, Q_HOME, TOOL_FRAME


def _plan(points):
    return SimpleNamespace(waypoints=[SimpleNamespace(p_WH=np.asarray(p, float)) for p in points])


def test_a_straight_handle_path_is_a_pull_and_an_arc_is_not():
    line = [[0.5 + 0.03 * k, 0.1, 0.4] for k in range(10)]
    np.testing.assert_allclose(straight_pull(_plan(line)), [0.27, 0.0, 0.0], atol=1e-12)
    angles = np.linspace(0.0, 0.6, 10)
    arc = [[0.5 + 0.4 * np.sin(a), 0.4 * (1 - np.cos(a)), 0.4] for a in angles]
    assert straight_pull(_plan(arc)) is None
    assert straight_pull(_plan([[0.5, 0.1, 0.4], [0.505, 0.1, 0.4]])) is None  # no travel to speak of
    # A fitted drawer path bowing 5 mm over 27 cm is a pull; a door swung 20 degrees is not.
    bowed = [[0.5 + 0.03 * k, 0.1 + 0.005 * np.sin(np.pi * k / 9), 0.4] for k in range(10)]
    assert straight_pull(_plan(bowed)) is not None
    swung = [[0.5 + 0.4 * np.sin(a), 0.4 * (1 - np.cos(a)), 0.4] for a in np.radians(np.linspace(0, 20, 10))]
    assert straight_pull(_plan(swung)) is None


def _moved(plant, q, d_W):
    """q with the arm stepped (least squares) to move the tool by d_W, m."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    tool = plant.GetFrameByName(TOOL_FRAME)
    J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kQDot, tool, np.zeros(3),
                                          plant.world_frame(), plant.world_frame())
    step = np.linalg.lstsq(J[:, :7], np.r_[np.zeros(3), d_W], rcond=None)[0]
    return q + np.r_[step, 0.0, 0.0]


def test_the_offset_moves_the_tool_by_the_measured_shortfall_along_the_pull(panda, tool_pose):
    u = np.array([-1.0, 0.0, 0.0])  # the handle comes towards the robot
    q_grasp = np.r_[Q_HOME, FINGER_OPEN, FINGER_OPEN]
    q_end = _moved(panda, q_grasp, 0.05 * u)  # the tool came 5 cm of a planned 6.2 cm
    q_command = _moved(panda, q_grasp, 0.062 * u)
    measured = (tool_pose(q_end).translation() - tool_pose(q_grasp).translation()) @ u
    cfg = SimulationConfig(grasp="contact")
    dq, shortfall = second_pull_offset(panda, 0.062 * u, q_grasp, q_end, q_command, cfg)
    assert shortfall == pytest.approx(0.062 - measured, abs=1e-9) and 0.01 < shortfall < 0.014
    X_a, X_b = tool_pose(q_command), tool_pose(q_command + np.r_[dq, 0.0, 0.0])
    np.testing.assert_allclose(X_b.translation() - X_a.translation(), shortfall * u, atol=1e-3)
    assert X_a.rotation().inverse().multiply(X_b.rotation()).ToAngleAxis().angle() < np.radians(0.5)
    # Clipped at second_pull_max; nothing below second_pull_min; nothing when it came too far.
    dq, _ = second_pull_offset(panda, 0.062 * u, q_grasp, q_end, q_command,
                               SimulationConfig(grasp="contact", second_pull_max=0.005))
    moved = tool_pose(q_command + np.r_[dq, 0.0, 0.0]).translation() - X_a.translation()
    np.testing.assert_allclose(moved, 0.005 * u, atol=5e-4)
    for travel in (measured + 0.001, measured - 0.01):
        dq, short = second_pull_offset(panda, travel * u, q_grasp, q_end, q_command, cfg)
        assert not np.any(dq) and short < cfg.second_pull_min
        # A pull to the stop goes `past` the planned end whatever the shortfall.
        dq, _ = second_pull_offset(panda, travel * u, q_grasp, q_end, q_command, cfg, past=0.03)
        moved = tool_pose(q_command + np.r_[dq, 0.0, 0.0]).translation() - X_a.translation()
        np.testing.assert_allclose(moved, 0.03 * u, atol=2e-3)  # a linear step


def test_the_offset_ramps_in_holds_and_ramps_out():
    builder = DiagramBuilder()
    desired = np.r_[np.arange(9.0), np.zeros(9)]
    source = builder.AddSystem(ConstantVectorSource(desired))
    pull = builder.AddSystem(SecondPull(9))
    measured = np.r_[np.arange(9.0) - 0.1, np.full(9, 0.2)]
    builder.Connect(source.get_output_port(), pull.get_input_port(0))
    sensed = builder.AddSystem(ConstantVectorSource(measured))
    builder.Connect(sensed.get_output_port(), pull.get_input_port(1))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    dq = np.linspace(0.01, 0.07, 7)

    def command_at(t):
        context.SetTime(t)
        return pull.get_output_port().Eval(pull.GetMyContextFromRoot(context))

    np.testing.assert_array_equal(command_at(5.0), desired)  # nothing set: passes the plan through
    pull.set(context, dq, t_in=1.0, ramp=0.6, t_out=3.0, ramp_out=2.0)
    np.testing.assert_array_equal(command_at(0.9), desired)
    mid = command_at(1.3)
    np.testing.assert_allclose(mid[:7] - desired[:7], 0.5 * dq)
    np.testing.assert_allclose(mid[9:16], 0.5 * np.pi / 0.6 * dq)  # the ramp's rate at its middle
    np.testing.assert_allclose(command_at(2.0)[:7] - desired[:7], dq)
    np.testing.assert_allclose(command_at(2.0)[9:], 0.0)
    assert np.all(command_at(4.0)[9:16] < 0.0)  # going back
    np.testing.assert_allclose(command_at(5.5), desired)
    np.testing.assert_array_equal(command_at(4.0)[7:9], desired[7:9])  # the fingers untouched
    # Compliant until t_soft: the arm's command pulled towards the measured state, by `stiffness`.
    pull.set(context, dq, t_in=1.0, ramp=0.6, t_soft=2.5, stiffness=0.1)
    arm = np.r_[np.arange(7), 9 + np.arange(7)]
    stiff = desired + np.r_[dq, 0.0, 0.0, np.zeros(9)]
    np.testing.assert_allclose(command_at(2.0)[arm], measured[arm] + 0.1 * (stiff - measured)[arm])
    np.testing.assert_allclose(command_at(2.0)[7:9], desired[7:9])
    np.testing.assert_allclose(command_at(2.6), stiff)
    # `hold`: from now on the arm is commanded where it is (measured), stiff.
    context.SetTime(2.0)
    q_now = np.r_[np.arange(9.0)] + 0.05
    pull.hold(context, q_now, desired[:9])
    np.testing.assert_allclose(command_at(2.0)[:7], q_now[:7])
    np.testing.assert_allclose(command_at(2.4)[arm], np.r_[q_now[:7], np.zeros(7)])


@pytest.mark.slow
@pytest.mark.parametrize("q_target", [1.0, 0.7])
def test_a_drawer_pulled_by_contact_is_pulled_again_to_its_end(q_target):
    """A training drawer opened by contact with its true keypoints: the plan's pull alone ends
    about a centimetre short (the bar held less deep than planned); the robot measures the
    shortfall from its joint positions and the second pull brings the drawer to within 3 mm of
    the target: to q 0.7 by the shortfall, to q 1 (the stop) 3 cm past the planned end, compliant,
    the bar held (drift under 5 mm; the largest force on the drawer 153 N, at its stop)."""
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    scene_object = SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)
    errors = {}
    for again in (False, True):
        outcome = run_task(scene_object, q_target, planner_config=grasp_planner(PlannerConfig(), "contact"),
                           simulation_config=SimulationConfig(grasp="contact", second_pull=again))
        sim = outcome.simulation
        assert sim.grasped and sim.max_drift < 0.005 and sim.max_constraint_force < 200.0, sim.summary()
        errors[again] = sim.joint_error
        assert np.isnan(sim.shortfall) != again
    assert errors[False] > 0.005
    assert errors[True] < 0.003 and errors[True] < 0.3 * errors[False], errors
