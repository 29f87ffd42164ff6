"""The furniture fit: z of a model with several slots from a capture set, with and without sighted
handles, and forward simulation of one part with the others held."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from pydrake.math import RotationMatrix

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS, slot_trajectory
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import observed_rays
from nfr_drake.inference.furniture_fit import (
    COMPARTMENT_MIDDLE_X,
    MAX_TRAVEL_M,
    FurnitureFitConfig,
    HandleTerm,
    depth_travel,
    drawer_goal,
    fit_furniture,
    handle_shift,
    pair_hinges,
    part_trajectory,
    parts_json,
    place_fronts,
    sighting_order,
    slot_path,
)
from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.model import NFRModel
from nfr_drake.objects import sample_object
from nfr_drake.objects.fronts import TRAVEL_FRACTION
from nfr_drake.perception.front_reading import SightedFront, handle_offset

S = 8
TINY = NFRModelConfig(latent_obj_dim=4, hyper_hidden=8, field_width=8, field_layers=2,
                      feature_dim=8, pe_frequencies=1, march_steps=3, lstm_hidden=4,
                      pixel_hidden=8, keypoint_hidden=8, num_slots=S, num_keypoints=4 * S,
                      bound_center=(0.35, 0.0, 1.0), bound_radius=1.6)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("furniture_captures")
    captures_command(category="furniture", n=1, out=out, views=2, size=24, seed=3)
    return read_capture_set(out / "furniture_000")


def test_fit_gives_every_slot_and_moves_z(capture):
    torch.manual_seed(0)
    model = NFRModel(TINY).eval().requires_grad_(False)
    codes = torch.randn(5, TINY.latent_obj_dim) * 0.1
    config = FurnitureFitConfig(starts=3, keep=2, steps=5, rays_per_step=64, lookup_rays=64)
    fit = fit_furniture(model, observed_rays(capture), codes, config)
    assert fit.z.shape == (TINY.latent_dim,) and fit.q.shape == (S,)
    assert fit.exists.shape == (S,) and fit.keypoints.shape == (S, 4, 3)
    assert ((fit.q >= 0) & (fit.q <= 1)).all() and np.isfinite(fit.image_loss)
    assert not any(torch.allclose(fit.z[2 * S:], c) for c in codes), "z_obj did not move"
    fit.exists[:] = [True, False, True] + [False] * (S - 3)
    parts = parts_json(model, fit, np.linspace(0, 1, 5))
    assert [p["index"] for p in parts] == [0, 2]
    assert set(parts[0]) == {"index", "type", "q", "keypoints", "trajectory"}
    assert parts[0]["type"] in PART_TYPES and list(parts[0]["keypoints"]) == list(SLOT_KEYPOINTS)
    assert np.asarray(parts[1]["trajectory"]["keypoints"]["handle"]).shape == (5, 3)


def test_fitted_keypoints_lie_on_each_slots_swept_path(capture):
    """Every slot's z_art ends on the upper half circle, so its keypoints at the fitted code are
    its path's at the q reported (a slot left on the lower half was drawn 4 cm off its path)."""
    torch.manual_seed(3)
    model = NFRModel(TINY).eval().requires_grad_(False)
    codes = torch.randn(5, TINY.latent_obj_dim) * 0.1
    config = FurnitureFitConfig(starts=3, keep=2, steps=20, rays_per_step=64, lookup_rays=64, lr=0.2)
    fit = fit_furniture(model, observed_rays(capture), codes, config)
    assert (fit.z[1:2 * S:2] >= 0).all()
    for k in range(S):
        np.testing.assert_allclose(part_trajectory(model, fit.z, k, fit.q[k:k + 1])[0], fit.keypoints[k],
                                   atol=1e-5)


