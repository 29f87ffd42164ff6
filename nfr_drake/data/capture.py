"""Capture sets: posed photos in nerfstudio's `transforms.json` (docs/DATASET_FORMAT.md), read and written.

A capture set is a folder with `transforms.json` and the images it names; synthetic ones may carry
`gt.json` (ground truth). This is the one interchange format between pose estimation, Drake
cameras and the neural-field fit.

Conventions at this boundary:
- `transform_matrix` is the camera-to-object pose with OpenGL camera axes (x right, y up,
  z backward). In code, poses are `X_OC` with OpenCV axes (x right, y down, z forward); the
  conversion happens here and nowhere else.
- Intrinsics use COLMAP/nerfstudio's pixel convention: the top-left pixel's centre is (0.5, 0.5).
  (`nfr_drake.data.render.drake_camera_info` gives Drake's renderer the matching camera.)
"""

from __future__ import annotations

import json
import math
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.data.camera import DISTORTION_KEYS, PinholeCamera
from nfr_drake.errors import CaptureSetError
from nfr_drake.jsonio import read_json

TRANSFORMS_FILE = "transforms.json"
GT_FILE = "gt.json"

_OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
_CAMERA_MODELS = {"PINHOLE": 0, "OPENCV": 4}
_DISTORTION_KEYS = DISTORTION_KEYS[:4]  # nerfstudio's OPENCV model
_RIGID_TOLERANCE = 1e-3


