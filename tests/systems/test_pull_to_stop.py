"""The guarded pull to a drawer's stop (constraint grasp): the stop, not the keypoints' travel, ends it."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.planner import PlannerConfig
from nfr_drake.planning.scene import reach_limit
from nfr_drake.systems import task
from nfr_drake.systems.articulation import _KD, _KP, _STOP_LINE, PullToStop, SimulationConfig, straight_pull
from nfr_drake.systems.corrections import felt_line, tool_step
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.systems.task import PULL_ON_REST, handle_left_at, pull_on, read_keypoints, run_task
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


def test_the_pull_starts_where_the_arm_is_not_where_the_plan_left_the_command(panda):
    """The arm measured 3 cm behind the plan's end along the line (the lag a drawer held off the
    plan's line leaves; 18 N through 10% of the gains): the pull starts from there, not at once
    stopped by that lag, and goes as far as from a hand with no lag before the force stops it."""
    q = np.r_[Q_HOME, FINGER_OPEN, FINGER_OPEN]
    behind = q + np.r_[tool_step(panda, q, np.array([0.03, 0.0, 0.0])), 0.0, 0.0]
    lagging, lagging_context, command = _guarded(panda, behind, 0.3, 15.0)
    held, held_context, _ = _guarded(panda, q, 0.3, 15.0)
    gone, gone_held = lagging.stopped_at(lagging_context)[1], held.stopped_at(held_context)[1]
    assert gone == pytest.approx(gone_held, abs=0.003) and gone > 0.01
    np.testing.assert_allclose(command[:9], behind, atol=1e-12)  # held where it is


def test_the_line_felt_is_the_hands_travel_once_long_enough():
    planned = np.array([1.0, 0.0, 0.0])
    turned = np.array([np.cos(0.2), np.sin(0.2), 0.0])
    path = np.outer(np.linspace(0.0, 0.2, 21), turned) + [0.5, 0.1, 0.3]
    np.testing.assert_allclose(felt_line(path, planned), turned, atol=1e-12)
    assert felt_line(path[:5], planned) is planned  # 4 cm: too short to tell
    assert felt_line(path[::-1], planned) is planned  # backwards: not a pull


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


def _turned(kt: KeypointTrajectory, degrees: float) -> KeypointTrajectory:
    """`kt` turned about the vertical through its handle at q 0 (a yaw error of the fit)."""
    R = RotationMatrix.MakeZRotation(np.radians(degrees)).matrix()
    centre = kt.point("handle", 0.0)
    p_WK = (kt.p_WK - centre) @ R.T + centre
    return KeypointTrajectory(kt.category, kt.q_grid, kt.names, p_WK, kt.q_current)


def test_a_drawer_planned_16_degrees_off_its_slide_is_pulled_on_along_the_slide_to_its_stop():
    """The training drawer planned on keypoints turned 16 degrees and 10 cm short: the planned
    pull, the compliant hand dragged along the slide, leaves it short, the plan's end off the
    slide. Pulled on along the plan's line from the plan's end (the code before 09f2926), the lag
    stopped the pull where the plan left it; along the hand's travel since it closed
    (`felt_line`), from where the arm is, the stop ends it at q 1 (within 5 mm)."""
    scene_object = _training_drawer()
    truth = read_keypoints(scene_object)
    keypoints = _turned(_short(truth, 0.10), 16.0)
    sim = run_task(scene_object, 1.0, keypoints=keypoints).simulation
    assert sim.q_pulled < 0.9 and sim.success and sim.joint_error < 0.005, sim.summary()
    slide = truth.point("handle", 1.0) - truth.point("handle", 0.0)
    assert np.degrees(np.arccos(sim.pull_line @ slide / np.linalg.norm(slide))) < 2.0


def test_a_door_is_opened_as_before():
    """A door's arc is no straight pull: no guarded pull, the same outcome with or without it."""
    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    scene_object = SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)
    sims = [run_task(scene_object, 0.6, simulation_config=SimulationConfig(guarded_pull=pull)).simulation
            for pull in (0.0, 0.3)]
    assert sims[1].grasped and np.isnan(sims[1].pulled_past)
    assert sims[1].q_final == sims[0].q_final and sims[1].max_constraint_force == sims[0].max_constraint_force
    np.testing.assert_array_equal(sims[1].q_object, sims[0].q_object)


def test_the_arms_reach_along_a_line_is_read_off_its_own_model(tool_pose):
    """The home posture moves on freely. Where a room drawer's pull stopped with joint 6 at its
    upper limit, pulling on toward the base would drive it further: the reach ends; pushing the
    other way would not, nor with the joint 0.25 rad inside its limit. Where another's stopped with
    the elbow folded into the shoulder (links 2 and 4 touching), pulling on folds it further;
    pushing away unfolds it."""
    base = RigidTransform()
    assert reach_limit(base, Q_HOME, np.array([-1.0, 0.0, 0.0])) is None
    at_limit = np.array([-1.37, 0.51, 0.71, -2.57, -1.42, 3.74, -0.63])
    toward_base = -tool_pose(np.r_[at_limit, 0.04, 0.04]).translation() * [1, 1, 0]
    toward_base /= np.linalg.norm(toward_base)
    assert reach_limit(base, at_limit, toward_base) == "panda_joint6 at its upper limit"
    assert reach_limit(base, at_limit, -toward_base) is None
    assert reach_limit(base, _with_joint(at_limit, 5, 3.5), toward_base) is None
    folded = np.array([-0.06, -0.14, 0.37, -2.94, -2.42, 2.48, 2.09])
    toward_base = -tool_pose(np.r_[folded, 0.04, 0.04]).translation() * [1, 1, 0]
    toward_base /= np.linalg.norm(toward_base)
    assert reach_limit(base, folded, toward_base) == "panda_link2 and panda_link4 touch"
    assert reach_limit(base, folded, -toward_base) is None