def test_a_drawer_slot_slides_straight_along_x_by_the_heads_travel(capture):
    """A slot typed drawer: handle and goal move along +x of O only, through where the fit put
    them at its q, by the fit's travel (a paired slot's from the depth its handle implies, an
    unpaired one's the head's x travel over [0, 1]); a door slot turns about its hinge points
    (`slot_trajectory`) from there."""
    torch.manual_seed(0)
    model = NFRModel(TINY).eval().requires_grad_(False)
    codes = torch.randn(5, TINY.latent_obj_dim) * 0.1
    config = FurnitureFitConfig(starts=3, keep=2, steps=3, rays_per_step=64, lookup_rays=64)
    fit = fit_furniture(model, observed_rays(capture), codes, config, np.array([[0.6, -0.3, 0.9]]))
    grid = np.linspace(0, 1, 5)
    h, g = SLOT_KEYPOINTS.index("handle"), SLOT_KEYPOINTS.index("goal")
    fit.types[:2] = [PART_TYPES.index("drawer"), PART_TYPES.index("door")]
    travel = depth_travel(0.6, fit.q[0], config.travel_depth_share, config.handle_standoff_m)
    assert fit.travel[0] == pytest.approx(travel)
    for k in range(1, len(fit.travel)):
        ends = part_trajectory(model, fit.z, k, np.array([0.0, 1.0]))[:, h]
        head = ends[1, 0] - ends[0, 0] if ends[1, 0] > ends[0, 0] else np.linalg.norm(ends[1] - ends[0])
        assert fit.travel[k] == pytest.approx(head)
    path = slot_path(model, fit, 0, grid)
    for i in (h, g):
        np.testing.assert_allclose(path[:, i, 1:], np.repeat(fit.keypoints[0, i, 1:][None], 5, 0))
        np.testing.assert_allclose(path[:, i, 0], fit.keypoints[0, i, 0] + (grid - fit.q[0]) * travel)
    assert travel > 0.0
    np.testing.assert_allclose(slot_path(model, fit, 1, grid),
                               slot_trajectory("door", fit.keypoints[1], fit.q[1], grid))


def test_part_trajectory_sweeps_one_slot_and_holds_the_others():
    torch.manual_seed(1)
    model = NFRModel(TINY).eval()
    z = torch.randn(TINY.latent_dim)
    grid = np.linspace(0, 1, 4)
    path = part_trajectory(model, z, 3, grid)
    assert path.shape == (4, 4, 3)
    # The same as the head on codes whose slot 3 alone is set to each q.
    for i, q in enumerate(grid):
        code = z.clone()
        code[6:8] = torch.tensor([np.cos(np.pi * q), np.sin(np.pi * q)])
        np.testing.assert_allclose(path[i], model.keypoints(code[None])[0, 12:16].detach().numpy(),
                                   atol=1e-6)


def test_fit_refuses_a_one_slot_model(capture):
    model = NFRModel(replace(TINY, num_slots=1, num_keypoints=4))
    with pytest.raises(ConfigError, match="several articulation slots"):
        fit_furniture(model, observed_rays(capture), torch.zeros(2, 4))


def test_handle_term_matches_sightings_to_slots_in_any_order():
    """The handle term is 0 when the sightings are the head's first M slot handles in any order,
    grows as they move away, and is 0 without sightings or weight."""
    torch.manual_seed(2)
    model = NFRModel(TINY).eval().requires_grad_(False)
    z = torch.randn(3, TINY.latent_dim)
    slots = model.keypoints(z).view(3, S, 4, 3)[:, :, SLOT_KEYPOINTS.index("handle")]
    sighted = slots[1, [2, 0, 1]].numpy()  # code 1's slots 0-2, shuffled
    term = HandleTerm(model, sighted, 2e-3, 0.015)
    values = term(z)
    assert values.shape == (3,) and float(values[1]) < 1e-9 and (values[[0, 2]] > 0).all()
    assert float(HandleTerm(model, sighted + 0.1, 2e-3, 0.015)(z[1:2])[0]) > 0
    assert (HandleTerm(model, np.zeros((0, 3)), 2e-3, 0.015)(z) == 0).all()
    assert (HandleTerm(model, sighted, 0.0, 0.015)(z) == 0).all()


