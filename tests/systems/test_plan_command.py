"""`nfr-drake plan` on a user's URDF model, and its error messages."""

import re

import pytest

from nfr_drake.cli import main

CABINET_URDF = """<?xml version="1.0"?>
<robot name="cabinet">
  <link name="frame">
    <inertial><mass value="10"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="-0.2 0 0.3"/><geometry><box size="0.4 0.5 0.6"/></geometry></collision>
    <visual><origin xyz="-0.2 0 0.3"/><geometry><box size="0.4 0.5 0.6"/></geometry></visual>
  </link>
  <link name="door">
    <inertial><origin xyz="0.01 0.25 0.3"/><mass value="2"/>
      <inertia ixx="0.05" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.01 0.25 0.3"/><geometry><box size="0.02 0.48 0.58"/></geometry></collision>
    <visual><origin xyz="0.01 0.25 0.3"/><geometry><box size="0.02 0.48 0.58"/></geometry></visual>
  </link>
  <link name="handle">
    <inertial><mass value="0.1"/>
      <inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry>HANDLE_GEOMETRY</geometry></visual>
    <collision><geometry><cylinder radius="0.01" length="0.12"/></geometry></collision>
  </link>
  <joint name="hinge" type="revolute">
    <parent link="frame"/><child link="door"/><origin xyz="0 -0.25 0"/><axis xyz="0 0 -1"/>
    <limit lower="0" upper="1.5708" effort="50" velocity="5"/><dynamics damping="1"/>
  </joint>
  <joint name="handle_fix" type="fixed">
    <parent link="door"/><child link="handle"/><origin xyz="0.06 0.43 0.32"/>
  </joint>
</robot>
"""


def _write(tmp_path, geometry='<cylinder radius="0.01" length="0.12"/>'):
    path = tmp_path / "cabinet.urdf"
    path.write_text(CABINET_URDF.replace("HANDLE_GEOMETRY", geometry))
    return path


@pytest.mark.parametrize("grasp", ["constraint", "contact"])
def test_plans_user_model(tmp_path, capsys, grasp):
    replay = tmp_path / "replay.html"
    status = main(["plan", "--object", str(_write(tmp_path)), "--joint", "hinge", "--handle-body", "handle",
                   "--object-xyz", "0.1", "0.0", "0.0", "--replay", str(replay), "--grasp", grasp])
    out = capsys.readouterr().out
    assert status == 0, out
    reached = re.search(r"SUCCESS: articulation (\d\.\d+) \(target 0\.600", out)
    assert reached and abs(float(reached.group(1)) - 0.6) * 90.0 <= 5.0, out  # within 5 deg of 54
    assert f"{grasp} grasp" in out, out
    assert "planning" in out and str(replay) in out
    assert replay.stat().st_size > 100_000


@pytest.mark.parametrize("args,message", [
    (["--joint", "lid", "--handle-body", "handle"], "has no joint 'lid'; its joints"),
    (["--joint", "handle_fix", "--handle-body", "handle"], "need revolute or prismatic"),
    (["--joint", "hinge"], "--object needs --joint and --handle-body"),
])
def test_user_errors_exit_2(tmp_path, capsys, args, message):
    assert main(["plan", "--object", str(_write(tmp_path)), *args]) == 2
    assert message in capsys.readouterr().err


def test_infeasible_plan_exits_2(tmp_path, capsys):
    status = main(["plan", "--object", str(_write(tmp_path)), "--joint", "hinge", "--handle-body", "handle",
                   "--object-xyz", "0", "0", "2.5"])
    assert status == 2
    assert "no feasible motion from q=0.00 to q=0.60" in capsys.readouterr().err


def test_unloadable_model_says_what_to_do(tmp_path, capsys):
    path = _write(tmp_path, '<mesh filename="handle.3ds"/>')
    assert main(["plan", "--object", str(path), "--joint", "hinge", "--handle-body", "handle"]) == 2
    err = capsys.readouterr().err
    assert "Drake could not load" in err and "convert" in err


@pytest.mark.parametrize("pose", [["--object-xyz", "nan", "0", "0"], ["--object-yaw-deg", "inf"]])
def test_a_non_finite_object_pose_exits_2(capsys, pose, tmp_path):
    assert main(["plan", "--category", "closet", *pose, "--replay", str(tmp_path / "r.html")]) == 2
    assert "object pose: need three finite coordinates" in capsys.readouterr().err


def test_a_scenario_with_a_non_finite_pose_is_refused():
    from nfr_drake.errors import ConfigError
    from nfr_drake.systems.scenario import Scenario

    with pytest.raises(ConfigError, match="finite"):
        Scenario(object_xyz=[0.0, float("nan"), 0.0])
    with pytest.raises(ConfigError, match="finite"):
        Scenario(object_yaw_deg=float("-inf"))


@pytest.mark.parametrize("category,task,given,span", [
    ("closet", "open", (None, None), (0.0, 0.6)),
    ("drawer", "open", (None, None), (0.0, 1.0)),
    ("drawer", "close", (None, None), (1.0, 0.0)),
    ("closet", "close", (0.3, None), (0.3, 0.0)),
    ("closet", "open", (0.2, 0.9), (0.2, 0.9)),
])
def test_task_span_defaults_and_given_values(category, task, given, span):
    from nfr_drake.systems.task import task_span

    assert task_span(category, task, *given) == span


