"""The place planner, from ground-truth keypoint trajectories and keypoint-derived obstacles."""

from dataclasses import replace

import numpy as np
import pytest
from pydrake.math import RigidTransform

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.compartment import (
    InteriorLook,
    carcass_half_width,
    closet_half_width,
    compartment_entry,
    compartment_obstacles,
    door_width,
    drawer_half_width,
    front_normal,
)
from nfr_drake.planning.place import (
    PLACE_REACH,
    PlaceConfig,
    PlaceUnreachable,
    fallback_configs,
    place_bases,
    place_problem,
    place_reach_points,
    plan_place,
    ready_posture,
)
from nfr_drake.planning.planner import PlannerConfig, plan_articulation
from nfr_drake.planning.scene import build_planning_scene
from nfr_drake.systems.place_task import ITEM_REACH, table_beside
from nfr_drake.world.cloud import SemanticCloud
from nfr_drake.world.items import Item, sample_item
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.obstacles import distance_to_box
from nfr_drake.world.plan import ObstacleBox
from nfr_drake.world.robot import FINGER_OPEN


@pytest.mark.parametrize("category,seed,q_target,reach", [
    pytest.param("closet", 0, 0.6, 0.7, marks=pytest.mark.slow),
    ("drawer", 3, 1.0, PLACE_REACH["drawer"][1])])
def test_place_plan_ends_at_the_goal(category, seed, q_target, reach):
    """The planned item, where the hand lets go, stands upright within 3 cm of the goal keypoint
    (kinematically: the tool's pose at the end of the carry times the grasp), and every segment
    starts where the last one ended; from the opening's base (a closet's too, within 0.7 m)."""
    obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, seed, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    item = sample_item(np.random.default_rng(seed))
    opening = plan_articulation(kt, q_target, config=PlannerConfig(place_reach=reach),
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


def _open_closet(q_target=0.6):
    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 0, 0))
    return KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)


def _crosses(box, a, b, clearance=0.0):
    """Whether the segment a-b (m, in W) passes within `clearance` of `box`."""
    points = a + np.linspace(0.0, 1.0, 200)[:, None] * (b - a)
    return distance_to_box(box, points).min() < clearance + 1e-9


def test_bases_in_front_of_an_open_closet_see_past_its_door():
    """Every re-placed base clears the closet and its open door, faces the goal, and its sight
    line to the front does not cross the door; a base straight out of the front on the door's side
    (behind the open door) is never offered, one turned to the door's free edge is."""
    kt = _open_closet()
    fixed, moving = compartment_obstacles(kt, 0.6)
    boxes = [*fixed, *moving]
    bases = place_bases(kt, 0.6, boxes)
    assert bases
    goal = kt.point("goal", 0.6)
    n = front_normal(kt, 0.6)
    hinge_side = np.sign((kt.point("hinge_bottom", 0.0) - goal) @ np.cross([0, 0, 1], n))
    for X_WB in bases:
        p = X_WB.translation()
        assert min(distance_to_box(b, p[None]).min() for b in boxes) >= 0.25
        facing = X_WB.rotation().col(0)
        assert facing @ (goal - p) / np.linalg.norm((goal - p)[:2]) > 0.99
        entry, opening = compartment_entry(kt, 0.6, p)
        pre = goal - (opening + 0.1) * entry
        start = p * [1, 1, 0] + [0, 0, pre[2] + 0.2]
        assert not any(_crosses(b, start, start + 0.8 * (pre - start)) for b in moving)
    lateral = [(X.translation() - goal) @ np.cross([0, 0, 1], n) for X in bases]
    assert max(np.sign(lat) == -hinge_side and abs(lat) > 0.2 for lat in lateral)