@dataclass(frozen=True)
class CaptureFrame:
    """One posed image: its absolute path, camera pose X_OC (4x4, OpenCV axes) and intrinsics;
    source_photo: file name of the photo it was made from (`nfr-drake poses`), else None."""

    image_path: Path
    X_OC: np.ndarray
    camera: PinholeCamera
    source_photo: str | None = None

    def load_rgb(self) -> np.ndarray:
        """The image as uint8 RGB, shape (height, width, 3)."""
        bgr = cv2.imread(str(self.image_path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise CaptureSetError(f"{self.image_path}: cannot be read as an image")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


@dataclass
class CaptureSet:
    """A validated capture set. `gt` is the parsed gt.json, or None when there is none."""

    root: Path
    frames: list[CaptureFrame]
    gt: dict | None = None
    extra: dict = field(default_factory=dict)

    def load_images(self) -> list[np.ndarray]:
        """All images as uint8 RGB arrays, each (height, width, 3)."""
        return [f.load_rgb() for f in self.frames]


def opencv_from_opengl(X_OC_opengl: np.ndarray) -> np.ndarray:
    """Camera pose with OpenGL axes -> the same pose with OpenCV axes (4x4 -> 4x4)."""
    return np.asarray(X_OC_opengl, dtype=float) @ _OPENGL_FROM_OPENCV


def opengl_from_opencv(X_OC: np.ndarray) -> np.ndarray:
    """Camera pose with OpenCV axes -> the same pose with OpenGL axes (4x4 -> 4x4)."""
    return np.asarray(X_OC, dtype=float) @ _OPENGL_FROM_OPENCV


def _fail(path: Path, problem: str) -> CaptureSetError:
    return CaptureSetError(f"{path}: {problem}")


def _read_json(path: Path) -> dict:
    data = read_json(path, CaptureSetError)
    if not isinstance(data, dict):
        raise _fail(path, "expected a JSON object at the top level")
    return data


def _camera_from_json(d: dict, base: PinholeCamera | None, where: str, path: Path
                      ) -> PinholeCamera:
    """Intrinsics from the keys of `d`, falling back to `base` for keys that `d` lacks."""
    def get(key, fallback):
        if key in d:
            value = d[key]
            if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
                raise _fail(path, f"{where}: '{key}' must be a finite number, got {value!r}")
            return value
        if fallback is None:
            raise _fail(path, f"{where}: missing intrinsic '{key}'")
        return fallback

    b = base
    fx = get("fl_x", b and b.fx)
    fy = get("fl_y", b and b.fy)
    cx = get("cx", b and b.cx)
    cy = get("cy", b and b.cy)
    w = int(get("w", b and b.width))
    h = int(get("h", b and b.height))
    if fx <= 0 or fy <= 0 or w <= 0 or h <= 0:
        raise _fail(path, f"{where}: focal lengths and image size must be positive")
    model = d.get("camera_model", "OPENCV" if (b and b.distortion) else "PINHOLE")
    if model not in _CAMERA_MODELS:
        raise _fail(path, f"{where}: camera_model {model!r} is not supported "
                          f"(use one of {sorted(_CAMERA_MODELS)})")
    distortion = ()
    if model == "OPENCV":
        base_dist = b.distortion if b and b.distortion else (None,) * 4
        distortion = tuple(float(get(k, bd)) for k, bd in zip(_DISTORTION_KEYS, base_dist,
                                                               strict=True))
    return PinholeCamera(float(fx), float(fy), float(cx), float(cy), w, h, distortion)


def _pose_from_json(matrix, where: str, path: Path) -> np.ndarray:
    try:
        X = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise _fail(path, f"{where}: transform_matrix is not a 4x4 array of numbers") from None
    if X.shape == (3, 4):
        X = np.vstack([X, [0.0, 0.0, 0.0, 1.0]])
    if X.shape != (4, 4):
        raise _fail(path, f"{where}: transform_matrix has shape {X.shape}, expected 4x4")
    if not np.all(np.isfinite(X)):
        raise _fail(path, f"{where}: transform_matrix has non-finite entries")
    R = X[:3, :3]
    if (np.abs(R.T @ R - np.eye(3)).max() > _RIGID_TOLERANCE
            or abs(np.linalg.det(R) - 1.0) > _RIGID_TOLERANCE
            or np.abs(X[3] - [0, 0, 0, 1]).max() > _RIGID_TOLERANCE):
        raise _fail(path, f"{where}: transform_matrix is not a rigid transform "
                          "(rotation not orthonormal with det +1, or last row not 0 0 0 1)")
    return opencv_from_opengl(X)


def _image_size(path: Path) -> tuple[int, int]:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise CaptureSetError(f"{path}: cannot be read as an image")
    return image.shape[1], image.shape[0]


def read_capture_set(root: str | os.PathLike, check_images: bool = True) -> CaptureSet:
    """Read and validate the capture set in folder `root`.

    Raises CaptureSetError naming the file and the problem: missing or malformed transforms.json,
    missing keys, a missing image, an image whose size differs from its intrinsics, a non-finite
    or non-rigid transform.
    """
    root = Path(root)
    if not root.is_dir():
        raise _fail(root, "capture set folder not found")
    tpath = root / TRANSFORMS_FILE
    data = _read_json(tpath)
    frames_json = data.get("frames")
    if not isinstance(frames_json, list) or not frames_json:
        raise _fail(tpath, "'frames' must be a non-empty list")
    has_global = all(k in data for k in ("fl_x", "fl_y", "cx", "cy", "w", "h"))
    base = _camera_from_json(data, None, "top level", tpath) if has_global else None
    frames = []
    for i, fj in enumerate(frames_json):
        where = f"frame {i}"
        if not isinstance(fj, dict) or "file_path" not in fj or "transform_matrix" not in fj:
            raise _fail(tpath, f"{where}: needs 'file_path' and 'transform_matrix'")
        camera = _camera_from_json(fj, base, where, tpath)
        X_OC = _pose_from_json(fj["transform_matrix"], where, tpath)
        image_path = (root / fj["file_path"]).resolve()
        if not image_path.is_file():
            raise _fail(image_path, f"image of {where} in {tpath} not found")
        if check_images:
            w, h = _image_size(image_path)
            if (w, h) != (camera.width, camera.height):
                raise _fail(image_path, f"image is {w}x{h} but {tpath} says "
                                        f"{camera.width}x{camera.height}")
        source = fj.get("source_photo")
        if source is not None and not isinstance(source, str):
            raise _fail(tpath, f"{where}: 'source_photo' must be a file name")
        frames.append(CaptureFrame(image_path, X_OC, camera, source))
    gt_path = root / GT_FILE
    gt = _read_json(gt_path) if gt_path.exists() else None
    extra = {k: v for k, v in data.items() if k != "frames" and k not in base_keys()}
    return CaptureSet(root, frames, gt, extra)


def capture_dirs(root: Path) -> list[Path]:
    """The capture sets in `root`: itself if it holds transforms.json, else its sub-folders."""
    root = Path(root)
    if (root / "transforms.json").exists():
        return [root]
    dirs = sorted(p for p in root.iterdir() if (p / "transforms.json").exists())
    if not dirs:
        raise CaptureSetError(f"{root}: no capture sets (folders with transforms.json) found")
    return dirs


def base_keys() -> set[str]:
    """transforms.json keys that describe intrinsics."""
    return {"fl_x", "fl_y", "cx", "cy", "w", "h", "camera_model", *_DISTORTION_KEYS}


def write_image(path: Path, rgb: np.ndarray) -> None:
    """Write a uint8 RGB (H, W, 3) or label (H, W) image as PNG."""
    path.parent.mkdir(parents=True, exist_ok=True)
    image = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR) if rgb.ndim == 3 else rgb
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")


def write_capture_set(
    root: str | os.PathLike,
    images: list[np.ndarray],
    X_OCs: list[np.ndarray],
    cameras: list[PinholeCamera] | PinholeCamera,
    gt: dict | None = None,
    extra_files: dict[str, np.ndarray | str] | None = None,
    source_photos: list[str] | None = None,
) -> Path:
    """Write a capture set atomically: into a temporary folder renamed to `root` when complete.

    Args:
        images: uint8 RGB, each (H, W, 3), written as images/frame_XXX.png.
        X_OCs: camera poses in O, 4x4, OpenCV axes.
        cameras: one camera for all frames, or one per frame.
        gt: ground truth written as gt.json.
        extra_files: more files, relative path -> uint8 image array (written as PNG) or text.
        source_photos: file name of the photo each frame was made from, written as the frame's
            `source_photo`.
    Raises FileExistsError if `root` exists.
    """
    root = Path(root)
    if root.exists():
        raise FileExistsError(f"{root} already exists")
    per_frame = isinstance(cameras, list)
    if len(images) != len(X_OCs) or (per_frame and len(cameras) != len(images)) or (
            source_photos is not None and len(source_photos) != len(images)):
        raise ValueError("images, poses, cameras and source photos must have the same length")
    tmp = root.with_name(f".{root.name}.tmp-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    frames = []
    for i, (rgb, X_OC) in enumerate(zip(images, X_OCs, strict=True)):
        rel = f"images/frame_{i:03d}.png"
        write_image(tmp / rel, rgb)
        frame = {"file_path": rel, "transform_matrix": opengl_from_opencv(X_OC).tolist()}
        if per_frame:
            frame.update(cameras[i].to_json())
        if source_photos is not None:
            frame["source_photo"] = source_photos[i]
        frames.append(frame)
    doc = {} if per_frame else cameras.to_json()
    doc["frames"] = frames
    (tmp / TRANSFORMS_FILE).write_text(json.dumps(doc, indent=2))
    if gt is not None:
        (tmp / GT_FILE).write_text(json.dumps(gt, indent=2))
    for rel, content in (extra_files or {}).items():
        if isinstance(content, str):
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            (tmp / rel).write_text(content)
        else:
            write_image(tmp / rel, content)
    os.replace(tmp, root)
    return root
