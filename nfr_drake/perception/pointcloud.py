"""Semantically labelled point clouds: open3d PLY files with a class per point."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nfr_drake.data.visualize import SEMANTIC_PALETTE


def write_semantic_ply(path: str | Path, points: np.ndarray, classes: np.ndarray) -> None:
    """Write points (N, 3) in metres with their semantic classes (N,) as a binary PLY.

    Each vertex carries x, y, z, its class (property `class`, int) and the class colour (red,
    green, blue as floats in [0, 1]) so that any PLY viewer shows the segmentation.
    """
    import open3d as o3d

    points = np.asarray(points, np.float32).reshape(-1, 3)
    classes = np.asarray(classes, np.int32).reshape(-1)
    if len(points) != len(classes):
        raise ValueError(f"{len(points)} points but {len(classes)} classes")
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(points))
    cloud.point.colors = o3d.core.Tensor(SEMANTIC_PALETTE[classes].astype(np.float32) / 255.0)
    cloud.point["class"] = o3d.core.Tensor(classes[:, None])
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    if not o3d.t.io.write_point_cloud(str(path), cloud):
        raise OSError(f"could not write {path}")


def read_semantic_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and classes (N,) of a PLY written by `write_semantic_ply`."""
    import open3d as o3d

    cloud = o3d.t.io.read_point_cloud(str(path))
    return cloud.point.positions.numpy(), cloud.point["class"].numpy().reshape(-1)
