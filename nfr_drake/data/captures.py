"""`nfr-drake captures`: capture sets of unseen objects rendered by Drake, with ground truth.

Each capture is a capture-set folder (transforms.json + images; docs/DATASET_FORMAT.md) plus `gt.json`
(category, q, keypoints at q and along a q grid, object parameters), `object.sdf` (the true object,
for planning and simulation, with the textures it names under `textures/`) and `labels/` (semantic
label images, for evaluation). Furniture captures have a q per front, per-part ground truth and
`parts/` (part-index images). Objects come from the capture seed domain, so they never coincide
with training objects of any seed; `--training-objects` photographs a dataset's own objects
instead (a diagnosis: is a miss the fit's or the field's reach beyond its training codes?).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
from tqdm import tqdm

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution, resolve_framing
from nfr_drake.data.capture import write_capture_set
from nfr_drake.data.generate import parse_shard, part_articulations
from nfr_drake.data.object_records import PART_ORDER, front_record, portable_sdformat
from nfr_drake.data.render import ObjectRenderer, sample_lighting
from nfr_drake.data.shards import PART_CATEGORIES, process_alive
from nfr_drake.errors import ConfigError
from nfr_drake.objects import (
    SEED_DOMAIN_CAPTURE,
    SEED_DOMAIN_TRAIN,
    ArticulatedObject,
    object_rng,
    sample_object,
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


def part_ground_truth(obj: ArticulatedObject, q: np.ndarray, label_paths: list[str], part_paths: list[str],
                      trajectory_points: int = GT_TRAJECTORY_POINTS) -> dict:
    """The gt.json document of an object with several fronts observed at articulations q (F,):
    per part (canonical order) its record (`front_record`), q, joint value, keypoints at q and
    along a q grid (the part's own q swept, the others held: a front's keypoints depend on its
    own q only), the outer face's corners at q (`Front.face_corners`); positions in O, metres."""
    grid = np.linspace(0.0, 1.0, trajectory_points)
    parts = []
    for k, front in enumerate(obj.fronts):
        along = front.keypoint_array(grid)  # (N, K, 3)
        parts.append({
            **front_record(obj, k),
            "q": float(q[k]),
            "joint_value": float(front.joint_value(q[k])),
            "keypoints": {n: v.tolist() for n, v in front.keypoints(q[k]).items()},
            "face_corners": front.face_corners(q[k]).tolist(),
            "trajectory": {"q": grid.tolist(), "keypoints": {
                n: along[:, i].tolist() for i, n in enumerate(front.keypoint_names)}},
        })
    return {"category": obj.category, "q": [float(v) for v in q], "part_order": PART_ORDER, "parts": parts,
            "object": {"name": obj.name, "params": obj.params}, "object_sdf": "object.sdf",
            "label_paths": label_paths, "part_paths": part_paths}


def _read_rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise OSError(f"could not read texture {path}")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def render_capture(obj: ArticulatedObject, q: float | np.ndarray, X_OCs: np.ndarray, camera: PinholeCamera,
                   rng: np.random.Generator, out: Path) -> Path:
    """Render `obj` at q (one value, or one per front for furniture) from each pose in X_OCs
    (n, 4, 4) and write the capture set `out`."""
    renderer = ObjectRenderer(obj, camera, sample_lighting(rng))
    views = [renderer.render(q, X) for X in X_OCs]
    label_paths = [f"labels/frame_{i:03d}.png" for i in range(len(views))]
    extra = {p: v.label for p, v in zip(label_paths, views, strict=True)}
    if obj.category in PART_CATEGORIES:
        part_paths = [f"parts/frame_{i:03d}.png" for i in range(len(views))]
        extra.update({p: v.part.view(np.uint8) for p, v in zip(part_paths, views, strict=True)})
        gt = part_ground_truth(obj, obj.articulation(q), label_paths, part_paths)
    else:
        gt = ground_truth(obj, q, label_paths)
    extra["object.sdf"], textures = portable_sdformat(obj)
    extra.update({rel: _read_rgb(path) for rel, path in textures.items()})
    return write_capture_set(out, [v.rgb for v in views], list(X_OCs), camera, gt=gt, extra_files=extra)


