"""`plan --object FILE` on realistic user models (tests/fixtures/user_models.py): each opens with its
true keypoints or is refused with one line saying what to change."""

import numpy as np
import pytest
from fixtures.user_models import OPENS, Geom, Joint, Link, random_models, write_models, write_sdf, write_urdf
from pydrake.math import RigidTransform

from nfr_drake.cli import main
from nfr_drake.errors import NfrDrakeError
from nfr_drake.planning.grasp import handle_waypoints
from nfr_drake.systems.scene_objects import SceneObject, object_pose
from nfr_drake.systems.task import run_task
from nfr_drake.world.keypoints import APPROACH_KEYPOINT, GRIP_AXIS_KEYPOINT
from nfr_drake.world.obstacles import distance_to_box


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    return {m.name: m for m in write_models(tmp_path_factory.mktemp("user_models"))}


def load(model, X_WO=None, closed_at=None) -> SceneObject:
    return SceneObject.from_model_file(model.path, model.joint, model.handle_body,
                                       X_WO if X_WO is not None else RigidTransform(), 0.0, closed_at)


REFUSED = ["root_link_named_world", "base_cabinet_in_centimetres", "base_cabinet_y_up", "base_cabinet_sunk",
           "carcass_one_concave_mesh", "sliding_door_flush_pull"]


@pytest.mark.parametrize("name", REFUSED)
def test_a_model_that_cannot_be_planned_on_is_refused_in_one_line(models, name, capsys, tmp_path):
    model = models[name]
    assert model.expect != OPENS
    assert main([*model.plan_args(), "--replay", str(tmp_path / "r.html")]) == 2
    err = capsys.readouterr().err.strip()
    assert model.expect in err and len(err.splitlines()) == 1, err


def test_the_handle_is_the_centre_of_its_grip(models):
    """The wardrobe's handle link has its frame at the hinge; its mesh is 35 cm away."""
    obj = load(models["wardrobe_handle_mesh_off_frame"])
    # The U-shaped mesh's bounding box: x 0 to 0.045 (standoff 0.035 plus half the 2 cm bar), y
    # -0.35 +- 0.01, z +- 0.07 about the link frame. The grip is the bar's axis, half the bar's 2 cm
    # in from the outermost face (x 0.035), not the box's middle (x 0.0225, between bar and door).
    np.testing.assert_allclose(obj.p_BH, [0.035, -0.35, 0.0], atol=1e-6)
    # The link frame sits on the door's face, 1 m up, at the hinge (x 0.275 + 0.018, y 0.225).
    np.testing.assert_allclose(obj.ground_truth.point("handle", 0.0), [0.328, -0.125, 1.0], atol=1e-6)
    assert any("u_handle.obj" in note and "concave" in note for note in obj.notes)


def test_a_joint_shut_at_its_upper_limit_starts_shut(models):
    fridge = models["fridge_shut_at_upper_limit"]
    obj = load(fridge)
    assert obj.joint_range == (0.0, -1.9)
    # Shut, where the file draws it: the grip, the axis of the bar (radius 1.1 cm, on posts) 4 cm in
    # front of the door's face at x = 0.33.
    np.testing.assert_allclose(obj.ground_truth.point("handle", 0.0), [0.37, 0.25, 1.1], atol=1e-6)
    opened = obj.ground_truth.point("handle", 1.0)
    assert opened[0] > 0.5  # swung out
    with pytest.raises(NfrDrakeError, match="from -1.9 towards 0"):  # --closed-at is taken at its word:
        load(fridge, closed_at="lower")                              # shut wide open, it would close


def test_a_model_drawn_open_is_shut_where_its_handle_meets_the_rest(models):
    """Joint value 0 is the door open 90 degrees; the rule (the limit nearer 0) would call that shut."""
    model = models["base_cabinet_drawn_open"]
    obj = load(model)
    assert obj.joint_range == pytest.approx((-np.pi / 2, 0.0), abs=1e-5)
    assert any("taken as shut at -1.57" in note for note in obj.notes)
    np.testing.assert_allclose(obj.ground_truth.point("handle", 0.0), [0.338, 0.24, 0.6], atol=1e-5)
    with pytest.raises(NfrDrakeError, match="from 0 towards -1.57"):  # the user's word stands
        load(model, closed_at="upper")


