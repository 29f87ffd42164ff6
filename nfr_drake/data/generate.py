"""`nfr-drake generate`: render a training dataset of one category with Drake, resumably.

Objects are independent jobs spread over worker processes. Object i's shape, lighting,
articulations and cameras all come from its own random stream, so the data do not depend on the
number of workers, on sharding or on interruptions.
"""

from __future__ import annotations

import math
import multiprocessing
from pathlib import Path
from typing import Literal

import numpy as np
from tqdm import tqdm

from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.data.shards import (
    DEPTH_SCALE,
    DatasetSpec,
    completed_objects,
    open_dataset_dir,
    remove_partial,
    write_object,
)
from nfr_drake.errors import DatasetError


def articulation_values(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` values of q covering [0, 1]: both ends exactly, interior points jittered within
    their share of the interval (a single value is drawn uniformly). Shape (count,)."""
    if count == 1:
        return rng.uniform(0.0, 1.0, size=1)
    q = np.linspace(0.0, 1.0, count)
    jitter = rng.uniform(-0.45, 0.45, size=count - 2) / (count - 1)
    q[1:-1] += jitter
    return q


def render_object_arrays(spec: DatasetSpec, index: int):
    """Render object `index` of `spec`: (arrays, meta, sdf) ready for `write_object`."""
    from nfr_drake.data.camera import PinholeCamera
    from nfr_drake.data.render import ObjectRenderer, sample_lighting
    from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object, to_sdformat

    rng = object_rng(SEED_DOMAIN_TRAIN, spec.seed, index)
    obj = sample_object(spec.category, rng, name=f"{spec.category}_{index:06d}")
    lighting = sample_lighting(rng)
    qs = articulation_values(rng, spec.articulations)
    X_OC = np.stack([spec.cameras.sample(rng, spec.views, obj.look_at_target()) for _ in qs])
    camera = PinholeCamera.from_fov(spec.size, spec.size, math.radians(spec.fov_y_deg))
    renderer = ObjectRenderer(obj, camera, lighting, spec.background_rgb)

    A, V, S = spec.articulations, spec.views, spec.size
    rgb = np.empty((A, V, S, S, 3), np.uint8)
    label = np.empty((A, V, S, S), np.uint8)
    depth = np.empty((A, V, S, S), np.uint16)
    for a, q in enumerate(qs):
        for v in range(V):
            view = renderer.render(q, X_OC[a, v])
            rgb[a, v], label[a, v] = view.rgb, view.label
            d = np.where(np.isfinite(view.depth), view.depth * DEPTH_SCALE, 0.0)
            depth[a, v] = np.clip(np.round(d), 0, np.iinfo(np.uint16).max)
    meta = {
        "index": index,
        "name": obj.name,
        "category": obj.category,
        "params": obj.params,
        "joint_upper": obj.joint_upper,
        "keypoint_names": list(obj.keypoint_names),
        "q": qs.tolist(),
        "X_OC": X_OC.tolist(),
        "keypoints": obj.keypoint_array(qs).tolist(),
        "camera": camera.to_json(),
        "lighting": {k: (list(v) if isinstance(v, tuple) else v)
                     for k, v in vars(lighting).items()},
    }
    return {"rgb": rgb, "label": label, "depth": depth}, meta, to_sdformat(obj)


def _render_and_write(job: tuple[DatasetSpec, str, int]) -> int:
    spec, root, index = job
    arrays, meta, sdf = render_object_arrays(spec, index)
    write_object(Path(root), index, arrays, meta, sdf)
    return index


def parse_shard(shard: str) -> tuple[int, int]:
    """'i/n' -> (i, n) with 0 <= i < n."""
    try:
        i, n = (int(x) for x in shard.split("/"))
    except ValueError:
        raise DatasetError(f"--shard must look like i/n (e.g. 0/4), got {shard!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise DatasetError(f"--shard {shard}: need 0 <= i < n")
    return i, n


def generate_dataset(spec: DatasetSpec, out: Path, workers: int = 2, shard: str = "0/1",
                     progress: bool = True) -> list[int]:
    """Render the objects of `spec` that belong to `shard` and are not yet in `out`.

    Returns the indices rendered by this call. Safe to interrupt and call again.
    """
    shard_i, shard_n = parse_shard(shard)
    out = Path(out)
    open_dataset_dir(out, spec)
    mine = [i for i in range(spec.objects) if i % shard_n == shard_i]
    remove_partial(out, set(mine))
    done = set(completed_objects(out))
    pending = [i for i in mine if i not in done]
    per_object = spec.articulations * spec.views
    bar = tqdm(total=len(pending) * per_object, unit="img", disable=not progress,
               desc=f"{spec.category}: {len(pending)} objects to render "
                    f"({len(done & set(mine))} already on disk)")
    jobs = [(spec, str(out), i) for i in pending]
    rendered = []
    if workers <= 1 or len(jobs) <= 1:
        results = map(_render_and_write, jobs)
        for index in results:
            rendered.append(index)
            bar.update(per_object)
    else:
        context = multiprocessing.get_context("spawn")
        with context.Pool(min(workers, len(jobs))) as pool:
            for index in pool.imap_unordered(_render_and_write, jobs):
                rendered.append(index)
                bar.update(per_object)
    bar.close()
    return rendered


def generate_command(
    category: Literal["closet", "drawer"],
    objects: int,
    out: Path,
    articulations: int = 10,
    views: int = 10,
    size: int = 64,
    seed: int = 0,
    workers: int = 2,
    shard: str = "0/1",
    fov_y_deg: float = 50.0,
    azimuth_deg: tuple[float, float] = (-60.0, 60.0),
    elevation_deg: tuple[float, float] = (5.0, 40.0),
    distance_m: tuple[float, float] = (1.4, 1.9),
) -> None:
    """Render a training dataset: `objects` instances x `articulations` q values x `views` cameras.

    Args:
        category: object category.
        objects: number of objects in the whole dataset (all shards together).
        out: dataset folder; an interrupted run resumes when started again with the same options.
        articulations: q values per object, covering [0, 1].
        views: cameras per articulation.
        size: square image size, pixels.
        seed: base seed of the dataset.
        workers: rendering processes.
        shard: i/n renders objects with index % n == i (split a large set across machines).
        fov_y_deg: vertical field of view, degrees.
        azimuth_deg: camera azimuth range around the front, degrees.
        elevation_deg: camera elevation range, degrees.
        distance_m: camera distance range to the object centre, metres.
    """
    spec = DatasetSpec(category, objects, articulations, views, size, seed, fov_y_deg,
                       CameraDistribution(azimuth_deg, elevation_deg, distance_m))
    rendered = generate_dataset(spec, out, workers, shard)
    print(f"rendered {len(rendered)} objects into {out}")
