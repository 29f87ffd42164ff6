"""Grasp frames and a static obstacle, derived from a keypoint trajectory alone.

Conventions (all in the world frame W):
- the approach direction is the unit vector the gripper moves along when closing in on the handle:
  from the approach keypoint to the handle where the trajectory has one (a sliding door, whose
  handle moves across the front), else minus the direction in which the handle moves for increasing
  q (for a drawer exactly minus the pull direction; for a door the tangent of the handle's circle
  about the hinge line, which is the door's outward normal up to the angle atan(standoff / radius)
  of the handle's standoff, 5-15 degrees here);
- the bar axis is the axis of the handle's grip: towards the grip-axis keypoint where the trajectory
  has one (true furniture models), else the hinge axis (hinge_top - hinge_bottom) for a door,
  horizontal and across the pull direction for a drawer;
- the grasp frame G of a `HandleWaypoint` (`nfr_drake.world.plan`) has its origin at the handle
  keypoint, +z along the approach, +x along the bar axis.
"""

from __future__ import annotations

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from nfr_drake.errors import NfrDrakeError
from nfr_drake.world.keypoints import APPROACH_KEYPOINT, GRIP_AXIS_KEYPOINT, KeypointTrajectory
from nfr_drake.world.plan import HandleWaypoint, ObstacleBox

_Z = np.array([0.0, 0.0, 1.0])

CARCASS_SETBACK = 0.05
"""Distance from the handle (at q = 0) back to the front face of the keypoint-derived carcass box, m.
Handles of both categories stand 4.5-7 cm in front of the carcass."""
PANEL_SETBACK = 0.03
"""Distance from the handle back to the front face of an open door's obstacle box, m: less than any
handle's standoff from its door (4.5-7 cm from the carcass, less the door's thickness), more than
the fingertips reach past the grasp point (1 cm) plus the planner's clearance."""
_PANEL_THICKNESS = 0.02
_PANEL_EDGE_MARGIN = 0.05  # door beyond the handle, away from the hinge, m
_PANEL_WIDTH_MARGIN = 0.03
"""How far a door's box reaches past its measured width, m: the width's 0.98 quantile fell 1.0-2.1 cm
short of the door on closets 0-5 of capture seed 901 (`scripts/fitted_widths.py`)."""
_PANEL_MIN_ANGLE_DEG = 10.0  # below this opening the carcass box already covers the door
_DRAWER_HALF_WIDTH = 0.4
_DRAWER_DEPTH = 0.5
_DRAWER_HEIGHT = 0.42


def _unit(v: np.ndarray, what: str) -> np.ndarray:
    n = np.linalg.norm(v)
    if n < 1e-9:
        raise NfrDrakeError(f"keypoint trajectory: {what} is degenerate (zero length)")
    return v / n


def handle_tangent(kt: KeypointTrajectory, q: float) -> np.ndarray:
    """Unit direction in which the handle moves for increasing q, at q, shape (3,): for a drawer
    the path's direction there (a finite difference); for a door the tangent of the handle's
    circle about the hinge line at q (hinge_bottom to hinge_top), the way the path goes. A fitted
    path can bend at its shut end where its hinge is close (closets 4 and 6 of capture seed 901,
    docs/PLANNING.md): the hand, approaching along the bent end, pressed the door shut."""
    dq = 0.5 * float(np.min(np.diff(kt.q_grid)))
    lo, hi = max(q - dq, kt.q_grid[0]), min(q + dq, kt.q_grid[-1])
    path = _unit(kt.point("handle", hi) - kt.point("handle", lo), "the handle path")
    if kt.category != "closet":
        return path
    bottom = kt.point("hinge_bottom", q)
    axis = _unit(kt.point("hinge_top", q) - bottom, "the hinge axis")
    tangent = _unit(np.cross(axis, kt.point("handle", q) - bottom), "the handle's radius about the hinge")
    return tangent if tangent @ path >= 0.0 else -tangent


def bar_axis(kt: KeypointTrajectory, q: float) -> np.ndarray:
    """Unit axis of the handle's grip, shape (3,): towards the `GRIP_AXIS_KEYPOINT` where there is
    one, else the hinge axis (upward) or horizontal across the pull."""
    if GRIP_AXIS_KEYPOINT in kt.names:
        return _unit(kt.point(GRIP_AXIS_KEYPOINT, q) - kt.point("handle", q), "the grip axis")
    if kt.category == "closet":
        a = _unit(kt.point("hinge_top", q) - kt.point("hinge_bottom", q), "the hinge axis")
        return a if a @ _Z >= 0 else -a
    return _unit(np.cross(_Z, handle_tangent(kt, q)), "the drawer's pull direction (vertical?)")


