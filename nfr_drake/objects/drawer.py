"""Drawers: a carcass holding one drawer that slides out along +x.

The drawer is a front panel covering the carcass front plus an open box behind it. The prismatic
joint's travel at q = 1 is 0.8 of the box depth. Keypoints: `handle` (centre of the grip) and
`goal` (centre of the box's inner floor; it moves with the drawer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nfr_drake.objects.appearance import sample_front_rgba, sample_handle_rgba, sample_rgba
from nfr_drake.objects.articulated import ArticulatedObject, Front, Part, SemanticClass
from nfr_drake.objects.carcass import carcass_parts

KEYPOINT_NAMES = ("handle", "goal")

TRAVEL_FRACTION = 0.8
"""Joint travel at q = 1 as a fraction of the drawer box depth (docs/CONVENTIONS.md)."""

_FRONT_GAP = 0.003  # gap between the drawer front and the carcass outline, m
_CLEARANCE = 0.005  # gap between the drawer box and the carcass inside, m
_BOX_WALL = 0.01  # drawer box wall thickness, m


@dataclass(frozen=True)
class DrawerRanges:
    """Uniform sampling ranges (min, max) of the drawer parameters, metres unless stated."""

    width: tuple[float, float] = (0.35, 0.70)
    height: tuple[float, float] = (0.18, 0.40)
    depth: tuple[float, float] = (0.30, 0.50)
    panel_thickness: tuple[float, float] = (0.012, 0.025)
    front_thickness: tuple[float, float] = (0.015, 0.025)
    handle_length: tuple[float, float] = (0.10, 0.25)
    handle_radius: tuple[float, float] = (0.007, 0.012)
    handle_standoff: tuple[float, float] = (0.03, 0.045)
    """Distance from the front's surface to the grip axis."""
    handle_height_offset: tuple[float, float] = (-0.15, 0.15)
    """Grip height relative to the front's centre, as a fraction of the front's height."""
    handle_lateral_offset: tuple[float, float] = (-0.1, 0.1)
    """Grip centre's y relative to the front's centre, as a fraction of the width."""


def sample_drawer(rng: np.random.Generator, ranges: DrawerRanges = DrawerRanges(),
                  name: str = "drawer") -> ArticulatedObject:
    """Draw one drawer cabinet; all randomness comes from `rng`."""
    u = lambda r: float(rng.uniform(*r))  # noqa: E731
    W, H, D = u(ranges.width), u(ranges.height), u(ranges.depth)
    t, tf = u(ranges.panel_thickness), u(ranges.front_thickness)
    carcass_rgba = sample_rgba(rng)
    front_rgba = sample_front_rgba(rng, carcass_rgba)
    box_rgba = sample_rgba(rng, value=(0.4, 0.9))
    handle_rgba = sample_handle_rgba(rng)

    # Drawer parts in M: origin at the carcass front (x = D/2), centre line, floor height.
    front_h, front_w = H - 2 * _FRONT_GAP, W - 2 * _FRONT_GAP
    box_d = D - t - 2 * _CLEARANCE
    box_w = W - 2 * t - 2 * _CLEARANCE
    box_h = H - 2 * t - 2 * _CLEARANCE
    box_z0 = t + _CLEARANCE
    m = SemanticClass.MOVING
    wall = _BOX_WALL
    moving = [
        Part("front", m, "box", (tf, front_w, front_h), (tf / 2, 0.0, H / 2), front_rgba),
        Part("box_bottom", m, "box", (box_d, box_w, wall), (-box_d / 2, 0.0, box_z0 + wall / 2),
             box_rgba),
        Part("box_left", m, "box", (box_d, wall, box_h), (-box_d / 2, -box_w / 2 + wall / 2,
                                                            box_z0 + box_h / 2), box_rgba),
        Part("box_right", m, "box", (box_d, wall, box_h), (-box_d / 2, box_w / 2 - wall / 2,
                                                             box_z0 + box_h / 2), box_rgba),
        Part("box_back", m, "box", (wall, box_w - 2 * wall, box_h),
             (-box_d + wall / 2, 0.0, box_z0 + box_h / 2), box_rgba),
    ]

    length = min(u(ranges.handle_length), 0.6 * front_w)
    radius = u(ranges.handle_radius)
    standoff = u(ranges.handle_standoff)
    z_handle = H / 2 + u(ranges.handle_height_offset) * front_h
    y_handle = u(ranges.handle_lateral_offset) * W
    p_MH = (tf + standoff, y_handle, z_handle)
    h = SemanticClass.HANDLE
    dy = length / 2 - radius
    post_x = tf + standoff / 2
    moving += [
        Part("bar", h, "cylinder", (radius, length), p_MH, handle_rgba, (np.pi / 2, 0, 0)),
        Part("post_left", h, "cylinder", (0.7 * radius, standoff), (post_x, y_handle - dy, z_handle),
             handle_rgba, (0, np.pi / 2, 0)),
        Part("post_right", h, "cylinder", (0.7 * radius, standoff), (post_x, y_handle + dy, z_handle),
             handle_rgba, (0, np.pi / 2, 0)),
    ]

    params = dict(width=W, height=H, depth=D, panel_thickness=t, front_thickness=tf,
                  box_depth=box_d, handle_length=length, handle_standoff=standoff,
                  handle_height=z_handle, handle_lateral=y_handle, carcass_rgba=carcass_rgba,
                  front_rgba=front_rgba, box_rgba=box_rgba, handle_rgba=handle_rgba)
    drawer_front = Front(
        kind="drawer",
        link_name="drawer",
        joint_name="drawer_slide",
        parts=tuple(moving),
        joint_type="prismatic",
        p_OJ=(D / 2, 0.0, 0.0),
        axis_O=(1.0, 0.0, 0.0),
        joint_upper=TRAVEL_FRACTION * box_d,
        fixed_keypoints={},
        moving_keypoints={"handle": p_MH, "goal": (-box_d / 2, 0.0, box_z0 + wall)},
        keypoint_names=KEYPOINT_NAMES,
        grip_axis_M=(0.0, 1.0, 0.0),
        grip_half_length=length / 2,
    )
    return ArticulatedObject(
        category="drawer",
        name=name,
        base_parts=carcass_parts(W, D, H, t, carcass_rgba),
        fronts=(drawer_front,),
        params=params,
    )
