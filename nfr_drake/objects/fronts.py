"""Door and drawer fronts of furniture: the link's parts, its joint and its keypoints.

A front covers a rectangle of the carcass's front plane x = x_front (O frame): y in [y0, y1],
z in [z0, z1], with its back face `FRONT_CLEARANCE` in front of that plane.

Doors hinge on a vertical edge of their front face (the hinge of the door's outer corner), so
that a door's sweep stays in front of the carcass and within its own width on the hinge side:
a neighbour on the hinge side is never hit. M's origin is on the hinge axis at the door's bottom
edge; `hinge_bottom` is M's origin, `hinge_top` is h above it; `goal` is fixed (the compartment's
floor behind the door). Drawers slide along +x; M's origin is on the front's back face, at its
horizontal centre and bottom edge; the box behind the front fits its compartment with clearance;
`goal` is the centre of the box's inner floor and moves with the drawer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nfr_drake.objects.articulated import Front, Part, SemanticClass, front_part_name
from nfr_drake.objects.handles import HandleSpec, handle_parts

DOOR_KEYPOINTS = ("handle", "hinge_top", "hinge_bottom", "goal")
DRAWER_KEYPOINTS = ("handle", "goal")
TRAVEL_FRACTION = 0.8
"""A drawer's travel at q = 1 as a fraction of its box depth (as the drawer category's)."""
DOOR_OPENING = np.pi / 2
"""A door's angle at q = 1, rad."""
FRONT_CLEARANCE = 0.001
"""Gap between a front's back face and the carcass's front plane, m."""
BOX_CLEARANCE = 0.006
"""Gap between a drawer box and its compartment, on every side, m."""
_BOX_WALL = 0.012
MAX_BOX_DEPTH = 0.6
"""Drawer boxes are at most this deep (m), however deep their compartment."""