def test_a_closets_way_in_turns_toward_the_base_within_its_sides():
    """Straight in without a base; toward a base turned 40 degrees, the way in turns toward it but
    the line stays 13 cm inside the sides at the front plane; its depth grows as 1 / cos."""
    kt = _open_closet()
    straight, opening = compartment_entry(kt, 0.6)
    n = front_normal(kt, 0.6)
    np.testing.assert_allclose(straight, -n, atol=1e-9)
    goal = kt.point("goal", 0.6)
    lat = np.cross([0, 0, 1], n)
    half = abs((kt.point("hinge_bottom", 0.0) - goal) @ lat)
    for degrees in (10.0, 40.0, 80.0):
        a = np.radians(degrees)
        entry, depth = compartment_entry(kt, 0.6, goal + 0.8 * (np.cos(a) * n + np.sin(a) * lat))
        turned = np.arctan2(-entry @ lat, -entry @ n)
        assert 0.0 < turned <= a + 1e-9
        assert depth * np.sin(turned) <= half - 0.13 + 1e-9
        np.testing.assert_allclose(depth, opening / np.cos(turned), rtol=1e-9)
    assert np.degrees(turned) < 80.0  # the widest turn is held


def test_the_table_is_not_set_behind_an_obstacle():
    """A wall on the robot's left, between it and the first bearing tried: the table goes where
    the arm sees it, and the line from above the base to the item clears the wall."""
    X_WB = RigidTransform()
    wall = ObstacleBox("wall", np.array([0.6, 0.02, 1.0]), RigidTransform([0.05, 0.25, 0.5]))
    table, X_WI = table_beside(X_WB, [wall], ITEM_REACH["side"])
    assert not _crosses(wall, np.array([0.0, 0.0, 0.55]), X_WI.translation(), 0.06)
    assert X_WI.translation()[1] < 0.0


def test_a_carried_item_goes_over_a_low_carcass_on_its_way_not_a_tall_one():
    """`_over`: a line from the table to the front that crosses a low closet's top is lifted 5 cm
    over it; one that passes 0.3 m beside it, or crosses a carcass taller than the lift allows,
    is not (the trajectory goes round)."""
    from nfr_drake.planning.place import _OVER_CLEARANCE, _over

    low = ObstacleBox("top", np.array([0.5, 0.6, 0.02]), RigidTransform([0.0, 0.0, 0.52]))
    a, b = np.array([-0.1, -0.9, 0.43]), np.array([0.1, 0.5, 0.04])
    assert _over([low], a, b, RigidTransform()) == pytest.approx(0.53 + _OVER_CLEARANCE)
    assert _over([low], a + [0.6, 0, 0], b + [0.6, 0, 0], RigidTransform()) == -np.inf
    tall = ObstacleBox("side", np.array([0.5, 0.02, 0.9]), RigidTransform([0.0, 0.0, 0.45]))
    assert _over([tall], a, b, RigidTransform()) == -np.inf


def _short_closet_with_shelves(shelves: int):
    """A 0.40 m closet (the lowest there are) with `shelves` shelves (the first such seed)."""
    from nfr_drake.objects.closet import ClosetRanges, sample_closet

    for seed in range(50):
        obj = sample_closet(np.random.default_rng(seed), ClosetRanges(height=(0.40, 0.40)))
        if obj.params["shelves"] == shelves:
            return obj
    raise AssertionError("no such closet in 50 seeds")


def test_a_measured_free_height_replaces_the_assumed_lowest_shelf():
    """Keypoint-derived boxes: without a look inside, the lowest shelf a 0.40 m closet can have,
    11-12 cm over its floor (a third of the way up, less half a panel), the floor at the goal;
    with one, the shelf's underside and the floor's top where the look saw them, and no shelf
    where the ceiling is the top."""
    from nfr_drake.planning.place import free_height

    kt = KeypointTrajectory.from_articulated_object(_short_closet_with_shelves(0), RigidTransform(), 0.0)
    goal = kt.point("goal", 0.6)
    assumed = free_height(compartment_obstacles(kt, 0.6)[0], goal)
    assert 0.10 < assumed < 0.14
    bottom = {b.name: b for b in compartment_obstacles(kt, 0.6)[0]}["compartment_bottom"]
    assert bottom.top == pytest.approx(goal[2])
    fixed, _ = compartment_obstacles(kt, 0.6, InteriorLook(goal[2] + 0.012, goal[2] + 0.25))
    assert free_height(fixed, goal + [0.0, 0.0, 0.012]) == pytest.approx(0.238, abs=0.006)
    assert {b.name: b for b in fixed}["compartment_bottom"].top == pytest.approx(goal[2] + 0.012)
    fixed, _ = compartment_obstacles(kt, 0.6, InteriorLook(None, goal[2] + 1.0))
    assert {b.name: b for b in fixed}["compartment_bottom"].top == pytest.approx(goal[2])
    assert not [b for b in fixed if "shelf" in b.name]
    assert free_height(fixed, goal) > 0.35  # the top panel


