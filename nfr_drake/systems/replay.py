"""Meshcat drawings of keypoint trajectories and planner obstacles, and self-contained HTML replays."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.geometry import Box, Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform

from nfr_drake.world.keypoints import KeypointTrajectory
from nfr_drake.world.plan import ObstacleBox

KEYPOINT_COLOURS = {"handle": Rgba(0.95, 0.15, 0.1, 1.0), "hinge_top": Rgba(0.1, 0.4, 0.95, 1.0),
                    "hinge_bottom": Rgba(0.1, 0.4, 0.95, 1.0), "goal": Rgba(0.1, 0.75, 0.2, 1.0)}


def draw_keypoint_trajectory(meshcat: Meshcat, kt: KeypointTrajectory, path: str = "keypoints",
                             q_range: tuple[float, float] | None = None, line_width: float = 4.0,
                             num_beads: int = 10) -> None:
    """Each keypoint's path over `q_range` (default the whole grid) as a line with beads at
    `num_beads` evenly spaced articulations, and a larger sphere at q_current."""
    lo, hi = q_range if q_range is not None else (kt.q_grid[0], kt.q_grid[-1])
    q = np.linspace(min(lo, hi), max(lo, hi), 60)
    for name in kt.names:
        colour = KEYPOINT_COLOURS.get(name, Rgba(0.9, 0.6, 0.1, 1.0))
        meshcat.SetLine(f"{path}/{name}/path", kt.point(name, q).T, line_width, colour)
        for i, p in enumerate(kt.point(name, np.linspace(min(lo, hi), max(lo, hi), num_beads))):
            meshcat.SetObject(f"{path}/{name}/bead{i}", Sphere(0.006), colour)
            meshcat.SetTransform(f"{path}/{name}/bead{i}", RigidTransform(p))
        meshcat.SetObject(f"{path}/{name}/now", Sphere(0.012), colour)
        meshcat.SetTransform(f"{path}/{name}/now", RigidTransform(kt.point(name, kt.q_current)))


def draw_obstacle(meshcat: Meshcat, box: ObstacleBox, path: str = "planner") -> None:
    """A planner obstacle as a translucent box."""
    meshcat.SetObject(f"{path}/{box.name}", Box(*box.size), Rgba(0.9, 0.2, 0.2, 0.15))
    meshcat.SetTransform(f"{path}/{box.name}", box.X_WB)


def frame_camera(meshcat: Meshcat, p_W_target: np.ndarray, p_W_camera: np.ndarray) -> None:
    """Point the default camera from `p_W_camera` at `p_W_target` (m, (3,)) and hide the grid."""
    meshcat.SetCameraPose(np.asarray(p_W_camera, dtype=float), np.asarray(p_W_target, dtype=float))
    meshcat.SetProperty("/Grid", "visible", False)


def write_replay(meshcat: Meshcat, path: Path) -> Path:
    """Write the meshcat scene with its published recording as one offline HTML file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(meshcat.StaticHtml())
    return path

