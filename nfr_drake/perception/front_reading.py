"""What the 2D detector reads of the front behind each sighted handle: door or drawer, and the
four corners of its outer face in 3D.

A detector with front outputs (`HandleDetectorConfig.fronts`) gives, on the image scaled to
`FRONT_HEIGHT_PX` rows (the whole front within its view: a tall door spans most of the image),
per pixel of a front the probability that the front is a door and the offsets to the
projections of its face's corners (`nfr_drake.objects.articulated.FACE_CORNERS`: top left,
top right, bottom left, bottom right as seen from the front). For a handle triangulated in 3D
(`nfr_drake.perception.handle_triangulation`), each view that agreed on it is read around the
handle's projection (`FrontMap.read`); the door probability is the views' mean and each corner
is the point nearest the rays through the views' corner votes (`read_front`).

A door's hinge is the vertical edge of its face away from the handle (`hinge_points`), its
opening the turn of its face (`opening_angle`), and the
front's place in the canonical order (left edge, then top edge, shut) follows from its corners
(`shut_edges`): the handle alone tells neither (docs/FURNITURE.md, "Fronts read by the detector").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nfr_drake.data.capture import CaptureFrame
from nfr_drake.perception.handle_triangulation import TriangulatedHandle, nearest_point, project, ray

FRONT_HEIGHT_PX = 64
"""Rows of the image the front outputs are read on (any image is scaled to this height)."""
READ_RADIUS_PX = 1.5
"""Pixels (of the FRONT_HEIGHT_PX image) around a handle's projection whose outputs are averaged."""


@dataclass(frozen=True)
class FrontMap:
    """A detector's front outputs for one image: door_probability (h, w) float32 and
    corner_offset_px (h, w, 4, 2) float32 from each map pixel's centre to the projected face
    corners, map pixels (du right, dv down); scale (2,): image pixels per map pixel in u and v."""

    door_probability: np.ndarray
    corner_offset_px: np.ndarray
    scale: np.ndarray

    def read(self, uv: np.ndarray) -> tuple[float, np.ndarray] | None:
        """At image pixel uv (2,): the door probability and the four corners' pixels (4, 2) in
        the image, averaged over the map pixels within `READ_RADIUS_PX` of it; None off the map."""
        h, w = self.door_probability.shape
        centre = np.asarray(uv, float) / self.scale
        rows, cols = np.mgrid[0:h, 0:w]
        near = np.hypot(cols + 0.5 - centre[0], rows + 0.5 - centre[1]) <= READ_RADIUS_PX
        if not near.any():
            return None
        door = float(self.door_probability[near].mean())
        corners = (np.stack([cols[near] + 0.5, rows[near] + 0.5], -1)[:, None]
                   + self.corner_offset_px[near]).mean(0)
        return door, corners * self.scale


@dataclass(frozen=True)
class SightedFront:
    """A sighted handle p_O (3,) in O with its front as read: door_probability in [0, 1] and the
    face corners (4, 3) in O (`FACE_CORNERS` order), m; views: how many views were read."""

    p_O: np.ndarray
    door_probability: float
    corners: np.ndarray
    views: int

    @property
    def is_door(self) -> bool:
        return self.door_probability > 0.5


def read_front(handle: TriangulatedHandle, maps: list[FrontMap], frames: list[CaptureFrame]
               ) -> SightedFront | None:
    """The front behind a triangulated handle from the front maps of the views that agreed on it
    (module docstring); None when fewer than two views could be read."""
    doors, votes = [], []
    for f in handle.views:
        uv = project(frames[f], handle.p_O)
        reading = None if uv is None else maps[f].read(uv)
        if reading is not None:
            doors.append(reading[0])
            votes.append((f, reading[1]))
    if len(votes) < 2:
        return None
    corners = np.empty((4, 3))
    for c in range(4):
        rays = [ray(frames[f], uv[c]) for f, uv in votes]
        corners[c] = nearest_point(np.array([o for o, _ in rays]), np.array([d for _, d in rays]))
    return SightedFront(np.asarray(handle.p_O, float), float(np.mean(doors)), corners, len(votes))


def _hinged_left(front: SightedFront) -> bool:
    """Whether the face's left edge is farther from the handle than its right edge in the
    horizontal plane (a door's handle sits near its free edge, at any opening)."""
    d_left = np.linalg.norm(front.corners[[0, 2], :2].mean(0) - front.p_O[:2])
    d_right = np.linalg.norm(front.corners[[1, 3], :2].mean(0) - front.p_O[:2])
    return bool(d_left > d_right)


def hinge_points(front: SightedFront) -> np.ndarray:
    """A door's hinge_top and hinge_bottom (2, 3) in O: the top and bottom corners of its face's
    edge farther from the handle."""
    return front.corners[[0, 2]] if _hinged_left(front) else front.corners[[1, 3]]


def opening_angle(front: SightedFront) -> float:
    """How far the face has turned from shut about a vertical axis, rad in [0, pi/2]: the mean
    turn of its top and bottom edges in the horizontal plane (shut, they run along y; doors
    open outward, so the sign needs no hinge)."""
    edges = front.corners[[1, 3], :2] - front.corners[[0, 2], :2]
    return float(np.mean(np.arctan2(np.abs(edges[:, 0]), np.abs(edges[:, 1]))))


def shut_edges(front: SightedFront) -> tuple[float, float]:
    """The front's left edge y and top edge z in O, m, when shut: a drawer's face keeps its y and
    z when pulled; a door hinged on its right edge has its left edge one face width (the corners'
    horizontal distance, the same at any opening) to the left of its hinge."""
    top = float(front.corners[:2, 2].mean())
    left_y = float(front.corners[[0, 2], 1].mean())
    if not front.is_door:
        return left_y, top
    if _hinged_left(front):
        return left_y, top
    width = np.linalg.norm(front.corners[[0, 2], :2].mean(0) - front.corners[[1, 3], :2].mean(0))
    return float(front.corners[[1, 3], 1].mean() - width), top