def test_a_side_held_item_under_a_low_shelf_is_refused_in_one_line():
    """Two shelves in a 0.40 m closet leave about 12 cm over the floor: less than the wrist needs
    with its clearances (12.6 cm), whatever the item; refused before any IK, naming both heights."""
    from nfr_drake.planning.place import free_height, side_room_needed
    from nfr_drake.planning.planner import PlanningError
    from nfr_drake.systems.place_task import true_compartment

    obj = _short_closet_with_shelves(2)
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    obstacles = true_compartment(obj, RigidTransform(), 0.6)
    item = Item("can", 0.05, 0.05, 0.08, 0.2)
    assert free_height(obstacles[0], kt.point("goal", 0.6)) < side_room_needed(item, PlaceConfig())
    X_WB = place_bases(kt, 0.6, [*obstacles[0], *obstacles[1]])[0]
    table, X_WI = table_beside(X_WB, [*obstacles[0], *obstacles[1]], ITEM_REACH["side"])
    problem = place_problem(kt, 0.6, item, X_WI, table, obstacles, toward=X_WB.translation())
    with pytest.raises(PlaceUnreachable, match=r"cm free over the goal: a side-held item needs 12\.6 cm"):
        plan_place(X_WB, np.zeros(9), problem)
    assert issubclass(PlaceUnreachable, PlanningError)


def _place_in_true_closet(index: int, q_door: float, cfg: PlaceConfig):
    """The place planned in closet `index` of capture seed 200 with its door at q_door, the
    true compartment as obstacles, from the first base in front that plans: (plan, item)."""
    from nfr_drake.systems.place_task import _place_in_front, door_band, true_compartment
    from nfr_drake.systems.scenario import Scenario

    scenario = Scenario(category="closet", seed=200, index=index, q_target=0.6)
    obj, _ = scenario.sample_piece()
    item = scenario.sample_item()
    kt = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, 0.0)
    obstacles = door_band(lambda q: true_compartment(obj, scenario.X_WO, q), q_door)
    plan, _ = _place_in_front(kt, q_door, item, obstacles, cfg)
    return plan, item


def _tool_poses(plan, piece, count: int = 200) -> list[RigidTransform]:
    """The tool's poses in W at `count` times along one piece of `plan`."""
    scene = build_planning_scene(plan.X_WB, [])
    poses = []
    for t in np.linspace(0.0, piece.end_time(), count):
        scene.plant.SetPositions(scene.plant_context, piece.value(t).ravel())
        poses.append(scene.tool_frame.CalcPoseInWorld(scene.plant_context))
    return poses


@pytest.mark.slow
def test_the_item_is_released_level_and_the_fingers_back_straight_off_it():
    """Closet 3 of capture seed 200 (true compartment, door at 0.6): the item leaves the hand
    within `release_upright_deg` of upright (the carry allows 12 degrees), and the retreat's first
    piece keeps the release point on the tool's axis and the tool's orientation while the fingers
    back off it, until their tips (1 cm past the tool) clear the item's near side. Between the
    piece's collision samples, where `back_off_tolerance` is not imposed, the release point stays
    off the axis by less than the open fingers' clearance of the item on either side."""
    cfg = PlaceConfig()
    plan, item = _place_in_true_closet(3, 0.6, cfg)
    tilt = np.degrees(np.arccos(plan.X_WI_place.rotation().col(2) @ [0, 0, 1]))
    assert tilt < cfg.release_upright_deg + 0.1
    X_WG = plan.X_WI_place @ plan.X_GI.inverse()
    a, p_release = X_WG.rotation().col(2), X_WG.translation()
    backed = []
    for X in _tool_poses(plan, plan.segments[2].pieces[0]):
        d = p_release - X.translation()
        assert np.linalg.norm(d - (d @ a) * a) < FINGER_OPEN - item.width / 2
        turn = X.rotation().InvertAndCompose(X_WG.rotation()).ToAngleAxis().angle()
        assert np.degrees(turn) < cfg.back_off_turn_deg + 0.5
        backed.append(d @ a)
    assert backed[-1] > item.depth / 2 + 0.01 + cfg.back_off_clearance - 0.005


