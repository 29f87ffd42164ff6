"""The object model: fronts, the single-joint API of one-front objects, part indices and labels."""

from dataclasses import replace

import numpy as np
import pytest

from nfr_drake.data.render import split_render_label
from nfr_drake.objects import SEED_DOMAIN_TRAIN, ArticulatedObject, object_rng, part_index_of, sample_object
from nfr_drake.objects.articulated import front_part_name, render_label_value
from nfr_drake.objects.plant import set_articulation


def _two_fronts():
    """A closet whose door is duplicated 1 m higher as a second front (names carry the index)."""
    closet = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 1, 0))
    door = closet.front(0)
    fronts = []
    for k, dz in enumerate((0.0, 1.0)):
        parts = tuple(replace(p, name=front_part_name(k, p.name)) for p in door.parts)
        fronts.append(replace(door, link_name=f"front{k}", joint_name=f"front{k}_joint", parts=parts,
                              p_OJ=tuple(np.add(door.p_OJ, (0, 0, dz)))))
    return ArticulatedObject("furniture", "two", closet.base_parts, tuple(fronts), closet.params)


def test_single_joint_api_delegates_to_the_only_front_and_refuses_several():
    closet = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 1, 0))
    front = closet.front(0)
    assert closet.joint_name == front.joint_name == "door_hinge" and closet.moving_link_name == "door"
    np.testing.assert_array_equal(closet.keypoint_array(0.3), front.keypoint_array(0.3))
    np.testing.assert_array_equal(closet.X_OM(0.3), closet.X_OM_k(0, 0.3))
    two = _two_fronts()
    with pytest.raises(ValueError, match="2 fronts"):
        _ = two.joint_type
    with pytest.raises(ValueError, match="2 articulations"):
        two.joint_values(np.zeros(3))
    kps = two.front_keypoints(np.array([0.0, 1.0]))
    np.testing.assert_allclose(kps[1]["handle"], two.front(1).keypoints(1.0)["handle"])
    assert kps[0]["handle"][2] + 1.0 == pytest.approx(two.front(1).keypoints(0.0)["handle"][2])
    with pytest.raises(ValueError, match="unique"):
        ArticulatedObject("furniture", "dup", two.base_parts, (two.front(0), two.front(0)))


def test_every_front_loads_as_its_own_joint_and_follows_its_q(load_object):
    two = _two_fronts()
    loaded = load_object(two)
    assert loaded.plant.num_positions() == 2
    set_articulation(loaded.plant, loaded.plant_context, two, loaded.model, np.array([0.0, 1.0]))
    for k, q in enumerate((0.0, 1.0)):
        X_WH = loaded.geometry_pose(f"handle__f{k}__bar" if two.params["handle_type"] == "bar"
                                    else f"handle__f{k}__knob")
        np.testing.assert_allclose(two.front(k).keypoints(q)["handle"], X_WH[:3, 3], atol=1e-6)


def test_part_indices_and_render_labels():
    assert part_index_of("carcass__top") == -1
    assert part_index_of("closet::moving__panel") == 0
    assert part_index_of("m::handle__f5__bar") == 5
    assert render_label_value("carcass__top") == 1
    assert render_label_value("moving__f2__panel") == 2 + 4 * 3
    assert render_label_value("handle__bar") == 3 + 4
    raw = np.array([0, 1, 6, 7, 2 + 4 * 8, 3 + 4 * 8, 32766, 32764])
    label, part = split_render_label(raw)
    np.testing.assert_array_equal(label, [0, 1, 2, 3, 2, 3, 0, 0])
    np.testing.assert_array_equal(part, [-1, -1, 0, 0, 7, 7, -1, -1])