@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle of the front plane (O frame): y in [y0, y1], z in [z0, z1], m."""

    y0: float
    y1: float
    z0: float
    z1: float

    @property
    def width(self) -> float:
        return self.y1 - self.y0

    @property
    def height(self) -> float:
        return self.z1 - self.z0

    @property
    def yc(self) -> float:
        return (self.y0 + self.y1) / 2


@dataclass(frozen=True)
class FrontLook:
    """Appearance and build of a front: thickness, frame-and-panel strips, materials."""

    thickness: float
    frame_width: float
    """Width of the raised frame strips of a frame-and-panel front, m; 0 for a flat front."""
    rgba: tuple[float, float, float, float]
    texture: str | None
    handle_rgba: tuple[float, float, float, float]
    box_rgba: tuple[float, float, float, float] = (0.8, 0.75, 0.65, 1.0)
    frame_depth: float = 0.006


def _panel_parts(look: FrontLook, w: float, h: float, y_c: float, x_back: float,
                 prefix: str) -> tuple[list[Part], float]:
    """The front's slab (x from x_back, width w centred on y_c, z in [0, h]) and frame strips.

    Returns the parts and the x of the front's outermost surface, in M.
    """
    m = SemanticClass.MOVING
    td = look.thickness
    parts = [Part(f"{prefix}panel", m, "box", (td, w, h), (x_back + td / 2, y_c, h / 2), look.rgba,
                  texture=look.texture)]
    fw, fd = look.frame_width, look.frame_depth
    if fw <= 0:
        return parts, x_back + td
    x = x_back + td + fd / 2
    for i, (sy, sz, cy, cz) in enumerate((
            (fw, h, y_c - w / 2 + fw / 2, h / 2), (fw, h, y_c + w / 2 - fw / 2, h / 2),
            (w - 2 * fw, fw, y_c, fw / 2), (w - 2 * fw, fw, y_c, h - fw / 2))):
        parts.append(Part(f"{prefix}frame{i}", m, "box", (fd, sy, sz), (x, cy, cz), look.rgba,
                          texture=look.texture))
    return parts, x_back + td + fd


def make_door(index: int, rect: Rect, x_front: float, hinge: str, look: FrontLook,
              handle: HandleSpec, handle_z: float, handle_edge_offset: float,
              p_O_goal: tuple[float, float, float]) -> Front:
    """A door over `rect`, hinged on its left or right edge ("left": y0, as seen from the front).

    handle_z: grip centre height in O, m; handle_edge_offset: grip centre's distance from the
    free edge, m; p_O_goal: the compartment floor point behind the door, in O.
    """
    prefix = front_part_name(index, "")
    w, h = rect.width, rect.height
    depth = look.thickness + (look.frame_depth if look.frame_width > 0 else 0.0)
    x_hinge = x_front + FRONT_CLEARANCE + depth
    y_hinge = rect.y0 if hinge == "left" else rect.y1
    inward = 1.0 if hinge == "left" else -1.0  # +y from a left hinge towards the free edge
    parts, x_face = _panel_parts(look, w, h, inward * w / 2, -depth, prefix)
    p_MH = (x_face + handle.standoff, inward * (w - handle_edge_offset), handle_z - rect.z0)
    parts += handle_parts(handle, p_MH, x_face, look.handle_rgba, prefix)
    return Front(
        kind="door", link_name=f"front{index}", joint_name=f"front{index}_joint", parts=tuple(parts),
        joint_type="revolute", p_OJ=(x_hinge, y_hinge, rect.z0),
        axis_O=(0.0, 0.0, -1.0) if hinge == "left" else (0.0, 0.0, 1.0), joint_upper=DOOR_OPENING,
        fixed_keypoints={"hinge_top": (x_hinge, y_hinge, rect.z1),
                         "hinge_bottom": (x_hinge, y_hinge, rect.z0),
                         "goal": tuple(float(v) for v in p_O_goal)},
        moving_keypoints={"handle": tuple(float(v) for v in p_MH)}, keypoint_names=DOOR_KEYPOINTS,
        grip_axis_M=handle.grip_axis, grip_half_length=handle.grip_half_length,
        face_M=(x_face, min(0.0, inward * w), max(0.0, inward * w), 0.0, h))


def make_drawer(index: int, rect: Rect, x_front: float, look: FrontLook, handle: HandleSpec,
                handle_z: float, compartment: tuple[float, float, float, float, float]) -> Front:
    """A drawer over `rect` whose box fills `compartment` = (depth, y0, y1, z0, z1) less clearance.

    The compartment is the space behind the front (O frame: x from x_front back by depth, y, z
    bounds, m); handle_z is the grip centre height in O (m), centred in y.
    """
    prefix = front_part_name(index, "")
    w, h = rect.width, rect.height
    x_back = x_front + FRONT_CLEARANCE
    parts, x_face = _panel_parts(look, w, h, 0.0, 0.0, prefix)
    comp_depth, cy0, cy1, cz0, cz1 = compartment
    c, wall = BOX_CLEARANCE, _BOX_WALL
    box_d = min(comp_depth - c - FRONT_CLEARANCE, MAX_BOX_DEPTH)
    box_w = (cy1 - cy0) - 2 * c
    box_h = min((cz1 - cz0) - 2 * c, max(0.06, 0.8 * h))
    y_box = (cy0 + cy1) / 2 - rect.yc
    z_box = cz0 + c - rect.z0  # box floor's underside, in M
    m = SemanticClass.MOVING
    rgba = look.box_rgba
    parts += [
        Part(f"{prefix}box_bottom", m, "box", (box_d, box_w, wall),
             (-box_d / 2, y_box, z_box + wall / 2), rgba),
        Part(f"{prefix}box_left", m, "box", (box_d, wall, box_h),
             (-box_d / 2, y_box - box_w / 2 + wall / 2, z_box + box_h / 2), rgba),
        Part(f"{prefix}box_right", m, "box", (box_d, wall, box_h),
             (-box_d / 2, y_box + box_w / 2 - wall / 2, z_box + box_h / 2), rgba),
        Part(f"{prefix}box_back", m, "box", (wall, box_w - 2 * wall, box_h),
             (-box_d + wall / 2, y_box, z_box + box_h / 2), rgba),
    ]
    p_MH = (x_face + handle.standoff, 0.0, handle_z - rect.z0)
    parts += handle_parts(handle, p_MH, x_face, look.handle_rgba, prefix)
    return Front(
        kind="drawer", link_name=f"front{index}", joint_name=f"front{index}_joint", parts=tuple(parts),
        joint_type="prismatic", p_OJ=(x_back, rect.yc, rect.z0), axis_O=(1.0, 0.0, 0.0),
        joint_upper=TRAVEL_FRACTION * box_d, fixed_keypoints={},
        moving_keypoints={"handle": tuple(float(v) for v in p_MH),
                          "goal": (-box_d / 2, y_box, z_box + wall)},
        keypoint_names=DRAWER_KEYPOINTS, grip_axis_M=handle.grip_axis,
        grip_half_length=handle.grip_half_length, face_M=(x_face, -w / 2, w / 2, 0.0, h))
