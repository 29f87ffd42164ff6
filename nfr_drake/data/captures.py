"""`nfr-drake captures`: capture sets of unseen objects rendered by Drake, with ground truth.

Each capture is a capture-set folder (transforms.json + images; docs/DATASET_FORMAT.md) plus `gt.json`
(category, q, keypoints at q and along a q grid, object parameters), `object.sdf` (the true object,
for planning and simulation) and `labels/` (semantic label images, for evaluation). Objects come
from the capture seed domain, so they never coincide with training objects of any seed.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm import tqdm

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.data.capture import write_capture_set
from nfr_drake.data.render import ObjectRenderer, sample_lighting
from nfr_drake.errors import ConfigError
from nfr_drake.objects import (
    SEED_DOMAIN_CAPTURE,
    ArticulatedObject,
    object_rng,
    sample_object,
    to_sdformat,
)

GT_TRAJECTORY_POINTS = 21


def ground_truth(obj: ArticulatedObject, q: float, label_paths: list[str],
                 trajectory_points: int = GT_TRAJECTORY_POINTS) -> dict:
    """The gt.json document of `obj` observed at articulation q (positions in O, metres)."""
    grid = np.linspace(0.0, 1.0, trajectory_points)
    along = obj.keypoint_array(grid)  # (N, K, 3)
    return {
        "category": obj.category,
        "q": float(q),
        "joint_value": float(obj.joint_value(q)),
        "keypoints": {k: v.tolist() for k, v in obj.keypoints(q).items()},
        "trajectory": {
            "q": grid.tolist(),
            "keypoints": {n: along[:, i].tolist() for i, n in enumerate(obj.keypoint_names)},
        },
        "object": {"name": obj.name, "joint_name": obj.joint_name, "joint_type": obj.joint_type,
                   "joint_upper": obj.joint_upper, "moving_link_name": obj.moving_link_name,
                   "params": obj.params},
        "object_sdf": "object.sdf",
        "label_paths": label_paths,
    }


def render_capture(obj: ArticulatedObject, q: float, X_OCs: np.ndarray, camera: PinholeCamera,
                   rng: np.random.Generator, out: Path) -> Path:
    """Render `obj` at q from each pose in X_OCs (n, 4, 4) and write the capture set `out`."""
    renderer = ObjectRenderer(obj, camera, sample_lighting(rng))
    views = [renderer.render(q, X) for X in X_OCs]
    label_paths = [f"labels/frame_{i:03d}.png" for i in range(len(views))]
    extra = {p: v.label for p, v in zip(label_paths, views, strict=True)}
    extra["object.sdf"] = to_sdformat(obj)
    return write_capture_set(out, [v.rgb for v in views], list(X_OCs), camera,
                             gt=ground_truth(obj, q, label_paths), extra_files=extra)


def captures_command(
    category: Literal["closet", "drawer"],
    n: int,
    out: Path,
    views: int = 10,
    size: int = 128,
    fov_y_deg: float = 50.0,
    distance_m: tuple[float, float] = (1.4, 1.9),
    azimuth_deg: tuple[float, float] = (-60.0, 60.0),
    elevation_deg: tuple[float, float] = (5.0, 40.0),
    seed: int = 0,
    q: float | None = None,
) -> None:
    """Render `n` capture sets of unseen objects into OUT/<category>_<i>, each at a random q.

    Args:
        category: object category.
        n: number of capture sets (objects).
        out: parent folder; existing capture sets in it are kept (a rerun completes a killed one).
        views: images per capture set.
        size: square image size, pixels.
        fov_y_deg: vertical field of view, degrees.
        distance_m: camera distance range to the object centre, metres.
        azimuth_deg: camera azimuth range around the front, degrees.
        elevation_deg: camera elevation range, degrees.
        seed: capture seed (objects are disjoint from training data for every seed).
        q: articulation of every capture set, in [0, 1] (default: uniform at random per set);
            objects and cameras are those of the same seed without it.
    """
    if q is not None and not 0.0 <= q <= 1.0:
        raise ConfigError(f"--q must lie in [0, 1], got {q}")
    cameras = CameraDistribution(azimuth_deg, elevation_deg, distance_m)
    camera = PinholeCamera.from_fov(size, size, math.radians(fov_y_deg))
    out.mkdir(parents=True, exist_ok=True)
    for i in tqdm(range(n), unit="capture", desc=f"{category} captures"):
        target = out / f"{category}_{i:03d}"
        if target.exists():
            continue
        rng = object_rng(SEED_DOMAIN_CAPTURE, seed, i)
        obj = sample_object(category, rng, name=f"{category}_capture_{i:03d}")
        q_random = float(rng.uniform(0.0, 1.0))
        X_OCs = cameras.sample(rng, views, obj.look_at_target())
        render_capture(obj, q_random if q is None else q, X_OCs, camera, rng, target)
    print(f"{n} capture sets in {out}")
