"""The camera model of a photo set: pinhole intrinsics plus OpenCV distortion coefficients.

`PhotoCamera` is what the photos were taken with (distortion allowed, up to OpenCV's 8 rational
coefficients); the capture set that `nfr-drake poses` writes holds undistorted images and plain
`PinholeCamera`s. Pixel convention: COLMAP's and the capture set's, the top-left pixel's centre at
(0.5, 0.5). OpenCV puts it at (0, 0); `K_opencv` converts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.data.capture import PinholeCamera
from nfr_drake.errors import ConfigError
from nfr_drake.jsonio import read_json

# OpenCV's order of distortion coefficients; COLMAP's OPENCV model takes the first four and its
# FULL_OPENCV model all eight.
DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


@dataclass(frozen=True)
class PhotoCamera:
    """Intrinsics of photos as taken.

    fx, fy, cx, cy in pixels (top-left pixel centre at (0.5, 0.5)); width, height in pixels;
    distortion: OpenCV coefficients (k1, k2, p1, p2, k3, k4, k5, k6), trailing ones may be left
    out; empty or all zero means none.
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

    @property
    def has_distortion(self) -> bool:
        return any(abs(k) > 0.0 for k in self.distortion)

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

    def scaled(self, width: int, height: int) -> PhotoCamera:
        """The same camera for the photos resized to width x height."""
        sx, sy = width / self.width, height / self.height
        return PhotoCamera(self.fx * sx, self.fy * sy, self.cx * sx, self.cy * sy, width, height,
                           self.distortion)

    def pinhole(self) -> PinholeCamera:
        """The capture-set camera of this camera's undistorted images (same K and size)."""
        return PinholeCamera(self.fx, self.fy, self.cx, self.cy, self.width, self.height)

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
    def from_colmap(cls, camera) -> PhotoCamera:
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

    # Files and images -----------------------------------------------------------------------
    @classmethod
    def from_json_file(cls, path: str | Path) -> PhotoCamera:
        """Read intrinsics from a JSON file with nerfstudio's keys.

        Keys: `fl_x`, `fl_y`, `cx`, `cy`, `w`, `h` (pixel centres at +0.5, as in transforms.json)
        and optionally `k1`, `k2`, `p1`, `p2`, `k3`, `k4`, `k5`, `k6`. A transforms.json works too.
        """
        path = Path(path)
        d = read_json(path, ConfigError, "intrinsics file")
        return cls.from_json(d, str(path))

    @classmethod
    def from_json(cls, d: dict, source: str = "intrinsics") -> PhotoCamera:
        """From a dict with the keys of `from_json_file`; `source` names it in errors."""
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
        """nerfstudio-style keys (with k3..k6 when used); `from_json_file` reads them back."""
        d = {"fl_x": self.fx, "fl_y": self.fy, "cx": self.cx, "cy": self.cy,
             "w": self.width, "h": self.height}
        d.update(dict(zip(DISTORTION_KEYS, self.distortion, strict=False)))
        return d

    def undistort(self, image: np.ndarray) -> tuple[np.ndarray, PinholeCamera]:
        """Undistort an image (H, W[, C]) taken with this camera.

        Returns the image resampled to the pinhole camera with the same K and size (bilinear), and
        that camera. Pixels that fall outside the photo are black.
        """
        if image.shape[:2] != (self.height, self.width):
            raise ValueError(f"image is {image.shape[1]}x{image.shape[0]}, camera is "
                             f"{self.width}x{self.height}")
        if not self.has_distortion:
            return image, self.pinhole()
        K = self.K_opencv
        map_x, map_y = cv2.initUndistortRectifyMap(K, self.dist_opencv, None, K,
                                                   (self.width, self.height), cv2.CV_32FC1)
        return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR), self.pinhole()
