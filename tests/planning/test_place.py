"""The place planner, from ground-truth keypoint trajectories and keypoint-derived obstacles."""

import numpy as np
import pytest
from pydrake.math import RigidTransform

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.compartment import compartment_obstacles
from nfr_drake.planning.place import (
    PLACE_REACH,
    PlaceConfig,
    place_problem,
    place_reach_points,
    plan_place,
)
from nfr_drake.planning.planner import PlannerConfig, plan_articulation
from nfr_drake.planning.scene import build_planning_scene
from nfr_drake.systems.place_task import ITEM_REACH, table_beside
from nfr_drake.world.items import Item, sample_item
from nfr_drake.world.keypoints import KeypointTrajectory


@pytest.mark.parametrize("category,seed,q_target", [("closet", 0, 0.6), ("drawer", 3, 1.0)])
def test_place_plan_ends_at_the_goal(category, seed, q_target):
    """The planned item, where the hand lets go, stands upright within 3 cm of the goal keypoint
    (kinematically: the tool's pose at the end of the carry times the grasp), and every segment
    starts where the last one ended."""
    obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, seed, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    item = sample_item(np.random.default_rng(seed))
    opening = plan_articulation(kt, q_target, config=PlannerConfig(place_reach=PLACE_REACH[category][1]),
                                must_reach=place_reach_points(kt, q_target, item))
    fixed, moving = compartment_obstacles(kt, q_target)
    grasp = "side" if category == "closet" else "top"
    table, X_WI = table_beside(opening.X_WB, [*fixed, *moving], ITEM_REACH[grasp])
    q_end = opening.trajectory.value(opening.duration).ravel()
    plan = plan_place(opening.X_WB, q_end, place_problem(kt, q_target, item, X_WI, table),
                      handle=opening.waypoints[-1])

    goal = obj.keypoints(q_target)["goal"]
    assert plan.place_error() < 0.03
    np.testing.assert_allclose(plan.goal, goal, atol=1e-9)
    drop = plan.X_WI_place.translation()[2] - goal[2]
    assert PlaceConfig().min_distance < drop < 0.03
    tilt = np.degrees(np.arccos(plan.X_WI_place.rotation().col(2) @ [0, 0, 1]))
    assert tilt < PlaceConfig().upright_tolerance_deg + 1
    ends = [opening.trajectory.value(opening.duration).ravel()]
    for segment in plan.segments:
        np.testing.assert_allclose(segment.value(0.0), ends[-1], atol=1e-6)
        ends.append(segment.value(segment.duration))
    # The pick: the tool on the item as the grasp says.
    scene = build_planning_scene(plan.X_WB, [])
    scene.plant.SetPositions(scene.plant_context, plan.segments[0].value(plan.segments[0].duration))
    X_WG = scene.tool_frame.CalcPoseInWorld(scene.plant_context)
    np.testing.assert_allclose((X_WG @ plan.X_GI).translation(), X_WI.translation(), atol=0.01)


def test_items_are_refused_in_one_line():
    with pytest.raises(NfrDrakeError, match="item kind must be one of box, can, mug"):
        Item("vase", 0.05, 0.05, 0.1, 0.2)
    with pytest.raises(NfrDrakeError, match="open gripper"):
        Item("box", 0.09, 0.05, 0.1, 0.2)
    kinds = {sample_item(np.random.default_rng(s)).kind for s in range(20)}
    assert kinds == {"box", "can", "mug"}


def test_a_trajectory_without_a_goal_cannot_be_placed_in():
    kt = KeypointTrajectory("drawer", np.array([0.0, 1.0]), ("handle",),
                            np.array([[[0.5, 0.0, 0.2]], [[0.8, 0.0, 0.2]]]), 0.0)
    with pytest.raises(NfrDrakeError, match="no goal keypoint"):
        compartment_obstacles(kt, 1.0)
