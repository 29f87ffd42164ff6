"""The look into an opened closet: its floor and the free height over the goal from one depth image."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from nfr_drake.objects.closet import ClosetRanges, sample_closet
from nfr_drake.planning.compartment import compartment_entry, front_normal
from nfr_drake.systems.interior import look_into_compartment
from nfr_drake.world.keypoints import KeypointTrajectory


@pytest.mark.parametrize("shelves", [0, 1, 2])
def test_the_look_sees_the_lowest_shelf_over_the_goal(shelves):
    """Closets 0.45-0.7 m tall, turned and moved, door at 0.6: with shelves, the lowest one's
    underside over the goal within 5 mm; without, at least 20 cm free (what the view reaches)
    and no more than the inside's height; the floor's top (the goal's height) within 2 mm."""
    X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, 2.3), [1.0, -0.4, 0.0])
    for seed in range(60):
        obj = sample_closet(np.random.default_rng(seed), ClosetRanges(height=(0.45, 0.7)))
        if obj.params["shelves"] == shelves:
            break
    p = obj.params
    kt = KeypointTrajectory.from_articulated_object(obj, X_WO, 0.0)
    goal = kt.point("goal", 0.6)
    _, opening = compartment_entry(kt, 0.6)
    look = look_into_compartment(obj, X_WO, 0.6, goal, front_normal(kt, 0.6), opening)
    seen = look.ceiling - goal[2]
    t, H = p["panel_thickness"], p["height"]
    assert look.floor == pytest.approx(goal[2], abs=0.002)
    if shelves:
        underside = t + (H - 2 * t) / (shelves + 1) - t / 2
        assert seen == pytest.approx(underside - goal[2], abs=0.005)
    else:
        assert 0.2 <= seen <= H - 2 * t + 1e-6


@pytest.mark.parametrize("low", [-0.03, 0.0, 0.015, 0.025])
def test_a_goal_fitted_off_the_floor_sees_the_true_floor_and_shelf(low):
    """A fitted goal from 3 cm over to 2.5 cm under the true inner floor (closet 14 of capture
    seed 200: 1.1 cm under; the held item scraped the floor's front edge on its way in): the look
    gives the floor's true top within 2 mm and the shelf's underside within 5 mm (a goal under
    the floor does not take the floor for a shelf), m."""
    for seed in range(60):
        obj = sample_closet(np.random.default_rng(seed), ClosetRanges(height=(0.45, 0.7)))
        if obj.params["shelves"] == 1:
            break
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    goal = kt.point("goal", 0.6) - [0.0, 0.0, low]
    _, opening = compartment_entry(kt, 0.6)
    look = look_into_compartment(obj, RigidTransform(), 0.6, goal, front_normal(kt, 0.6), opening)
    t, H = obj.params["panel_thickness"], obj.params["height"]
    assert look.floor == pytest.approx(kt.point("goal", 0.6)[2], abs=0.002)
    assert look.ceiling == pytest.approx(t + (H - 2 * t) / 2 - t / 2, abs=0.005)
