"""Is the board on the floor? The floor plane that the sparse points imply, in the floor frame W.

`nfr-drake poses --world floor` puts W under a ChArUco board lying on the floor (z up, the floor
at z = 0). A board on a table, a box or a slope would put W's floor in the wrong place, and the
object's pose (estimated on the floor, `object_pose`) with it. The sparse points of a room hold
the floor wherever it has texture: the largest nearly horizontal plane among them (RANSAC) should
then be W's floor, z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INLIER_M = 0.01
"""Points this close to a plane support it, metres."""
MAX_CANDIDATE_TILT_DEG = 30.0
"""Planes steeper than this are walls or furniture sides, not candidates for the floor."""
MIN_SUPPORT = 30
"""Fewer supporting points say nothing about the floor."""
MIN_SUPPORT_FRACTION = 0.1
"""Nor does a plane that holds less than this fraction of the sparse points."""
MAX_TILT_DEG = 3.0
"""A floor tilted more than this against W's xy plane: the board does not lie flat on it."""
MAX_HEIGHT_M = 0.03
"""A floor this far above or below z = 0 (under the board's origin): the board is not on it."""


@dataclass(frozen=True)
class FloorPlane:
    """The plane that the most sparse points support among the nearly horizontal ones.

    tilt_deg: angle between its normal and W's z; height_m: its height at W's origin (x = y = 0),
    metres; support: points within `INLIER_M` of it, of `points` in all; found: whether enough
    points support it (`MIN_SUPPORT`, `MIN_SUPPORT_FRACTION`) to judge the board by it.
    """

    tilt_deg: float
    height_m: float
    support: int
    points: int

    @property
    def found(self) -> bool:
        return self.support >= max(MIN_SUPPORT, MIN_SUPPORT_FRACTION * self.points)

    def problem(self) -> str | None:
        """One line when a found floor contradicts the board lying on it (tilt or height), else None."""
        if not self.found or (self.tilt_deg <= MAX_TILT_DEG and abs(self.height_m) <= MAX_HEIGHT_M):
            return None
        return (f"the board does not lie on the floor: the floor that {self.support} of the "
                f"{self.points} sparse points lie on is tilted {self.tilt_deg:.1f} deg against the "
                f"board and {100 * self.height_m:+.1f} cm from it (limits {MAX_TILT_DEG:g} deg, "
                f"{100 * MAX_HEIGHT_M:g} cm); lay the board flat on the floor, or use --world board")

    def to_json(self) -> dict:
        return {"tilt_deg": self.tilt_deg, "height_m": self.height_m, "support": self.support,
                "points": self.points, "found": self.found}


def floor_plane(p_W: np.ndarray, seed: int = 0, iterations: int = 2000) -> FloorPlane:
    """The best-supported nearly horizontal plane (`MAX_CANDIDATE_TILT_DEG`) through the points
    p_W (N, 3), metres, by RANSAC over point triples, refined by least squares on its inliers.
    A FloorPlane with support 0 when there are fewer than 3 points or no candidate."""
    p_W = np.asarray(p_W, float).reshape(-1, 3)
    best = (0, None)
    if len(p_W) >= 3:
        rng = np.random.default_rng(seed)
        cos_max = np.cos(np.deg2rad(MAX_CANDIDATE_TILT_DEG))
        for a, b, c in rng.integers(len(p_W), size=(iterations, 3)):
            n = np.cross(p_W[b] - p_W[a], p_W[c] - p_W[a])
            norm = np.linalg.norm(n)
            if norm < 1e-9 or abs(n[2]) / norm < cos_max:
                continue
            n = n / norm
            inliers = np.abs((p_W - p_W[a]) @ n) < INLIER_M
            if inliers.sum() > best[0]:
                best = (int(inliers.sum()), inliers)
    if best[1] is None:
        return FloorPlane(float("nan"), float("nan"), 0, len(p_W))
    inliers = p_W[best[1]]
    centre = inliers.mean(axis=0)
    n = np.linalg.svd(inliers - centre)[2][-1]
    n = n if n[2] > 0 else -n
    tilt = float(np.degrees(np.arccos(np.clip(n[2], -1.0, 1.0))))
    return FloorPlane(tilt, float(centre @ n / n[2]), best[0], len(p_W))