def test_sighted_handles_give_the_part_count(capture):
    """With M sighted handles the fit says slots 0..M-1 exist (slot k is front k), whatever the
    head's logits; without, or with `count_from_handles` off, the head's logits decide."""
    torch.manual_seed(0)
    model = NFRModel(TINY).eval().requires_grad_(False)
    codes = torch.randn(5, TINY.latent_obj_dim) * 0.1
    config = FurnitureFitConfig(starts=3, keep=2, steps=3, rays_per_step=64, lookup_rays=64)
    handles = np.array([[0.6, -0.3, 0.9], [0.6, 0.3, 0.9], [0.6, 0.0, 0.4]])
    fit = fit_furniture(model, observed_rays(capture), codes, config, handles)
    assert fit.exists.tolist() == [True] * 3 + [False] * (S - 3)
    np.testing.assert_allclose(fit.handles, handles[[0, 2, 1]])  # in the fronts' order: by y
    assert fit.handle_order.tolist() == [0, 2, 1]  # which given handle each slot took
    plain = fit_furniture(model, observed_rays(capture), codes, config)
    off = fit_furniture(model, observed_rays(capture), codes, replace(config, count_from_handles=False),
                        handles)
    logits = model.slot_logits(off.z[None])[0, :, 0] > 0
    assert off.exists.tolist() == logits.tolist() and len(plain.handles) == 0


def test_handle_shift_moves_each_matched_slot_onto_its_sighting():
    """Slots 0..M-1 are matched one to one with the sightings by least squared distance (here
    slot 0 <-> sighting 1, slot 1 <-> sighting 0); the other slots stay."""
    slots = np.array([[0.5, -0.3, 0.9], [0.5, 0.3, 0.9], [0.5, 0.0, 0.3]])
    sighted = np.array([[0.6, 0.25, 1.0], [0.55, -0.2, 0.85]])
    shift = handle_shift(slots, sighted)
    np.testing.assert_allclose((slots + shift)[:2], sighted[[1, 0]])
    np.testing.assert_array_equal(shift[2], 0.0)
    np.testing.assert_array_equal(handle_shift(slots, np.zeros((0, 3))), 0.0)
    in_order = handle_shift(slots, sighted, in_order=True)  # slot k onto sighting k
    np.testing.assert_allclose((slots + in_order)[:2], sighted)
    np.testing.assert_array_equal(in_order[2], 0.0)
    np.testing.assert_array_equal(handle_shift(slots, np.zeros((0, 3)), in_order=True), 0.0)


def test_sighting_order_follows_the_fronts_canonical_order():
    """Columns left to right (y), top to bottom within one, level handles left to right: a
    drawer over a door pair (handles near the pair's middle), then a stack of two drawers."""
    handles = np.array([[0.3, 0.45, 0.3],    # 4: right column, lower drawer
                        [0.3, 0.05, 0.5],    # 2: right door of the pair
                        [0.3, 0.0, 0.8],     # 0: drawer over the pair
                        [0.3, 0.45, 0.6],    # 3: right column, upper drawer
                        [0.3, -0.05, 0.51]])  # 1: left door (level with the right one)
    assert sighting_order(handles, 0.2).tolist() == [2, 4, 1, 3, 0]
    assert sighting_order(handles, 0.0).tolist()[:3] == [4, 2, 1]  # no columns: by y
    assert sighting_order(np.zeros((0, 3)), 0.2).tolist() == []


def test_a_split_cells_right_half_comes_after_its_columns_full_width_fronts():
    """Two drawers side by side over two full-width drawers (a dresser): the right half's left
    edge is the column's middle, so the canonical order is left half, the two full-width drawers,
    right half; level handles without a pull centred between them keep their order (two
    columns' fronts at one height by chance)."""
    handles = np.array([[0.3, 0.16, 0.9],    # 3: right half
                        [0.3, 0.0, 0.45],    # 2: lower full-width drawer
                        [0.3, -0.16, 0.9],   # 0: left half
                        [0.3, 0.0, 0.7]])    # 1: upper full-width drawer
    assert sighting_order(handles, 0.2).tolist() == [2, 3, 1, 0]
    assert sighting_order(handles, 0.2, centred_m=0.0).tolist() == [2, 0, 3, 1]  # the rule off
    off_centre = handles + [[0, 0, 0], [0, 0.1, 0], [0, 0, 0], [0, 0.1, 0]]  # doors' handles
    assert sighting_order(off_centre, 0.2).tolist() == [2, 0, 3, 1]


NO_OFFSET_ODDS = ((), (0.0,))
"""`place_fronts`'s offset odds that weigh nothing."""


