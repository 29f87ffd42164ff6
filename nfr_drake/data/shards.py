"""On-disk layout of rendered datasets (see docs/DATASET_FORMAT.md).

```
DIR/dataset.json                 DatasetSpec (what the images are) + format version
DIR/objects/obj_000123/          one folder per object, renamed into place when complete
    rgb.npy     uint8   (A, V, S, S, 3)
    label.npy   uint8   (A, V, S, S)      semantic class per pixel (docs/CONVENTIONS.md)
    part.npy    int8    (A, V, S, S)      furniture only: front index per pixel, -1 where none
    depth.npy   uint16  (A, V, S, S)      millimetres along the optical axis, 0 = no surface
    meta.json   q (A,), X_OC (A, V, 4, 4) OpenCV axes, keypoints (A, K, 3) in O, params;
                furniture: q (A, F) and per part its joint, q and named keypoints
    object.sdf  the object's SDFormat
    textures/   the PNG textures object.sdf names (by relative path), if any
```
A = articulations, V = views, S = image size, F = fronts. Arrays are plain .npy so that readers
memory-map them; a folder without the `.tmp` prefix is always complete.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.errors import DatasetError

FORMAT_NAME = "nfr-drake-dataset"
FORMAT_VERSION = 1
SPEC_FILE = "dataset.json"
OBJECTS_DIR = "objects"
DEPTH_SCALE = 1000.0  # depth.npy units per metre
PART_CATEGORIES = frozenset({"furniture"})
"""Categories whose objects have several fronts: datasets add part.npy and per-part metadata."""


@dataclass(frozen=True)
class DatasetSpec:
    """Everything that determines a dataset's content; two runs with equal specs write equal data.

    Attributes:
        category: object category ("closet", "drawer" or "furniture").
        objects: number of objects in the whole dataset (all shards).
        articulations: articulations per object (A).
        views: camera views per articulation (V).
        size: square image size in pixels (S).
        seed: base seed; object i draws from `object_rng(SEED_DOMAIN_TRAIN, seed, i)`.
        fov_y_deg: vertical field of view, degrees.
        cameras: the camera distribution around each object.
        background_rgb: clear colour of the renders, each channel in [0, 1].
    """

    category: str
    objects: int
    articulations: int
    views: int
    size: int
    seed: int = 0
    fov_y_deg: float = 50.0
    cameras: CameraDistribution = field(default_factory=CameraDistribution)
    background_rgb: tuple[float, float, float] = (0.92, 0.92, 0.92)

    def __post_init__(self):
        for name in ("objects", "articulations", "views", "size"):
            if getattr(self, name) < 1:
                raise DatasetError(f"{name} must be at least 1, got {getattr(self, name)}")
        if not 1.0 <= self.fov_y_deg <= 170.0:
            raise DatasetError(f"fov_y_deg must lie in [1, 170], got {self.fov_y_deg}")

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> DatasetSpec:
        d = dict(d)
        cams = {k: tuple(v) if isinstance(v, list) else v for k, v in d.pop("cameras").items()}
        d["background_rgb"] = tuple(d["background_rgb"])
        return cls(cameras=CameraDistribution(**cams), **d)


def object_dir_name(index: int) -> str:
    return f"obj_{index:06d}"


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON so that a reader sees the old file or the new one, never a partial one."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(data, indent=2))
    os.replace(tmp, path)


def open_dataset_dir(root: Path, spec: DatasetSpec) -> None:
    """Create `root` for `spec`, or check that an existing one was written with the same spec."""
    (root / OBJECTS_DIR).mkdir(parents=True, exist_ok=True)
    spec_path = root / SPEC_FILE
    doc = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "spec": spec.to_json()}
    if spec_path.exists():
        existing = read_spec(root)
        if existing != spec:
            raise DatasetError(
                f"{spec_path} was written with other options ({_spec_diff(existing, spec)}); "
                "use the same options to resume, or another --out")
    else:
        write_json_atomic(spec_path, doc)


def _spec_diff(a: DatasetSpec, b: DatasetSpec) -> str:
    da, db = a.to_json(), b.to_json()
    return ", ".join(f"{k}: {da[k]} vs {db[k]}" for k in da if da[k] != db[k])


def read_spec(root: Path) -> DatasetSpec:
    """The spec of the dataset in `root`; DatasetError when it is missing or not one of ours."""
    path = Path(root) / SPEC_FILE
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{path}: not found; is {root} a dataset written by "
                           "`nfr-drake generate`?") from None
    except json.JSONDecodeError as err:
        raise DatasetError(f"{path}: malformed JSON ({err})") from None
    if doc.get("format") != FORMAT_NAME or doc.get("version") != FORMAT_VERSION:
        raise DatasetError(f"{path}: not an {FORMAT_NAME} v{FORMAT_VERSION} file")
    return DatasetSpec.from_json(doc["spec"])


def completed_objects(root: Path) -> list[int]:
    """Indices of the objects whose folders are complete, sorted."""
    names = os.listdir(Path(root) / OBJECTS_DIR)
    return sorted(int(n[4:]) for n in names if n.startswith("obj_"))


def remove_partial(root: Path, indices: set[int]) -> None:
    """Delete temporary folders left by killed runs, for the given object indices only."""
    objects = Path(root) / OBJECTS_DIR
    for name in os.listdir(objects):
        if name.startswith(".obj_") and ".tmp-" in name:
            index = int(name[5:11])
            if index in indices:
                shutil.rmtree(objects / name, ignore_errors=True)


def write_object(root: Path, index: int, arrays: dict[str, np.ndarray], meta: dict,
                 sdf: str, files: dict[str, bytes] | None = None) -> None:
    """Write one object's folder atomically (temporary folder, then rename); `files` maps more
    relative paths to their bytes (the textures object.sdf names).

    If another process completed the same object meanwhile (an orphaned worker of a killed run),
    its folder is kept and this one discarded: both hold the same deterministic data.
    """
    final = Path(root) / OBJECTS_DIR / object_dir_name(index)
    tmp = final.with_name(f".{final.name}.tmp-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    for name, array in arrays.items():
        np.save(tmp / f"{name}.npy", array)
    (tmp / "meta.json").write_text(json.dumps(meta))
    (tmp / "object.sdf").write_text(sdf)
    for rel, content in (files or {}).items():
        (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp / rel).write_bytes(content)
    try:
        os.replace(tmp, final)
    except OSError:
        if not final.is_dir():
            raise
        shutil.rmtree(tmp, ignore_errors=True)
