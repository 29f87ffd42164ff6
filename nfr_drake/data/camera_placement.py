"""Camera placement: look-at poses and the front-hemisphere distribution used for training data."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nfr_drake.errors import ConfigError

_UP_O = np.array([0.0, 0.0, 1.0])


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


@dataclass(frozen=True)
class CameraDistribution:
    """Cameras on the front hemisphere of an object, looking at its centre (angles in degrees).

    Azimuth 0 is straight in front (+x of O); positive azimuth moves the camera towards +y.
    """

    azimuth_deg: tuple[float, float] = (-60.0, 60.0)
    elevation_deg: tuple[float, float] = (5.0, 40.0)
    distance_m: tuple[float, float] = (1.4, 1.9)
    look_at_jitter_m: float = 0.05
    """Standard deviation of the look-at point's offset from the object centre, per axis."""

    def __post_init__(self):
        for name in ("azimuth_deg", "elevation_deg", "distance_m"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ConfigError(f"{name}: min {lo} exceeds max {hi}")
        if not 0.0 < self.distance_m[0]:
            raise ConfigError("distance_m must be positive")
        if not -90.0 < self.elevation_deg[0] <= self.elevation_deg[1] < 90.0:
            raise ConfigError("elevation_deg must lie strictly between -90 and 90")

    def sample(self, rng: np.random.Generator, n: int, p_OT: np.ndarray) -> np.ndarray:
        """n camera poses X_OC looking near the target p_OT, shape (n, 4, 4)."""
        az = np.deg2rad(rng.uniform(*self.azimuth_deg, size=n))
        el = np.deg2rad(rng.uniform(*self.elevation_deg, size=n))
        dist = rng.uniform(*self.distance_m, size=n)
        jitter = rng.normal(0.0, self.look_at_jitter_m, size=(n, 3))
        poses = []
        for a, e, d, j in zip(az, el, dist, jitter, strict=True):
            direction = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
            poses.append(look_at(p_OT + d * direction, p_OT + j))
        return np.stack(poses)
