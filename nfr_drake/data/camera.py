"""The camera model: pinhole intrinsics, OpenCV distortion and image size; its conversions.

One class for every camera of the project: Drake's render cameras, capture-set frames, datasets,
the photos `nfr-drake poses` reads and the cameras COLMAP calibrates. Pixel convention: COLMAP's
and nerfstudio's, the top-left pixel's centre at (0.5, 0.5); OpenCV puts it at (0, 0) (`K_opencv`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.errors import ConfigError
from nfr_drake.jsonio import read_json

DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
"""OpenCV's order of distortion coefficients; COLMAP's OPENCV model takes the first four and its
FULL_OPENCV model all eight, nerfstudio's OPENCV the first four."""


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics with optional OpenCV distortion.

    fx, fy, cx, cy in pixels (top-left pixel centre at (0.5, 0.5)); width, height in pixels;
    distortion: OpenCV coefficients (k1, k2, p1, p2, k3, k4, k5, k6), trailing ones may be left
    out; () for none (a capture set's "OPENCV" camera holds the first four, even when zero).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple[float, ...] = ()

    def __post_init__(self):
        if self.fx <= 0 or self.fy <= 0 or self.width <= 0 or self.height <= 0:
            raise ConfigError("camera: focal lengths and image size must be positive")
        if len(self.distortion) > len(DISTORTION_KEYS):
            raise ConfigError(f"camera: at most {len(DISTORTION_KEYS)} distortion coefficients")
        object.__setattr__(self, "distortion", tuple(float(k) for k in self.distortion))

    @classmethod
    def from_fov(cls, width: int, height: int, fov_y_rad: float) -> PinholeCamera:
        """A centred, square-pixel camera with the given vertical field of view."""
        f = height / 2.0 / math.tan(fov_y_rad / 2.0)
        return cls(f, f, width / 2.0, height / 2.0, width, height)

    @property
    def has_distortion(self) -> bool:
        return any(abs(k) > 0.0 for k in self.distortion)

    @property
    def fov_y(self) -> float:
        """Vertical field of view, rad."""
        return 2.0 * math.atan(self.height / 2.0 / self.fy)

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix, top-left pixel centre at (0.5, 0.5)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def K_opencv(self) -> np.ndarray:
        """3x3 intrinsic matrix in OpenCV's convention (top-left pixel centre at (0, 0))."""
        K = self.K
        K[:2, 2] -= 0.5
        return K

    @property
    def dist_opencv(self) -> np.ndarray:
        """Distortion coefficients for OpenCV functions, shape (4,), (5,) or (8,)."""
        n = len(self.distortion)
        size = 4 if n <= 4 else 5 if n == 5 else 8
        return np.pad(np.asarray(self.distortion, float), (0, size - n))

    def scaled(self, width: int, height: int) -> PinholeCamera:
        """The same camera for an image resized to width x height."""
        sx, sy = width / self.width, height / self.height
        return PinholeCamera(self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy, width, height,
                             self.distortion)

    def undistort(self, image: np.ndarray) -> tuple[np.ndarray, PinholeCamera]:
        """Undistort an image (H, W[, C]) taken with this camera.

        Returns the image resampled to the pinhole camera with the same K and size (bilinear), and
        that camera. Pixels that fall outside the photo are black.
        """
        if image.shape[:2] != (self.height, self.width):
            raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, camera is "
                             f"{self.width}x{self.height}")
        pinhole = replace(self, distortion=())
        if not self.has_distortion:
            return image, pinhole
        K = self.K_opencv
        map_x, map_y = cv2.initUndistortRectifyMap(K, self.dist_opencv, None, K,
                                                   (self.width, self.height), cv2.CV_32FC1)
        return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR), pinhole

    # COLMAP ---------------------------------------------------------------------------------
    def colmap_model(self) -> tuple[str, list[float]]:
        """COLMAP camera model name and parameters: PINHOLE, OPENCV or FULL_OPENCV."""
        base = [self.fx, self.fy, self.cx, self.cy]
        if not self.has_distortion:
            return "PINHOLE", base
        if len(self.distortion) <= 4:
            return "OPENCV", base + list(np.pad(self.distortion, (0, 4 - len(self.distortion))))
        return "FULL_OPENCV", base + list(np.pad(self.distortion, (0, 8 - len(self.distortion))))

    @classmethod
    def from_colmap(cls, camera) -> PinholeCamera:
        """From a `pycolmap.Camera` of a model OpenCV can express.

        Supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV.
        """
        name, p = camera.model.name, [float(v) for v in camera.params]
        w, h = int(camera.width), int(camera.height)
        if name == "SIMPLE_PINHOLE":
            return cls(p[0], p[0], p[1], p[2], w, h)
        if name == "PINHOLE":
            return cls(p[0], p[1], p[2], p[3], w, h)
        if name == "SIMPLE_RADIAL":
            return cls(p[0], p[0], p[1], p[2], w, h, (p[3],))
        if name == "RADIAL":
            return cls(p[0], p[0], p[1], p[2], w, h, (p[3], p[4]))
        if name in ("OPENCV", "FULL_OPENCV"):
            return cls(p[0], p[1], p[2], p[3], w, h, tuple(p[4:]))
        raise ConfigError(f"COLMAP camera model {name} has no OpenCV equivalent here")

    # JSON (nerfstudio's keys) -----------------------------------------------------------------
    @classmethod
    def from_json_file(cls, path: str | Path) -> PinholeCamera:
        """Read intrinsics from a JSON file with nerfstudio's keys (`from_json`); a
        transforms.json with top-level intrinsics works too."""
        path = Path(path)
        return cls.from_json(read_json(path, ConfigError, "intrinsics file"), str(path))

    @classmethod
    def from_json(cls, d: dict, source: str = "intrinsics") -> PinholeCamera:
        """From `fl_x`, `fl_y`, `cx`, `cy`, `w`, `h` (pixel centres at +0.5, as in transforms.json)
        and optionally `k1`, `k2`, `p1`, `p2`, `k3`, `k4`, `k5`, `k6` (trailing zeros dropped;
        `camera_model` is not read); `source` names the dict in errors."""
        if not isinstance(d, dict):
            raise ConfigError(f"{source}: expected a JSON object of intrinsics")
        required = ("fl_x", "fl_y", "cx", "cy", "w", "h")
        missing = [k for k in required if k not in d]
        if missing:
            raise ConfigError(f"{source}: intrinsics need keys {', '.join(missing)}")
        values = [d[k] for k in required] + [d.get(k, 0.0) for k in DISTORTION_KEYS]
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
            raise ConfigError(f"{source}: intrinsics must be finite numbers")
        fx, fy, cx, cy, w, h, *distortion = values
        used = max((i + 1 for i, k in enumerate(distortion) if k != 0.0), default=0)
        return cls(float(fx), float(fy), float(cx), float(cy), int(w), int(h),
                   tuple(float(k) for k in distortion[:used]))

    def to_json(self) -> dict:
        """nerfstudio's keys with `camera_model`: PINHOLE without distortion, OPENCV with up to
        four coefficients (written as k1 k2 p1 p2), FULL_OPENCV with more (all eight keys)."""
        d = {"fl_x": self.fx, "fl_y": self.fy, "cx": self.cx, "cy": self.cy,
             "w": self.width, "h": self.height}
        n = len(self.distortion)
        d["camera_model"] = "PINHOLE" if n == 0 else "OPENCV" if n <= 4 else "FULL_OPENCV"
        if n:
            keys = DISTORTION_KEYS[:4] if n <= 4 else DISTORTION_KEYS
            d.update(zip(keys, np.pad(self.distortion, (0, len(keys) - n)).tolist(), strict=True))
        return d


def project_points(p_W: np.ndarray, X_WC: np.ndarray, camera: PinholeCamera
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (n, 2) (top-left pixel centre at (0.5, 0.5)) of points p_W (n, 3) in a camera at
    X_WC (4, 4, OpenCV axes), with its distortion; and whether each lies in front of it (n,)."""
    X_CW = np.linalg.inv(X_WC)
    p_C = p_W @ X_CW[:3, :3].T + X_CW[:3, 3]
    front = p_C[:, 2] > 1e-3
    z = np.where(front, p_C[:, 2], 1.0)
    xy = p_C[:, :2] / z[:, None]
    if camera.has_distortion:
        uv = cv2.projectPoints(np.column_stack([xy, np.ones(len(xy))]), np.zeros(3), np.zeros(3),
                               camera.K_opencv, camera.dist_opencv)[0].reshape(-1, 2) + 0.5
    else:
        uv = xy * [camera.fx, camera.fy] + [camera.cx, camera.cy]
    return uv, front