def approach_direction(kt: KeypointTrajectory, q: float) -> np.ndarray:
    """Unit direction the gripper moves in to close in on the handle at q, shape (3,): from the
    `APPROACH_KEYPOINT` where there is one, else against the handle's motion."""
    if APPROACH_KEYPOINT in kt.names:
        return _unit(kt.point("handle", q) - kt.point(APPROACH_KEYPOINT, q), "the approach")
    return -handle_tangent(kt, q)


def handle_waypoints(kt: KeypointTrajectory, q_values: np.ndarray) -> list[HandleWaypoint]:
    """The handle, its approach direction and bar axis at each articulation in `q_values`."""
    return [HandleWaypoint(float(q), kt.point("handle", q), approach_direction(kt, q), bar_axis(kt, q))
            for q in q_values]


def carcass_box(kt: KeypointTrajectory) -> ObstacleBox:
    """A box inside the object's static part, from the keypoints alone.

    Its front face is `CARCASS_SETBACK` behind the closed handle, across the front normal (the handle
    tangent at q = 0). Closet: it spans the hinge line to its mirror image about the `goal` keypoint
    (the carcass centre) and the floor to `hinge_top`. Drawer: centred on the handle,
    `2 * _DRAWER_HALF_WIDTH` wide, `_DRAWER_DEPTH` deep, from the floor to `_DRAWER_HEIGHT` (the
    keypoints say nothing of the drawer carcass's size: the box covers the category's largest).
    """
    n = handle_tangent(kt, 0.0)
    n = _unit(n - (n @ _Z) * _Z, "the horizontal front normal")
    lateral = np.cross(_Z, n)
    p_handle = kt.point("handle", 0.0)
    front = p_handle @ n - CARCASS_SETBACK
    if kt.category == "closet" and "goal" in kt.names:
        hinge, goal = kt.point("hinge_bottom", 0.0), kt.point("goal", 0.0)
        half_width = abs((hinge - goal) @ lateral)
        centre_lat = goal @ lateral
        depth = max(2.0 * (front - goal @ n), 0.1)
        height = kt.point("hinge_top", 0.0)[2]
    else:
        half_width, centre_lat, depth = _DRAWER_HALF_WIDTH, p_handle @ lateral, _DRAWER_DEPTH
        height = max(_DRAWER_HEIGHT, p_handle[2] + 0.05)
    size = np.array([depth, 2.0 * half_width, height])
    centre = (front - depth / 2) * n + centre_lat * lateral + height / 2 * _Z
    R = RotationMatrix(np.column_stack([n, lateral, _Z]))
    return ObstacleBox("carcass", size, RigidTransform(R, centre))


def door_panel_box(kt: KeypointTrajectory, width: float | None = None, top: float | None = None
                   ) -> ObstacleBox | None:
    """A thin box standing for an open door at kt.q_current, from the keypoints alone; None for a
    drawer or a door opened less than `_PANEL_MIN_ANGLE_DEG` (the carcass box covers it).

    It reaches from the hinge axis to `_PANEL_EDGE_MARGIN` past the handle (or, with the door's
    measured `width` from its hinge, m, `compartment.door_width`, to `_PANEL_WIDTH_MARGIN` past
    that) and from `hinge_bottom` to `hinge_top` (or to `top`, m in W, where that lies higher: the
    door's top edge as measured, `compartment.part_top`, with its margin); its front face lies
    `PANEL_SETBACK` behind the handle across the door's outward normal (the handle tangent). It
    only holds for the approach: the door moves once grasped.
    """
    if kt.category != "closet":
        return None
    q = kt.q_current
    a, b = kt.point("hinge_bottom", q), kt.point("hinge_top", q)
    axis = _unit(b - a, "the hinge axis")
    axis = axis if axis @ _Z >= 0 else -axis

    def across(q_: float) -> np.ndarray:  # hinge axis to handle, horizontal, at q_
        r = kt.point("handle", q_) - kt.point("hinge_bottom", q_)
        return _unit(r - (r @ _Z) * _Z, "the hinge-to-handle direction")

    if np.degrees(np.arccos(np.clip(across(q) @ across(0.0), -1.0, 1.0))) < _PANEL_MIN_ANGLE_DEG:
        return None
    n = handle_tangent(kt, q)
    n = _unit(n - (n @ axis) * axis, "the door's normal")
    u = np.cross(axis, n)  # across the door; (n, u, axis) is right-handed
    h = kt.point("handle", q) - a
    width = abs(h @ u) + _PANEL_EDGE_MARGIN if width is None else width + _PANEL_WIDTH_MARGIN
    height = max(abs((b - a) @ axis), (top - a[2]) / axis[2] if top is not None else 0.0)
    depth_centre = h @ n - PANEL_SETBACK - _PANEL_THICKNESS / 2
    centre = a + height / 2 * axis + depth_centre * n + np.sign(h @ u) * (width / 2) * u
    R = RotationMatrix(np.column_stack([n, u, axis]))
    return ObstacleBox("open_door", np.array([_PANEL_THICKNESS, width, height]), RigidTransform(R, centre))