def _reading(head_weight: float, pair_odds: tuple[float, float], offset_odds) -> FurnitureFitConfig:
    """A fit config that weighs the head's door margin, a pair and the handle's offset so."""
    return FurnitureFitConfig(head_type_weight=head_weight, pair_type_log_odds=pair_odds,
                              offset_edges=offset_odds[0], offset_type_log_odds=offset_odds[1])


def _face(y0, y1, z0, z1, x=0.3):
    return np.array([[x, y0, z1], [x, y1, z1], [x, y0, z0], [x, y1, z0]], float)


def test_sighting_order_puts_stacked_doors_in_one_column_by_their_read_fronts():
    """Two doors one above the other, the upper one's handle on the right and the lower one's on
    the left: by the handles alone they are two columns (the lower door first); their read fronts
    share both side edges, so they are one column, top to bottom, as the fronts' canonical order
    (a face read as wide as two fronts shares its left edge only, and merges nothing)."""
    handles = np.array([[0.42, -0.33, 0.96],   # lower door, handle on its left
                        [0.42, 0.33, 1.13]])   # upper door, handle on its right
    lower = SightedFront(handles[0], 0.9, _face(-0.4, 0.4, 0.1, 0.9), 5)
    upper = SightedFront(handles[1], 0.9, _face(-0.4, 0.4, 0.92, 1.7), 5)
    assert sighting_order(handles, 0.2).tolist() == [0, 1]
    assert sighting_order(handles, 0.2, fronts=[lower, upper]).tolist() == [1, 0]
    assert sighting_order(handles, 0.2, fronts=[lower, None]).tolist() == [0, 1]  # one not read
    too_wide = SightedFront(handles[1], 0.9, _face(-0.4, 1.2, 0.92, 1.7), 5)  # read with its neighbour
    assert sighting_order(handles, 0.2, fronts=[lower, too_wide]).tolist() == [0, 1]


def test_read_fronts_give_the_types_hinges_and_goals():
    """A read door gets its hinge on its face's edge away from the handle, a read drawer the head
    took for a door a pull line along +x through its handle; a door's goal moves to its face's
    middle (a door of a pair: halfway from its hinge to where the pair meets) and bottom edge at
    the compartment's middle depth, a drawer's from its handle
    (`drawer_goal`: half its box's depth behind its front, under its handle); a slot without a
    read front keeps the head's."""
    drawer = SightedFront(np.array([0.33, 0.0, 0.9]), 0.1, _face(-0.4, 0.4, 0.8, 1.0), 5)
    left_door = SightedFront(np.array([0.33, -0.05, 0.6]), 0.9, _face(-0.4, 0.0, 0.2, 0.78), 5)
    right_door = SightedFront(np.array([0.33, 0.05, 0.6]), 0.9, _face(0.0, 0.4, 0.2, 0.78), 5)
    side = SightedFront(np.array([0.33, 0.6, 0.5]), 0.2, _face(0.45, 0.75, 0.2, 1.0), 5)
    head = np.zeros((4, 4, 3))
    head[:, 0] = [f.p_O for f in (drawer, left_door, right_door, side)]
    head[:, 1] = [0.3, 0.1, 0.7]  # the head's goals, off in every coordinate
    types = np.array([PART_TYPES.index(t) for t in ("door", "door", "drawer", "drawer")])
    q = np.array([0.5, 0.3, 0.3, 0.2])
    read = [drawer, left_door, right_door, None]
    placed, read_types, _ = place_fronts(head, types, q, [0.3] * 4, read, np.zeros(4), np.zeros(4),
                                      _reading(0.1, (0.0, 0.0), NO_OFFSET_ODDS))
    assert [PART_TYPES[t] for t in read_types] == ["drawer", "door", "door", "drawer"]
    np.testing.assert_allclose(placed[0, 2:], [[0.18, 0.0, 0.9], [0.48, 0.0, 0.9]])  # pull line
    np.testing.assert_allclose(placed[1, 2:], _face(-0.4, 0.0, 0.2, 0.78)[[0, 2]])  # hinged left
    np.testing.assert_allclose(placed[2, 2:], _face(0.0, 0.4, 0.2, 0.78)[[1, 3]])  # hinged right
    below = FurnitureFitConfig.drawer_goal_below_handle_m
    box_half = 0.3 / (2 * TRAVEL_FRACTION)  # the travel is the box's TRAVEL_FRACTION
    np.testing.assert_allclose(placed[:3, 1], [[0.33 - 0.04 - box_half, 0.0, 0.9 - below],
                                               [COMPARTMENT_MIDDLE_X, -0.2, 0.2],
                                               [COMPARTMENT_MIDDLE_X, 0.2, 0.2]])  # goals
    np.testing.assert_array_equal(placed[3], head[3])
    # a pair read as one wide face: each door hinges on the edge away from its neighbour
    wide = _face(-0.4, 0.4, 0.2, 0.78)
    pair = [SightedFront(left_door.p_O, 0.9, wide, 5), SightedFront(right_door.p_O, 0.9, wide, 5)]
    placed, _, _ = place_fronts(head[1:3], types[1:3], q[1:3], [0.3] * 2, pair, np.array([1.0, -1.0]),
                             np.zeros(2), _reading(0.1, (0.0, 0.0), NO_OFFSET_ODDS))
    np.testing.assert_allclose(placed[:, 2:], [wide[[0, 2]], wide[[1, 3]]])
    np.testing.assert_allclose(placed[:, 1, 1], [0.0, 0.0])  # the wide face's middle
    # where the pair meets known (halfway between the handles): each goal halfway from its hinge
    placed, _, _ = place_fronts(head[1:3], types[1:3], q[1:3], [0.3] * 2, pair, np.array([1.0, -1.0]),
                                np.zeros(2), _reading(0.1, (0.0, 0.0), NO_OFFSET_ODDS), np.array([0.0, 0.0]))
    np.testing.assert_allclose(placed[:, 1, 1], [-0.2, 0.2])
    unpaired, _, _ = place_fronts(head[1:3], types[1:3], q[1:3], [0.3] * 2, pair, np.zeros(2), np.zeros(2),
                               _reading(0.1, (0.0, 0.0), NO_OFFSET_ODDS))
    np.testing.assert_allclose(unpaired[:, 2:], [wide[[1, 3]], wide[[0, 2]]])  # the wrong sides


