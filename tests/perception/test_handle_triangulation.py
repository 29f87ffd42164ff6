"""Triangulating a handle from per-view sightings: exact on clean views, robust to wrong ones."""

from pathlib import Path

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import CaptureFrame
from nfr_drake.perception.handle_triangulation import HandleMap, sighting, triangulate_handle

P_TRUE = np.array([0.25, -0.2, 0.5])


def _look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """X_OC with OpenCV axes (z forward, y down) looking from eye at target."""
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    X = np.eye(4)
    X[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    X[:3, 3] = eye
    return X


def _frames(n: int, size: int, distortion=None) -> list[CaptureFrame]:
    cam = PinholeCamera.from_fov(size, size, np.radians(50.0))
    if distortion is not None:
        cam = PinholeCamera(cam.fx, cam.fy, cam.cx, cam.cy, size, size, distortion)
    frames = []
    for az in np.linspace(-50, 50, n):
        a = np.radians(az)
        eye = np.array([1.6 * np.cos(a), 1.6 * np.sin(a), 1.0])
        frames.append(CaptureFrame(Path(f"{az}.png"), _look_at(eye, np.array([0.0, 0, 0.5])), cam))
    return frames


def _project(frame: CaptureFrame, p: np.ndarray) -> np.ndarray:
    X_CO = np.linalg.inv(frame.X_OC)
    p_C = X_CO[:3, :3] @ p + X_CO[:3, 3]
    cam = frame.camera
    x, y = p_C[:2] / p_C[2]
    if cam.distortion:
        k1, k2, p1, p2 = cam.distortion
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        x, y = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
    return np.array([cam.fx * x + cam.cx, cam.fy * y + cam.cy])


def _blob(size: int, uv: np.ndarray) -> HandleMap:
    """A 3 x 3 px probability blob centred on pixel uv (sub-pixel weights), without offsets."""
    prob = np.zeros((size, size), np.float32)
    c, r = uv - 0.5
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            rr, cc = int(round(r)) + dr, int(round(c)) + dc
            prob[rr, cc] = max(0.0, 1.0 - 0.4 * np.hypot(rr - r, cc - c))
    return HandleMap.centroid_only(prob)


@pytest.mark.parametrize("distortion", [None, (-0.1, 0.02, 0.001, -0.001)])
def test_exact_views_give_the_point(distortion):
    frames = _frames(8, 128, distortion)
    found = [sighting(_blob(128, _project(f, P_TRUE)), i) for i, f in enumerate(frames)]
    assert all(s is not None for s in found)
    result = triangulate_handle(frames, found)
    assert result is not None and len(result.views) == 8
    assert np.linalg.norm(result.p_O - P_TRUE) < 0.005  # a blob's centroid is within ~0.2 px
    assert result.rms_px < 0.5


def test_wrong_sightings_are_left_out():
    frames = _frames(10, 128)
    found = [sighting(_blob(128, _project(f, P_TRUE)), i) for i, f in enumerate(frames)]
    decoy = P_TRUE + [0.0, 0.4, 0.0]  # three views "see" the handle 40 cm to the side
    for i in (1, 4, 7):
        found[i] = sighting(_blob(128, _project(frames[i], decoy)), i)
    result = triangulate_handle(frames, found)
    assert result is not None
    assert set(result.views) == set(range(10)) - {1, 4, 7}
    assert np.linalg.norm(result.p_O - P_TRUE) < 0.005


def test_too_few_agreeing_views_give_none():
    frames = _frames(4, 64)
    offsets = np.array([[0, 0, 0], [0, 0, 0.15], [0, -0.2, -0.1], [0.1, 0.2, 0.2]])
    found = [sighting(_blob(64, _project(f, P_TRUE + o)), i)
             for i, (f, o) in enumerate(zip(frames, offsets, strict=True))]  # each sees another
    assert triangulate_handle(frames, found) is None
    assert triangulate_handle(frames, found[:2]) is None


def test_sighting_takes_the_strongest_blob():
    prob = np.zeros((32, 32), np.float32)
    prob[5, 5] = 0.6  # a weak speck
    prob[20:23, 10:12] = 0.9  # the handle
    s = sighting(HandleMap.centroid_only(prob), 3)
    assert s is not None and s.frame == 3
    np.testing.assert_allclose(s.uv, [11.0, 21.5])
    assert sighting(HandleMap.centroid_only(np.full((8, 8), 0.4, np.float32)), 0) is None


def test_sighting_is_where_the_blob_votes():
    """Offsets that all point at one spot put the sighting there, wherever the blob's centroid."""
    prob = np.zeros((32, 32), np.float32)
    prob[20:23, 10:14] = [0.6, 0.9, 0.9, 0.7]
    rows, cols = np.mgrid[0:32, 0:32]
    target = np.array([15.3, 18.8])
    offset = np.stack([target[0] - (cols + 0.5), target[1] - (rows + 0.5)], -1).astype(np.float32)
    s = sighting(HandleMap(prob, offset), 0)
    np.testing.assert_allclose(s.uv, target, atol=1e-5)
    assert abs(s.mass - prob.sum()) < 1e-5


def test_strong_sightings_outweigh_more_numerous_weak_ones():
    """Four faint partial blobs agree on a point 8 cm off; three full ones on the handle."""
    frames = _frames(7, 128)
    decoy = P_TRUE + [0.0, 0.0, -0.08]
    found = []
    for i, f in enumerate(frames):
        strong = i in (1, 3, 5)
        blob = _blob(128, _project(f, P_TRUE if strong else decoy))
        prob = blob.probability * (1.0 if strong else 0.3)
        found.append(sighting(HandleMap.centroid_only(prob), i, threshold=0.1))
    result = triangulate_handle(frames, found)
    assert result is not None and set(result.views) == {1, 3, 5}
    assert np.linalg.norm(result.p_O - P_TRUE) < 0.005
