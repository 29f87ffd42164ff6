"""`nfr-drake generate`: render a training dataset of one category with Drake, resumably.

Objects are independent jobs spread over worker processes. Object i's shape, lighting,
articulations and cameras all come from its own random stream, so the data do not depend on the
number of workers, on sharding or on interruptions. Furniture (several fronts) adds a q per
front, a part-index image and per-part metadata (docs/DATASET_FORMAT.md).
"""

from __future__ import annotations

import json
import math
import multiprocessing
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from tqdm import tqdm

from nfr_drake.data.camera_placement import CameraDistribution, resolve_framing
from nfr_drake.data.shards import (
    DEPTH_SCALE,
    OBJECT_DATASET,
    OBJECTS_DIR,
    PART_CATEGORIES,
    DatasetFormat,
    DatasetSpec,
    completed_objects,
    dataset_lock,
    object_dir_name,
    open_dataset_dir,
    remove_partial,
    write_object,
)
from nfr_drake.errors import DatasetError

if TYPE_CHECKING:
    from nfr_drake.objects import ArticulatedObject


def articulation_values(rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` values of q covering [0, 1]: both ends exactly, interior points jittered within
    their share of the interval (a single value is drawn uniformly). Shape (count,)."""
    if count == 1:
        return rng.uniform(0.0, 1.0, size=1)
    q = np.linspace(0.0, 1.0, count)
    jitter = rng.uniform(-0.45, 0.45, size=count - 2) / (count - 1)
    q[1:-1] += jitter
    return q


PART_STATE_SHARES = (0.15, 0.35, 0.5)
"""Shares of a furniture articulation's states: all fronts shut, one front open, fronts mixed."""
FRONT_OPEN_PROBABILITY = 0.5
"""In a mixed state, each front is open (q uniform in [0, 1]) with this probability, else shut."""


def part_articulations(rng: np.random.Generator, count: int, fronts: int) -> np.ndarray:
    """`count` articulations of an object with `fronts` fronts, shape (count, fronts), q in [0, 1].

    Each articulation is drawn on its own (`PART_STATE_SHARES`): every front shut; one front
    (chosen uniformly) at q uniform in [0, 1], the others shut; or every front independently
    shut or, with probability `FRONT_OPEN_PROBABILITY`, at q uniform in [0, 1].
    """
    q = np.zeros((count, fronts))
    for a, state in enumerate(rng.choice(len(PART_STATE_SHARES), size=count, p=PART_STATE_SHARES)):
        if state == 1:
            q[a, rng.integers(fronts)] = rng.uniform()
        elif state == 2:
            opened = rng.uniform(size=fronts) < FRONT_OPEN_PROBABILITY
            q[a] = np.where(opened, rng.uniform(size=fronts), 0.0)
    return q


def part_meta(obj: ArticulatedObject, qs: np.ndarray) -> dict:
    """meta.json's per-part entries of an object rendered at articulations qs (A, F): the part
    order and, per front, its record (`front_record`), q (A,), named keypoints (A, 3) and the
    outer face's corners (A, 4, 3) (`Front.face_corners`), in O."""
    from nfr_drake.data.object_records import PART_ORDER, front_record

    parts = []
    for k, front in enumerate(obj.fronts):
        along = front.keypoint_array(qs[:, k])  # (A, K, 3)
        parts.append({**front_record(obj, k), "q": qs[:, k].tolist(),
                      "keypoints": {n: along[:, i].tolist() for i, n in enumerate(front.keypoint_names)},
                      "face_corners": front.face_corners(qs[:, k]).tolist()})
    return {"part_order": PART_ORDER, "parts": parts}


def draw_object(spec: DatasetSpec, index: int):
    """Object `index` of `spec` as the generator draws it now: (object, lighting, its random
    stream after them, which the articulations and cameras continue)."""
    from nfr_drake.data.render import sample_lighting
    from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object

    rng = object_rng(SEED_DOMAIN_TRAIN, spec.seed, index)
    obj = sample_object(spec.category, rng, name=f"{spec.category}_{index:06d}")
    return obj, sample_lighting(rng), rng


def _lighting_json(lighting) -> dict:
    """meta.json's `lighting` entry."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(lighting).items()}


def stale_objects(spec: DatasetSpec, out: Path) -> list[int]:
    """Complete objects in `out` that the generator now draws otherwise (their meta.json params or
    lighting differ from a fresh draw, e.g. after a change to an object sampler): a resumed run
    would mix two versions of the generator. Draws only, no rendering."""
    stale = []
    for index in completed_objects(out):
        meta = json.loads((Path(out) / OBJECTS_DIR / object_dir_name(index) / "meta.json").read_text())
        obj, lighting, _ = draw_object(spec, index)
        now = json.loads(json.dumps({"params": obj.params, "lighting": _lighting_json(lighting)}))
        if any(meta.get(k) != v for k, v in now.items()):
            stale.append(index)
    return stale


def render_object_arrays(spec: DatasetSpec, index: int):
    """Render object `index` of `spec`: (arrays, meta, sdf, files) ready for `write_object`."""
    from nfr_drake.data.camera import PinholeCamera
    from nfr_drake.data.object_records import portable_sdformat
    from nfr_drake.data.render import ObjectRenderer

    obj, lighting, rng = draw_object(spec, index)
    parts = spec.category in PART_CATEGORIES
    A, V, S = spec.articulations, spec.views, spec.size
    qs = part_articulations(rng, A, obj.num_fronts) if parts else articulation_values(rng, A)
    camera = PinholeCamera.from_fov(S, S, math.radians(spec.fov_y_deg))
    target, bounds = spec.cameras.target_of(obj)
    X_OC = np.stack([spec.cameras.sample(rng, V, target, bounds, camera) for _ in qs])
    renderer = ObjectRenderer(obj, camera, lighting, spec.background_rgb)

    arrays = {"rgb": np.empty((A, V, S, S, 3), np.uint8), "label": np.empty((A, V, S, S), np.uint8),
              "depth": np.empty((A, V, S, S), np.uint16)}
    if parts:
        arrays["part"] = np.empty((A, V, S, S), np.int8)
    for a, q in enumerate(qs):
        for v in range(V):
            view = renderer.render(q, X_OC[a, v])
            arrays["rgb"][a, v], arrays["label"][a, v] = view.rgb, view.label
            if parts:
                arrays["part"][a, v] = view.part
            d = np.where(np.isfinite(view.depth), view.depth * DEPTH_SCALE, 0.0)
            arrays["depth"][a, v] = np.clip(np.round(d), 0, np.iinfo(np.uint16).max)
    meta = {"index": index, "name": obj.name, "category": obj.category, "params": obj.params}
    if not parts:
        meta.update(joint_upper=obj.joint_upper, keypoint_names=list(obj.keypoint_names))
    meta.update(q=qs.tolist(), X_OC=X_OC.tolist())
    meta.update(part_meta(obj, qs) if parts else {"keypoints": obj.keypoint_array(qs).tolist()})
    meta.update(camera=camera.to_json(), lighting=_lighting_json(lighting))
    sdf, textures = portable_sdformat(obj)
    return arrays, meta, sdf, {rel: path.read_bytes() for rel, path in textures.items()}


def _render_and_write(job: tuple[DatasetSpec, str, int]) -> int:
    spec, root, index = job
    write_object(Path(root), index, *render_object_arrays(spec, index))
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

    Returns the indices rendered by this call. Safe to interrupt and call again; a second run
    on `out` while this one writes it is refused (`dataset_lock`), and so is a run whose generator
    draws objects already on disk otherwise (`stale_objects`).
    """
    if (Path(out) / OBJECTS_DIR).is_dir() and (stale := stale_objects(spec, out)):
        shown = ", ".join(object_dir_name(i) for i in stale[:5]) + (", ..." if len(stale) > 5 else "")
        raise DatasetError(f"{out}: {len(stale)} objects on disk ({shown}) were drawn by another "
                           "version of the generator; delete those object folders and rerun to "
                           "draw them again, or use another --out")
    return render_dataset(spec, OBJECT_DATASET, spec.objects, _render_and_write, out, workers, shard,
                          progress, images_per_index=spec.articulations * spec.views)


def render_dataset(spec, fmt: DatasetFormat, count: int, render_and_write: Callable[[tuple], int],
                   out: Path, workers: int, shard: str, progress: bool, images_per_index: int
                   ) -> list[int]:
    """Render the indices in range(`count`) of `shard` that are not complete in `out`, a dataset
    of format `fmt` and spec `spec`: `render_and_write((spec, str(out), index))` (a module-level
    function: workers are spawned processes) writes one index and returns it. Holds the folder's
    lock; returns the indices rendered by this call."""
    shard_i, shard_n = parse_shard(shard)
    out = Path(out)
    with dataset_lock(out):
        open_dataset_dir(out, spec, fmt)
        mine = [i for i in range(count) if i % shard_n == shard_i]
        remove_partial(out, set(mine))
        done = set(completed_objects(out))
        jobs = [(spec, str(out), i) for i in mine if i not in done]
        bar = tqdm(total=len(jobs) * images_per_index, unit="img", disable=not progress,
                   desc=f"{spec.category}: {len(jobs)} to render "
                        f"({len(done & set(mine))} already on disk)")
        rendered = []
        with ExitStack() as stack:
            if workers > 1 and len(jobs) > 1:
                pool = stack.enter_context(
                    multiprocessing.get_context("spawn").Pool(min(workers, len(jobs))))
                results = pool.imap_unordered(render_and_write, jobs)
            else:
                results = map(render_and_write, jobs)
            for index in results:
                rendered.append(index)
                bar.update(images_per_index)
        bar.close()
        return rendered


def generate_command(
    category: Literal["closet", "drawer", "furniture"],
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
    framing: Literal["auto", "distance", "bounds"] = "auto",
    margin: tuple[float, float] = (0.05, 0.25),
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
        distance_m: camera distance range to the object centre, metres (framing "distance").
        framing: "distance": distance drawn from distance_m, looking at the carcass centre;
            "bounds": from the distance at which the object's bounds over all articulations fill
            the image but a margin, looking at their centre; "auto": "bounds" for furniture,
            "distance" for closets and drawers.
        margin: framing "bounds": free border around the bounds, a fraction of the image's
            half-size, drawn per view from this range.
    """
    cameras = CameraDistribution(azimuth_deg, elevation_deg, distance_m,
                                 framing=resolve_framing(framing, category), margin=margin)
    spec = DatasetSpec(category, objects, articulations, views, size, seed, fov_y_deg, cameras)
    rendered = generate_dataset(spec, out, workers, shard)
    print(f"rendered {len(rendered)} objects into {out}")