def test_a_drawers_goal_from_its_handle_matches_the_generators_drawers():
    """`drawer_goal` from a generated drawer's true handle and travel lands on its true goal: in x
    within 3 cm (the handle's standoff varies with the handle), in y under the handle, in z within
    the spread of how far the box floor lies under the pull; at any opening, as the drawer moves
    its goal with it."""
    rng = np.random.default_rng(3)
    drawers = [f for _ in range(30) for f in sample_object("furniture", rng).fronts if f.kind == "drawer"]
    assert len(drawers) > 20
    config = FurnitureFitConfig()
    for front in drawers:
        for q in (0.0, 0.6):
            kp = front.keypoints(q)
            goal = drawer_goal(np.asarray(kp["handle"]), front.joint_upper, config.handle_standoff_m,
                               config.drawer_goal_below_handle_m)
            assert abs(goal[0] - kp["goal"][0]) < 0.03
            assert goal[1] == pytest.approx(kp["goal"][1], abs=0.01)
            assert abs(goal[2] - kp["goal"][2]) < 0.1


def test_a_door_read_well_open_takes_its_handles_turn_as_its_q():
    """A door (hinged left at y = -0.2) whose face and handle are read turned 40 degrees takes
    q = 40 / 90 whatever the field's q; one turned 10 degrees (below `read_turn_min_deg`) keeps
    the field's, and so does one whose face is read turned 40 degrees with its handle at the
    shut face (a misread face); a drawer keeps the field's q."""
    def turned(angle_deg):
        a = np.radians(angle_deg)
        hinge = np.array([0.3, -0.2])
        free = hinge + 0.4 * np.array([np.sin(a), np.cos(a)])
        corners = np.array([[*hinge, 0.8], [*free, 0.8], [*hinge, 0.2], [*free, 0.2]])
        return SightedFront(np.array([*(hinge + 0.35 * (free - hinge) / 0.4), 0.5]), 0.95, corners, 5)
    drawer = SightedFront(np.array([0.33, 0.0, 1.0]), 0.05, _face(-0.2, 0.2, 0.9, 1.1), 5)
    misread = SightedFront(np.array([0.3, 0.15, 0.5]), 0.95, turned(40.0).corners, 5)
    fronts = [turned(40.0), turned(10.0), drawer, misread]
    head = np.zeros((4, 4, 3))
    head[:, 0] = [f.p_O for f in fronts]
    field_q = np.array([0.05, 0.3, 0.2, 0.1])
    _, types, q = place_fronts(head, np.zeros(4, int), field_q, [0.3] * 4, fronts, np.zeros(4), np.zeros(4),
                               _reading(0.0, (0.0, 0.0), NO_OFFSET_ODDS))
    assert [PART_TYPES[t] for t in types] == ["door", "door", "drawer", "door"]
    np.testing.assert_allclose(q, [40.0 / 90.0, 0.3, 0.2, 0.1])


