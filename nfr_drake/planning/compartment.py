"""The opened compartment as obstacle boxes, from a keypoint trajectory alone (for placing an item
at the `goal` keypoint).

The keypoints give the front plane, the hinge line, the goal (a closet's inner floor centre, a
drawer's inner floor centre that moves with it) and the handle; the rest comes from the categories'
layouts (`nfr_drake.objects.closet`, `nfr_drake.objects.drawer`), on the side of caution:
- a closet is a hollow box (bottom, top, sides, back, `_WALL` thick) spanning the carcass box of
  `grasp.carcass_box`, with a shelf at the lowest height a closet of that height can have (two
  shelves: a third of the way up) and its floor at the goal's height or, where a look into the
  opened closet measured them (`InteriorLook`, `nfr_drake.systems.interior`), the shelf's
  underside and the floor where it saw them, and its open door
  (`grasp.door_panel_box` at the target); the top and the door's top edge as high as the fitted
  field's points reach where that is higher than `hinge_top` (`part_top`);
- a drawer is the solid carcass box (`grasp.carcass_box`) and the pulled-out box: its front panel
  behind the handle, its back as far behind the goal as the front is ahead, side walls at the
  narrowest box's half width (`_DRAWER_MIN_HALF_WIDTH`) or, where the fitted field's points give
  the front's width (`drawer_half_width`), from the front's edge (and a wall's thickness beyond)
  to the box's inside behind it (`_DRAWER_FRONT_OVERLAY` in from the edge), as high as a front
  with its handle at mid-height, the front itself as high as the category allows for its
  handle's height.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from nfr_drake.errors import NfrDrakeError
from nfr_drake.planning.grasp import CARCASS_SETBACK, carcass_box, door_panel_box, handle_tangent
from nfr_drake.world.cloud import SemanticCloud
from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.plan import ObstacleBox

_Z = np.array([0.0, 0.0, 1.0])
_WALL = 0.02  # thickness of the estimated panels, m
_DRAWER_MIN_HALF_WIDTH = 0.145  # half the narrowest drawer box's inside, m (0.35 m wide, 2.5 cm panels)
_DRAWER_FRONT_OVERLAY = 0.045
"""How far a drawer box's inside lies in from its front's edge, m: the carcass's side panel, the
runners' clearance and the box's wall (2.4-3.7 cm in `nfr_drake.objects.drawer`; 18 mm + 12.5 mm +
15 mm in a kitchen cabinet)."""
_DRAWER_FRONT_BEHIND_HANDLE = 0.05  # the drawer front's inner face behind its grip, m (standoff + front)
_DRAWER_FLOOR_ABOVE_BASE = 0.03  # a drawer's inner floor above its carcass's base, m (panel, gap, wall)
_DRAWER_LOWEST_HANDLE = 0.35  # the lowest handle height as a fraction of the front's (0.5 - 0.15)
_DRAWER_MAX_HEIGHT = 0.40  # the tallest drawer front, m
_DOOR_GRIP_OFFSET = 0.0575  # a door's grip axis in front of its hinge line, m (door + standoff, mean)
ENTRY_SIDE_CLEARANCE = 0.13
"""A closet's turned way in stays this far inside its sides at the front plane, m (half the hand's
20 cm width across the fingers and 3 cm)."""


def _frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray, RotationMatrix]:
    """The horizontal unit front normal n, the lateral axis Z x n and the rotation [n, lateral, Z]."""
    n = n - (n @ _Z) * _Z
    if np.linalg.norm(n) < 1e-9:
        raise NfrDrakeError("keypoint trajectory: the handle moves vertically; no front plane")
    n = n / np.linalg.norm(n)
    lateral = np.cross(_Z, n)
    return n, lateral, RotationMatrix(np.column_stack([n, lateral, _Z]))


def _box(name: str, R: RotationMatrix, axes: tuple[np.ndarray, ...], lo: np.ndarray,
         hi: np.ndarray) -> ObstacleBox:
    """A box between coordinates lo and hi (m, (3,)) along the axes (n, lateral, Z)."""
    centre = sum(a * (l_ + h) / 2 for a, l_, h in zip(axes, lo, hi, strict=True))
    return ObstacleBox(name, np.abs(np.asarray(hi) - np.asarray(lo)), RigidTransform(R, centre))


@dataclass(frozen=True)
class InteriorLook:
    """What a look into an opened closet saw in the vertical column over its goal keypoint,
    heights in W, m: the floor's top (None where the view saw nothing below the camera) and the
    underside of the lowest thing over it (a shelf, the top panel; where nothing was seen, the
    height the view reaches)."""

    floor: float | None
    ceiling: float


def compartment_obstacles(kt: KeypointTrajectory, q: float, look: InteriorLook | None = None,
                          cloud: SemanticCloud | None = None) -> tuple[list[ObstacleBox], list[ObstacleBox]]:
    """Obstacle boxes in W of the compartment opened to articulation q (module docstring): those
    that stay put, and those of the moving part (the door, the drawer's box). look: a closet's
    floor and the shelf over the goal as a look inside saw them (no shelf where the ceiling
    reaches the top); None: the floor at the goal's height, the lowest shelf the closet's
    height allows. cloud: the fitted field's points that came with the keypoints: the moving
    part's width from them (a drawer front's half width about its goal, `drawer_half_width`; a
    closet door's width from its hinge, `door_width`) and a closet's top and its door's top edge
    (`part_top`, where higher than the keypoints' `hinge_top`); None, or too few points: a
    drawer's walls those of the narrowest box, a door as wide as the handle says
    (`grasp.door_panel_box`), the tops at `hinge_top`."""
    if "goal" not in kt.names:
        raise NfrDrakeError(f"the {kt.category}'s keypoint trajectory has no goal keypoint to place at")
    if kt.category == "closet":
        return _closet(kt, q, look, cloud)
    half_width = None if cloud is None else drawer_half_width(kt, cloud)
    if half_width is None:
        return _drawer(kt, q, _DRAWER_MIN_HALF_WIDTH, _DRAWER_MIN_HALF_WIDTH + _WALL)
    return _drawer(kt, q, half_width - _DRAWER_FRONT_OVERLAY, half_width + _WALL)


def drawer_half_width(kt: KeypointTrajectory, cloud: SemanticCloud, share: float = 0.98) -> float | None:
    """A drawer front's half width about its goal keypoint, m, from the fitted field's points of
    its moving part (`SemanticCloud.moving`; at the shut drawer the front is all there is to see):
    the `share` quantile of their lateral distances from the goal; None when the cloud holds under
    20 such points. The quantile, not the largest: a few stray labels do not widen it. The
    walls (`compartment_obstacles`) reach a wall's thickness (2 cm) past it on the side of
    caution: on drawers 0-5 of capture seed 901 (the object alone) the quantile of 48-pixel
    views lay from 1.2 cm inside to 0.5 cm outside the front's true half width."""
    moving = cloud.moving()
    if len(moving) < 20:
        return None
    _, lat, _ = _frame(handle_tangent(kt, cloud.q))
    lateral = np.abs((moving - kt.point("goal", cloud.q)) @ lat)
    return float(np.quantile(lateral, share))


def door_width(kt: KeypointTrajectory, cloud: SemanticCloud, share: float = 0.98) -> float | None:
    """A closet door's width from its hinge line, m, from the fitted field's points of its moving
    part (`SemanticCloud.moving`): the `share` quantile of their horizontal distances from the
    keypoints' hinge line at the cloud's articulation; None under 20 such points. The handle
    lies 3.5-8 cm from a generated door's free edge, more than the 5 cm the keypoints alone
    allow past it (`grasp.door_panel_box`)."""
    moving = cloud.moving()
    if len(moving) < 20:
        return None
    bottom, top = kt.point("hinge_bottom", cloud.q), kt.point("hinge_top", cloud.q)
    axis = (top - bottom) / np.linalg.norm(top - bottom)
    offsets = moving - bottom
    radial = offsets - np.outer(offsets @ axis, axis)
    return float(np.quantile(np.linalg.norm(radial, axis=1), share))


TOP_MARGIN = 0.02
"""How far above the fitted field's highest points (`part_top`) a closet's top and its door's
top edge are taken to lie, m: on closets 0-15 of capture seed 901 the points' 0.98 quantile of
height lay 0.2-0.9 cm under the door's true top and from 0.6 cm under to 0.3 cm over the
carcass's (`scripts/fitted_widths.py`), the keypoints' `hinge_top` from 1.4 cm under to 3.8 cm
over them."""


def part_top(points: np.ndarray, share: float = 0.98) -> float | None:
    """The top of a part's fitted points (m, (N, 3) in W): their heights' `share` quantile, m;
    None under 20 points."""
    if len(points) < 20:
        return None
    return float(np.quantile(points[:, 2], share))


def _door_normal(kt: KeypointTrajectory) -> np.ndarray:
    """The shut door's outward normal, horizontal, unit, (3,). The handle's tangent at q = 0 is
    perpendicular to the hinge-to-handle vector r, which leans out of the door plane by the grip's
    offset a (`_DOOR_GRIP_OFFSET`): the normal is t cos(theta) + r/|r| sin(theta), sin(theta) = a/|r|."""
    t = handle_tangent(kt, 0.0)
    r = kt.point("handle", 0.0) - kt.point("hinge_bottom", 0.0)
    r = r - (r @ _Z) * _Z
    sin = min(_DOOR_GRIP_OFFSET / np.linalg.norm(r), 0.5)
    return np.sqrt(1.0 - sin ** 2) * (t - (t @ _Z) * _Z) + sin * r / np.linalg.norm(r)


def closet_half_width(kt: KeypointTrajectory, q: float) -> float:
    """Half a closet's width as its keypoints give it, m: the hinge line's distance from the goal
    at articulation q across the shut door's normal (`compartment_obstacles` builds the carcass
    that wide either side of the goal)."""
    _, lat, _ = _frame(_door_normal(kt))
    return float(abs((kt.point("hinge_bottom", 0.0) - kt.point("goal", q)) @ lat))


def carcass_half_width(kt: KeypointTrajectory, cloud: SemanticCloud, q: float, share: float = 0.98
                       ) -> float | None:
    """Half a closet's width as the fitted field's carcass points give it, m: the larger of the
    `share` quantiles of their lateral offsets from the goal at articulation q either way (across
    the shut door's normal, as `closet_half_width`); None under 20 such points."""
    static = cloud.static()
    if len(static) < 20:
        return None
    _, lat, _ = _frame(_door_normal(kt))
    offsets = (static - kt.point("goal", q)) @ lat
    return float(max(np.quantile(offsets, share), -np.quantile(offsets, 1.0 - share)))


def _closet(kt: KeypointTrajectory, q: float, look: InteriorLook | None, cloud: SemanticCloud | None
            ) -> tuple[list[ObstacleBox], list[ObstacleBox]]:
    """A closet's hollow carcass and its open door; its top panel spans from a wall under the
    lower of the keypoints' and the points' top to the higher; its sides stand at the larger of
    the keypoints' and the carcass points' half width (`closet_half_width`,
    `carcass_half_width`)."""
    n, lat, R = _frame(_door_normal(kt))
    axes = (n, lat, _Z)
    goal = kt.point("goal", q)
    front = kt.point("handle", 0.0) @ n - CARCASS_SETBACK
    back = goal @ n - max(front - goal @ n, 0.05)
    half = closet_half_width(kt, q)
    seen = None if cloud is None else carcass_half_width(kt, cloud, q)
    half = half if seen is None else max(half, seen)
    y0, floor, top = goal @ lat, goal[2], kt.point("hinge_top", 0.0)[2]
    measured = None if cloud is None else part_top(cloud.static())
    underside = top if measured is None else min(top, measured)
    shelf = floor + (top - 2 * floor) / 3 - floor / 2  # underside of the lowest shelf a closet can have
    top = top if measured is None else max(top, measured + TOP_MARGIN)
    if look is not None:
        floor, shelf = (floor if look.floor is None else look.floor), look.ceiling
    boxes = [
        _box("compartment_bottom", R, axes, [back, y0 - half, 0.0], [front, y0 + half, floor]),
        _box("compartment_top", R, axes, [back, y0 - half, underside - _WALL], [front, y0 + half, top]),
        _box("compartment_back", R, axes, [back - _WALL, y0 - half, 0.0], [back, y0 + half, top]),
        _box("compartment_side_a", R, axes, [back, y0 - half, 0.0], [front, y0 - half + _WALL, top]),
        _box("compartment_side_b", R, axes, [back, y0 + half - _WALL, 0.0], [front, y0 + half, top]),
    ]
    if shelf < underside - _WALL:
        boxes.append(_box("compartment_shelf", R, axes, [back, y0 - half, shelf],
                          [front - 0.01, y0 + half, shelf + _WALL]))
    width, door_top = (None, None) if cloud is None else (door_width(kt, cloud), part_top(cloud.moving()))
    door = door_panel_box(kt.with_current(q), width, None if door_top is None else door_top + TOP_MARGIN)
    return boxes, [door] if door is not None else []


def _drawer(kt: KeypointTrajectory, q: float, inner: float, outer: float) -> list[ObstacleBox]:
    """The drawer's boxes at q, its side walls from `inner` to `outer` (m) either side of the goal."""
    n, lat, R = _frame(handle_tangent(kt, q))
    axes = (n, lat, _Z)
    goal, handle = kt.point("goal", q), kt.point("handle", q)
    inner_front = handle @ n - _DRAWER_FRONT_BEHIND_HANDLE
    half_depth = max(inner_front - goal @ n, 0.05)
    back = goal @ n - half_depth
    top, front_top = _drawer_tops(kt, q)
    y0, floor = goal @ lat, goal[2]
    return [carcass_box(kt)], [
        _box("drawer_floor", R, axes, [back, y0 - outer, 0.0], [inner_front, y0 + outer, floor]),
        _box("drawer_front", R, axes, [inner_front, y0 - outer, 0.0],
             [inner_front + 0.02, y0 + outer, front_top]),
        _box("drawer_back", R, axes, [back - _WALL, y0 - outer, 0.0], [back, y0 + outer, top]),
        _box("drawer_side_a", R, axes, [back, y0 - outer, 0.0], [inner_front, y0 - inner, top]),
        _box("drawer_side_b", R, axes, [back, y0 + inner, 0.0], [inner_front, y0 + outer, top]),
    ]


def compartment_entry(kt: KeypointTrajectory, q: float, toward: np.ndarray | None = None
                      ) -> tuple[np.ndarray, float]:
    """The way into the compartment opened to q, a unit vector in W (a closet: horizontal, across
    its front; a drawer: down), and the goal's depth behind the opening along it, m (a closet: the
    front plane of `compartment_obstacles`; a drawer: the top of its estimated walls). A closet's
    way in is turned toward the horizontal line from `toward` (m, (3,) in W: the robot's base) to
    the goal, at most as far as keeps the line `ENTRY_SIDE_CLEARANCE` inside its sides at the front
    plane: an arm beside the front reaches in along its own line."""
    goal = kt.point("goal", q)
    if kt.category != "closet":
        return -_Z, float(_drawer_tops(kt, q)[0] - goal[2])
    n, lat, _ = _frame(_door_normal(kt))
    opening = float(kt.point("handle", 0.0) @ n - CARCASS_SETBACK - goal @ n)
    if toward is None:
        return -n, opening
    half = closet_half_width(kt, q)
    widest = np.arctan2(max(half - ENTRY_SIDE_CLEARANCE, 0.0), max(opening, 1e-3))
    d = (np.asarray(toward) - goal) * [1.0, 1.0, 0.0]
    angle = float(np.clip(np.arctan2(d @ lat, d @ n), -widest, widest))
    return -(np.cos(angle) * n + np.sin(angle) * lat), opening / np.cos(angle)


def front_normal(kt: KeypointTrajectory, q: float) -> np.ndarray:
    """The compartment's front's outward normal at articulation q, horizontal, unit, (3,) in W (a
    closet: its shut door's; a drawer: the way it is pulled out)."""
    return _frame(_door_normal(kt) if kt.category == "closet" else handle_tangent(kt, q))[0]


def _drawer_tops(kt: KeypointTrajectory, q: float) -> tuple[float, float]:
    """A drawer's walls' top in W, m: the front's height were its handle at mid-height, and, for
    its front (which the arm reaches over), the most the category allows for that handle."""
    floor = kt.point("goal", q)[2] - _DRAWER_FLOOR_ABOVE_BASE
    above = kt.point("handle", q)[2] - floor
    return floor + min(2.0 * above, _DRAWER_MAX_HEIGHT), floor + min(above / _DRAWER_LOWEST_HANDLE,
                                                                    _DRAWER_MAX_HEIGHT)
