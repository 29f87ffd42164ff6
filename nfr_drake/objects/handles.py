"""Handle shapes of furniture fronts: bars, knobs, cup pulls and edge pulls.

Every builder takes the grip centre `p_MH` and the front's surface x (`x_face`) in the front's link
frame M (+x out of the front) and returns the handle's parts there; the grip centre is what the
`handle` keypoint names. Bars run along y (horizontal) or z (vertical).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from nfr_drake.objects.articulated import Part, SemanticClass

HandleStyle = Literal["bar", "knob", "cup", "edge"]
_Y_AXIS_RPY = (np.pi / 2, 0.0, 0.0)  # a cylinder's z along y
_X_AXIS_RPY = (0.0, np.pi / 2, 0.0)  # a cylinder's z along x


@dataclass(frozen=True)
class HandleSpec:
    """One handle: style, grip direction and size.

    Attributes:
        style: "bar" (a grip on two posts), "knob", "cup" (a hood over a finger slot) or "edge"
            (a lip along the front's edge).
        vertical: a bar or edge pull along z (else along y).
        length: grip length, m (bars 0.06-0.60; 0 for a knob).
        radius: bar or knob radius, m.
        standoff: distance from the front's surface to the grip axis, m.
    """

    style: HandleStyle
    vertical: bool
    length: float
    radius: float
    standoff: float

    @property
    def grip_axis(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 1.0) if self.vertical else (0.0, 1.0, 0.0)

    @property
    def grip_half_length(self) -> float:
        return 0.0 if self.style == "knob" else self.length / 2


def handle_parts(spec: HandleSpec, p_MH: tuple[float, float, float], x_face: float,
                 rgba, prefix: str) -> list[Part]:
    """Parts of a handle with grip centre p_MH, mounted on the surface x = x_face (m, in M)."""
    h = SemanticClass.HANDLE
    x, y, z = p_MH
    along = np.array(spec.grip_axis)
    grip_rpy = (0.0, 0.0, 0.0) if spec.vertical else _Y_AXIS_RPY
    if spec.style == "bar":
        r, half = spec.radius, spec.length / 2 - spec.radius
        post = x - x_face
        ends = [np.array([x_face + post / 2, y, z]) + s * half * along for s in (-1, 1)]
        return [Part(f"{prefix}bar", h, "cylinder", (r, spec.length), (x, y, z), rgba, grip_rpy),
                *(Part(f"{prefix}post{i}", h, "cylinder", (0.7 * r, post), tuple(e), rgba, _X_AXIS_RPY)
                  for i, e in enumerate(ends))]
    if spec.style == "knob":
        stem = x - x_face - 0.5 * spec.radius
        return [Part(f"{prefix}knob", h, "sphere", (spec.radius,), (x, y, z), rgba),
                Part(f"{prefix}stem", h, "cylinder", (0.45 * spec.radius, stem),
                     (x_face + stem / 2, y, z), rgba, _X_AXIS_RPY)]
    across = np.array([0.0, 0.0, 1.0]) if not spec.vertical else np.array([0.0, 1.0, 0.0])

    def box(a: float, b: float, c: float) -> tuple[float, float, float]:
        """Size of a box with extents a along the grip, b across it on the face, c along x."""
        return tuple(float(v) for v in a * np.abs(along) + b * np.abs(across) + (c, 0.0, 0.0))

    if spec.style == "cup":
        # A plate on the front and a half-sunk rounded hood whose centre is the grip.
        return [Part(f"{prefix}plate", h, "box", box(spec.length, 3 * spec.radius, 0.003),
                     (x_face + 0.0015, y, z), rgba),
                Part(f"{prefix}cup", h, "cylinder", (spec.radius, spec.length), (x, y, z), rgba, grip_rpy)]
    # Edge pull: a lip standing out of the front's edge and a flange parallel to the front, whose
    # centre is the grip (fingers reach between the front and the flange).
    lip_depth = x - x_face
    edge = 1.25 * spec.radius * across
    return [Part(f"{prefix}lip", h, "box", box(spec.length, 0.004, lip_depth),
                 tuple(np.array([x_face + lip_depth / 2, y, z]) + edge), rgba),
            Part(f"{prefix}flange", h, "box", box(spec.length, 2.5 * spec.radius, 0.004), (x, y, z), rgba)]


GRIP_PART_NAME = {"bar": "bar", "knob": "knob", "cup": "cup", "edge": "flange"}
"""The part of each handle style whose centre is the grip centre (the `handle` keypoint)."""
