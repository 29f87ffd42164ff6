"""What the 2D detector reads of the front behind each sighted handle: door or drawer, and the
four corners of its outer face in 3D.

A detector with front outputs (`HandleDetectorConfig.fronts`) gives, on the image scaled to
`FRONT_HEIGHT_PX` rows (the whole front within its view: a tall door spans most of the image),
per pixel of a front the probability that the front is a door and the offsets to the
projections of its face's corners (`nfr_drake.objects.articulated.FACE_CORNERS`: top left,
top right, bottom left, bottom right as seen from the front). For a handle triangulated in 3D
(`nfr_drake.perception.handle_triangulation`), each view that agreed on it is read around the
handle's projection and its front's corners refined from the votes of the pixels that agree
(`FrontMap.read`); the door probability is the views' mean and each corner the median of the
points nearest each two views' rays through it (`median_of_pairs`: a view that misreads a
corner moves it little), the four then squared up into an upright rectangle (`read_front`,
`upright`).

A door's hinge is the vertical edge of its face away from the handle (`hinge_points`), and the
front's place in the canonical order (left edge, then top edge, shut) follows from its corners
(`shut_edges`): the handle alone tells neither (docs/FURNITURE.md, "Fronts read by the detector").
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from nfr_drake.data.capture import CaptureFrame
from nfr_drake.perception.handle_triangulation import TriangulatedHandle, nearest_point, project, ray

FRONT_HEIGHT_PX = 64
"""Rows of the image the front outputs are read on (any image is scaled to this height)."""
READ_RADIUS_PX = 1.5
"""Pixels (of the FRONT_HEIGHT_PX image) around a handle's projection that give the first guess
of its front's corners (`FrontMap.read`)."""
AGREE_PX = (6.0, 3.0)
"""How far (pixels of the FRONT_HEIGHT_PX image) a pixel's vote for a corner may lie from the
guess to count, in the two rounds of `FrontMap.read`."""


@dataclass(frozen=True)
class FrontMap:
    """A detector's front outputs for one image, per map pixel: front_probability (h, w) that it
    shows a door or a drawer, door_probability (h, w) that its front is a door, corner_offset_px
    (h, w, 4, 2) from its centre to its front's projected face corners, map pixels (du right,
    dv down); scale (2,): image pixels per map pixel in u and v."""

    front_probability: np.ndarray
    door_probability: np.ndarray
    corner_offset_px: np.ndarray
    scale: np.ndarray

    @cached_property
    def centres(self) -> np.ndarray:
        """Map pixel centres (h, w, 2), map pixels (u, v)."""
        rows, cols = np.mgrid[0:self.front_probability.shape[0], 0:self.front_probability.shape[1]]
        return np.stack([cols + 0.5, rows + 0.5], -1).astype(np.float64)

    @cached_property
    def votes(self) -> np.ndarray:
        """Each map pixel's vote for its front's corners (h, w, 4, 2), map pixels: computed once,
        read for every handle seen in the image."""
        return self.centres[:, :, None] + self.corner_offset_px

    def read(self, uv: np.ndarray) -> tuple[float, np.ndarray] | None:
        """The front at image pixel uv (2,): its door probability and its four corners' pixels
        (4, 2) in the image; None where no front is seen. The pixels within `READ_RADIUS_PX`
        of uv give a first guess of the corners (their votes' mean, weighted by the front
        probability); each corner is then the mean of the votes for it that agree with it
        (within `AGREE_PX`, twice, the radius shrinking), a pixel's weight its front probability
        over the square of 1 + its distance to the corner (a vote's error grows with its reach).
        The door probability is the first guess's pixels' mean, weighted as they are."""
        centres, votes = self.centres, self.votes
        weight = self.front_probability.astype(np.float64)
        near = (np.linalg.norm(centres - np.asarray(uv, float) / self.scale, axis=-1) <= READ_RADIUS_PX)
        if weight[near].sum() < 0.5:
            return None
        corners = (weight[near][:, None, None] * votes[near]).sum(0) / weight[near].sum()
        for radius in AGREE_PX:
            agree = np.linalg.norm(votes - corners, axis=-1) <= radius  # (h, w, 4)
            for c in range(4):
                wc = weight * agree[..., c] / (1.0 + np.linalg.norm(centres - corners[c], axis=-1)) ** 2
                if wc.sum() > 0:
                    corners[c] = (wc[..., None] * votes[:, :, c]).sum((0, 1)) / wc.sum()
        door = float((weight[near] * self.door_probability[near]).sum() / weight[near].sum())
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
        corners[c] = median_of_pairs(np.array([o for o, _ in rays]), np.array([d for _, d in rays]))
    return SightedFront(np.asarray(handle.p_O, float), float(np.mean(doors)), upright(corners), len(votes))


