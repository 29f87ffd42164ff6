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

import fcntl
import json
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.errors import DatasetError

FORMAT_NAME = "nfr-drake-dataset"
FORMAT_VERSION = 1
SPEC_FILE = "dataset.json"
LOCK_FILE = ".generate.lock"
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


@dataclass(frozen=True)
class DatasetFormat:
    """A kind of dataset folder: the format name and version dataset.json states, the spec class
    it holds (with `to_json` / `from_json`) and the command that writes such folders (named in
    errors)."""

    name: str
    version: int
    spec_type: type
    command: str


OBJECT_DATASET = DatasetFormat(FORMAT_NAME, FORMAT_VERSION, DatasetSpec, "nfr-drake generate")
"""The object datasets of `nfr-drake generate`."""


def object_dir_name(index: int) -> str:
    return f"obj_{index:06d}"


@contextmanager
def dataset_lock(root: Path) -> Iterator[None]:
    """Hold the lock of the dataset folder `root` (flock on ROOT/.generate.lock, released when
    the holder exits, even by kill -9) while writing it; DatasetError naming the holder's pid
    when another run holds it."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    fd = os.open(root / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            raise DatasetError(f"{root} is being written by another `nfr-drake generate` (pid "
                               f"{holder}); wait for it to finish, or use another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)


def open_dataset_dir(root: Path, spec, fmt: DatasetFormat = OBJECT_DATASET) -> None:
    """Create `root` for `spec` (a dataset of format `fmt`), or check that an existing one was
    written with the same spec.

    dataset.json is written under a temporary name and linked into place, which fails when the
    file exists: it is created once, whole, even by two runs at the same moment."""
    (root / OBJECTS_DIR).mkdir(parents=True, exist_ok=True)
    spec_path = root / SPEC_FILE
    tmp = spec_path.with_name(f".{SPEC_FILE}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps({"format": fmt.name, "version": fmt.version,
                               "spec": spec.to_json()}, indent=2))
    try:
        os.link(tmp, spec_path)
    except FileExistsError:
        existing = read_spec(root, fmt)
        if existing != spec:
            raise DatasetError(
                f"{spec_path} was written with other options ({_spec_diff(existing, spec)}); "
                "use the same options to resume, or another --out") from None
    finally:
        tmp.unlink()


def _spec_diff(a: DatasetSpec, b: DatasetSpec) -> str:
    da, db = a.to_json(), b.to_json()
    return ", ".join(f"{k}: {da[k]} vs {db[k]}" for k in da if da[k] != db[k])


def read_spec(root: Path, fmt: DatasetFormat = OBJECT_DATASET):
    """The spec (a `fmt.spec_type`) of the dataset in `root`; DatasetError when it is missing or
    not a dataset of format `fmt`."""
    path = Path(root) / SPEC_FILE
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{path}: not found; is {root} a dataset written by "
                           f"`{fmt.command}`?") from None
    except json.JSONDecodeError as err:
        raise DatasetError(f"{path}: malformed JSON ({err})") from None
    if doc.get("format") != fmt.name or doc.get("version") != fmt.version:
        raise DatasetError(f"{path}: not an {fmt.name} v{fmt.version} file")
    try:
        return fmt.spec_type.from_json(doc["spec"])
    except (KeyError, TypeError) as err:
        raise DatasetError(f"{path}: bad spec ({err})") from None


def completed_objects(root: Path) -> list[int]:
    """Indices of the objects whose folders are complete, sorted."""
    names = os.listdir(Path(root) / OBJECTS_DIR)
    return sorted(int(n[4:]) for n in names if n.startswith("obj_"))


def process_alive(pid: int) -> bool:
    """Whether a process with this id runs on this machine; a zombie (killed, not yet reaped by
    its parent) does not."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        pass
    if not Path("/proc/self/stat").exists():  # no procfs (not Linux): cannot tell a zombie
        return True
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:  # ended meanwhile
        return False
    return state not in ("Z", "X")


def remove_partial(root: Path, indices: set[int]) -> None:
    """Delete the temporary folders of the given objects whose writer (the pid in the name,
    `write_object`) is gone; a live one (an orphaned worker of a killed run) keeps its folder."""
    objects = Path(root) / OBJECTS_DIR
    for name in os.listdir(objects):
        if name.startswith(".obj_") and ".tmp-" in name:
            index, pid = int(name[5:11]), int(name.rsplit("-", 1)[1])
            if index in indices and not process_alive(pid):
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