def test_task_span_refuses_q_outside_the_unit_interval():
    from nfr_drake.errors import NfrDrakeError
    from nfr_drake.systems.task import task_span

    with pytest.raises(NfrDrakeError, match="target_q 1.2 is outside"):
        task_span("closet", "open", None, 1.2)


def test_sampled_part_draws_the_part_from_the_pieces_stream_unless_given():
    from pydrake.math import RigidTransform

    from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
    from nfr_drake.systems.scene_objects import random_part, sampled_part

    rng = object_rng(SEED_DOMAIN_TRAIN, 7, 3)
    expected = sample_object("furniture", rng)
    drawn = random_part(expected, rng)
    obj, part, scene_object = sampled_part("furniture", 7, 3, RigidTransform())
    assert obj.params == expected.params and part == drawn
    assert scene_object.joint_name == obj.front(part).joint_name
    other = (drawn + 1) % obj.num_fronts
    _, part, scene_object = sampled_part("furniture", 7, 3, RigidTransform(), other)
    assert part == other and scene_object.joint_name == obj.front(other).joint_name


def _fit_result(path, X_WO, in_W: bool, shift=(0.0, 0.0, 0.0)):
    """A fit result JSON (docs/CONVENTIONS.md) holding the true keypoints of sampled closet 3, in W
    (placed at X_WO, with `extra.object_pose` as `infer --estimate-pose` writes it) or in O,
    moved by `shift` (m)."""
    import json

    import numpy as np

    from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object

    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    grid = np.linspace(0.0, 1.0, 21)
    p = obj.keypoint_array(grid) + shift  # (N, K, 3) in O
    if in_W:
        p = p @ X_WO[:3, :3].T + X_WO[:3, 3]
    doc = {"category": "closet", "q": 0.0,
           "keypoints": {n: p[0, i].tolist() for i, n in enumerate(obj.keypoint_names)},
           "trajectory": {"q": grid.tolist(),
                          "keypoints": {n: p[:, i].tolist() for i, n in enumerate(obj.keypoint_names)}},
           "image_loss": 0.0, "seconds": 0.0,
           "extra": {"object_pose": {"X_WO": X_WO.tolist()}} if in_W else {}}
    path.write_text(json.dumps(doc))
    return path


def test_fitted_keypoints_in_W_or_placed_from_O(tmp_path):
    import numpy as np

    from nfr_drake.systems.plan_command import fitted_keypoints
    from nfr_drake.systems.scene_objects import object_pose

    X_WO = object_pose((0.4, -0.2, 0.0), 30.0)
    elsewhere = object_pose((5.0, 5.0, 0.0), 90.0)  # ignored: the result is in W already
    in_W = fitted_keypoints(_fit_result(tmp_path / "w.json", X_WO.GetAsMatrix4(), True), elsewhere)
    in_O = fitted_keypoints(_fit_result(tmp_path / "o.json", X_WO.GetAsMatrix4(), False), X_WO)
    assert np.allclose(in_W.p_WK, in_O.p_WK) and in_W.q_current == 0.0


def test_plans_with_fitted_keypoints_in_W(tmp_path, capsys):
    """Keypoints in W (as `infer --estimate-pose` writes them) 1 cm off the true ones: the plan uses
    them, the simulation opens the true closet and writes its replay."""
    from nfr_drake.systems.scene_objects import object_pose

    X_WO = object_pose((0.3, -0.4, 0.0), 25.0).GetAsMatrix4()
    result = _fit_result(tmp_path / "result.json", X_WO, True, shift=(0.0, 0.01, 0.0))
    replay = tmp_path / "replay.html"
    status = main(["plan", "--category", "closet", "--seed", "3", "--object-xyz", "0.3", "-0.4", "0.0",
                   "--object-yaw-deg", "25", "--keypoints", str(result), "--replay", str(replay)])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "planning with the fitted keypoints" in out and "handle 1.0 cm from the object's" in out
    assert "SUCCESS" in out and replay.stat().st_size > 100_000


def test_fitted_keypoints_of_another_category_exit_2(tmp_path, capsys):
    import numpy as np

    result = _fit_result(tmp_path / "result.json", np.eye(4), True)
    assert main(["plan", "--category", "drawer", "--keypoints", str(result),
                 "--replay", str(tmp_path / "r.html")]) == 2
    assert "keypoints of a closet, but the object's joint makes it a drawer" in capsys.readouterr().err
    assert main(["plan", "--category", "closet", "--keypoints", str(tmp_path / "none.json"),
                 "--replay", str(tmp_path / "r.html")]) == 2
    assert "fit result not found" in capsys.readouterr().err


def test_plans_with_fitted_keypoints_alone_and_replays_the_motion(tmp_path, capsys):
    """Photos of a real object: no model to simulate on, so the motion is planned and replayed."""
    from nfr_drake.systems.scene_objects import object_pose

    result = _fit_result(tmp_path / "result.json", object_pose((0.3, -0.4, 0.0), 25.0).GetAsMatrix4(), True)
    replay = tmp_path / "planned.html"
    assert main(["plan", "--keypoints", str(result), "--replay", str(replay)]) == 0
    out = capsys.readouterr().out
    assert "closet from q = 0.00 to 0.60, the robot's base at" in out and "not simulated" in out
    assert replay.stat().st_size > 100_000