def captures_command(
    category: Literal["closet", "drawer", "furniture"],
    n: int,
    out: Path,
    views: int = 10,
    size: int = 128,
    fov_y_deg: float = 50.0,
    distance_m: tuple[float, float] | None = None,
    azimuth_deg: tuple[float, float] = (-60.0, 60.0),
    elevation_deg: tuple[float, float] = (5.0, 40.0),
    seed: int = 0,
    q: float | None = None,
    framing: Literal["auto", "distance", "bounds"] = "auto",
    margin: tuple[float, float] = (0.05, 0.25),
    shard: str = "0/1",
    training_objects: bool = False,
) -> None:
    """Render `n` capture sets of unseen objects into OUT/<category>_<i>, each at a random q
    (furniture: a q per front, drawn as `nfr-drake generate` draws them).

    Args:
        category: object category.
        n: number of capture sets (objects).
        out: parent folder; existing capture sets in it are kept (a rerun completes a killed one).
        views: images per capture set.
        size: square image size, pixels.
        fov_y_deg: vertical field of view, degrees.
        distance_m: camera distance range to the object centre, metres (framing "distance";
            default 1.4 1.9). Refused with framing "bounds", where each view's distance follows
            from the piece's bounds, the field of view and `margin`.
        azimuth_deg: camera azimuth range around the front, degrees.
        elevation_deg: camera elevation range, degrees.
        seed: capture seed (objects are disjoint from training data for every seed).
        q: articulation of every capture set (furniture: of every front), in [0, 1] (default:
            drawn per set); objects and cameras are those of the same seed without it.
        framing: camera framing as in `nfr-drake generate`: "auto" is "bounds" for furniture
            (the whole piece in view at every q), "distance" for closets and drawers.
        margin: framing "bounds": free border around the bounds, a fraction of the image's half-size.
        shard: i/n renders the capture sets with index % n == i.
        training_objects: photograph objects 0..n-1 of the training dataset of seed `seed`
            (`nfr-drake generate --seed`; the same shapes, colours and textures, named as there),
            each at a q, lighting and cameras drawn anew, instead of unseen objects.
    """
    if q is not None and not 0.0 <= q <= 1.0:
        raise ConfigError(f"--q must lie in [0, 1], got {q}")
    shard_i, shard_n = parse_shard(shard)
    framing = resolve_framing(framing, category)
    if distance_m is not None and framing == "bounds":
        raise ConfigError("--distance-m: unused with framing bounds (furniture's by default), where each "
                          "camera stands as far as the piece's bounds and --margin ask; give --margin, or "
                          "--framing distance")
    cameras = CameraDistribution(azimuth_deg, elevation_deg, distance_m or CameraDistribution.distance_m,
                                 framing=framing, margin=margin)
    camera = PinholeCamera.from_fov(size, size, math.radians(fov_y_deg))
    out.mkdir(parents=True, exist_ok=True)
    mine = [i for i in range(n) if i % shard_n == shard_i]
    for i in tqdm(mine, unit="capture", desc=f"{category} captures"):
        target = out / f"{category}_{i:03d}"
        for partial in out.glob(f".{target.name}.tmp-*"):  # left by a killed run (`write_capture_set`)
            if not process_alive(int(partial.name.rsplit("-", 1)[1])):
                shutil.rmtree(partial, ignore_errors=True)
        if target.exists():
            continue
        rng = object_rng(SEED_DOMAIN_CAPTURE, seed, i)
        if training_objects:  # object i as `generate` draws it; q, lighting and cameras from rng
            obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, seed, i), name=f"{category}_{i:06d}")
        else:
            obj = sample_object(category, rng, name=f"{category}_capture_{i:03d}")
        if category in PART_CATEGORIES:
            q_drawn = part_articulations(rng, 1, obj.num_fronts)[0]
        else:
            q_drawn = float(rng.uniform(0.0, 1.0))
        X_OCs = cameras.sample(rng, views, *cameras.target_of(obj), camera)
        render_capture(obj, q_drawn if q is None else q, X_OCs, camera, rng, target)
    print(f"{len(mine)} capture sets in {out}")