def test_a_read_type_weighs_the_heads_door_margin():
    """A front read a door with probability 0.4 (log-odds -0.41) is a door where the head's door
    margin times the weight outweighs that (+5 x 0.1), a drawer where the head is unsure (0) or
    the weight is 0; a sure read (0.05) keeps its type against the head. Being one of a pair
    adds the pair's log-odds, being alone the other."""
    unsure = SightedFront(np.array([0.33, 0.0, 0.6]), 0.4, _face(-0.2, 0.2, 0.2, 0.8), 5)
    sure = SightedFront(np.array([0.33, 0.5, 0.6]), 0.05, _face(0.3, 0.7, 0.2, 0.8), 5)
    head = np.zeros((2, 4, 3))
    head[:, 0] = [unsure.p_O, sure.p_O]
    types, q = np.zeros(2, int), np.zeros(2)

    def read(margin, weight, sides=(0.0, 0.0), pair_log_odds=(0.0, 0.0)):
        read_types = place_fronts(head, types, q, [0.3] * 2, [unsure, sure], np.array(sides),
                                  np.array(margin, float), _reading(weight, pair_log_odds, NO_OFFSET_ODDS))[1]
        return [PART_TYPES[t] for t in read_types]

    assert read([5.0, 5.0], 0.1) == ["door", "drawer"]
    assert read([0.0, 0.0], 0.1) == ["drawer", "drawer"]
    assert read([5.0, 5.0], 0.0) == ["drawer", "drawer"]
    # one of a pair: the generator's odds (+3.4) outweigh an unsure read, not a sure one (-2.94)
    assert read([0.0, 0.0], 0.0, (1.0, 1.0), (3.4, -0.4)) == ["door", "door"]
    assert read([0.0, 0.0], 0.0, (1.0, 1.0), (2.0, -0.4)) == ["door", "drawer"]
    # a lone front: -0.4 more for a drawer (-0.41 + 0.5 - 0.4 < 0 < -0.41 + 1.0 - 0.4)
    assert read([5.0, 5.0], 0.1, (0.0, 0.0), (3.4, -0.4)) == ["drawer", "drawer"]
    assert read([10.0, 10.0], 0.1, (0.0, 0.0), (3.4, -0.4)) == ["door", "drawer"]


def test_a_lone_front_whose_handle_sits_by_an_edge_is_more_likely_a_door():
    """`handle_offset`: 0 for a handle in the middle of its face, 0.8 for one 4 cm from the edge of
    a 40 cm face, whatever the face's turn. The offset's odds (here -1 in the middle, +2.7 by an
    edge) turn an unsure read (0.3, log-odds -0.85) into a door by an edge and leave a centred
    handle's front a drawer; one of a pair (a pair can be read as one wide face) is not weighed."""
    face = _face(-0.2, 0.2, 0.2, 0.8)
    by_edge = SightedFront(np.array([0.33, 0.16, 0.6]), 0.3, face, 5)
    centred = SightedFront(np.array([0.33, 0.0, 0.6]), 0.3, face, 5)
    assert handle_offset(centred) == pytest.approx(0.0, abs=1e-9)
    assert handle_offset(by_edge) == pytest.approx(0.8)
    turn = RotationMatrix.MakeZRotation(0.7).matrix()
    turned = SightedFront(turn @ by_edge.p_O, 0.3, face @ turn.T, 5)
    assert handle_offset(turned) == pytest.approx(0.8)
    head = np.zeros((2, 4, 3))
    head[:, 0] = [by_edge.p_O, centred.p_O]
    odds = ((0.1, 0.5), (-1.0, -0.3, 2.7))

    def read(sides, offset_odds):
        read_types = place_fronts(head, np.zeros(2, int), np.zeros(2), [0.3] * 2, [by_edge, centred],
                                  np.array(sides), np.zeros(2), _reading(0.0, (0.0, 0.0), offset_odds))[1]
        return [PART_TYPES[t] for t in read_types]

    assert read([0.0, 0.0], NO_OFFSET_ODDS) == ["drawer", "drawer"]
    assert read([0.0, 0.0], odds) == ["door", "drawer"]
    assert read([1.0, -1.0], odds) == ["drawer", "drawer"]


