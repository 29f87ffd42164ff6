"""One 3D handle point from 2D handle maps in posed views.

Each view's handle map (`nfr_drake.perception.handle_detector`: a handle probability and, per
pixel, an offset to the projected grip centre) gives at most one sighting: the
probability-weighted mean of the votes (pixel + offset) of its strongest connected blob. Sightings are turned
into rays in the capture frame O; the point is triangulated robustly: every pair of views proposes
the point nearest both rays, the proposal whose agreeing views (reprojection within `max_error_px`,
scaled to a 128 px high image) have the largest summed mass wins, and the point nearest the rays
of those views, weighted by mass, is returned. Mass, not the number of views, decides: a bar seen
in part (one bracket, the end below an edge) gives a small blob whose centroid is off its middle,
and several such views can agree with each other.

With zero offsets the sighting is the blob's centroid, the visible middle of the handle (posts
included), which lies 1-2 cm from the grip centre, between the bar and the door.

Furniture has up to eight handles: `sightings` gives every peak of a view's votes (each handle
pixel's vote, pixel + offset, weighted by its probability, summed into a vote image; peaks after
non-maximum suppression, a peak's sighting the weighted mean of the votes near it, kept when their
mass is at least `min_mass`), and `triangulate_handles` finds the handles one after the other: the
point with the most agreeing mass (each view agreeing with at most one sighting, its nearest),
each sighting's mass weighed by 1 - (e / tolerance)^2 for its reprojection error e (MSAC's
truncated quadratic: a point between two close handles, agreeing loosely with one in some views
and the other in the rest, scores below either handle), its agreeing sightings removed, again,
until no point has `min_views` views. Where an earlier handle projects within a few pixels of a
point, the detector sees the two as one (one sighting, taken by the earlier handle): that view
neither supports nor counts against the point's share of views (`FURNITURE_MERGED_PX`).

A long upright bar (a door's) is often detected pixel by pixel in most views while its votes
spread along it and agree in few (the farther a pixel from the grip centre, the larger its vote's
error): `bar_sightings` takes each elongated blob of handle pixels as a segment, and
`triangulate_bars` finds the upright bars that the points left unexplained from the planes
through each camera and its segment (`locate_handles`, `FURNITURE_BARS`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations

import cv2
import numpy as np

from nfr_drake.data.capture import CaptureFrame

_REFERENCE_HEIGHT_PX = 128.0
MIN_VIEWS = 3
"""Views that must agree on a handle for a point."""
AGREE_PX = 3.0
"""A sighting agrees with a triangulated point within this reprojection error, px of a 128 px high
image (scaled to the frame's height)."""
INSIDE_MASK_PX = 3.0
"""How far inside the object's mask a handle pixel must lie, px (scaled to a 128 px high image),
in `inside_masks`."""


@dataclass(frozen=True)
class HandleMap:
    """A detector's output for one image: probability (H, W) float32 of each pixel showing the
    handle, and offset_px (H, W, 2) float32 from each pixel's centre to the projected grip
    centre, pixels (du right, dv down)."""

    probability: np.ndarray
    offset_px: np.ndarray

    @classmethod
    def centroid_only(cls, probability: np.ndarray) -> HandleMap:
        """A map without offsets: sightings are the blobs' centroids."""
        return cls(probability, np.zeros((*probability.shape, 2), np.float32))

    def inside(self, mask: np.ndarray, margin_px: float = INSIDE_MASK_PX) -> HandleMap:
        """This map with the probability 0 off the object's mask (H, W) (probability > 0.5) and
        within `margin_px` (scaled to a 128 px high image) of its edge."""
        margin = margin_px * mask.shape[0] / _REFERENCE_HEIGHT_PX
        depth = cv2.distanceTransform((np.asarray(mask) > 0.5).astype(np.uint8), cv2.DIST_L2, 3)
        return HandleMap(np.where(depth > margin, self.probability, 0.0).astype(np.float32), self.offset_px)


def inside_masks(maps: list[HandleMap], masks: list[np.ndarray]) -> list[HandleMap]:
    """Each view's map kept only well inside the object's mask (`HandleMap.inside`): on a room
    photo painted off the segmenter's mask, the cut along the object's bottom edge (a dark strip of
    floor or shadow left between the object and the paint) reads as a handle bar, and several
    views agree on it since it is a real edge (docs/ROOMS.md, "Handles sighted on the object's
    edge")."""
    return [m.inside(mask) for m, mask in zip(maps, masks, strict=True)]


@dataclass(frozen=True)
class HandleSighting:
    """A handle in one view: pixel (u, v) (top-left pixel centre at (0.5, 0.5)) and its mass
    (summed probability of the blob, pixels)."""

    frame: int
    uv: np.ndarray
    mass: float


@dataclass(frozen=True)
class TriangulatedHandle:
    """p_O (3,) m in frame O; views: indices of the frames whose sighting agrees; rms_px: their
    reprojection error RMS, px (of the frames' own size); sightings: how many views saw a handle."""

    p_O: np.ndarray
    views: tuple[int, ...]
    rms_px: float
    sightings: int

    def rms_reference_px(self, frames: list[CaptureFrame]) -> float:
        """rms_px scaled to a 128 px high image (the agreeing frames' mean height): comparable
        across photo sizes, as the agreement tolerance is."""
        if not self.views:
            return self.rms_px
        height = np.mean([frames[v].camera.height for v in self.views])
        return float(self.rms_px * _REFERENCE_HEIGHT_PX / height)


def sighting(handle_map: HandleMap, frame: int, threshold: float = 0.5,
             min_mass: float = 0.5) -> HandleSighting | None:
    """The votes of the strongest blob of pixels with probability > threshold, or None when there
    is none or its summed probability is below `min_mass`."""
    prob = handle_map.probability
    mask = (prob > threshold).astype(np.uint8)
    count, labels = cv2.connectedComponents(mask, connectivity=8)
    if count < 2:
        return None
    masses = np.bincount(labels.ravel(), weights=prob.ravel(), minlength=count)[1:]
    best = int(np.argmax(masses)) + 1
    if masses[best - 1] < min_mass:
        return None
    rows, cols = np.nonzero(labels == best)
    w = prob[rows, cols]
    votes = np.stack([cols + 0.5, rows + 0.5], -1) + handle_map.offset_px[rows, cols]
    uv = (w[:, None] * votes).sum(0) / np.sum(w)
    return HandleSighting(frame, uv, float(masses[best - 1]))


def sightings(handle_map: HandleMap, frame: int, threshold: float = 0.5, min_mass: float = 0.5,
              radius_px: float = 2.5) -> list[HandleSighting]:
    """Every handle in one view (module docstring), strongest first: peaks of the vote image at
    least `radius_px` (scaled to a 128 px high image) apart; a sighting is the mean of the votes
    within that radius of its peak, weighted by probability, each vote counted once."""
    prob = handle_map.probability
    H, W = prob.shape
    rows, cols = np.nonzero(prob > threshold)
    if rows.size == 0:
        return []
    w = prob[rows, cols].astype(np.float64)
    votes = np.stack([cols + 0.5, rows + 0.5], -1) + handle_map.offset_px[rows, cols]
    r = radius_px * H / _REFERENCE_HEIGHT_PX
    image = np.zeros((H, W), np.float32)
    inside = (votes[:, 0] >= 0) & (votes[:, 0] < W) & (votes[:, 1] >= 0) & (votes[:, 1] < H)
    np.add.at(image, (votes[inside, 1].astype(int), votes[inside, 0].astype(int)), w[inside])
    image = cv2.GaussianBlur(image, (0, 0), max(0.5, r / 2.5))
    size = 2 * int(np.ceil(r)) + 1
    peaks = np.argwhere((image >= cv2.dilate(image, np.ones((size, size), np.uint8))) & (image > 1e-3))
    free = np.ones(len(votes), bool)
    found = []
    for pv, pu in sorted(peaks.tolist(), key=lambda rc: -image[rc[0], rc[1]]):
        near = free & (np.linalg.norm(votes - [pu + 0.5, pv + 0.5], axis=1) <= r)
        if w[near].sum() < min_mass:
            continue
        free &= ~near
        found.append(HandleSighting(frame, (w[near, None] * votes[near]).sum(0) / w[near].sum(),
                                    float(w[near].sum())))
    return sorted(found, key=lambda s: -s.mass)


def ray(frame: CaptureFrame, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin and unit direction in O of the ray through pixel uv of a frame."""
    cam = frame.camera
    if not cam.distortion:
        xy = (uv - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    else:
        xy = cv2.undistortPoints((uv - 0.5).reshape(1, 1, 2), cam.K_opencv, cam.dist_opencv).reshape(2)
    d = frame.X_OC[:3, :3] @ np.array([xy[0], xy[1], 1.0])
    return frame.X_OC[:3, 3].copy(), d / np.linalg.norm(d)


def nearest_point(origins: np.ndarray, directions: np.ndarray,
                   weights: np.ndarray | None = None) -> np.ndarray:
    """The point (3,) of least weighted summed squared distance to the rays (n, 3), n >= 2."""
    w = np.ones(len(origins)) if weights is None else weights
    P = (np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]) * w[:, None, None]
    return np.linalg.lstsq(P.sum(0), np.einsum("nij,nj->i", P, origins), rcond=None)[0]


def project(frame: CaptureFrame, p_O: np.ndarray) -> np.ndarray | None:
    """Pixel (u, v) (top-left pixel centre at (0.5, 0.5)) of the point p_O (3,) in a frame, with
    its distortion; None behind the camera."""
    X_CO = np.linalg.inv(frame.X_OC)
    p_C = X_CO[:3, :3] @ p_O + X_CO[:3, 3]
    if p_C[2] <= 1e-6:
        return None
    cam = frame.camera
    proj = cv2.projectPoints(p_C.reshape(1, 3), np.zeros(3), np.zeros(3), cam.K_opencv,
                             cam.dist_opencv)[0]
    return proj.reshape(2) + 0.5


def _reprojection_px(frame: CaptureFrame, p_O: np.ndarray, uv: np.ndarray) -> float:
    """Pixel distance between uv and the projection of p_O (inf behind the camera)."""
    uv_p = project(frame, p_O)
    return np.inf if uv_p is None else float(np.linalg.norm(uv_p - uv))


def triangulate_handle(frames: list[CaptureFrame], sightings: list[HandleSighting],
                       max_error_px: float = AGREE_PX, min_views: int = MIN_VIEWS
                       ) -> TriangulatedHandle | None:
    """Robust triangulation (module docstring); None when fewer than `min_views` views agree."""
    if len(sightings) < max(2, min_views):
        return None
    rays = [ray(frames[s.frame], s.uv) for s in sightings]
    origins = np.array([o for o, _ in rays])
    directions = np.array([d for _, d in rays])
    tolerance = [max_error_px * frames[s.frame].camera.height / _REFERENCE_HEIGHT_PX
                 for s in sightings]

    def agreeing(p: np.ndarray) -> tuple[list[int], float]:
        errors = [_reprojection_px(frames[s.frame], p, s.uv) for s in sightings]
        inliers = [i for i, e in enumerate(errors) if e <= tolerance[i]]
        return inliers, float(np.sqrt(np.mean([errors[i] ** 2 for i in inliers]))) if inliers else np.inf

    mass = np.array([s.mass for s in sightings])
    best: tuple[float, float, list[int]] | None = None
    for i, j in combinations(range(len(sightings)), 2):
        if abs(float(directions[i] @ directions[j])) > np.cos(np.radians(2.0)):
            continue  # nearly parallel rays fix no depth
        inliers, rms = agreeing(nearest_point(origins[[i, j]], directions[[i, j]]))
        score = float(mass[inliers].sum()) if len(inliers) >= min_views else 0.0
        if best is None or (score, -rms) > (best[0], -best[1]):
            best = (score, rms, inliers)
    if best is None or best[0] == 0.0:
        return None
    inliers = best[2]
    for _ in range(2):  # refit on the agreeing views, then on those that agree with the refit
        p = nearest_point(origins[inliers], directions[inliers], mass[inliers])
        inliers, _ = agreeing(p)
        if len(inliers) < min_views:
            return None
    p = nearest_point(origins[inliers], directions[inliers], mass[inliers])
    return TriangulatedHandle(p, tuple(sightings[i].frame for i in inliers), agreeing(p)[1],
                              len(sightings))


def _project_many(frame: CaptureFrame, p_O: np.ndarray) -> np.ndarray:
    """Pixels (m, 2) of points p_O (m, 3) in a frame, with its distortion; inf behind it."""
    X_CO = np.linalg.inv(frame.X_OC)
    p_C = p_O @ X_CO[:3, :3].T + X_CO[:3, 3]
    cam = frame.camera
    uv = cv2.projectPoints(p_C.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K_opencv,
                           cam.dist_opencv)[0].reshape(-1, 2) + 0.5
    uv[p_C[:, 2] <= 1e-6] = np.inf
    return uv


def _agreeing(frames: list[CaptureFrame], found: list[HandleSighting], tolerance: np.ndarray,
              points: np.ndarray, earlier: np.ndarray | None = None, merged_px: float = 0.0
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For points (m, 3): which sightings agree (m, n) bool, at most one per view (the nearest
    projection within its tolerance), their reprojection errors (m, n) px, and in how many of
    the frames each point projects into the image (m,), leaving out the frames where one of the
    `earlier` points (k, 3) projects within `merged_px` (scaled to a 128 px high image) of it."""
    n = len(found)
    errors = np.full((len(points), n), np.inf)
    agree = np.zeros((len(points), n), bool)
    inside = np.zeros(len(points), int)
    uv = np.array([s.uv for s in found]).reshape(-1, 2)
    for f, frame in enumerate(frames):
        projected = _project_many(frame, points)
        in_image = ((projected >= 0) & (projected <= [frame.camera.width, frame.camera.height])).all(1)
        if earlier is not None and len(earlier) and merged_px > 0:
            gap = np.linalg.norm(projected[:, None] - _project_many(frame, earlier)[None], axis=-1)
            in_image &= gap.min(1) > merged_px * frame.camera.height / _REFERENCE_HEIGHT_PX
        inside += in_image
        idx = np.array([i for i, s in enumerate(found) if s.frame == f], int)
        if idx.size == 0:
            continue
        e = np.linalg.norm(projected[:, None] - uv[idx][None], axis=-1)
        errors[:, idx] = e
        nearest = np.argmin(e, axis=1)
        ok = e[np.arange(len(points)), nearest] <= tolerance[idx][nearest]
        agree[np.flatnonzero(ok), idx[nearest[ok]]] = True
    return agree, errors, inside


SIDE_BY_SIDE_M = 0.04
"""`triangulate_handles`: two handles side by side at least this far apart are two even where
they project within a few pixels of each other in every view, m. A pair of doors' handles can be
9 cm apart, 5-7 px at 128 px (pipeline pieces 52, 69, 70 of seed 200 lost one of them to the
projection test); a bar the detector splits in two gives two points along it, and a door's bar
is upright (so the test stays for points one above the other)."""


STACKED_M = 0.10
"""`triangulate_handles` with bar segments: two points close in every view are one handle only
when nearer than this, m, or where one bar holds both (`_one_handle`). Stacked fronts' pulls lie
at least a front's height apart (a generated drawer front is at least 12 cm tall, as a kitchen's
is); nearer points are one handle that the detector's votes split."""


def _side_by_side(a: np.ndarray, b: np.ndarray, apart_m: float) -> bool:
    """Whether points a, b (3,) in O lie side by side (further apart in xy than in z) and at
    least `apart_m` apart."""
    horizontal = float(np.linalg.norm(a[:2] - b[:2]))
    return horizontal > abs(float(a[2] - b[2])) and horizontal >= apart_m


def _holding_bars(frames: list[CaptureFrame], bars: list[BarSighting], views: tuple[int, ...],
                  a: np.ndarray, b: np.ndarray, max_error_px: float) -> list[BarSighting]:
    """Of the `views`, each one's first bar segment that both points a, b (3,) in O project within
    `max_error_px` (scaled to a 128 px high image) of."""
    holding = []
    for f in views:
        uv_a, uv_b = project(frames[f], a), project(frames[f], b)
        tolerance = max_error_px * frames[f].camera.height / _REFERENCE_HEIGHT_PX
        if uv_a is not None and uv_b is not None:
            holding += [bar for bar in bars if bar.frame == f and bar.distance_px(uv_a) <= tolerance
                        and bar.distance_px(uv_b) <= tolerance][:1]
    return holding


def _on_one_bar(frames: list[CaptureFrame], bars: list[BarSighting], views: tuple[int, ...],
                a: np.ndarray, b: np.ndarray, max_error_px: float) -> bool:
    """Whether points a, b (3,) in O both project within `max_error_px` (scaled to a 128 px high
    image) of one bar segment in at least half of the `views`."""
    return 2 * len(_holding_bars(frames, bars, views, a, b, max_error_px)) >= len(views)


def _one_handle(frames: list[CaptureFrame], a: np.ndarray, b: np.ndarray, views: tuple[int, ...],
                tolerance_px: np.ndarray, side_by_side_m: float, bars: list[BarSighting] | None,
                max_error_px: float) -> str:
    """How points a, b (3,) in O are one handle, seen in `views` with those views' agreement
    tolerances (px): "votes" (a grip whose votes split: not side by side, projecting within twice
    the tolerance of each other in every view and, given the views' `bars`, nearer than
    `STACKED_M`), "bar" (not side by side and one bar segment holds both, `_on_one_bar`), or ""
    (two handles)."""
    if _side_by_side(a, b, side_by_side_m):
        return ""
    close = all(np.linalg.norm(_project_many(frames[f], a[None])[0] - _project_many(frames[f], b[None])[0])
                <= 2 * t for f, t in zip(views, tolerance_px, strict=True))
    if close and (bars is None or np.linalg.norm(a - b) < STACKED_M):
        return "votes"
    return "bar" if bars is not None and _on_one_bar(frames, bars, views, a, b, max_error_px) else ""


def triangulate_handles(frames: list[CaptureFrame], found: list[HandleSighting],
                        max_error_px: float = AGREE_PX, min_views: int = MIN_VIEWS,
                        min_share: float = 0.0, side_by_side_m: float = SIDE_BY_SIDE_M,
                        loose_share: float = 0.0, loose_rms_px: float = np.inf,
                        merged_px: float = 0.0, bars: list[BarSighting] | None = None
                        ) -> list[TriangulatedHandle]:
    """Several handles from the sightings of all views (module docstring), strongest first; a
    point that projects within 2 `max_error_px` of an earlier one in all its views is the same
    handle and dropped, unless the two lie side by side (further apart horizontally in O than
    vertically) and at least `side_by_side_m` apart: the handles of a pair of doors, near the
    edge where the doors meet (`SIDE_BY_SIDE_M`); with the views' `bars` (`bar_sightings`), two
    at least `STACKED_M` apart only where both lie on one bar segment in at least half its views
    (a bar whose votes split, not two stacked drawers' pulls, `_one_handle`), and two that one bar
    holds are one handle even where they project further apart: a long bar's votes land along it,
    and the handle is then its point nearest the bar's middle as the views' segments holding its
    points see it (a segment can run on across the gap to a stacked front's bar, so the middle
    itself can lie off the bar's). A point must
    agree with at least `min_share` of the views it projects into (sightings that agree by chance
    across a few views do not), and one that agrees with fewer than `loose_share` of them must
    agree within `loose_rms_px` RMS (scaled to a 128 px high image): edges that line up by chance
    agree with few views and loosely (`FURNITURE_LOOSE`). Neither share counts the views where an
    earlier handle projects within `merged_px` (scaled to a 128 px high image) of the point
    (`FURNITURE_MERGED_PX`)."""
    found = list(found)
    tolerance = np.array([max_error_px * frames[s.frame].camera.height / _REFERENCE_HEIGHT_PX
                          for s in found])
    rays = [ray(frames[s.frame], s.uv) for s in found]
    origins = np.array([o for o, _ in rays]).reshape(-1, 3)
    directions = np.array([d for _, d in rays]).reshape(-1, 3)
    mass = np.array([s.mass for s in found])
    view = np.array([s.frame for s in found])
    left = np.ones(len(found), bool)
    handles: list[TriangulatedHandle] = []
    spans: list[list[np.ndarray]] = []  # each handle's points, with those one bar joined to it
    while left.sum() >= max(2, min_views):
        earlier = np.array([h.p_O for h in handles]).reshape(-1, 3)
        i, j = np.triu_indices(len(found), 1)
        keep = (left[i] & left[j] & (view[i] != view[j])
                & (np.abs(np.einsum("ij,ij->i", directions[i], directions[j])) < np.cos(np.radians(2.0))))
        i, j = i[keep], j[keep]
        if i.size == 0:
            break
        # nearest point to two rays: the middle of their common perpendicular
        d_i, d_j, w0 = directions[i], directions[j], origins[i] - origins[j]
        b = np.einsum("ij,ij->i", d_i, d_j)
        d, e = np.einsum("ij,ij->i", d_i, w0), np.einsum("ij,ij->i", d_j, w0)
        s_i, s_j = (b * e - d) / (1 - b * b), (e - b * d) / (1 - b * b)
        points = 0.5 * (origins[i] + s_i[:, None] * d_i + origins[j] + s_j[:, None] * d_j)
        agree, errors, inside = _agreeing(frames, found, tolerance, points, earlier, merged_px)
        agree &= left
        count = agree.sum(1)
        enough = (count >= min_views) & (count >= min_share * inside)
        closeness = 1.0 - (np.where(agree, errors, 0.0) / tolerance) ** 2
        score = np.where(enough, (agree * mass * closeness).sum(1), 0.0)
        if score.max() == 0.0:
            break
        rms = np.sqrt(np.where(agree, errors ** 2, 0).sum(1) / np.maximum(count, 1))
        inliers = np.flatnonzero(agree[np.lexsort((rms, -score))[0]])
        for _ in range(3):  # refit on the agreeing sightings, then on those agreeing with the refit
            p = nearest_point(origins[inliers], directions[inliers], mass[inliers])
            agree_p, errors_p, inside_p = _agreeing(frames, found, tolerance, p[None], earlier, merged_px)
            new = np.flatnonzero(agree_p[0] & left)
            if len(new) < max(min_views, min_share * inside_p[0]):
                break
            inliers = new
        left[inliers] = False
        if len(new) < max(min_views, min_share * inside_p[0]):
            continue
        p = nearest_point(origins[inliers], directions[inliers], mass[inliers])
        _, errors_p, inside_p = _agreeing(frames, found, tolerance, p[None], earlier, merged_px)
        rms_px = float(np.sqrt(np.mean(errors_p[0, inliers] ** 2)))
        rms_128 = float(np.sqrt(np.mean((errors_p[0, inliers] * max_error_px / tolerance[inliers]) ** 2)))
        if len(inliers) < loose_share * inside_p[0] and rms_128 > loose_rms_px:
            continue
        frames_in = tuple(int(view[k]) for k in inliers)
        how = [_one_handle(frames, h.p_O, p, frames_in, tolerance[inliers], side_by_side_m, bars,
                           max_error_px) for h in handles]
        k = next((k for k, kind in enumerate(how) if kind), None)
        if k is None:
            handles.append(TriangulatedHandle(p, frames_in, rms_px, len(set(view.tolist()))))
            spans.append([p])
        elif how[k] == "bar":  # a long bar's votes land along it: of its points, the most central
            spans[k].append(p)
            views_k = tuple(sorted(set(handles[k].views) | set(frames_in)))
            z = [q[2] for q in spans[k]]
            low, high = spans[k][int(np.argmin(z))], spans[k][int(np.argmax(z))]
            middle = 0.5 * (low + high)  # where fewer than two views' segments hold the span
            holding = _holding_bars(frames, bars, views_k, low, high, max_error_px)
            if len(holding) >= 2:
                middle = _bar_through([b.plane(frames[b.frame]) for b in holding],
                                      [ray(frames[b.frame], b.centre)[1] for b in holding],
                                      np.array([b.mass for b in holding]))[0]
            nearest = spans[k][int(np.argmin([np.linalg.norm(q - middle) for q in spans[k]]))]
            handles[k] = replace(handles[k], p_O=nearest, views=views_k)
    return handles


BAR_MIN_PX = 8.0
"""`bar_sightings`: a blob of handle pixels at least this long (px, scaled to a 128 px high image)
and `BAR_ASPECT` times as long as it is wide is a bar's segment."""
BAR_ASPECT = 3.0
BAR_UPRIGHT_DEG = 20.0
"""`triangulate_bars` keeps bars within this of O's z (upright: a door's bar; a drawer's pull is
horizontal, and a horizontal line seen by cameras spread along it fixes no depth)."""
BAR_PARALLEL_DEG = 15.0
"""A segment agrees with a 3D bar only if the bar's projection runs within this of its axis."""


@dataclass(frozen=True)
class BarSighting:
    """An elongated blob of handle pixels in one view, a bar seen whole or in part whatever its
    votes say of its grip centre: the middle of its extent `centre` (2,) px (top-left pixel centre
    at (0.5, 0.5)), unit `axis` (2,) along it, `half_length` px, and its mass (summed
    probability, pixels)."""

    frame: int
    centre: np.ndarray
    axis: np.ndarray
    half_length: float
    mass: float

    def distance_px(self, uv: np.ndarray) -> float:
        """Distance, px, from pixel uv (2,) to the segment."""
        d = np.asarray(uv, float) - self.centre
        t = float(np.clip(d @ self.axis, -self.half_length, self.half_length))
        return float(np.linalg.norm(d - t * self.axis))

    def plane(self, frame: CaptureFrame) -> tuple[np.ndarray, np.ndarray]:
        """The plane through the camera centre and the segment's image line, in O: a point on it
        (3,) (the camera centre) and its unit normal (3,)."""
        origin, d_a = ray(frame, self.centre - self.half_length * self.axis)
        _, d_b = ray(frame, self.centre + self.half_length * self.axis)
        normal = np.cross(d_a, d_b)
        return origin, normal / np.linalg.norm(normal)


def bar_sightings(handle_map: HandleMap, frame: int, threshold: float = 0.5,
                  min_length_px: float = BAR_MIN_PX, aspect: float = BAR_ASPECT) -> list[BarSighting]:
    """The view's blobs of pixels with probability > threshold (8-connected) that are at least
    `min_length_px` long (scaled to a 128 px high image) and `aspect` times as long as wide
    (their probability-weighted second moments), as segments along their principal axis."""
    prob = handle_map.probability
    count, labels = cv2.connectedComponents((prob > threshold).astype(np.uint8), connectivity=8)
    min_length = min_length_px * prob.shape[0] / _REFERENCE_HEIGHT_PX
    bars = []
    for blob in range(1, count):
        rows, cols = np.nonzero(labels == blob)
        if rows.size < 3:
            continue
        w = prob[rows, cols].astype(np.float64)
        xy = np.stack([cols + 0.5, rows + 0.5], -1)
        mean = (w[:, None] * xy).sum(0) / w.sum()
        values, vectors = np.linalg.eigh(np.cov((xy - mean).T, aweights=w, bias=True))
        axis = vectors[:, 1]
        along = (xy - mean) @ axis
        length = float(along.max() - along.min()) + 1.0  # pixel centres to pixel edges
        width = np.sqrt(12.0 * max(float(values[0]), 0.0)) + 1.0
        if length < min_length or length < aspect * width:
            continue
        centre = mean + 0.5 * (along.max() + along.min()) * axis
        bars.append(BarSighting(frame, centre, axis, 0.5 * length, float(w.sum())))
    return bars


def _on_bar(origins: np.ndarray, normals: np.ndarray, rays: np.ndarray, weights: np.ndarray,
            along_weight: float = 1e-3) -> np.ndarray:
    """The point (3,) on the planes (origins, unit normals (n, 3)) in least squares, placed along
    their common line by the rays through the segments' middles (origins, unit directions (n, 3))
    with `along_weight`: the middle of the bar as the views see it."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for o, n, d, w in zip(origins, normals, rays, weights, strict=True):
        P = np.outer(n, n) + along_weight * (np.eye(3) - np.outer(d, d))
        A += w * P
        b += w * P @ o
    return np.linalg.lstsq(A, b, rcond=None)[0]


def _bar_through(planes: list[tuple[np.ndarray, np.ndarray]], middles: list[np.ndarray],
                 weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bar (3D line) in the segments' planes (`BarSighting.plane`: a point, unit normal) of
    two or more views: its middle as they see it (`_on_bar`, with the rays through the segments'
    middles, unit (3,) each, and weights (n,)) and its unit direction (3,), both in O."""
    normals = np.array([n for _, n in planes])
    u = np.linalg.svd(normals)[2][-1]  # the direction in every plane
    p = _on_bar(np.array([o for o, _ in planes]), normals, np.array(middles), np.asarray(weights, float))
    return p, u


def _bar_agreement(frames: list[CaptureFrame], bars: list[BarSighting], tolerance: np.ndarray,
                   p: np.ndarray, u: np.ndarray, left: np.ndarray) -> tuple[list[int], int]:
    """Which of the `left` segments agree with the bar through p (3,) along unit u (3,) in O (at most
    one per view, the nearest: p's projection within its tolerance of the segment, the bar's
    projected direction within `BAR_PARALLEL_DEG` of its axis), and in how many frames p projects
    into the image."""
    agree, inside = [], 0
    cos_parallel = np.cos(np.radians(BAR_PARALLEL_DEG))
    for f, frame in enumerate(frames):
        uv = project(frame, p)
        tip = project(frame, p + 0.05 * u)
        if uv is None or tip is None:
            continue
        inside += bool(np.all(uv >= 0) and np.all(uv <= [frame.camera.width, frame.camera.height]))
        direction = (tip - uv) / max(float(np.linalg.norm(tip - uv)), 1e-9)
        near = [(bars[k].distance_px(uv), k) for k in np.flatnonzero(left) if bars[k].frame == f
                and abs(float(direction @ bars[k].axis)) >= cos_parallel]
        near = [(e, k) for e, k in near if e <= tolerance[k]]
        if near:
            agree.append(min(near)[1])
    return agree, inside


def _points_on_bar(frames: list[CaptureFrame], bars: list[BarSighting], agree: list[int],
                   points: list[HandleSighting], max_error_px: float, p: np.ndarray, u: np.ndarray
                   ) -> dict[int, float]:
    """The views without an agreeing segment (`agree`, indices into `bars`) where one of the point
    sightings lies within `max_error_px` (scaled to a 128 px high image) of the bar through p (3,)
    along unit u (3,) in O, as long as the longest agreeing segment shows it: per such view, the
    largest such sighting's mass. A bar's votes land anywhere along it, and its pixels make a
    segment in the views that see it whole: the others' sightings on it are its views too."""
    half_m = 0.0
    for k in agree:  # the bar's half length, m, from each agreeing segment's length
        frame = frames[bars[k].frame]
        uv, tip = project(frame, p), project(frame, p + 0.05 * u)
        if uv is not None and tip is not None and np.linalg.norm(tip - uv) > 1e-9:
            half_m = max(half_m, bars[k].half_length * 0.05 / float(np.linalg.norm(tip - uv)))
    seen = {bars[k].frame for k in agree}
    support: dict[int, float] = {}
    for f, frame in enumerate(frames):
        if f in seen:
            continue
        a, b = project(frame, p - half_m * u), project(frame, p + half_m * u)
        if a is None or b is None:
            continue
        tolerance = max_error_px * frame.camera.height / _REFERENCE_HEIGHT_PX
        length = float(np.linalg.norm(b - a))
        axis = (b - a) / length if length > 1e-9 else np.zeros(2)
        segment = BarSighting(f, (a + b) / 2, axis, length / 2, 0.0)
        masses = [s.mass for s in points if s.frame == f and segment.distance_px(s.uv) <= tolerance]
        if masses:
            support[f] = max(masses)
    return support


def triangulate_bars(frames: list[CaptureFrame], bars: list[BarSighting],
                     handles: list[TriangulatedHandle], max_error_px: float = AGREE_PX,
                     min_views: int = MIN_VIEWS, min_share: float = 0.0,
                     points: list[HandleSighting] | None = None) -> list[TriangulatedHandle]:
    """Upright bars (within `BAR_UPRIGHT_DEG` of O's z) from the views' segments that none of the
    `handles` (points already triangulated) explains (projects within `max_error_px` of, scaled
    to a 128 px high image), strongest first: every two segments of two views whose planes cross
    at least 5 degrees apart propose their common line, the point on it nearest the rays
    through their middles; the proposal whose agreeing views have the largest summed mass, with
    at least `min_views` agreeing segments and `min_share` of the views it projects into
    agreeing, is refitted on its segments (`_on_bar`) and its agreeing segments removed; again
    until none is left. A view agrees by a segment (`_bar_agreement`) or, given the views' point
    sightings `points` (those no handle explains), by one lying on the bar (`_points_on_bar`):
    those count toward the share only. Each bar is returned as its middle as the agreeing
    segments see it, with the views of both kinds."""
    tolerance = np.array([max_error_px * frames[b.frame].camera.height / _REFERENCE_HEIGHT_PX for b in bars])
    planes = [b.plane(frames[b.frame]) for b in bars]
    middles = [ray(frames[b.frame], b.centre)[1] for b in bars]

    def explained(frame: int, distance_px) -> bool:
        """Whether a handle projects within the tolerance of a sighting in `frame` (distance_px:
        from a pixel (2,) to the sighting)."""
        return any((uv := project(frames[frame], h.p_O)) is not None
                   and distance_px(uv) <= max_error_px * frames[frame].camera.height / _REFERENCE_HEIGHT_PX
                   for h in handles)

    left = ~np.array([explained(b.frame, b.distance_px) for b in bars], bool).reshape(-1)
    loose = [s for s in points or []
             if not explained(s.frame, lambda uv, s=s: float(np.linalg.norm(uv - s.uv)))]
    mass = np.array([b.mass for b in bars])
    upright, coincident = np.cos(np.radians(BAR_UPRIGHT_DEG)), np.cos(np.radians(5.0))
    found: list[TriangulatedHandle] = []

    def fit(members: list[int]) -> tuple[np.ndarray, np.ndarray]:
        return _bar_through([planes[k] for k in members], [middles[k] for k in members], mass[members])

    def support(agree: list[int], p: np.ndarray, u: np.ndarray) -> dict[int, float]:
        return _points_on_bar(frames, bars, agree, loose, max_error_px, p, u) if loose else {}

    def agreement(p: np.ndarray, u: np.ndarray) -> tuple[list[int], dict[int, float], bool]:
        """The agreeing segments, the views agreeing by a point and whether they are enough."""
        agree, inside = _bar_agreement(frames, bars, tolerance, p, u, left)
        by_point = support(agree, p, u)
        views = len(agree) + len(by_point)
        return agree, by_point, len(agree) >= min_views and views >= min_share * inside

    while left.sum() >= max(2, min_views):
        best: tuple[float, list[int]] | None = None
        for i, j in combinations(np.flatnonzero(left), 2):
            if bars[i].frame == bars[j].frame or abs(float(planes[i][1] @ planes[j][1])) > coincident:
                continue
            p, u = fit([i, j])
            if abs(u[2]) < upright:
                continue
            agree, by_point, enough = agreement(p, u)
            score = float(mass[agree].sum()) + sum(by_point.values())
            if enough and (best is None or score > best[0]):
                best = (score, agree)
        if best is None:
            break
        members = best[1]
        p, u = fit(members)
        agree, _, enough = agreement(p, u)
        left[members] = False
        if not enough or abs(u[2]) < upright:
            continue
        p, _ = fit(agree)
        by_point = support(agree, p, u)
        left[agree] = False
        errors = [bars[k].distance_px(uv) if (uv := project(frames[bars[k].frame], p)) is not None else np.inf
                  for k in agree]
        found.append(TriangulatedHandle(p, tuple(sorted([bars[k].frame for k in agree] + list(by_point))),
                                        float(np.sqrt(np.mean(np.square(errors)))),
                                        len({b.frame for b in bars} | {s.frame for s in loose})))
    return found


FURNITURE_MIN_SHARE = 0.5
"""`min_share` of `locate_handles`: chosen on 20 furniture capture sets of seed 8 (10 views, 128
px) among 0, 0.3 and 0.5 (docs/FURNITURE.md, "Handle detector")."""


FURNITURE_LOOSE = (0.6, 1.2)
"""`loose_share` and `loose_rms_px` of `locate_handles`, chosen on the pipeline's photos of the
development seed 901 (`python benchmarks/furniture_pipeline_sightings.py --seed 901`, 100 pieces, 10
views): the points of no front agreed with 3-5 views in 14 of 29 cases, at 1.62 px RMS (median),
the fronts' with 8-10 views in 294 of 339, at 0.72 px; the rule drops 10 of the 29 and none of the
339 (docs/FURNITURE.md, "Handle detector")."""


FURNITURE_MERGED_PX = 4.0
"""`merged_px` of `locate_handles`: a pair of doors' knobs 9-10 cm apart project 2-5 px apart in
the oblique views, where the detector gives one sighting between them, and the second knob was
lost for agreeing with fewer than half its views. Chosen among 0, 3, 4 and 6 px on the
pipeline's photos of the development seed 901 (`python benchmarks/furniture_pipeline_sightings.py
--seed 901 --merged-px M`): 0, 3, 4, 6 px sight 345, 348, 349, 349 of 376 fronts, with 9, 10,
10, 19 points of no front; docs/FURNITURE.md, "Handle detector: several handles"."""


FURNITURE_BEHIND_M = 0.05
"""`in_front`'s margin in `locate_handles`, m: on the development pipeline's photos (seed 901,
shut pieces; `python benchmarks/furniture_pipeline_sightings.py --seed 901`) no point of a
front lies more than 2.3 cm behind all the other points (the triangulated depth's error), and
no point of no front more than 2.2 cm (docs/FURNITURE.md, "Handle detector: several
handles")."""


FURNITURE_BARS = True
"""Whether `locate_handles` adds the upright bars the points leave unexplained
(`triangulate_bars`) and keeps two close points apart unless one bar holds both (`_on_one_bar`):
on the pipeline's photos (`python benchmarks/furniture_pipeline_sightings.py [--no-bars]`) fronts
sighted 349 -> 350 of 376 on the development seed 901, 257 -> 260 of 290 on the evaluation seed
200 (docs/FURNITURE.md, "Handle detector: several handles")."""
FURNITURE_BAR_SHARE = 0.5
"""`triangulate_bars`' min_share in `locate_handles`: 0.5 and 0.3 tie on the development seed's
part to open (87 of 100), 0.3 with two more fronts and one more point of no front; the
stricter was kept (docs/FURNITURE.md)."""


FURNITURE_IN_IMAGES = 0.5
"""`in_most_images`' share in `locate_handles`: the furniture evaluation's unseen cameras (35 degrees
field of view, `furniture_ood_fov35`) made a point of piece 12 nearer the cameras than the piece,
inside few of its images (docs/FURNITURE.md, "Handle detector: several handles")."""


FURNITURE_BAR_POINTS = True
"""Whether `locate_handles` counts the views' point sightings that lie on an upright bar as the
bar's views (`triangulate_bars`' points): where a bar is seen whole in a few views its votes
land anywhere along it in the others (docs/FURNITURE.md, "Handle detector: several handles")."""


def in_most_images(handles: list[TriangulatedHandle], frames: list[CaptureFrame], share: float
                   ) -> list[TriangulatedHandle]:
    """The handles (p_O in O) that project inside at least `share` of the frames' images: every
    view looks at the object, so a handle on it is in nearly all of them, while rays of a few views
    can cross near the cameras, far in front of the object, where most images do not reach."""
    def in_image(frame: CaptureFrame, p_O: np.ndarray) -> bool:
        uv = _project_many(frame, p_O[None])[0]
        return bool(np.all(uv >= 0) and np.all(uv <= [frame.camera.width, frame.camera.height]))

    return [h for h in handles if sum(in_image(f, h.p_O) for f in frames) >= share * len(frames)]


def in_front(handles: list[TriangulatedHandle], behind_m: float) -> list[TriangulatedHandle]:
    """The handles (p_O in O, whose +x is the fronts' outward normal) but those more than
    `behind_m` behind every other one, where there are at least two others: a handle stands in
    front of its front, and a front, shut or open, on or in front of the carcass's front plane,
    so a point behind all the others (an edge inside the carcass that lines up across views) is
    no handle."""
    x = np.array([h.p_O[0] for h in handles])
    return [h for i, h in enumerate(handles)
            if len(handles) < 3 or x[i] >= np.delete(x, i).min() - behind_m]


def locate_handles(maps: list[HandleMap], frames: list[CaptureFrame],
                   min_share: float = FURNITURE_MIN_SHARE, bars: bool = FURNITURE_BARS,
                   loose: tuple[float, float] = FURNITURE_LOOSE, merged_px: float = FURNITURE_MERGED_PX,
                   bar_share: float = FURNITURE_BAR_SHARE, behind_m: float = FURNITURE_BEHIND_M,
                   bar_points: bool = FURNITURE_BAR_POINTS, in_images: float = FURNITURE_IN_IMAGES
                   ) -> list[TriangulatedHandle]:
    """Every handle triangulated from per-frame handle maps, one per frame (furniture): the
    points of the votes (`triangulate_handles` with `min_share`, `loose` = (loose_share,
    loose_rms_px) and `merged_px`), then (`bars`) the upright bars they leave unexplained
    (`triangulate_bars` with `bar_share`; with `bar_points`, the views' point sightings on a bar
    count as its views), those more than `behind_m` behind all the others (`in_front`) and those
    inside fewer than `in_images` of the images (`in_most_images`) left out. The defaults are the
    fit's; a benchmark varies them."""
    segments = [b for i, m in enumerate(maps) for b in bar_sightings(m, i)] if bars else None
    points = [s for i, m in enumerate(maps) for s in sightings(m, i)]
    handles = triangulate_handles(frames, points, min_share=min_share, loose_share=loose[0],
                                  loose_rms_px=loose[1], merged_px=merged_px, bars=segments)
    if segments is not None:
        handles = handles + triangulate_bars(frames, segments, handles, min_share=bar_share,
                                             points=points if bar_points else None)
    return in_front(in_most_images(handles, frames, in_images), behind_m)


def locate_handle(maps: list[HandleMap], frames: list[CaptureFrame]) -> TriangulatedHandle | None:
    """The handle triangulated from per-frame handle maps, one per frame."""
    found = [s for i, m in enumerate(maps) if (s := sighting(m, i)) is not None]
    return triangulate_handle(frames, found)