def test_the_fallback_configs_give_up_the_back_off_then_the_level_release_then_try_more_seeds():
    cfg = PlaceConfig()
    configs = fallback_configs(cfg)
    first = [(True, cfg.release_upright_deg), (False, cfg.release_upright_deg),
             (False, cfg.upright_tolerance_deg)]
    assert [(c.back_off, c.release_upright_deg) for c in configs] == first * 3
    assert [c.ik_seeds for c in configs] == [cfg.ik_seeds] * 3 + [cfg.retry_ik_seeds] * 6
    assert [c.deep_seeds for c in configs] == [0] * 6 + [cfg.retry_deep_seeds] * 3
    assert all(replace(c, back_off=True, release_upright_deg=cfg.release_upright_deg,
                       ik_seeds=cfg.ik_seeds, deep_seeds=0) == cfg for c in configs)
    assert fallback_configs(configs[-1]) == [configs[-1]]
    assert len(fallback_configs(replace(cfg, retry_ik_seeds=cfg.ik_seeds, retry_deep_seeds=0))) == 3


def test_a_low_compartments_goal_is_reached_from_the_place_out():
    """Closet 74 of capture seed 200 (true compartment, door at 0.6: the goal 18.8 cm behind the
    front, 18 cm under the shelf), from one base in front of it: solved from the place out
    (`PlaceConfig.deep_seeds`) the carry's knots plan, the item released within 1 cm of the goal
    and the arm on one branch along the way in (no joint turns more than 1 rad on any of its
    straight pieces: the chains solved from the place out but not held to its branch jumped 2.5
    rad in joint 1 from one knot to the next). Whether the knots solved in turn from the pick also
    plan here depends on the solver's numerics (none did with the environment of 2026-12-06, one
    does with that of 2026-12-07), so it is not asserted."""
    from nfr_drake.systems.place_task import true_compartment
    from nfr_drake.systems.scenario import Scenario

    scenario = Scenario(category="closet", seed=200, index=74, q_target=0.6)
    obj, _ = scenario.sample_piece()
    item = scenario.sample_item()
    kt = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, 0.0)
    fixed, moving = true_compartment(obj, scenario.X_WO, 0.6)
    X_WB = place_bases(kt, 0.6, [*fixed, *moving])[6]
    table, X_WI = table_beside(X_WB, [*fixed, *moving], ITEM_REACH["side"])
    problem = place_problem(kt, 0.6, item, X_WI, table, (fixed, moving), toward=X_WB.translation())
    q0 = ready_posture(X_WB, X_WI.translation())
    plan = plan_place(X_WB, q0, problem, PlaceConfig(deep_seeds=150))
    assert plan.place_error() < 0.01
    carry = plan.segments[1]
    for piece in carry.pieces[-3:]:  # entering 1, entering 2, place
        q = np.array([piece.value(t).ravel() for t in np.linspace(0.0, piece.end_time(), 50)])
        assert np.ptp(q[:, :7], axis=0).max() < 1.0


@pytest.mark.slow
def test_where_no_base_backs_off_the_item_the_retreat_is_free():
    """Closet 3 of capture seed 200 (true compartment, door at 0.6) with a back-off no arm can
    make (2 m behind the release): no base plans it, and the place is planned with the free
    retreat (`fallback_configs`), its first piece out along the way in."""
    plan, _ = _place_in_true_closet(3, 0.6, PlaceConfig(back_off_clearance=2.0))
    retreat = plan.segments[2]
    assert retreat.name == "retreat" and len(retreat.pieces) == 2
    p_first = _tool_poses(plan, retreat.pieces[0])[-1].translation()
    X_WG = plan.X_WI_place @ plan.X_GI.inverse()
    assert np.linalg.norm(p_first - X_WG.translation()) > 0.1  # half the way in, not a 2 m back-off


