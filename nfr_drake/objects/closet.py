"""Closets: a carcass with 0-2 shelves and one door hinged on a vertical front edge.

The door covers the whole front (an overlay door) and opens outward by up to 90 degrees. Its hinge
axis is the back edge of the door on the hinged side: x = depth/2, y = -width/2 (hinge on the left
as seen from the front, i.e. from +x) or +width/2 (right). Keypoints: `handle` (centre of the
grip), `hinge_top` and `hinge_bottom` (on the hinge axis at the door's top and bottom edges) and
`goal` (centre of the top surface of the bottom panel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nfr_drake.objects.appearance import sample_front_rgba, sample_handle_rgba, sample_rgba
from nfr_drake.objects.articulated import ArticulatedObject, Front, Part, SemanticClass
from nfr_drake.objects.carcass import carcass_parts

KEYPOINT_NAMES = ("handle", "hinge_top", "hinge_bottom", "goal")

# Gap between the door's edges and the carcass outline, m.
_DOOR_GAP = 0.003


@dataclass(frozen=True)
class ClosetRanges:
    """Uniform sampling ranges (min, max) of the closet parameters, metres unless stated."""

    width: tuple[float, float] = (0.35, 0.70)
    height: tuple[float, float] = (0.40, 0.90)
    depth: tuple[float, float] = (0.30, 0.50)
    panel_thickness: tuple[float, float] = (0.012, 0.025)
    door_thickness: tuple[float, float] = (0.015, 0.025)
    handle_length: tuple[float, float] = (0.08, 0.20)
    """Length of a bar handle."""
    handle_radius: tuple[float, float] = (0.007, 0.012)
    handle_standoff: tuple[float, float] = (0.03, 0.045)
    """Distance from the door's front surface to the axis of the grip."""
    handle_edge_offset: tuple[float, float] = (0.035, 0.08)
    """Distance from the door's free edge to the grip axis."""
    handle_height_fraction: tuple[float, float] = (0.35, 0.65)
    """Height of the grip centre as a fraction of the closet height."""
    knob_probability: float = 0.2
    knob_radius: tuple[float, float] = (0.015, 0.022)


def _bar_handle(length, radius, standoff, p_M, rgba) -> list[Part]:
    """A vertical bar on two standoffs, grip centre at p_M (door front surface at x = p_M.x - standoff)."""
    h = SemanticClass.HANDLE
    x, y, z = p_M
    post_r = 0.7 * radius
    post_len = standoff
    post_x = x - standoff / 2
    dz = length / 2 - radius
    return [
        Part("bar", h, "cylinder", (radius, length), (x, y, z), rgba),
        Part("post_top", h, "cylinder", (post_r, post_len), (post_x, y, z + dz), rgba, (0, np.pi / 2, 0)),
        Part("post_bottom", h, "cylinder", (post_r, post_len), (post_x, y, z - dz), rgba, (0, np.pi / 2, 0)),
    ]


def _knob_handle(radius, standoff, p_M, rgba) -> list[Part]:
    """A ball on a stem, ball centre at p_M."""
    h = SemanticClass.HANDLE
    x, y, z = p_M
    stem_len = standoff - 0.5 * radius
    return [
        Part("knob", h, "sphere", (radius,), (x, y, z), rgba),
        Part("stem", h, "cylinder", (0.4 * radius, stem_len), (x - standoff + stem_len / 2, y, z),
             rgba, (0, np.pi / 2, 0)),
    ]


def sample_closet(rng: np.random.Generator, ranges: ClosetRanges = ClosetRanges(),
                  name: str = "closet") -> ArticulatedObject:
    """Draw one closet; all randomness comes from `rng`."""
    u = lambda r: float(rng.uniform(*r))  # noqa: E731
    W, H, D = u(ranges.width), u(ranges.height), u(ranges.depth)
    t, td = u(ranges.panel_thickness), u(ranges.door_thickness)
    hinge_side = "left" if rng.uniform() < 0.5 else "right"
    n_shelves = int(rng.integers(0, 3))
    shelf_heights = tuple(t + (H - 2 * t) * (i + 1) / (n_shelves + 1) for i in range(n_shelves))
    carcass_rgba = sample_rgba(rng)
    door_rgba = sample_front_rgba(rng, carcass_rgba)
    handle_rgba = sample_handle_rgba(rng)

    # Hinge axis and the sign of the free edge's y; positive joint angles open the door outward.
    y_hinge = -W / 2 if hinge_side == "left" else W / 2
    axis = (0.0, 0.0, -1.0) if hinge_side == "left" else (0.0, 0.0, 1.0)
    p_OJ = (D / 2, y_hinge, 0.0)

    door_height = H - 2 * _DOOR_GAP
    door_width = W - 2 * _DOOR_GAP
    # Door parts in M (origin on the hinge axis at floor height, axes parallel to O at q = 0).
    door = Part("panel", SemanticClass.MOVING, "box", (td, door_width, door_height),
                (td / 2, -y_hinge, H / 2), door_rgba)

    knob = rng.uniform() < ranges.knob_probability
    standoff = u(ranges.handle_standoff)
    edge_offset = u(ranges.handle_edge_offset)
    z_handle = u(ranges.handle_height_fraction) * H
    y_free_M = -2 * y_hinge  # free edge of the door, in M
    y_handle_M = y_free_M - np.sign(y_free_M) * (edge_offset + _DOOR_GAP)
    p_MH = (td + standoff, float(y_handle_M), z_handle)
    if knob:
        handle = _knob_handle(u(ranges.knob_radius), standoff, p_MH, handle_rgba)
        handle_length = 0.0
    else:
        handle_length = u(ranges.handle_length)
        handle = _bar_handle(handle_length, u(ranges.handle_radius), standoff, p_MH, handle_rgba)

    params = dict(width=W, height=H, depth=D, panel_thickness=t, door_thickness=td,
                  hinge_side=hinge_side, shelves=n_shelves, handle_type="knob" if knob else "bar",
                  handle_length=handle_length, handle_standoff=standoff,
                  handle_edge_offset=edge_offset, handle_height=z_handle,
                  carcass_rgba=carcass_rgba, door_rgba=door_rgba, handle_rgba=handle_rgba)
    door_front = Front(
        kind="door",
        link_name="door",
        joint_name="door_hinge",
        parts=(door, *handle),
        joint_type="revolute",
        p_OJ=p_OJ,
        axis_O=axis,
        joint_upper=np.pi / 2,
        fixed_keypoints={
            "hinge_top": (D / 2, y_hinge, _DOOR_GAP + door_height),
            "hinge_bottom": (D / 2, y_hinge, _DOOR_GAP),
            "goal": (0.0, 0.0, t),
        },
        moving_keypoints={"handle": p_MH},
        keypoint_names=KEYPOINT_NAMES,
        grip_axis_M=(0.0, 0.0, 1.0),
        grip_half_length=handle_length / 2,
    )
    return ArticulatedObject(
        category="closet",
        name=name,
        base_parts=carcass_parts(W, D, H, t, carcass_rgba, shelf_heights),
        fronts=(door_front,),
        params=params,
    )