def test_a_joint_with_no_clear_shut_limit_asks_for_closed_at(tmp_path):
    links = [Link("box", (), 5.0), Link("door", (), 1.0)]
    joints = [Joint("hinge", "revolute", "box", "door", limits=(-1.0, 1.0))]
    path = write_urdf(tmp_path / "ambiguous.urdf", "ambiguous", links, joints)
    with pytest.raises(NfrDrakeError, match="--closed-at lower or --closed-at upper"):
        SceneObject.from_model_file(path, "hinge", "door", RigidTransform(), 0.0)


def test_a_continuous_joint_is_refused_with_what_to_change(tmp_path):
    links = [Link("box", (), 5.0), Link("door", (), 1.0)]
    path = write_urdf(tmp_path / "spinning.urdf", "spinning", links,
                      [Joint("hinge", "continuous", "box", "door", limits=(0.0, 0.0))])
    with pytest.raises(NfrDrakeError, match="give it a <limit> with lower and upper"):
        SceneObject.from_model_file(path, "hinge", "door", RigidTransform(), 0.0)


def test_an_exported_model_with_turned_frames_and_a_visual_only_handle(models):
    """The handle's mesh (no collision geometry) gives its grip; the door's joint frame is turned."""
    obj = load(models["exported_cabinet"])
    # The U handle's bar axis, 3.5 cm out of the door's face (x = 0.298; its box reaches 4.5 cm, the
    # bar 2 cm thick), 6 cm from the free edge (to 10 um: the file's angles have 6 digits).
    np.testing.assert_allclose(obj.ground_truth.point("handle", 0.0), [0.333, 0.24, 0.6], atol=1e-5)
    assert len(obj.obstacles) == 5  # one box per convex collision piece of the carcass