@pytest.mark.slow
@pytest.mark.parametrize("index,q_door", [(2, 0.6), (10, 0.5925)])
def test_the_pick_comes_in_straight_and_stops_at_the_item(index, q_door):
    """Closets of capture seed 200, the door at q_door, the place from the first base in front that
    plans: the tool's path from the pre-pick to the pick stays within 1.5 cm of the line between
    them and never passes the pick by more than 7 mm. Closet 2: without `_straight_in` it swung
    9.5 cm off the line, and on the measured door it overshot 12 cm and nudged the item off its
    hold. Closet 10, the door where its opening by contact leaves it: the pick's IK lay on another
    branch of the arm than the pre-pick's (joint 1 at 0.23 against 2.47 rad), no straight piece
    joins them, and no base planned until the pre-pick is re-solved from the pick's posture."""
    plan, _ = _place_in_true_closet(index, q_door, PlaceConfig())
    X_WG = plan.X_WI_pick @ plan.X_GI.inverse()
    a, p_pick = X_WG.rotation().col(2), X_WG.translation()
    for X in _tool_poses(plan, plan.segments[0].pieces[-1]):
        d = X.translation() - p_pick
        assert np.linalg.norm(d - (d @ a) * a) < 0.015
        assert d @ a < 0.007


@pytest.mark.slow
def test_a_carried_item_keeps_its_clearance_between_collision_samples():
    """Closet 11 of capture seed 200 (0.83 m tall, no shelf), true keypoints, contact grasp: the
    carry swept the held mug's handle 4 mm from the closet's side wall between collision samples,
    and in simulation the wall knocked the mug out of the fingers (it ended 26 cm from the goal).
    Checked densely, the carry now clears the carcass by at least half the planner's 1 cm
    (`_optimise_piece` samples again where it does not), and the mug is placed."""
    from nfr_drake.systems.articulation import SimulationConfig
    from nfr_drake.systems.place_task import PlaceSimulationConfig, run_place_task, true_compartment
    from nfr_drake.systems.scenario import Scenario

    scenario = Scenario(category="closet", seed=200, index=11, q_target=0.6)
    obj, _ = scenario.sample_piece()
    item = scenario.sample_item()
    outcome = run_place_task(obj, scenario.X_WO, 0.0, 0.6, item, simulation_config=PlaceSimulationConfig(
        opening=SimulationConfig(grasp="contact")))
    assert outcome.success, outcome.planning_error or outcome.simulation.summary()
    plan = outcome.place
    carcass, _ = true_compartment(obj, scenario.X_WO, outcome.simulation.q_final)
    scene = build_planning_scene(plan.X_WB, carcass, (item, plan.X_GI))
    query_port = scene.plant.get_geometry_query_input_port()
    closest = np.inf
    for piece in plan.segments[1].pieces[1:]:  # off the table: the carry to the place
        for t in np.linspace(0.0, piece.end_time(), 300):
            scene.plant.SetPositions(scene.plant_context, piece.value(t).ravel())
            query = query_port.Eval(scene.plant_context)
            held = [p.distance for p in query.ComputeSignedDistancePairwiseClosestPoints(0.02)
                    if any("held" in query.inspector().GetName(g) for g in (p.id_A, p.id_B))]
            closest = min([closest, *held])
    assert closest >= 0.5 * PlaceConfig().min_distance - 1e-4


@pytest.mark.parametrize("program,failure", [("trajectory", "collision query error in the solver"),
                                              ("IK", "IK of backing off the handle")])
def test_a_collision_query_error_in_the_solver_fails_the_plan_in_one_line(monkeypatch, program, failure):
    """FCL's distance query can raise inside SNOPT on a degenerate pair of capsules (drawer 25 of
    capture seed 201 in a trajectory, closet 18 of capture seed 200 in an IK, each stopped an
    evaluation with a traceback): the piece or the knot fails, the plan raises a PlanningError
    naming it."""
    import nfr_drake.planning.place as place_module
    from nfr_drake.planning.planner import PlanningError

    real = place_module.SnoptSolver

    class Failing(real):
        def Solve(self, prog, *args):
            if (prog.num_vars() > 50) == (program == "trajectory"):  # a trajectory's program has more
                raise RuntimeError("Exception while evaluating SNOPT costs and constraints: 'Error with "
                                   "configuration\n  Original error message: ...'")
            return super().Solve(prog, *args)

    monkeypatch.setattr(place_module, "SnoptSolver", Failing)
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    item = sample_item(np.random.default_rng(3))
    opening = plan_articulation(kt, 1.0, config=PlannerConfig(place_reach=PLACE_REACH["drawer"][1]),
                                must_reach=place_reach_points(kt, 1.0, item))
    fixed, moving = compartment_obstacles(kt, 1.0)
    table, X_WI = table_beside(opening.X_WB, [*fixed, *moving], ITEM_REACH["top"])
    with pytest.raises(PlanningError, match=failure):
        plan_place(opening.X_WB, opening.trajectory.value(opening.duration).ravel(),
                   place_problem(kt, 1.0, item, X_WI, table), handle=opening.waypoints[-1])


