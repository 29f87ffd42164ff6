"""Keypoint trajectories: where an object's keypoints are for each articulation q in [0, 1].

This is the planner's only knowledge of the object. It is built from an object's model (ground
truth: `from_articulated_object` here, `nfr_drake.systems.scene_objects` for any SDFormat/URDF
model) or from the neural field's forward simulation (`from_fit_result`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from pydrake.math import RigidTransform

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects.articulated import ArticulatedObject
from nfr_drake.objects.fronts import DOOR_OPENING

DEFAULT_GRID_SIZE = 41
GRIP_AXIS_KEYPOINT = "grip_axis"
"""An optional keypoint `GRIP_AXIS_OFFSET` from the handle along its grip (the ground truth of
furniture fronts): the bar axis the hand aligns with. Without it the planner takes the hinge axis
(doors) or the horizontal across the pull (drawers), as the closet and drawer grips lie."""
GRIP_AXIS_OFFSET = 0.05
PART_CATEGORY = {"door": "closet", "drawer": "drawer"}
"""The trajectory category of a part of a piece of furniture, by its type."""
APPROACH_KEYPOINT = "approach_from"
"""An optional keypoint `GRIP_AXIS_OFFSET` out in front of the handle, moving with it (the ground truth
of a loaded sliding door, whose handle moves across its front): the hand approaches the handle from
it. Without it the approach runs against the handle's motion (a door's outward normal, a drawer's
pull)."""


@dataclass(frozen=True)
class KeypointTrajectory:
    """Keypoint positions along the object's articulation, in the world frame W.

    Attributes:
        category: "closet" (a door on a hinge) or "drawer" (a slide); tells which keypoints exist.
        q_grid: articulations, increasing, in [0, 1] (a door's told in another joint's range may
            pass 1, `rescaled`), shape (N,).
        names: keypoint names, length K (always includes "handle"; closets add "hinge_top" and
            "hinge_bottom").
        p_WK: keypoint positions in W at each grid articulation, m, shape (N, K, 3).
        q_current: the object's present articulation, in [0, 1].
        turn_per_q: a door's turn per unit of q as its model tells, rad (a generated door's or
            a fit's quarter turn, `DOOR_OPENING`; a model file's own range); None where unknown
            (and for drawers).
    """

    category: str
    q_grid: np.ndarray
    names: tuple[str, ...]
    p_WK: np.ndarray
    q_current: float
    turn_per_q: float | None = None

    def __post_init__(self) -> None:
        q = np.asarray(self.q_grid, dtype=float)
        p = np.asarray(self.p_WK, dtype=float)
        if q.ndim != 1 or len(q) < 2 or np.any(np.diff(q) <= 0):
            raise NfrDrakeError("keypoint trajectory: q_grid must be 1-D, increasing, at least 2 values")
        if p.shape != (len(q), len(self.names), 3):
            raise NfrDrakeError(f"keypoint trajectory: p_WK has shape {p.shape}, expected "
                                f"({len(q)}, {len(self.names)}, 3)")
        required = {"closet": ("handle", "hinge_top", "hinge_bottom"), "drawer": ("handle",)}
        if self.category not in required:
            raise NfrDrakeError(f"keypoint trajectory: unknown category {self.category!r}")
        missing = [n for n in required[self.category] if n not in self.names]
        if missing:
            raise NfrDrakeError(f"keypoint trajectory of a {self.category} lacks keypoints {missing}")
        object.__setattr__(self, "q_grid", q)
        object.__setattr__(self, "p_WK", p)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "q_current", float(np.clip(self.q_current, q[0], q[-1])))

    def at(self, q: float | np.ndarray) -> np.ndarray:
        """Keypoints at articulation(s) q by linear interpolation: (K, 3), or (M, K, 3) for M values."""
        qs = np.clip(np.atleast_1d(np.asarray(q, dtype=float)), self.q_grid[0], self.q_grid[-1])
        flat = self.p_WK.reshape(len(self.q_grid), -1)
        out = np.stack([np.interp(qs, self.q_grid, flat[:, j]) for j in range(flat.shape[1])], axis=-1)
        out = out.reshape(len(qs), len(self.names), 3)
        return out if np.ndim(q) else out[0]

    def point(self, name: str, q: float | np.ndarray) -> np.ndarray:
        """One keypoint at articulation(s) q, in W: (3,) or (M, 3)."""
        return self.at(q)[..., self.names.index(name), :]

    def nearest_q(self, name: str, p_W: np.ndarray, samples: int = 401) -> float:
        """The articulation in [q_grid[0], q_grid[-1]] at which keypoint `name` passes nearest p_W
        (m, (3,) in W), e.g. where a held handle was let go: the part's measured articulation."""
        qs = np.linspace(self.q_grid[0], self.q_grid[-1], samples)
        return float(qs[np.argmin(np.linalg.norm(self.point(name, qs) - np.asarray(p_W), axis=1))])

    def with_current(self, q_current: float) -> KeypointTrajectory:
        """The same trajectory with another present articulation."""
        return replace(self, q_current=q_current)

    def rescaled(self, factor: float) -> KeypointTrajectory:
        """The same motion with its articulations multiplied by `factor` > 0 (q_grid and q_current):
        a door's keypoints, whose q is 90 degrees per unit, told in the q of a joint whose range
        from shut to open is another angle (`SceneObject.in_joint_units`)."""
        return replace(self, q_grid=self.q_grid * factor, q_current=self.q_current * factor,
                       turn_per_q=None if self.turn_per_q is None else self.turn_per_q / factor)

    def shifted(self, offset_W: np.ndarray) -> KeypointTrajectory:
        """All keypoints translated by `offset_W` (m, (3,)): a deliberately wrong estimate."""
        return replace(self, p_WK=self.p_WK + np.asarray(offset_W, dtype=float))

    def told_turn(self, turn_per_q: float = DOOR_OPENING) -> KeypointTrajectory:
        """A door's trajectory with its turn per unit of q (rad; by default a generated door's and
        a fit's quarter turn); a drawer's as it is."""
        return replace(self, turn_per_q=turn_per_q) if self.category == "closet" else self

    @staticmethod
    def from_object_frame(category: str, q_grid: np.ndarray, names: Sequence[str], p_OK: np.ndarray,
                          X_WO: RigidTransform, q_current: float) -> KeypointTrajectory:
        """From positions in the object frame O (m, (N, K, 3)) and the object's pose X_WO."""
        p_OK = np.asarray(p_OK, dtype=float)
        p_WK = (X_WO.rotation().matrix() @ p_OK.reshape(-1, 3).T).T + X_WO.translation()
        return KeypointTrajectory(category, q_grid, tuple(names), p_WK.reshape(p_OK.shape), q_current)

    @staticmethod
    def from_articulated_object(obj: ArticulatedObject, X_WO: RigidTransform, q_current: float,
                                grid_size: int = DEFAULT_GRID_SIZE, part: int = 0) -> KeypointTrajectory:
        """Ground truth from a sampled object's keypoint function, for its front `part`.

        The category is that of the front's joint: "closet" for a door, "drawer" for a drawer. A
        piece of furniture's bar, cup or edge grip adds `GRIP_AXIS_KEYPOINT` (its grips run either
        way on doors; a knob has no axis)."""
        q_grid = np.linspace(0.0, 1.0, grid_size)
        front = obj.front(part)
        category = "closet" if front.joint_type == "revolute" else "drawer"
        names, p_OK = front.keypoint_names, front.keypoint_array(q_grid)
        if obj.category == "furniture" and front.grip_half_length > 0.0:
            p_MA = (np.asarray(front.moving_keypoints["handle"])
                    + GRIP_AXIS_OFFSET * np.asarray(front.grip_axis_M))
            p_OA = np.stack([X[:3, :3] @ p_MA + X[:3, 3] for X in map(front.X_OM, q_grid)])
            names, p_OK = (*names, GRIP_AXIS_KEYPOINT), np.concatenate([p_OK, p_OA[:, None]], axis=1)
        kt = KeypointTrajectory.from_object_frame(category, q_grid, names, p_OK, X_WO, q_current)
        return kt.told_turn()

    @staticmethod
    def from_fit_result(result: Mapping, X_WO: RigidTransform) -> KeypointTrajectory:
        """From a fit result dict (docs/CONVENTIONS.md: "category", "q", "trajectory" in frame O);
        a furniture result's single-part fields are those of its "part", a "closet" for a door and
        a "drawer" for a drawer."""
        try:
            traj = result["trajectory"]
            names = tuple(traj["keypoints"])
            p_OK = np.stack([np.asarray(traj["keypoints"][n], dtype=float) for n in names], axis=1)
            part = result.get("part")
            category = result["category"] if part is None else PART_CATEGORY[part["type"]]
            kt = KeypointTrajectory.from_object_frame(
                category, np.asarray(traj["q"], dtype=float), names, p_OK, X_WO, float(result["q"]))
            return kt.told_turn()
        except (KeyError, TypeError, ValueError) as err:
            raise NfrDrakeError(f"fit result has no usable keypoint trajectory: {err}") from None