def median_of_pairs(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The coordinate-wise median (3,) of the points nearest each two of the rays (n, 3), n >= 2
    (`nearest_point`): the views' corner readings are a few pixels off in most views and far off
    in a few (a neighbour's edge, a stack's bottom), and the points nearest all rays at once
    follow the far ones (`python benchmarks/front_reading.py`, docs/FURNITURE.md "Fronts read by
    the detector")."""
    pairs = [nearest_point(origins[[i, j]], directions[[i, j]])
             for i in range(len(origins)) for j in range(i + 1, len(origins))]
    return np.median(np.array(pairs), axis=0)


def upright(corners: np.ndarray) -> np.ndarray:
    """Face corners (4, 3) in O (`FACE_CORNERS` order) made an upright rectangle's, as every
    front's face is (O's z is up, doors turn about vertical hinges, drawers slide level): each
    vertical edge's two corners share their mean x and y, each horizontal edge's two their
    mean z."""
    out = corners.copy()
    for edge in ((0, 2), (1, 3)):
        out[list(edge), :2] = corners[list(edge), :2].mean(0)
    for edge in ((0, 1), (2, 3)):
        out[list(edge), 2] = corners[list(edge), 2].mean()
    return out


def _hinged_left(front: SightedFront) -> bool:
    """Whether the face's left edge is farther from the handle than its right edge in the
    horizontal plane (a door's handle sits near its free edge, at any opening)."""
    d_left = np.linalg.norm(front.corners[[0, 2], :2].mean(0) - front.p_O[:2])
    d_right = np.linalg.norm(front.corners[[1, 3], :2].mean(0) - front.p_O[:2])
    return bool(d_left > d_right)


def hinge_points(front: SightedFront, left: bool | None = None) -> np.ndarray:
    """A door's hinge_top and hinge_bottom (2, 3) in O: the top and bottom corners of its face's
    left edge (`left` True), right edge (False) or, with None, the edge farther from the handle."""
    left = _hinged_left(front) if left is None else left
    return front.corners[[0, 2]] if left else front.corners[[1, 3]]


def handle_offset(front: SightedFront) -> float:
    """Where the handle sits across its read face: its horizontal distance from the face's middle
    along the face's top edge (so at any opening) over half the face's width; 0 at the middle
    (a drawer's pull), near 1 by a vertical edge (a door's, by its free edge)."""
    across = (front.corners[1] - front.corners[0])[:2]
    width = max(float(np.linalg.norm(across)), 1e-3)
    return float(abs((front.p_O - front.corners.mean(0))[:2] @ across) / width / (width / 2))


def face_turn(front: SightedFront) -> float:
    """How far the read face has turned from shut about a vertical axis, rad in [0, pi/2]: the
    mean turn of its top and bottom edges in the horizontal plane (shut, they run along y; doors
    open outward, so the sign needs no hinge)."""
    edges = front.corners[[1, 3], :2] - front.corners[[0, 2], :2]
    return float(np.mean(np.arctan2(np.abs(edges[:, 0]), np.abs(edges[:, 1]))))


def handle_turn(front: SightedFront, hinge: np.ndarray) -> float:
    """How far a door has turned from shut about its hinge line, rad in [-pi/2, pi/2], by where
    its handle stands in front of the hinge: the arcsine of the handle's offset along O's +x over
    its horizontal distance from the hinge points (2, 3) in O (`hinge_points`); a shut door's
    handle stands only its standoff in front of the face."""
    v = front.p_O[:2] - np.asarray(hinge, float)[:, :2].mean(0)
    return float(np.arcsin(np.clip(v[0] / max(float(np.linalg.norm(v)), 1e-6), -1.0, 1.0)))


def face_width(front: SightedFront) -> float:
    """The read face's width, m: its vertical edges' horizontal distance (the same at any
    opening)."""
    return float(np.linalg.norm(front.corners[[0, 2], :2].mean(0) - front.corners[[1, 3], :2].mean(0)))


def shut_edges(front: SightedFront) -> tuple[float, float]:
    """The front's left edge y and top edge z in O, m, when shut: a drawer's face keeps its y and
    z when pulled; a door hinged on its right edge has its left edge one face width
    (`face_width`) to the left of its hinge."""
    top = float(front.corners[:2, 2].mean())
    left_y = float(front.corners[[0, 2], 1].mean())
    if not front.is_door or _hinged_left(front):
        return left_y, top
    return float(front.corners[[1, 3], 1].mean()) - face_width(front), top
