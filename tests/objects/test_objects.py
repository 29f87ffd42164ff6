"""Sampled objects: they load in Drake, and their keypoints agree with the plant's geometry."""

import numpy as np
import pytest

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects import (
    SEED_DOMAIN_TRAIN,
    SemanticClass,
    object_rng,
    part_semantic_class,
    sample_object,
)
from nfr_drake.objects.closet import ClosetRanges
from nfr_drake.objects.drawer import TRAVEL_FRACTION, DrawerRanges


def _objects(category, n=12):
    return [sample_object(category, object_rng(SEED_DOMAIN_TRAIN, 7, i)) for i in range(n)]


@pytest.mark.parametrize("category", ["closet", "drawer"])
def test_many_seeds_parse_with_one_articulated_joint(category, load_object):
    for obj in _objects(category, 25):
        loaded = load_object(obj)
        assert loaded.plant.num_positions() == 1
        joint = loaded.plant.GetJointByName(obj.joint_name, loaded.model)
        expected = "revolute" if category == "closet" else "prismatic"
        assert joint.type_name() == expected
        assert joint.position_upper_limits()[0] == pytest.approx(obj.joint_upper, rel=1e-5)


def test_parameters_lie_in_their_ranges():
    for obj in _objects("closet", 40):
        r, p = ClosetRanges(), obj.params
        assert r.width[0] <= p["width"] <= r.width[1]
        assert r.height[0] <= p["height"] <= r.height[1]
        assert r.depth[0] <= p["depth"] <= r.depth[1]
        assert p["shelves"] in (0, 1, 2)
    for obj in _objects("drawer", 40):
        r, p = DrawerRanges(), obj.params
        assert r.width[0] <= p["width"] <= r.width[1]
        assert r.height[0] <= p["height"] <= r.height[1]
        assert obj.joint_upper == pytest.approx(TRAVEL_FRACTION * p["box_depth"])
    sides = {o.params["hinge_side"] for o in _objects("closet", 40)}
    assert sides == {"left", "right"}


@pytest.mark.parametrize("q", [0.0, 0.37, 1.0])
def test_closet_keypoints_match_plant_geometry(q, load_object):
    seen_sides = set()
    for obj in _objects("closet", 12):
        loaded = load_object(obj)
        loaded.set_q(q)
        kp = obj.keypoints(q)
        grip = "knob" if obj.params["handle_type"] == "knob" else "bar"
        X_WH = loaded.geometry_pose(f"handle__{grip}")
        np.testing.assert_allclose(kp["handle"], X_WH[:3, 3], atol=1e-3)
        # Hinge keypoints lie on the plant's joint axis, at the heights of the door's edges.
        joint = loaded.plant.GetJointByName(obj.joint_name, loaded.model)
        X_WJ = joint.frame_on_parent().CalcPoseInWorld(loaded.plant_context).GetAsMatrix4()
        axis_W = X_WJ[:3, :3] @ joint.revolute_axis()
        for name in ("hinge_top", "hinge_bottom"):
            offset = kp[name] - X_WJ[:3, 3]
            assert np.linalg.norm(np.cross(offset, axis_W)) < 1e-3
        X_WD = loaded.geometry_pose("moving__panel")
        door_half_height = (obj.params["height"] - 2 * 0.003) / 2
        assert kp["hinge_top"][2] == pytest.approx(X_WD[2, 3] + door_half_height, abs=1e-3)
        assert kp["hinge_bottom"][2] == pytest.approx(X_WD[2, 3] - door_half_height, abs=1e-3)
        # Goal: centre of the top face of the bottom panel.
        X_WB = loaded.geometry_pose("carcass__bottom")
        t = obj.params["panel_thickness"]
        np.testing.assert_allclose(kp["goal"], X_WB[:3, 3] + [0, 0, t / 2], atol=1e-3)
        seen_sides.add(obj.params["hinge_side"])
    assert seen_sides == {"left", "right"}


def test_closet_door_opens_outward_and_handle_moves_on_an_arc():
    for obj in _objects("closet", 8):
        front_x = obj.params["depth"] / 2
        kp0, kp1 = obj.keypoints(0.0), obj.keypoints(1.0)
        assert kp1["handle"][0] > kp0["handle"][0] + 0.1  # moves out of the front
        assert kp1["handle"][0] > front_x
        for q in np.linspace(0, 1, 7):
            r = np.linalg.norm(obj.keypoints(q)["handle"][:2] - kp0["hinge_top"][:2])
            r0 = np.linalg.norm(kp0["handle"][:2] - kp0["hinge_top"][:2])
            assert r == pytest.approx(r0, abs=1e-9)


@pytest.mark.parametrize("q", [0.0, 0.5, 1.0])
def test_drawer_keypoints_match_plant_geometry(q, load_object):
    for obj in _objects("drawer", 10):
        loaded = load_object(obj)
        loaded.set_q(q)
        kp = obj.keypoints(q)
        np.testing.assert_allclose(kp["handle"], loaded.geometry_pose("handle__bar")[:3, 3],
                                   atol=1e-3)
        X_WB = loaded.geometry_pose("moving__box_bottom")
        np.testing.assert_allclose(kp["goal"], X_WB[:3, 3] + [0, 0, 0.005], atol=1e-3)
        travel = kp["handle"] - obj.keypoints(0.0)["handle"]
        np.testing.assert_allclose(travel, [q * obj.joint_upper, 0, 0], atol=1e-9)


def test_geometry_names_carry_semantic_classes():
    obj = _objects("closet", 1)[0]
    assert {p.semantic for p in obj.base_parts} == {SemanticClass.CARCASS}
    assert {part_semantic_class(p.geometry_name) for p in obj.moving_parts} == {
        SemanticClass.MOVING, SemanticClass.HANDLE}
    assert part_semantic_class("closet::handle__bar") == SemanticClass.HANDLE
    with pytest.raises(ValueError, match="semantic class"):
        part_semantic_class("model::unknown_part")


def test_same_stream_gives_the_same_object_and_unknown_category_is_an_error():
    a = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 5))
    b = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 5))
    c = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 6))
    assert a.params == b.params and a.params != c.params
    with pytest.raises(NfrDrakeError, match="unknown category"):
        sample_object("fridge", object_rng(0, 0, 0))