def _with_joint(q: np.ndarray, i: int, value: float) -> np.ndarray:
    """q with joint i (0-based) at value."""
    q = q.copy()
    q[i] = value
    return q


def test_the_handle_left_past_the_keypoints_end_is_taken_as_open_to_just_short_of_it():
    """Moved to where the hand let go, 0.5 cm of path short of q 1, the path turned onto the line
    the hand felt (10 degrees off the keypoints' here), every keypoint moved alike."""
    kt = read_keypoints(_training_drawer())
    p_WH = kt.point("handle", 1.0) + [0.07, 0.01, 0.0]
    path = kt.point("handle", 1.0) - kt.point("handle", 0.0)
    felt = RotationMatrix.MakeZRotation(np.radians(10.0)).matrix() @ (path / np.linalg.norm(path))
    on = handle_left_at(kt, p_WH, felt)
    np.testing.assert_allclose(on.point("handle", on.q_current), p_WH, atol=1e-9)
    rest = on.point("handle", np.linspace(on.q_current, 1.0, 50))
    assert np.linalg.norm(np.diff(rest, axis=0), axis=1).sum() == pytest.approx(PULL_ON_REST, rel=0.01)
    new_path = on.point("handle", 1.0) - on.point("handle", 0.0)
    np.testing.assert_allclose(new_path / np.linalg.norm(new_path), felt, atol=1e-6)
    turned = _turned(kt, 10.0)  # about the handle at q 0: the same turn, moved
    np.testing.assert_allclose(on.p_WK - turned.p_WK, np.broadcast_to(on.p_WK[0, 0] - turned.p_WK[0, 0],
                                                                      kt.p_WK.shape), atol=1e-9)
    same = handle_left_at(kt, p_WH, path / np.linalg.norm(path))  # felt along the keypoints' path
    np.testing.assert_allclose(same.p_WK - kt.p_WK, np.broadcast_to(same.p_WK[0, 0] - kt.p_WK[0, 0],
                                                                     kt.p_WK.shape), atol=1e-9)


def test_a_pull_the_arms_reach_ended_goes_on_from_a_second_base_to_the_stop(monkeypatch):
    """A training drawer planned on keypoints whose travel is 10 cm short and pulled without the
    guarded pull ends 7.6 cm short. Told that its arm's reach ended the pull there, the robot
    grasps the handle where its hand let go of it from a second base and pulls on: the drawer's
    stop ends it at q 1 (within 5 mm). Without a reach limit, or where the guarded pull went its
    whole distance (the drawer did not stop it), there is no second base."""
    scene_object = _training_drawer()
    keypoints = _short(read_keypoints(scene_object), 0.10)
    first = run_task(scene_object, 1.0, keypoints=keypoints,
                     simulation_config=SimulationConfig(guarded_pull=0.0))
    assert first.simulation.grasped and first.simulation.joint_error > 0.05 and first.pulled_on is None
    line = first.plan.waypoints[-1].p_WH - first.plan.waypoints[0].p_WH
    stopped = replace(first.simulation, pulled_past=0.01,  # as if the guarded pull stopped 1 cm on
                      pull_line=line / np.linalg.norm(line))
    config = SimulationConfig()
    args = (scene_object, keypoints, first.plan, stopped, None, PlannerConfig(), config, None, None)
    monkeypatch.setattr(task, "reach_limit", lambda X_WB, q, u: None)
    assert pull_on(*args) is None
    monkeypatch.setattr(task, "reach_limit", lambda X_WB, q, u: "panda_joint6 at its upper limit")
    assert pull_on(*args[:3], replace(stopped, pulled_past=config.guarded_pull), *args[4:]) is None
    on = pull_on(*args)
    assert on is not None and on.reason == "panda_joint6 at its upper limit" and on.plan is not None
    held = scene_object.ground_truth.point("handle", stopped.q_final)
    assert np.linalg.norm(on.plan.waypoints[0].p_WH - held) < 0.01  # grasped where the hand let go
    assert np.linalg.norm(on.plan.X_WB.translation() - first.plan.X_WB.translation()) > 0.05
    assert on.simulation.success and on.simulation.joint_error < 0.005, on.simulation.summary()
    assert on.details().startswith("pulled on from a second base (panda_joint6 at its upper limit): "
                                   "articulation 1.0")
    outcome = replace(first, pulled_on=on)
    assert outcome.success and outcome.final is on.simulation and outcome.summary().startswith("SUCCESS: ")
