"""What a plan is made of and what it returns: handle waypoints, obstacle boxes, the planned motion.

All in the world frame W. The grasp frame G of a waypoint has its origin at the handle keypoint,
+z along the approach (the direction the gripper moves in when closing in on the handle), +x along
the bar axis (the axis of the handle's grip), +y = z x x (the fingers' closing axis); it matches the
tool frame of `nfr_drake.world.robot`. `nfr_drake.planning.grasp` derives them from keypoints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.trajectories import BsplineTrajectory


@dataclass(frozen=True)
class HandleWaypoint:
    """The handle at one articulation.

    Attributes:
        q: articulation in [0, 1].
        p_WH: handle keypoint, m, shape (3,).
        approach_W: unit approach direction, shape (3,).
        bar_W: unit bar axis, shape (3,).
    """

    q: float
    p_WH: np.ndarray
    approach_W: np.ndarray
    bar_W: np.ndarray

    def X_WG(self, flip: bool = False) -> RigidTransform:
        """Grasp frame G (module docstring); `flip` turns the hand 180 degrees about the approach."""
        x = -self.bar_W if flip else self.bar_W
        z = self.approach_W
        R = np.column_stack([x, np.cross(z, x), z])
        return RigidTransform(RotationMatrix(R), self.p_WH)


@dataclass(frozen=True)
class ObstacleBox:
    """A box obstacle: full extents `size` (m, (3,)) and pose X_WB of its centre."""

    name: str
    size: np.ndarray
    X_WB: RigidTransform

    @property
    def top(self) -> float:
        """Height of its highest corner in W, m."""
        return float(self.X_WB.translation()[2] + np.abs(self.X_WB.rotation().matrix()[2]) @ self.size / 2)


@dataclass
class PlanResult:
    """A planned motion.

    Attributes:
        trajectory: positions of the planning plant (7 arm joints, 2 fingers) over time t in
            [0, duration], s.
        X_WB: the chosen robot base pose.
        s_grasp: normalised time of the grasp; the grasp happens at t = s_grasp * duration.
        waypoints: the handle waypoints (current q to target q, then any end-stop overshoot).
        flip: whether the hand is turned 180 degrees about the approach (grasp frame convention).
        seconds: wall time: "placement" (base candidates, their chained IK and any failed
            optimisations), "trajopt" (the successful optimisation), "total"; "cpu" is the
            process CPU time of the whole call (wall time suffers when the machine is shared).
    """

    trajectory: BsplineTrajectory
    X_WB: RigidTransform
    s_grasp: float
    waypoints: list[HandleWaypoint]
    flip: bool
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return float(self.trajectory.end_time() - self.trajectory.start_time())

    @property
    def t_grasp(self) -> float:
        return self.s_grasp * self.duration
