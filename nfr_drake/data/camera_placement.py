"""Camera placement: look-at poses and the front-hemisphere distribution used for training data."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.errors import ConfigError

if TYPE_CHECKING:
    from nfr_drake.objects import ArticulatedObject

_UP_O = np.array([0.0, 0.0, 1.0])
_MIN_DEPTH_M = 0.1  # nearest depth of a framed corner, m (the renderer clips at 0.05 m)


def look_at(p_OC: np.ndarray, p_OT: np.ndarray, up_O: np.ndarray = _UP_O) -> np.ndarray:
    """Pose X_OC (4x4) of a camera at p_OC looking at p_OT, OpenCV axes (x right, y down, z forward).

    The image's up direction is as close to `up_O` as possible. Raises ValueError when the viewing
    direction is parallel to `up_O`.
    """
    z = np.asarray(p_OT, float) - np.asarray(p_OC, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up_O)  # right = forward x up
    if np.linalg.norm(x) < 1e-9:
        raise ValueError("the camera looks along the up direction; choose another up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)  # down
    X = np.eye(4)
    X[:3, :3] = np.column_stack([x, y, z])
    X[:3, 3] = p_OC
    return X


def resolve_framing(framing: str, category: str) -> str:
    """The framing "auto" stands for: "bounds" for furniture (pieces of 0.3 to 2.1 m, no one
    distance range fits them all), "distance" for closets and drawers (the paper's cameras)."""
    if framing != "auto":
        return framing
    return "bounds" if category == "furniture" else "distance"


def framing_distance(corners_O: np.ndarray, p_OT: np.ndarray, direction_O: np.ndarray,
                     camera: PinholeCamera, margin: float) -> float:
    """Smallest distance d (m) at which a camera at p_OT + d * direction_O looking at p_OT (`look_at`)
    sees every point of `corners_O` (N, 3) inside the image shrunk by `margin`: a free border of
    margin times the half-width (half-height) on the left and right (top and bottom).

    A point at r = p - p_OT has depth d - r.u (u the unit direction) and lateral offsets r.x, r.y
    along the camera's axes, so each image border bounds d from below; d is the largest bound.
    """
    u = np.asarray(direction_O, float) / np.linalg.norm(direction_O)
    R_OC = look_at(u, np.zeros(3))[:3, :3]
    r = np.asarray(corners_O, float) - np.asarray(p_OT, float)
    lateral = r @ R_OC[:, :2]  # (N, 2): along the camera's x (right) and y (down)
    focal = np.array([camera.fx, camera.fy])
    centre = np.array([camera.cx, camera.cy])
    border = margin * np.array([camera.width, camera.height]) / 2.0
    # Tangents of the half-angles to the shrunk image's far (+) and near (-) borders, per axis.
    t_plus = (np.array([camera.width, camera.height]) - border - centre) / focal
    t_minus = (centre - border) / focal
    if np.any(t_plus <= 0) or np.any(t_minus <= 0):
        raise ConfigError(f"margin {margin} leaves no image to frame the object in")
    depth = np.maximum(lateral / t_plus, -lateral / t_minus).max(1)
    return float((r @ u + np.maximum(depth, _MIN_DEPTH_M)).max())


@dataclass(frozen=True)
class CameraDistribution:
    """Cameras on the front hemisphere of an object, looking at a target (angles in degrees).

    Azimuth 0 is straight in front (+x of O); positive azimuth moves the camera towards +y.
    Framing "distance" (closets, drawers: the paper's setting) draws the distance from
    `distance_m`. Framing "bounds" (furniture) puts each camera at the smallest distance from
    which a given box (the object's bounds over all articulations) lies inside the image with a
    free border drawn from `margin` (`framing_distance`); `distance_m` is then unused.
    """

    azimuth_deg: tuple[float, float] = (-60.0, 60.0)
    elevation_deg: tuple[float, float] = (5.0, 40.0)
    distance_m: tuple[float, float] = (1.4, 1.9)
    look_at_jitter_m: float = 0.05
    """Standard deviation of the look-at point's offset from the target, per axis, m."""
    framing: Literal["distance", "bounds"] = "distance"
    margin: tuple[float, float] = (0.05, 0.25)
    """Framing "bounds": free border around the box, a fraction of the image's half-size, per view."""

    def __post_init__(self):
        for name in ("azimuth_deg", "elevation_deg", "distance_m", "margin"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ConfigError(f"{name}: min {lo} exceeds max {hi}")
        if not 0.0 < self.distance_m[0]:
            raise ConfigError("distance_m must be positive")
        if not -90.0 < self.elevation_deg[0] <= self.elevation_deg[1] < 90.0:
            raise ConfigError("elevation_deg must lie strictly between -90 and 90")
        if self.framing not in ("distance", "bounds"):
            raise ConfigError(f"framing must be 'distance' or 'bounds', got {self.framing!r}")
        if not 0.0 <= self.margin[0] <= self.margin[1] < 1.0:
            raise ConfigError(f"margin must lie in [0, 1), got {self.margin}")

    def sample(self, rng: np.random.Generator, n: int, p_OT: np.ndarray,
               bounds: tuple[np.ndarray, np.ndarray] | None = None,
               camera: PinholeCamera | None = None) -> np.ndarray:
        """n camera poses X_OC looking near the target p_OT (O, m, shape (3,)), shape (n, 4, 4).

        Framing "bounds" needs `bounds` (min and max corner of the box to keep in view, O, m) and
        the `camera` whose image must hold it.
        """
        az = np.deg2rad(rng.uniform(*self.azimuth_deg, size=n))
        el = np.deg2rad(rng.uniform(*self.elevation_deg, size=n))
        if self.framing == "bounds":
            if bounds is None or camera is None:
                raise ValueError("framing 'bounds' needs the bounds and the camera")
            margins = rng.uniform(*self.margin, size=n)
            lo, hi = (np.asarray(b, float) for b in bounds)
            corners = np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                                for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        else:
            dist = rng.uniform(*self.distance_m, size=n)
        jitter = rng.normal(0.0, self.look_at_jitter_m, size=(n, 3))
        poses = []
        for v, (a, e, j) in enumerate(zip(az, el, jitter, strict=True)):
            direction = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
            if self.framing == "bounds":
                target = p_OT + j
                d = framing_distance(corners, target, direction, camera, margins[v])
                poses.append(look_at(target + d * direction, target))
            else:
                poses.append(look_at(p_OT + dist[v] * direction, p_OT + j))
        return np.stack(poses)

    def target_of(self, obj: ArticulatedObject) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """What cameras around `obj` look at (O, m, (3,)) and the bounds they frame: its carcass
        centre (`look_at_target`) and None for framing "distance"; for framing "bounds" its bounds
        over every articulation (`swept_bounds`: doors open included) and their centre."""
        if self.framing == "distance":
            return obj.look_at_target(), None
        lo, hi = obj.swept_bounds()
        return (lo + hi) / 2.0, (lo, hi)