def test_the_doors_of_a_pair_hinge_on_their_outer_sides():
    """Two level door handles 10 cm apart: each door's hinge (and goal) is put on the side away
    from the other handle, mirrored about its own handle; a lone door, a drawer and a slot
    without a sighting keep the head's."""
    def door(handle_y, hinge_y, z=0.9):
        return [[0.3, handle_y, z], [0.0, (handle_y + hinge_y) / 2, 0.1], [0.3, hinge_y, 1.6],
                [0.3, hinge_y, 0.1]]
    keypoints = np.array([door(-0.05, 0.3),     # left door of a pair, hinged toward its neighbour
                          door(0.05, 0.4),      # right door, right already
                          door(0.8, 0.4),       # a lone door further right
                          door(-0.04, 0.3, 0.5),  # a drawer below (type), not level anyway
                          door(0.15, 0.5)])     # level and near, but not sighted
    types = np.array([PART_TYPES.index(t) for t in ("door", "door", "door", "drawer", "door")])
    out = pair_hinges(keypoints, types, 4, 0.25)
    np.testing.assert_allclose(out[0, 1:, 1], [-0.225, -0.4, -0.4])
    np.testing.assert_allclose(out[1:], keypoints[1:])
    np.testing.assert_allclose(pair_hinges(keypoints, types, 4, 0.0), keypoints)


def test_fitted_parts_are_translated_onto_the_sighted_handles(capture):
    """With sightings, each matched slot's handle lies on its sighting at the fitted q, and so
    does its path there; `snap_to_handles` off: the head's keypoints."""
    torch.manual_seed(0)
    model = NFRModel(TINY).eval().requires_grad_(False)
    codes = torch.randn(5, TINY.latent_obj_dim) * 0.1
    config = FurnitureFitConfig(starts=3, keep=2, steps=3, rays_per_step=64, lookup_rays=64)
    handles = np.array([[0.6, -0.3, 0.9], [0.6, 0.3, 0.9]])
    fit = fit_furniture(model, observed_rays(capture), codes, config, handles)
    head = fit_furniture(model, observed_rays(capture), codes, replace(config, snap_to_handles=False),
                         handles)
    h = SLOT_KEYPOINTS.index("handle")
    assert sorted(map(tuple, fit.keypoints[:2, h].round(9))) == sorted(map(tuple, handles))
    np.testing.assert_allclose(fit.keypoints - fit.shift[:, None], head.keypoints, atol=1e-9)
    assert (head.shift == 0).all() and (fit.shift[2:] == 0).all() and (fit.shift[:2] != 0).any()
    grid = np.linspace(0, 1, 3)
    part = parts_json(model, fit, grid)[1]
    np.testing.assert_allclose(np.asarray(part["trajectory"]["keypoints"]["handle"]),
                               slot_path(model, fit, 1, grid)[:, h], atol=1e-9)
    for k in (0, 1):  # each path passes through its sighting at the fitted q
        np.testing.assert_allclose(slot_path(model, fit, k, fit.q[k:k + 1])[0, h], fit.keypoints[k, h],
                                   atol=1e-9)


