"""The guarded pull to a drawer's stop (constraint grasp): the stop, not the keypoints' travel, ends it."""

from types import SimpleNamespace

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.systems.articulation import _KD, _KP, _STOP_LINE, PullToStop, SimulationConfig, straight_pull
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.systems.task import read_keypoints, run_task
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.robot import FINGER_OPEN, NUM_ARM_JOINTS, Q_HOME, TOOL_FRAME


def _guarded(panda, measured, distance, force, stiffness=0.1):
    """PullToStop alone, the plan held at Q_HOME and the arm measured at `measured` (9,), pulling
    along -x from t 0.1 at 5 cm/s; run 8 s. Returns the system, its context and the command (18,)."""
    q = np.r_[Q_HOME, FINGER_OPEN, FINGER_OPEN]
    system = PullToStop(panda, stiffness)
    context = system.CreateDefaultContext()
    system.get_input_port(0).FixValue(context, np.r_[q, np.zeros(9)])
    system.get_input_port(1).FixValue(context, np.r_[measured, np.zeros(9)])
    system.start(context, np.array([-1.0, 0.0, 0.0]), 0.1, distance, 0.05, force)
    simulator = Simulator(system, context)
    simulator.AdvanceTo(8.0)
    return system, context, system.get_output_port().Eval(context)


def test_a_free_pull_goes_its_distance_along_the_line_the_hand_turned_no_more(panda, tool_pose):
    """The arm follows (measured = command, no lag): the command goes the whole distance along
    the line, at the set speed, and stops there."""
    q = np.r_[Q_HOME, FINGER_OPEN, FINGER_OPEN]
    system = PullToStop(panda, 0.1)
    context = system.CreateDefaultContext()
    system.get_input_port(0).FixValue(context, np.r_[q, np.zeros(9)])
    system.start(context, np.array([-1.0, 0.0, 0.0]), 0.1, 0.12, 0.05, 15.0)
    simulator = Simulator(system, context)
    for t in np.arange(0.0, 5.0, 0.01):  # the arm where it is commanded
        system.get_input_port(1).FixValue(context, system.get_output_port().Eval(context))
        simulator.AdvanceTo(t)
    t_stop, gone = system.stopped_at(context)
    assert gone == pytest.approx(0.12, abs=0.002)
    assert t_stop == pytest.approx(0.1 + 0.12 / 0.05 + 0.1, abs=0.05)  # the ramp costs half its time
    command = system.get_output_port().Eval(context)
    X_a, X_b = tool_pose(q), tool_pose(command[:9])
    np.testing.assert_allclose(X_b.translation() - X_a.translation(), [-0.12, 0.0, 0.0], atol=2e-3)
    assert X_a.rotation().inverse().multiply(X_b.rotation()).ToAngleAxis().angle() < np.radians(1.0)
    np.testing.assert_array_equal(command[7:9], q[7:9])  # the fingers pass through
    np.testing.assert_allclose(command[9:], 0.0)  # stopped: no rate


def test_a_held_tool_stops_the_pull_at_the_set_force(panda):
    """The arm measured where the plan ended (a drawer at its stop): the command stops once the
    arm's PD (10% of its gains) pulls the tool with 15 N along the line, through its stiffness at
    the tool (the lag) and its damping (the command's rate), and then commands the arm where it
    is."""
    q = np.r_[Q_HOME, FINGER_OPEN, FINGER_OPEN]
    system, context, command = _guarded(panda, q, 0.3, 15.0)
    t_stop, gone = system.stopped_at(context)
    assert t_stop < 1.5 and 0.0 < gone < 0.3
    context_q = panda.CreateDefaultContext()
    panda.SetPositions(context_q, q)
    tool = panda.GetFrameByName(TOOL_FRAME)
    J = panda.CalcJacobianSpatialVelocity(context_q, JacobianWrtVariable.kQDot, tool, np.zeros(3),
                                          panda.world_frame(), panda.world_frame())[:, :7]
    stiffness = np.linalg.inv((J[3:] / (0.1 * _KP[:NUM_ARM_JOINTS])) @ J[3:].T)  # N / m at the tool
    rate = np.linalg.lstsq(J, np.r_[0.0, 0.0, 0.0, -0.05, 0.0, 0.0], rcond=None)[0]  # the command's, rad/s
    damping = stiffness @ J[3:] @ (_KD[:NUM_ARM_JOINTS] / _KP[:NUM_ARM_JOINTS] * rate)  # N
    assert stiffness[0, 0] * gone - damping[0] == pytest.approx(15.0, rel=0.1)  # along -x
    np.testing.assert_allclose(command[:9], q, atol=1e-12)  # where it is
    # A stiffer arm feels the stop sooner; the distance bounds a pull that feels nothing.
    stiff, stiff_context, _ = _guarded(panda, q, 0.3, 15.0, stiffness=1.0)
    assert stiff.stopped_at(stiff_context)[1] < 0.5 * gone
    far, far_context, _ = _guarded(panda, q, 0.05, 1e6)
    assert far.stopped_at(far_context)[1] == pytest.approx(0.05, abs=0.001)


