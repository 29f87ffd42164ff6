"""`nfr-drake generate-rooms`: objects photographed in random rooms, for 2D segmentation.

Same layout and crash safety as the object datasets (`nfr_drake.data.shards`; one folder per
room, written by `write_object`), its own spec and format name (docs/ROOMS.md):
```
DIR/dataset.json                 {"format": "nfr-drake-room-dataset", "version": 1, "spec": RoomDatasetSpec}
DIR/objects/obj_000123/          one room around one target object
    rgb.npy     uint8  (A, V, S, S, 3)  the photo: render + sensor effects (exposure, noise, blur)
    label.npy   uint8  (A, V, S, S)     the TARGET's semantic class, 0 on everything else
    part.npy    int8   (A, V, S, S)     the target's front index, -1 elsewhere
    depth.npy   uint16 (A, V, S, S)     mm along the optical axis (the whole room), 0 = none
    carcass_amodal.npy uint8 (A, V, S, S) the target's carcass body alone as if nothing hid it
                (no fronts, no clutter; `data.amodal`), 1 on it; `nfr-drake label-amodal` adds it
    meta.json   q (A, F), X_OC (A, V, 4, 4) OpenCV axes (W = O), keypoints per front (A, K, 3)
                in O, camera, room (textures, neighbours, clutter, arm, lights), sensor (A, V)
    object.sdf  the target object (textures/ beside it)
```
The object mask is label > 0. Room i is drawn from `object_rng(SEED_DOMAIN_ROOM, seed, i)`.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from nfr_drake.data.generate import render_dataset
from nfr_drake.data.rooms import RoomDistribution
from nfr_drake.data.shards import (
    DEPTH_SCALE,
    OBJECTS_DIR,
    DatasetFormat,
    completed_objects,
    object_dir_name,
    read_spec,
    write_object,
)
from nfr_drake.errors import DatasetError

ROOM_FORMAT_NAME = "nfr-drake-room-dataset"
ROOM_FORMAT_VERSION = 1
SHUT_PROBABILITY = 0.4
"""Chance that a front of the target is shut (q = 0) in an articulation; else q is uniform."""


@dataclass(frozen=True)
class RoomDatasetSpec:
    """Everything that determines a room dataset's content.

    category: the target objects' category; rooms: number of rooms (one target each);
    articulations (A) and views (V) per room; size: square image size, px; seed: base seed;
    fov_y_deg: vertical field of view, degrees; room: what the rooms hold.
    """

    category: str
    rooms: int
    articulations: int = 2
    views: int = 4
    size: int = 96
    seed: int = 0
    fov_y_deg: float = 50.0
    room: RoomDistribution = field(default_factory=RoomDistribution)

    def __post_init__(self):
        from nfr_drake.objects import CATEGORIES

        if self.category not in CATEGORIES:
            raise DatasetError(f"unknown category {self.category!r}; choose one of {sorted(CATEGORIES)}")
        for name in ("rooms", "articulations", "views", "size"):
            if getattr(self, name) < 1:
                raise DatasetError(f"{name} must be at least 1, got {getattr(self, name)}")
        if not 1.0 <= self.fov_y_deg <= 170.0:
            raise DatasetError(f"fov_y_deg must lie in [1, 170], got {self.fov_y_deg}")

    def to_json(self) -> dict:
        return json.loads(json.dumps(asdict(self)))

    @classmethod
    def from_json(cls, d: dict) -> RoomDatasetSpec:
        d = dict(d)
        room = {k: tuple(v) if isinstance(v, list) else v for k, v in d.pop("room").items()}
        return cls(room=RoomDistribution(**room), **d)



ROOM_DATASET = DatasetFormat(ROOM_FORMAT_NAME, ROOM_FORMAT_VERSION, RoomDatasetSpec,
                             "nfr-drake generate-rooms")
"""The room datasets of `nfr-drake generate-rooms`."""

def read_room_spec(root: Path) -> RoomDatasetSpec:
    """The spec of the room dataset in `root`; DatasetError when missing or not a room dataset."""
    return read_spec(root, ROOM_DATASET)


def render_room_arrays(spec: RoomDatasetSpec, index: int):
    """Render room `index` of `spec`: (arrays, meta, sdf, files) ready for `write_object`."""
    from nfr_drake.data.amodal import amodal_labels
    from nfr_drake.data.camera import PinholeCamera
    from nfr_drake.data.object_records import portable_sdformat
    from nfr_drake.data.render import ObjectRenderer
    from nfr_drake.data.rooms import sample_room, sample_room_cameras
    from nfr_drake.data.sensor_effects import sample_sensor_effects
    from nfr_drake.objects import SEED_DOMAIN_ROOM, object_rng, sample_object

    rng = object_rng(SEED_DOMAIN_ROOM, spec.seed, index)
    obj = sample_object(spec.category, rng, name=f"{spec.category}_{index:06d}")
    A, V, S = spec.articulations, spec.views, spec.size
    camera = PinholeCamera.from_fov(S, S, math.radians(spec.fov_y_deg))
    X_OC = sample_room_cameras(rng, A * V, obj, camera, spec.room).reshape(A, V, 4, 4)
    room = sample_room(rng, obj, X_OC[..., :3, 3].reshape(-1, 3), spec.room)
    qs = rng.uniform(0.0, 1.0, (A, obj.num_fronts)) * (rng.uniform(size=(A, obj.num_fronts))
                                                       >= SHUT_PROBABILITY)
    renderer = ObjectRenderer(obj, camera, room.lighting, add_scenery=room.add_to)
    arrays = {"rgb": np.empty((A, V, S, S, 3), np.uint8), "label": np.empty((A, V, S, S), np.uint8),
              "part": np.empty((A, V, S, S), np.int8), "depth": np.empty((A, V, S, S), np.uint16)}
    sensor = []
    for a in range(A):
        sensor.append([])
        for v in range(V):
            view = renderer.render(qs[a], X_OC[a, v])
            effects = sample_sensor_effects(rng)
            sensor[-1].append(effects.to_json())
            arrays["rgb"][a, v] = effects.apply(view.rgb)
            arrays["label"][a, v], arrays["part"][a, v] = view.label, view.part
            d = np.where(np.isfinite(view.depth), view.depth * DEPTH_SCALE, 0.0)
            arrays["depth"][a, v] = np.clip(np.round(d), 0, np.iinfo(np.uint16).max)
    meta = {"index": index, "name": obj.name, "category": obj.category, "params": obj.params,
            "q": qs.tolist(), "X_OC": X_OC.tolist(),
            "keypoints": [{n: front.keypoint_array(qs[:, k])[:, i].tolist()
                           for i, n in enumerate(front.keypoint_names)}
                          for k, front in enumerate(obj.fronts)],
            "camera": camera.to_json(), "room": room.to_json(), "sensor": sensor}
    sdf, textures = portable_sdformat(obj)
    arrays["carcass_amodal"] = amodal_labels(sdf, X_OC, camera)
    return arrays, meta, sdf, {rel: path.read_bytes() for rel, path in textures.items()}


def _render_and_write(job: tuple[RoomDatasetSpec, str, int]) -> int:
    spec, root, index = job
    write_object(Path(root), index, *render_room_arrays(spec, index))
    return index


def generate_rooms(spec: RoomDatasetSpec, out: Path, workers: int = 1, shard: str = "0/1",
                   progress: bool = True) -> list[int]:
    """Render the rooms of `spec` that belong to `shard` and are not yet in `out`; returns the
    indices rendered by this call. Safe to interrupt and call again."""
    return render_dataset(spec, ROOM_DATASET, spec.rooms, _render_and_write, out, workers, shard,
                          progress, images_per_index=spec.articulations * spec.views)


def room_dirs(root: Path) -> list[Path]:
    """The complete room folders of a room dataset, by index."""
    read_room_spec(root)
    return [Path(root) / OBJECTS_DIR / object_dir_name(i) for i in completed_objects(root)]


def generate_rooms_command(
    category: Literal["closet", "drawer", "furniture"],
    rooms: int,
    out: Path,
    articulations: int = 2,
    views: int = 4,
    size: int = 96,
    seed: int = 0,
    style: Literal["train", "heldout"] = "train",
    neighbours: tuple[int, int] = (0, 3),
    twin_probability: float = 0.0,
    cut_probability: float = 0.2,
    robot_probability: float = 0.8,
    margin: tuple[float, float] = (0.05, 0.5),
    workers: int = 1,
    shard: str = "0/1",
) -> None:
    """Render objects of one category in random rooms (floor, walls, furniture, clutter, the arm).

    Args:
        category: the target objects' category.
        rooms: number of rooms (one target object each).
        out: dataset folder; an interrupted run resumes when started again with the same options.
        articulations: articulations of the target per room.
        views: cameras per articulation.
        size: square image size, px.
        seed: base seed (use another seed for evaluation sets).
        style: "train" textures and lights, or the "heldout" family (for evaluation).
        neighbours: range of the number of other pieces of furniture.
        twin_probability: chance of a copy of the object right beside it.
        cut_probability: chance that a view's image edge cuts the object.
        robot_probability: chance that the Panda arm stands in front of the object.
        margin: range of the free border around the object's bounds, a fraction of the half-image.
        workers: rendering processes.
        shard: i/n renders rooms with index % n == i.
    """
    room = RoomDistribution(style=style, neighbours=neighbours, twin_probability=twin_probability,
                            cut_probability=cut_probability, robot_probability=robot_probability,
                            margin=margin)
    spec = RoomDatasetSpec(category, rooms, articulations, views, size, seed, room=room)
    rendered = generate_rooms(spec, out, workers, shard)
    print(f"rendered {len(rendered)} rooms into {out}")
