"""The look into an opened closet: the free height over the goal from one depth image."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from nfr_drake.objects.closet import ClosetRanges, sample_closet
from nfr_drake.planning.compartment import compartment_entry, front_normal
from nfr_drake.systems.interior import free_height_above_goal
from nfr_drake.world.keypoints import KeypointTrajectory


@pytest.mark.parametrize("shelves", [0, 1, 2])
def test_the_look_sees_the_lowest_shelf_over_the_goal(shelves):
    """Closets 0.45-0.7 m tall, turned and moved, door at 0.6: with shelves, the lowest one's
    underside over the goal within 5 mm; without, at least 20 cm free (what the view reaches)
    and no more than the inside's height."""
    X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, 2.3), [1.0, -0.4, 0.0])
    for seed in range(60):
        obj = sample_closet(np.random.default_rng(seed), ClosetRanges(height=(0.45, 0.7)))
        if obj.params["shelves"] == shelves:
            break
    p = obj.params
    kt = KeypointTrajectory.from_articulated_object(obj, X_WO, 0.0)
    goal = kt.point("goal", 0.6)
    _, opening = compartment_entry(kt, 0.6)
    seen = free_height_above_goal(obj, X_WO, 0.6, goal, front_normal(kt, 0.6), opening)
    t, H = p["panel_thickness"], p["height"]
    if shelves:
        underside = t + (H - 2 * t) / (shelves + 1) - t / 2
        assert seen == pytest.approx(underside - goal[2], abs=0.005)
    else:
        assert 0.2 <= seen <= H - 2 * t + 1e-6


@pytest.mark.parametrize("low", [0.0, 0.015, 0.025])
def test_a_goal_fitted_below_the_floor_does_not_see_the_floor_as_a_shelf(low):
    """A fitted goal up to 2.5 cm below the true inner floor (closet 14 of capture seed 200: the
    look saw the floor's top 1.5 cm over its fitted goal and the place was refused): the free
    height is still the shelf's underside over the goal, m."""
    for seed in range(60):
        obj = sample_closet(np.random.default_rng(seed), ClosetRanges(height=(0.45, 0.7)))
        if obj.params["shelves"] == 1:
            break
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    goal = kt.point("goal", 0.6) - [0.0, 0.0, low]
    _, opening = compartment_entry(kt, 0.6)
    seen = free_height_above_goal(obj, RigidTransform(), 0.6, goal, front_normal(kt, 0.6), opening)
    t, H = obj.params["panel_thickness"], obj.params["height"]
    assert seen == pytest.approx(t + (H - 2 * t) / 2 - t / 2 - goal[2], abs=0.005)