def test_a_pull_to_the_stop_needs_a_line_a_fitted_drawer_bows_from_but_no_door_arc():
    """A drawer path bowing 6 mm over 18 cm (a fit in a room) is no straight pull for the second
    pull, but its line serves the pull to the stop; a door's arc opened 45 degrees serves neither."""
    bowed = [[0.5 + 0.02 * k, 0.1 + 0.006 * np.sin(np.pi * k / 9), 0.4] for k in range(10)]
    plan = SimpleNamespace(waypoints=[SimpleNamespace(p_WH=np.array(p)) for p in bowed])
    assert straight_pull(plan) is None
    np.testing.assert_allclose(straight_pull(plan, _STOP_LINE), [0.18, 0.0, 0.0], atol=1e-12)
    arc = [[0.5 + 0.4 * np.sin(a), 0.4 * (1 - np.cos(a)), 0.4] for a in np.radians(np.linspace(0, 46, 10))]
    assert straight_pull(SimpleNamespace(waypoints=[SimpleNamespace(p_WH=np.array(p)) for p in arc]),
                         _STOP_LINE) is None


def _training_drawer():
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    return SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)


def _short(kt: KeypointTrajectory, short: float) -> KeypointTrajectory:
    """`kt` with its keypoints' travel from q 0 scaled so that the handle's is `short` m less."""
    handle = kt.point("handle", kt.q_grid)
    travel = float(np.linalg.norm(handle[-1] - handle[0]))
    scale = (travel - short) / travel
    return KeypointTrajectory(kt.category, kt.q_grid, kt.names, kt.p_WK[:1] + scale * (kt.p_WK - kt.p_WK[:1]),
                              kt.q_current)


def test_a_drawer_whose_keypoints_travel_is_10_cm_short_ends_at_its_stop():
    """A training drawer (true travel 27 cm) planned on keypoints whose travel is 10 cm short,
    constraint grasp: the plan alone leaves it 7.6 cm short of fully open; the guarded pull goes
    on some 8 cm and the drawer's stop ends it (within 5 mm of q 1), the force on the drawer
    bounded (19 N at the stop's impact, 15 N set), the hand on the handle."""
    scene_object = _training_drawer()
    keypoints = _short(read_keypoints(scene_object), 0.10)
    sims = {pull: run_task(scene_object, 1.0, keypoints=keypoints,
                           simulation_config=SimulationConfig(guarded_pull=pull)).simulation
            for pull in (0.0, 0.3)}
    assert sims[0.0].grasped and sims[0.0].joint_error > 0.05 and np.isnan(sims[0.0].pulled_past)
    sim = sims[0.3]
    assert sim.success and sim.joint_error < 0.005, sim.summary()
    assert 0.05 < sim.pulled_past < 0.3
    assert sim.max_constraint_force < 40.0 and sim.max_drift < 0.005, sim.summary()


def test_a_door_is_opened_as_before():
    """A door's arc is no straight pull: no guarded pull, the same outcome with or without it."""
    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    scene_object = SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)
    sims = [run_task(scene_object, 0.6, simulation_config=SimulationConfig(guarded_pull=pull)).simulation
            for pull in (0.0, 0.3)]
    assert sims[1].grasped and np.isnan(sims[1].pulled_past)
    assert sims[1].q_final == sims[0].q_final and sims[1].max_constraint_force == sims[0].max_constraint_force
    np.testing.assert_array_equal(sims[1].q_object, sims[0].q_object)