def test_a_drawers_walls_take_the_width_the_fitted_points_give():
    """A drawer's front seen as the field's points (a 0.6 m wide panel, two stray points 1 m out,
    the carcass's points wider still): its half width is the front's to within a centimetre; the
    walls reach from the box's inside, 4.5 cm in, to a wall's thickness past the front's edge, the
    front across it all; without points, the narrowest box's walls; under 20 points, none."""
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    goal, handle = kt.point("goal", 0.0), kt.point("handle", 0.0)
    rng = np.random.default_rng(0)
    front = np.c_[np.full(1000, handle[0]), goal[1] + rng.uniform(-0.3, 0.3, 1000),
                  rng.uniform(0.02, 0.2, 1000)]
    stray = np.array([[handle[0], goal[1] + 1.0, 0.1], [handle[0], goal[1] - 1.0, 0.1]])
    carcass = np.c_[np.full(200, handle[0] - 0.02), goal[1] + rng.uniform(-0.5, 0.5, 200), np.full(200, 0.1)]
    cloud = SemanticCloud(np.r_[front, stray, carcass], np.r_[np.full(1002, 2), np.ones(200, int)], 0.0)
    half = drawer_half_width(kt, cloud)
    assert 0.29 <= half <= 0.30
    _, moving = compartment_obstacles(kt, 1.0, cloud=cloud)
    walls = {b.name: b for b in moving}
    for side in ("drawer_side_a", "drawer_side_b"):
        centre = abs(walls[side].X_WB.translation()[1] - goal[1])
        width = walls[side].size[1]
        assert centre - width / 2 == pytest.approx(half - 0.045)
        assert centre + width / 2 == pytest.approx(half + 0.02)
    assert walls["drawer_front"].size[1] == pytest.approx(2 * half + 0.04)
    _, narrow = compartment_obstacles(kt, 1.0)
    assert max(b.size[1] for b in narrow) == pytest.approx(2 * 0.165)
    few = SemanticCloud(front[:19], np.full(19, 2), 0.0)
    assert drawer_half_width(kt, few) is None
    assert [b.size[1] for b in compartment_obstacles(kt, 1.0, cloud=few)[1]] == [b.size[1] for b in narrow]


def test_a_closet_doors_box_takes_the_width_the_fitted_points_give():
    """A shut door seen as the field's points from its hinge line to its free edge: its width is
    the door's within 1.5 cm, and the open door's box reaches 3 cm past it, where from the handle
    alone it reaches 5 cm past the handle."""
    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 0, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    hinge, handle = kt.point("hinge_bottom", 0.0), kt.point("handle", 0.0)
    across = (handle - hinge) * [1.0, 1.0, 0.0]
    reach = np.linalg.norm(across)
    door = reach + obj.params["handle_edge_offset"]
    rng = np.random.default_rng(0)
    points = hinge + np.outer(rng.uniform(0.0, door, 2000), across / reach) + np.outer(
        rng.uniform(0.0, 0.8, 2000), [0.0, 0.0, 1.0])
    cloud = SemanticCloud(points, np.full(2000, 2), 0.0)
    width = door_width(kt, cloud)
    assert width == pytest.approx(door, abs=0.015)
    boxes = {b.name: b for b in compartment_obstacles(kt, 0.6, cloud=cloud)[1]}
    assert boxes["open_door"].size[1] == pytest.approx(width + 0.03)
    from_handle = {b.name: b for b in compartment_obstacles(kt, 0.6)[1]}
    assert from_handle["open_door"].size[1] == pytest.approx(reach + 0.05, abs=0.01)


