"""Similarity transforms that put a reconstruction (frame R, arbitrary scale) into metres.

A similarity S_WR maps a point as p_W = s R_WR p_R + p_WR and a camera pose X_RC to X_WC (the
rotation is composed, the position mapped; the camera's axes keep unit length). Two estimators:
- `align_to_centres`: known camera centres p_WC (anchors), Umeyama's least squares; at least three
  anchors that are not nearly collinear (a line leaves the rotation about it undetermined), and
  refused when the anchors do not fit the cameras (they belong to other photos).
- `align_to_camera_poses`: known camera poses X_WC (e.g. from a ChArUco board in each photo); the
  rotation is averaged over the photos, so two photos suffice and a straight camera path is fine.
Both return residuals per image. `parse_object_pose` reads X_WO, which takes frame W to frame O.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nfr_drake.errors import NfrDrakeError
from nfr_drake.jsonio import read_json

MIN_ANCHORS = 3
COLLINEARITY_RATIO = 0.02
"""Anchors are refused as collinear when their spread across the best-fit line (second singular
value of the centred positions) is below this fraction of their spread along it."""


MAX_ANCHOR_RESIDUAL = 0.05
"""Anchors are refused when their RMS residual after the best similarity exceeds this fraction of
their spread (RMS distance from their centroid). Anchors of the right photos leave a fraction of a
per cent (SfM's own error; Herz-Jesu-P8: 0.1 %), anchors of the wrong photos a sizeable part of the
spread (Herz-Jesu-P8: two neighbours swapped 23 %, all shuffled 80-100 %)."""


class AlignmentError(NfrDrakeError):
    """Metric alignment is impossible: too few, collinear or unmatched anchors, or no board poses."""


@dataclass(frozen=True)
class Similarity:
    """p_W = scale * R_WR @ p_R + p_WR. R_WR: (3, 3) rotation; p_WR: (3,) metres; scale: m per unit."""

    scale: float
    R_WR: np.ndarray
    p_WR: np.ndarray

    @classmethod
    def identity(cls) -> Similarity:
        return cls(1.0, np.eye(3), np.zeros(3))

    def apply(self, p_R: np.ndarray) -> np.ndarray:
        """Map points (..., 3) from R to W."""
        return self.scale * np.asarray(p_R, float) @ self.R_WR.T + self.p_WR

    def apply_pose(self, X_RC: np.ndarray) -> np.ndarray:
        """Map a camera pose X_RC (4x4, rigid) to X_WC (4x4, rigid, metres)."""
        X_WC = np.eye(4)
        X_WC[:3, :3] = self.R_WR @ X_RC[:3, :3]
        X_WC[:3, 3] = self.apply(X_RC[:3, 3])
        return X_WC

    def to_json(self) -> dict:
        return {"scale": float(self.scale), "R_WR": self.R_WR.tolist(), "p_WR": self.p_WR.tolist()}


@dataclass(frozen=True)
class AlignmentResult:
    """A similarity and how well it fits.

    method: "anchors", "charuco" or "none"; position_residuals_m: image name -> distance between
    mapped and known camera centre (metres); rotation_residuals_rad: the same for rotations where
    known rotations were used.
    """

    method: str
    similarity: Similarity
    position_residuals_m: dict[str, float]
    rotation_residuals_rad: dict[str, float]

    @property
    def rms_position_m(self) -> float:
        r = np.array(list(self.position_residuals_m.values()))
        return float(np.sqrt(np.mean(r ** 2))) if len(r) else 0.0

    def to_json(self) -> dict:
        d = {"method": self.method, **self.similarity.to_json(),
             "rms_position_residual_m": self.rms_position_m,
             "position_residuals_m": self.position_residuals_m}
        if self.rotation_residuals_rad:
            d["rotation_residuals_deg"] = {k: math.degrees(v)
                                           for k, v in self.rotation_residuals_rad.items()}
        return d


def rotation_angle(R: np.ndarray) -> float:
    """Angle of a rotation matrix (3, 3), rad in [0, pi]."""
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def _project_to_rotation(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def check_not_collinear(p: np.ndarray, names: list[str]) -> None:
    """Raise AlignmentError unless points p (N, 3) span a plane (N >= 3, not nearly on a line)."""
    if len(p) < MIN_ANCHORS:
        raise AlignmentError(f"{len(p)} anchors match registered images ({', '.join(names) or 'none'}); "
                             f"a similarity needs at least {MIN_ANCHORS}")
    sv = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    if sv[0] <= 1e-12 or sv[1] / sv[0] < COLLINEARITY_RATIO:
        raise AlignmentError(
            f"the {len(p)} anchor camera centres are nearly collinear (spread across their line is "
            f"{sv[1] / max(sv[0], 1e-12):.4f} of the spread along it, minimum {COLLINEARITY_RATIO}): "
            "the rotation about that line is undetermined. Add anchors off the line, or align with "
            "--charuco, which also knows the cameras' rotations")


def umeyama(p_R: np.ndarray, p_W: np.ndarray) -> Similarity:
    """Least-squares similarity with p_W ~ S(p_R), points (N, 3) each (Umeyama 1991)."""
    mu_R, mu_W = p_R.mean(axis=0), p_W.mean(axis=0)
    a, b = p_R - mu_R, p_W - mu_W
    U, sv, Vt = np.linalg.svd(b.T @ a / len(p_R))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    scale = float(np.trace(np.diag(sv) @ D) / (a ** 2).sum(axis=1).mean())
    return Similarity(scale, R, mu_W - scale * R @ mu_R)


def align_to_centres(X_RCs: dict[str, np.ndarray], p_WCs: dict[str, np.ndarray],
                     max_residual: float = MAX_ANCHOR_RESIDUAL) -> AlignmentResult:
    """Similarity from reconstructed poses X_RC to known camera centres p_WC (metres), by name.

    Anchors of unregistered images are ignored. Raises AlignmentError for fewer than three usable
    anchors, nearly collinear ones, or an RMS residual above `max_residual` times the anchors'
    spread (RMS distance from their centroid).
    """
    names = sorted(set(X_RCs) & set(p_WCs))
    p_W = np.array([p_WCs[n] for n in names], float).reshape(-1, 3)
    check_not_collinear(p_W, names)
    p_R = np.array([X_RCs[n][:3, 3] for n in names])
    S = umeyama(p_R, p_W)
    residuals = np.linalg.norm(S.apply(p_R) - p_W, axis=1)
    result = AlignmentResult("anchors", S, dict(zip(names, residuals.tolist(), strict=True)), {})
    spread = float(np.sqrt(((p_W - p_W.mean(axis=0)) ** 2).sum(axis=1).mean()))
    if result.rms_position_m > max_residual * spread:
        worst = sorted(result.position_residuals_m.items(), key=lambda item: -item[1])[:3]
        raise AlignmentError(
            f"the anchors do not fit the reconstructed cameras: RMS residual "
            f"{result.rms_position_m:.3g} m after the best similarity, "
            f"{100 * result.rms_position_m / spread:.0f} % of the anchors' spread ({spread:.3g} m; "
            f"limit {100 * max_residual:g} %), largest "
            + ", ".join(f"{n} {r:.3g} m" for n, r in worst)
            + "; the anchors probably belong to other photos (check the file names)")
    return result


def align_to_camera_poses(X_RCs: dict[str, np.ndarray], X_WCs: dict[str, np.ndarray],
                          method: str = "charuco") -> AlignmentResult:
    """Similarity from reconstructed poses X_RC to known poses X_WC (4x4 each), matched by name.

    R_WR is the chordal mean of R_WC R_RC^T over the images; scale and translation then fit the
    camera centres by least squares. Needs two images with distinct centres.
    """
    names = sorted(set(X_RCs) & set(X_WCs))
    if len(names) < 2:
        raise AlignmentError(f"known poses for {len(names)} registered image(s); need at least 2")
    R_WR = _project_to_rotation(sum(X_WCs[n][:3, :3] @ X_RCs[n][:3, :3].T for n in names))
    q = np.array([R_WR @ X_RCs[n][:3, 3] for n in names])
    p_W = np.array([X_WCs[n][:3, 3] for n in names])
    dq, dp = q - q.mean(axis=0), p_W - p_W.mean(axis=0)
    spread = (dq ** 2).sum()
    if spread < 1e-12:
        raise AlignmentError("the registered cameras with known poses share one centre: scale "
                             "undetermined")
    scale = float((dq * dp).sum() / spread)
    if scale <= 0:
        raise AlignmentError("known and reconstructed camera centres disagree (negative scale)")
    S = Similarity(scale, R_WR, p_W.mean(axis=0) - scale * q.mean(axis=0))
    pos = {n: float(np.linalg.norm(S.apply(X_RCs[n][:3, 3]) - X_WCs[n][:3, 3])) for n in names}
    rot = {n: rotation_angle(X_WCs[n][:3, :3].T @ R_WR @ X_RCs[n][:3, :3]) for n in names}
    return AlignmentResult(method, S, pos, rot)


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _key_lines(text: str, key: str) -> list[int]:
    """Line numbers (from 1) where `key` appears as an object key in the JSON `text`."""
    pattern = re.escape(json.dumps(key, ensure_ascii=False)) + r"\s*:"
    return [text.count("\n", 0, m.start()) + 1 for m in re.finditer(pattern, text)]


def read_anchors(path: Path) -> dict[str, np.ndarray]:
    """Read `{"photo.jpg": [x, y, z], ...}` (camera centres in W, metres).

    Raises AlignmentError with one line naming the file, the line of the entry and the problem:
    missing or malformed file, not an object, an entry that is not three finite numbers, a photo
    named twice.
    """
    path = Path(path)
    data = read_json(path, AlignmentError, "anchors file")
    if not isinstance(data, dict) or not data:
        raise AlignmentError(f"{path}: expected an object {{photo file name: [x, y, z]}}")
    text = path.read_text()
    anchors = {}
    for name, value in data.items():
        lines = _key_lines(text, name)
        where = f"{path}, line {lines[-1]}" if lines else str(path)
        if len(lines) > 1:
            raise AlignmentError(f"{where}: photo {name!r} has {len(lines)} anchors (lines "
                                 f"{', '.join(map(str, lines))}); give one")
        if not isinstance(value, list) or len(value) != 3 or not all(map(_is_number, value)):
            raise AlignmentError(f"{where}: the anchor of {name!r} is {json.dumps(value)}; expected "
                                 "[x, y, z], three numbers in metres")
        anchors[name] = np.array(value, float)
    return anchors


def pose_from_xyz_rpy(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    """4x4 pose from a position (m) and Drake roll-pitch-yaw angles (rad): R = Rz(y) Ry(p) Rx(r)."""
    from pydrake.math import RigidTransform, RollPitchYaw

    return RigidTransform(RollPitchYaw(np.asarray(rpy, float)), np.asarray(xyz, float)).GetAsMatrix4()


def parse_object_pose(value: str) -> np.ndarray:
    """X_WO (4x4) from "x y z roll pitch yaw" (metres, radians; commas allowed) or a JSON file.

    The JSON file holds a 4x4 matrix or {"xyz": [...], "rpy": [...]}. Raises AlignmentError.
    """
    numbers = [v for v in re.split(r"[,\s]+", value.strip()) if v]
    try:
        floats = [float(v) for v in numbers]
    except ValueError:
        floats = None
    if floats is not None:
        if len(floats) != 6 or not all(math.isfinite(v) for v in floats):
            raise AlignmentError(f"object pose {value!r}: expected 6 numbers 'x y z roll pitch yaw' "
                                 "(metres, radians) or a JSON file")
        return pose_from_xyz_rpy(floats[:3], floats[3:])
    path = Path(value)
    data = read_json(path, AlignmentError, "object pose file")
    if isinstance(data, dict) and {"xyz", "rpy"} <= data.keys():
        X = pose_from_xyz_rpy(data["xyz"], data["rpy"])
    else:
        try:
            X = np.asarray(data, dtype=float) if isinstance(data, list) else np.empty(0)
        except ValueError:
            X = np.empty(0)
        if X.shape != (4, 4) or not np.all(np.isfinite(X)):
            raise AlignmentError(f"{path}: expected a 4x4 matrix or {{\"xyz\": ..., \"rpy\": ...}}")
        R = X[:3, :3]
        if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0 or \
                np.abs(X[3] - [0, 0, 0, 1]).max() > 1e-9:
            raise AlignmentError(f"{path}: the object pose is not a rigid transform")
    return X
