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
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import cv2
import numpy as np

from nfr_drake.data.capture import CaptureFrame

_REFERENCE_HEIGHT_PX = 128.0
MIN_VIEWS = 3
"""Views that must agree on a handle for a point."""


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


def _ray(frame: CaptureFrame, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin and unit direction in O of the ray through pixel uv of a frame."""
    cam = frame.camera
    if not cam.distortion:
        xy = (uv - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    else:
        xy = cv2.undistortPoints((uv - 0.5).reshape(1, 1, 2), cam.K_opencv, cam.dist_opencv).reshape(2)
    d = frame.X_OC[:3, :3] @ np.array([xy[0], xy[1], 1.0])
    return frame.X_OC[:3, 3].copy(), d / np.linalg.norm(d)


def _nearest_point(origins: np.ndarray, directions: np.ndarray,
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
                       max_error_px: float = 3.0, min_views: int = MIN_VIEWS
                       ) -> TriangulatedHandle | None:
    """Robust triangulation (module docstring); None when fewer than `min_views` views agree."""
    if len(sightings) < max(2, min_views):
        return None
    rays = [_ray(frames[s.frame], s.uv) for s in sightings]
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
        inliers, rms = agreeing(_nearest_point(origins[[i, j]], directions[[i, j]]))
        score = float(mass[inliers].sum()) if len(inliers) >= min_views else 0.0
        if best is None or (score, -rms) > (best[0], -best[1]):
            best = (score, rms, inliers)
    if best is None or best[0] == 0.0:
        return None
    inliers = best[2]
    for _ in range(2):  # refit on the agreeing views, then on those that agree with the refit
        p = _nearest_point(origins[inliers], directions[inliers], mass[inliers])
        inliers, _ = agreeing(p)
        if len(inliers) < min_views:
            return None
    p = _nearest_point(origins[inliers], directions[inliers], mass[inliers])
    return TriangulatedHandle(p, tuple(sightings[i].frame for i in inliers), agreeing(p)[1],
                              len(sightings))


def locate_handle(maps: list[HandleMap], frames: list[CaptureFrame]) -> TriangulatedHandle | None:
    """The handle triangulated from per-frame handle maps, one per frame."""
    found = [s for i, m in enumerate(maps) if (s := sighting(m, i)) is not None]
    return triangulate_handle(frames, found)