def test_a_sliding_door_is_approached_from_the_front(models):
    obj = load(models["sliding_door"])
    kt = obj.ground_truth
    assert APPROACH_KEYPOINT in kt.names and GRIP_AXIS_KEYPOINT in kt.names
    # It slides along +y; the hand comes along -x (towards the front face) and holds the vertical bar.
    np.testing.assert_allclose(kt.point("handle", 1.0) - kt.point("handle", 0.0), [0.0, 0.45, 0.0], atol=1e-9)
    for waypoint in handle_waypoints(kt, np.linspace(0.0, 1.0, 3)):
        np.testing.assert_allclose(waypoint.approach_W, [-1.0, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(abs(waypoint.bar_W), [0.0, 0.0, 1.0], atol=1e-9)


def test_a_drawer_is_still_pulled_along_its_slide(models):
    kt = load(models["desk_drawer"]).ground_truth
    assert APPROACH_KEYPOINT not in kt.names
    np.testing.assert_allclose(handle_waypoints(kt, [0.0])[0].approach_W, [-1.0, 0.0, 0.0], atol=1e-9)


def test_the_planner_sees_the_worktop_overhang(models):
    obj = load(models["worktop_drawer"])
    overhang = np.array([[0.315, 0.0, 0.88]])  # under the worktop's front edge, 1.5 cm past the drawer
    assert any(distance_to_box(box, overhang)[0] == 0.0 for box in obj.obstacles)
    drawer_front = np.array([[0.29, 0.0, 0.78]])  # the moving part is no obstacle
    assert all(distance_to_box(box, drawer_front)[0] > 0.0 for box in obj.obstacles)


def test_other_joints_are_held_and_massless_parts_get_a_mass(models):
    obj = load(models["cupboard_right_door"])
    assert obj.locked_joints == ("left_hinge",)
    assert any("'left_door'" in note and "no mass" in note for note in obj.notes)


def test_the_suggested_pose_stands_a_y_up_model_on_the_floor(models):
    """The refusal suggests --object-rpy-deg 90 0 0 --object-xyz 0 0 0; with it the hinge is vertical."""
    obj = load(models["base_cabinet_y_up"], object_pose((0, 0, 0), 0.0, (90, 0, 0)))
    hinge = obj.ground_truth.point("hinge_top", 0.0) - obj.ground_truth.point("hinge_bottom", 0.0)
    np.testing.assert_allclose(hinge / np.linalg.norm(hinge), [0, 0, 1], atol=1e-5)  # rpy in 6 digits
    load(models["base_cabinet_sunk"], object_pose((0, 0, 0.1), 0.0))  # the suggested lift: accepted


def test_a_body_without_a_joint_is_fixed_to_the_model_as_drawn(models, tmp_path):
    """An SDFormat link with no joint (a loose shelf) would fall; it is welded where the file draws it."""
    text = models["worktop_drawer"].path.read_text().replace(
        "</model>", '<link name="shelf"><pose>0 0 0.4 0 0 0</pose><collision name="c"><geometry><box>'
        "<size>0.5 0.5 0.02</size></box></geometry></collision></link>\n</model>")
    path = tmp_path / "with_shelf.sdf"
    path.write_text(text)
    obj = SceneObject.from_model_file(path, "slide", "pull", RigidTransform([1.0, 0.0, 0.0]), 0.0)
    assert any(distance_to_box(box, np.array([[1.0, 0.0, 0.4]]))[0] == 0.0 for box in obj.obstacles)


def test_a_door_resting_on_the_floor_does_not_drag_on_it(models):
    outcome = run_task(load(models["base_cabinet_door_on_floor"]), 0.6)
    assert outcome.success, outcome.simulation.summary()
    assert outcome.simulation.max_constraint_force < 100.0  # 812 N when it dragged


def test_a_door_swinging_into_its_neighbour_by_a_few_mm_is_not_stopped_by_it(models):
    """The kitchen counter's right door of the pair is hinged at its back edge on the partition: its
    front edge swings 6 mm into the locked drawer fronts beside it (8.8 kN and stuck at q = 0.2 when
    the object's own parts collided)."""
    outcome = run_task(load(models["kitchen_counter_door_of_a_pair"]), 0.6)
    assert outcome.success, outcome.simulation.summary()
    assert outcome.simulation.max_constraint_force < 100.0


def test_a_massless_door_opens(models):
    outcome = run_task(load(models["cupboard_massless_door"]), 0.6)
    assert outcome.success, outcome.simulation.summary()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["worktop_drawer", "sliding_door", "fridge_shut_at_upper_limit",
                                  "cupboard_right_door", "desk_drawer", "wardrobe_handle_mesh_off_frame",
                                  "kitchen_counter_middle_drawer"])
def test_a_user_model_opens(models, name, capsys, tmp_path):
    model = models[name]
    assert model.expect == OPENS
    assert main([*model.plan_args(), "--replay", str(tmp_path / "r.html")]) == 0, capsys.readouterr()
    assert "SUCCESS" in capsys.readouterr().out


def test_sdf_writer_places_links_at_their_joints(tmp_path):
    """The fixtures' SDFormat writer: a child link's frame is its joint's origin in the parent."""
    links = [Link("a", (), 1.0), Link("b", (), 1.0)]
    path = write_sdf(tmp_path / "m.sdf", "m", links, [Joint("j", "prismatic", "a", "b", (0.1, 0.2, 0.3),
                                                             limits=(0.0, 0.5))])
    assert "<pose>0.1 0.2 0.3 0 0 0</pose>" in path.read_text()


def test_a_handle_body_that_is_the_door_is_noted(models):
    model = models["base_cabinet_door_on_floor"]
    obj = SceneObject.from_model_file(model.path, "hinge", "door", RigidTransform(), 0.0)
    assert any("'door' is 0.72 m by 0.60 m" in note for note in obj.notes)
    assert not load(model).notes  # its handle: a bar


def test_a_plan_out_of_reach_suggests_a_shorter_motion(models, capsys, tmp_path):
    model = models["base_cabinet_door_on_floor"]
    high = ["--object-xyz", "0", "0", "2.5", "--replay", str(tmp_path / "r.html")]
    assert main([*model.plan_args(), *high]) == 2
    captured = capsys.readouterr()
    assert "lowest point is 250 cm above the floor" in captured.out  # a warning, not a refusal
    assert "no feasible motion" in captured.err and "--target-q between 0 and 0.6" in captured.err


def test_a_handle_body_that_does_not_move_is_refused(models):
    model = models["cupboard_right_door"]
    with pytest.raises(NfrDrakeError, match="'left_handle' does not move with joint 'right_hinge'"):
        SceneObject.from_model_file(model.path, "right_hinge", "left_handle", RigidTransform(), 0.0)


def test_a_handle_drawn_only_in_a_mesh_drake_cannot_measure_is_refused(tmp_path):
    """Drake loads a COLLADA visual but cannot size it: the handle's centre would be a guess."""
    (tmp_path / "handle.dae").write_text("<COLLADA/>")
    links = [Link("box", (), 5.0), Link("door", (), 1.0),
             Link("handle", (), 0.1, visual=(Geom("mesh", ("handle.dae",)),))]
    joints = [Joint("hinge", "revolute", "box", "door", limits=(0.0, 1.5)),
              Joint("handle_fix", "fixed", "door", "handle", (0.0, 0.3, 0.5))]
    path = write_urdf(tmp_path / "dae_handle.urdf", "dae_handle", links, joints)
    with pytest.raises(NfrDrakeError, match="the mesh handle.dae of body 'handle' cannot be measured"):
        SceneObject.from_model_file(path, "hinge", "handle", RigidTransform(), 0.0)


def test_object_pose_turns_by_rpy_then_adds_the_yaw():
    X = object_pose((1.0, 2.0, 0.0), 90.0, (90.0, 0.0, 0.0))
    # Roll 90 (y up to z), then yaw 90 about W's z: the model's y axis ends up along W's z.
    np.testing.assert_allclose(X.rotation().matrix() @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(X.rotation().matrix() @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    with pytest.raises(NfrDrakeError, match="finite"):
        object_pose((0.0, 0.0, 0.0), 0.0, (float("nan"), 0.0, 0.0))


def test_model_file_options_need_a_model_file(capsys, tmp_path):
    for option in (["--closed-at", "upper"], ["--object-rpy-deg", "90", "0", "0"]):
        assert main(["plan", "--category", "closet", *option, "--replay", str(tmp_path / "r.html")]) == 2
        assert "apply to a model file (--object)" in capsys.readouterr().err


@pytest.mark.slow
def test_random_user_models_open(tmp_path, capsys):
    """Two each of random doors, drawers and sliding doors at random poses (benchmarks/user_models.py
    --random runs more)."""
    for model in random_models(tmp_path, 6, seed=0):
        status = main([*model.plan_args(), "--replay", str(tmp_path / f"{model.name}.html")])
        out = capsys.readouterr()
        assert status == 0 and "SUCCESS" in out.out, (model.name, out)


def test_a_door_that_would_open_into_its_cabinet_is_refused(models, tmp_path):
    """The base cabinet with its hinge axis negated: from shut (0) to 1.75 rad it swings inwards."""
    text = models["base_cabinet_door_on_floor"].path.read_text()
    text = text.replace('<axis xyz="0 0 -1"/>', '<axis xyz="0 0 1"/>')
    path = tmp_path / "inward.urdf"
    path.write_text(text)
    with pytest.raises(NfrDrakeError, match="moves its handle into the model as it opens"):
        SceneObject.from_model_file(path, "hinge", "handle", RigidTransform(), 0.0)


def test_a_handle_without_collision_geometry_is_refused_for_a_grasp_by_contact(models, capsys, tmp_path):
    """The exported cabinet's handle is a visual mesh only: the constraint grasp holds it (the
    fixture opens), fingers closing by contact would pass through it."""
    model = models["exported_cabinet"]
    assert main([*model.plan_args(), "--replay", str(tmp_path / "r.html"), "--grasp", "contact"]) == 2
    err = capsys.readouterr().err.strip()
    assert "has no collision geometry" in err and "--grasp constraint" in err, err
    assert len(err.splitlines()) == 1, err
