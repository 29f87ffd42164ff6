"""ChArUco boards: detection with OpenCV's detector classes (OpenCV 4.7+) and the board's pose.

Board frame B (OpenCV's): origin at the board's outer corner next to the first chessboard corner,
x along the rows of squares, y along the columns, both in the board plane, z = x cross y (into the
board when it is seen from the front). A board pose in a photo gives X_BC, the camera in B, in
metres: this is what makes a reconstruction metric with `--charuco`.

Floor frame F of a board lying face up on the floor (`floor_frame_in_board`): origin on the floor
under B's origin, x_F = x_B, y_F = -y_B, z_F = -z_B (up); the board's face lies at z_F = its
thickness.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.errors import NfrDrakeError

MIN_CORNERS = 6
"""ChArUco corners a photo needs for a board pose (fewer give unreliable poses)."""


class BoardNotFoundError(NfrDrakeError):
    """No (or too few) photos show the ChArUco board."""


@dataclass(frozen=True)
class CharucoBoardSpec:
    """Geometry of a printed ChArUco board."""

    squares: tuple[int, int] = (5, 7)
    """Squares along x and y (columns, rows), OpenCV's `CharucoBoard((nx, ny), ...)`."""
    square_m: float = 0.04
    """Side of a chessboard square, metres (measure the print)."""
    marker_m: float = 0.02
    """Side of an ArUco marker, metres."""
    dictionary: str = "DICT_6X6_250"
    """OpenCV's predefined ArUco dictionary, e.g. DICT_4X4_50, DICT_5X5_100, DICT_6X6_250."""
    legacy_pattern: bool = False
    """Boards printed by OpenCV before 4.6 with an even number of rows need the legacy layout."""
    thickness_m: float = 0.0
    """Height of the printed face above the surface the board lies on, metres (a print on card:
    about 0.001-0.003); with `poses --world floor` the floor is this far below the face."""

    def board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board. Raises NfrDrakeError for an unknown dictionary or bad sizes."""
        if not hasattr(cv2.aruco, self.dictionary) or not self.dictionary.startswith("DICT_"):
            raise NfrDrakeError(f"unknown ArUco dictionary {self.dictionary!r}")
        if min(self.squares) < 2 or not 0 < self.marker_m < self.square_m:
            raise NfrDrakeError("ChArUco board: at least 2x2 squares and 0 < marker_m < square_m")
        if not 0.0 <= self.thickness_m < 0.1:
            raise NfrDrakeError(f"ChArUco board: thickness_m {self.thickness_m} must lie in [0, 0.1) m")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard(tuple(self.squares), self.square_m, self.marker_m, dictionary)
        board.setLegacyPattern(self.legacy_pattern)
        return board


def floor_frame_in_board(thickness_m: float = 0.0) -> np.ndarray:
    """X_BF (4x4): the floor frame F (module docstring) of a board lying face up on the floor,
    its face `thickness_m` above the floor (B's z points down, so the floor is at z_B = thickness)."""
    X_BF = np.diag([1.0, -1.0, -1.0, 1.0])
    X_BF[2, 3] = thickness_m
    return X_BF


@dataclass(frozen=True)
class BoardPose:
    """The board seen in one photo.

    X_BC: camera pose in the board frame (4x4, OpenCV axes, metres); corners: ChArUco corners
    used; reprojection_error_px: their mean reprojection error.
    """

    X_BC: np.ndarray
    corners: int
    reprojection_error_px: float


class CharucoPoseEstimator:
    """Detects a ChArUco board and estimates its pose in images of known cameras."""

    def __init__(self, spec: CharucoBoardSpec = CharucoBoardSpec(), min_corners: int = MIN_CORNERS):
        self.spec = spec
        self.board = spec.board()
        self.detector = cv2.aruco.CharucoDetector(self.board)
        self.min_corners = max(min_corners, 4)

    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ChArUco corners in an image (H, W[, 3] uint8, BGR or grey).

        Returns object points (N, 3) in B (metres) and image points (N, 2) in the capture set's
        pixel convention (top-left pixel centre at (0.5, 0.5)); N may be 0.
        """
        corners, ids, _, _ = self.detector.detectBoard(image)
        if corners is None or ids is None or len(ids) == 0:
            return np.empty((0, 3)), np.empty((0, 2))
        p_B, uv = self.board.matchImagePoints(corners, ids)
        return p_B.reshape(-1, 3).astype(float), uv.reshape(-1, 2).astype(float) + 0.5

    def estimate(self, image: np.ndarray, camera: PinholeCamera) -> BoardPose | None:
        """The board's pose in one image taken with `camera`, or None with too few corners.

        PnP: IPPE for a planar target, refined by Levenberg-Marquardt; distortion is modelled.
        """
        p_B, uv = self.detect(image)
        if len(p_B) < self.min_corners:
            return None
        if _collinear(p_B):
            return None
        K, dist = camera.K_opencv, camera.dist_opencv
        uv_cv = uv - 0.5
        ok, rvec, tvec = cv2.solvePnP(p_B, uv_cv, K, dist, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(p_B, uv_cv, K, dist, rvec, tvec)
        projected, _ = cv2.projectPoints(p_B, rvec, tvec, K, dist)
        error = float(np.linalg.norm(projected.reshape(-1, 2) - uv_cv, axis=1).mean())
        X_CB = np.eye(4)
        X_CB[:3, :3] = cv2.Rodrigues(rvec)[0]
        X_CB[:3, 3] = tvec.ravel()
        return BoardPose(np.linalg.inv(X_CB), len(p_B), error)


def _collinear(p_B: np.ndarray) -> bool:
    """True when the board points (N, 3) lie nearly on one line (no pose from them)."""
    sv = np.linalg.svd(p_B - p_B.mean(axis=0), compute_uv=False)
    return sv[1] < 1e-3 * max(sv[0], 1e-12)