def test_a_furniture_model_folder_loads_and_uses_its_handle_detector(furniture_model_folder, capture,
                                                                       tmp_path):
    """A furniture model folder with `handle_detector/` gets its detector (the slot keypoints
    are named front{k}/handle), and infer_parts says what it sighted; without one, or turned
    off, `extra["handles"]` says why."""
    import shutil

    from nfr_drake.inference.infer import FittedModel, infer_parts
    from nfr_drake.perception.handle_detector.model import (
        DETECTOR_DIR,
        HandleDetector,
        HandleDetectorConfig,
        save_detector,
    )

    folder = tmp_path / "furniture"
    shutil.copytree(furniture_model_folder, folder)
    small = HandleDetectorConfig(channels=4, dilations=(1, 2))
    save_detector(folder / DETECTOR_DIR, HandleDetector(small),
                  {"model": {"channels": 4, "dilations": [1, 2]}})
    assert FittedModel(furniture_model_folder).handle_detector is None
    fitted = FittedModel(folder)
    assert fitted.handle_detector is not None
    config = FurnitureFitConfig(starts=2, keep=1, steps=2, rays_per_step=32, lookup_rays=32)
    grid = np.linspace(0, 1, 3)
    result, fit, _ = infer_parts(fitted, capture, config, grid)
    handles = result.extra["handles"]
    assert handles["count"] == len(fit.handles) == len(handles["p_O"])  # 2 views: none agree
    off, _, _ = infer_parts(fitted, capture, replace(config, handle_detector=False), grid)
    assert off.extra["handles"] == {"used": False, "why": "turned off"}
    none, _, _ = infer_parts(FittedModel(furniture_model_folder), capture, config, grid)
    assert none.extra["handles"]["why"] == "the model ships no handle detector"


def test_furniture_handles_are_sighted_only_inside_the_kept_pixels(capture, monkeypatch):
    """A room photo's furniture fit (`sighted_handles` with a region): the detector's maps reach
    the triangulation zero off the region and at its edge, untouched inside it; without a region
    untouched everywhere."""
    import nfr_drake.inference.infer as infer_module
    from nfr_drake.perception.handle_triangulation import HandleMap

    h, w = 128, 160
    images = [np.zeros((h, w, 3), np.uint8)] * len(capture.frames)  # triangulation is replaced
    detector = type("Detector", (), {"detect": lambda self, ims: [
        HandleMap.centroid_only(np.full(im.shape[:2], 0.9, np.float32)) for im in ims]})()
    fitted = type("Fitted", (), {"handle_detector": detector})()
    seen = []
    monkeypatch.setattr(infer_module, "locate_handles", lambda maps, frames: seen.append(maps) or [])
    region = np.zeros((h, w), bool)
    region[h // 4:3 * h // 4, w // 4:3 * w // 4] = True
    infer_module.sighted_handles(fitted, capture, images, FurnitureFitConfig(), [region] * len(images))
    infer_module.sighted_handles(fitted, capture, images, FurnitureFitConfig())
    inside, everywhere = (maps[0].probability for maps in seen)
    assert (inside[~region] == 0).all() and inside[h // 2, w // 2] == np.float32(0.9)
    assert inside[h // 4, w // 2] == 0  # the region's edge
    assert (everywhere == np.float32(0.9)).all()


@pytest.mark.parametrize("bad", [{"handle_pairing": "random"}, {"column_gap_m": -0.1}, {"pair_gap_m": -0.1}])
def test_the_handle_options_are_checked(bad):
    with pytest.raises(ConfigError, match="handle_pairing"):
        FurnitureFitConfig(**bad)


@pytest.mark.parametrize("q", [0.0, 0.3, 1.0])
def test_depth_travel_inverts_the_drawer_it_assumes(q):
    """A carcass 0.5 m deep (front at x = 0.25 in O) whose drawer travels 0.75 of it, the handle
    4 cm in front: at any q the handle's x gives back the travel 0.375 m; a carcass deeper than
    the training world's drawers gets `MAX_TRAVEL_M`, a handle behind the carcass front 5 cm."""
    share, standoff = 0.75, 0.04
    travel = share * 0.5
    assert depth_travel(0.25 + standoff + q * travel, q, share, standoff) == pytest.approx(travel)
    assert depth_travel(0.6 + standoff + q * 0.6, q, share, standoff) == pytest.approx(MAX_TRAVEL_M)
    assert depth_travel(0.0, q, share, standoff) == pytest.approx(0.05)