def test_a_closets_sides_stand_where_the_carcass_points_reach_if_they_reach_further():
    """Carcass points spread evenly out to 3 cm past the keypoints' half width either side (the
    hinge line's distance from the goal): the carcass's side walls stand at the points' half
    width (their 0.98 quantile, 0.96 of that reach); points that end 2 cm short of it leave the
    walls where the keypoints put them."""
    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 0, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    half = closet_half_width(kt, 0.6)
    goal = kt.point("goal", 0.6)
    lateral = np.cross([0.0, 0.0, 1.0], front_normal(kt, 0.6))
    rng = np.random.default_rng(0)

    def cloud(reach: float) -> SemanticCloud:
        points = goal + np.outer(rng.uniform(-reach, reach, 1000), lateral) + np.outer(
            rng.uniform(0.0, 0.5, 1000), [0.0, 0.0, 1.0])
        return SemanticCloud(points, np.ones(1000, int), 0.0)

    def sides(c: SemanticCloud | None) -> list[float]:
        """The side walls' centres' lateral distances from the goal, m."""
        fixed, _ = compartment_obstacles(kt, 0.6, cloud=c)
        walls = [b for b in fixed if b.name.startswith("compartment_side")]
        return [abs((b.X_WB.translation() - goal) @ lateral) for b in walls]

    wide = cloud(half + 0.03)
    seen = carcass_half_width(kt, wide, 0.6)
    assert seen == pytest.approx(0.96 * (half + 0.03), abs=0.005) and seen > half + 0.01
    assert len(sides(None)) == 2
    assert np.subtract(sides(wide), sides(None)) == pytest.approx([seen - half] * 2, abs=1e-9)
    assert sides(cloud(half - 0.02)) == pytest.approx(sides(None), abs=1e-12)
    assert carcass_half_width(kt, SemanticCloud(wide.points[:19], np.ones(19, int), 0.0), 0.6) is None


def test_a_closets_tops_reach_as_high_as_the_fitted_points_where_they_reach_higher():
    """Points of the door and of the carcass (their upper 5 cm) up to 4 and 3 cm over the
    keypoints' hinge_top: the open door's box and the carcass's top panel reach 2 cm over the
    points' top (the panel's underside stays a wall under hinge_top); points that end lower leave
    the boxes at hinge_top."""
    obj = sample_object("closet", object_rng(SEED_DOMAIN_TRAIN, 0, 0))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    hinge_top = kt.point("hinge_top", 0.0)[2]
    rng = np.random.default_rng(0)

    def cloud(door_above: float, carcass_above: float) -> SemanticCloud:
        door = kt.point("hinge_bottom", 0.0) + np.outer(rng.uniform(0.05, 0.3, 500), [0.0, -1.0, 0.0])
        door[:, 2] = hinge_top + door_above - rng.uniform(0.0, 0.05, 500)
        carcass = np.column_stack([rng.uniform(-0.1, 0.1, 500), rng.uniform(-0.2, 0.2, 500),
                                   hinge_top + carcass_above - rng.uniform(0.0, 0.05, 500)])
        return SemanticCloud(np.vstack([door, carcass]), np.r_[np.full(500, 2), np.full(500, 1)], 0.0)

    fixed, moving = compartment_obstacles(kt, 0.6, cloud=cloud(0.04, 0.03))
    top_panel = {b.name: b for b in fixed}["compartment_top"]
    assert moving[0].top == pytest.approx(hinge_top + 0.04 + 0.02, abs=0.006)
    assert top_panel.top == pytest.approx(hinge_top + 0.03 + 0.02, abs=0.006)
    assert top_panel.top - top_panel.size[2] == pytest.approx(hinge_top - 0.02)
    plain_fixed, plain_moving = compartment_obstacles(kt, 0.6)
    low_fixed, low_moving = compartment_obstacles(kt, 0.6, cloud=cloud(-0.1, -0.1))
    assert low_moving[0].top == pytest.approx(plain_moving[0].top)
    assert plain_moving[0].top == pytest.approx(hinge_top, abs=1e-6)
    assert [b.top for b in low_fixed] == pytest.approx([b.top for b in plain_fixed])
