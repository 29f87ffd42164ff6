"""`nfr-drake validate`: check a capture set or a rendered dataset and summarise it.

Beyond what `read_capture_set` checks (transforms.json and its images), ground truth is checked
where there is some: the files gt.json names exist; object.sdf names its textures by paths inside
the folder, and they exist; furniture ground truth lists every part in canonical order with its
fields, and the part-index images agree with the label images (a part exactly where the class is
moving part or handle). A dataset's objects are checked likewise (array shapes and types, meta.json,
part.npy against label.npy, object.sdf and its textures).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
import tyro

from nfr_drake.data.capture import CaptureSet, read_capture_set
from nfr_drake.data.shards import (
    OBJECTS_DIR,
    PART_CATEGORIES,
    SPEC_FILE,
    completed_objects,
    object_dir_name,
    read_spec,
)
from nfr_drake.errors import CaptureSetError, DatasetError
from nfr_drake.objects import SemanticClass

PART_KEYS = ("index", "type", "link_name", "joint_name", "joint_type", "joint_upper", "keypoint_names",
             "q", "joint_value", "keypoints", "face_corners", "trajectory")
"""Fields of every part of a furniture capture's gt.json; doors add hinge_axis, drawers pull_axis
and travel."""
NO_PART_PNG = 255  # a part image's value where no front is seen (int8 -1 stored as uint8)
_DIFFUSE_MAP = "{http://drake.mit.edu}diffuse_map"


def check_object_sdf(path: Path, error: type[Exception]) -> int:
    """Raise `error` unless the SDFormat file at `path` exists and every texture it names is a
    relative path to a file in its folder; returns the number of textures."""
    try:
        tree = ET.parse(path)
    except (OSError, ET.ParseError) as err:
        raise error(f"{path}: not a readable SDFormat file ({err})") from None
    names = {(e.text or "").strip() for e in tree.iter(_DIFFUSE_MAP)}
    for name in sorted(names):
        if "://" in name or Path(name).is_absolute():
            raise error(f"{path}: texture {name!r} is not a path relative to its folder")
        if not (path.parent / name).is_file():
            raise error(f"{path}: texture {name!r} not found")
    return len(names)


def check_part_image(label: np.ndarray, part: np.ndarray, fronts: int, where: str,
                     error: type[Exception]) -> None:
    """Raise `error` unless part (int8, -1 where none) is a front index < `fronts` exactly where
    label (same shape) is a moving part or a handle."""
    moving = label >= SemanticClass.MOVING
    if not np.array_equal(part >= 0, moving):
        raise error(f"{where}: {int(np.sum((part >= 0) != moving))} pixels where the part image and "
                    "the label image disagree on whether a front is seen")
    if part.max(initial=-1) >= fronts:
        raise error(f"{where}: part index {int(part.max())} but the object has {fronts} fronts")


def _check_parts_gt(cap: CaptureSet) -> str:
    gt, root = cap.gt, cap.root
    parts = gt["parts"]
    fail = CaptureSetError
    if [p.get("index") for p in parts] != list(range(len(parts))):
        raise fail(f"{root / 'gt.json'}: parts must be listed in order 0..{len(parts) - 1}")
    for p in parts:
        axis = ("hinge_axis",) if p.get("joint_type") == "revolute" else ("pull_axis", "travel")
        missing = [k for k in PART_KEYS + axis if k not in p]
        if missing:
            raise fail(f"{root / 'gt.json'}: part {p['index']} lacks {', '.join(missing)}")
        names = list(p["keypoint_names"])
        if sorted(p["keypoints"]) != sorted(names) or sorted(p["trajectory"]["keypoints"]) != sorted(names):
            raise fail(f"{root / 'gt.json'}: part {p['index']}: keypoints differ from {names}")
    if len(gt.get("q", [])) != len(parts):
        raise fail(f"{root / 'gt.json'}: q has {len(gt.get('q', []))} values for {len(parts)} parts")
    for label_path, part_path in zip(gt["label_paths"], gt.get("part_paths") or [], strict=True):
        label = cv2.imread(str(root / label_path), cv2.IMREAD_UNCHANGED)
        part = cv2.imread(str(root / part_path), cv2.IMREAD_UNCHANGED)
        part = np.where(part == NO_PART_PNG, -1, part.astype(np.int16))
        check_part_image(label, part, len(parts), str(root / part_path), fail)
    return f"{len(parts)} parts ({', '.join(p['type'] for p in parts)})"


def check_capture_ground_truth(cap: CaptureSet) -> str:
    """Check the ground truth of a capture set (module docstring); a one-line summary of it."""
    gt, root = cap.gt, cap.root
    if gt is None:
        return "ground truth: no"
    paths = list(gt.get("label_paths", [])) + list(gt.get("part_paths") or [])
    for rel in paths:
        if not (root / rel).is_file():
            raise CaptureSetError(f"{root / 'gt.json'} names {rel}, which is not in {root}")
    for key in ("label_paths", "part_paths"):
        if gt.get(key) is not None and len(gt[key]) != len(cap.frames):
            raise CaptureSetError(f"{root / 'gt.json'}: {len(gt[key])} {key} for {len(cap.frames)} frames")
    textures = check_object_sdf(root / gt["object_sdf"], CaptureSetError) if gt.get("object_sdf") else 0
    what = _check_parts_gt(cap) if "parts" in gt else f"q {gt.get('q')}"
    return f"ground truth: {gt.get('category', 'no category')}, {what}, {textures} textures"


def check_dataset(root: Path) -> str:
    """Check every complete object of the dataset in `root` (module docstring); a summary line."""
    spec = read_spec(root)
    A, V, S = spec.articulations, spec.views, spec.size
    shapes = {"rgb": ((A, V, S, S, 3), np.uint8), "label": ((A, V, S, S), np.uint8),
              "depth": ((A, V, S, S), np.uint16)}
    has_parts = spec.category in PART_CATEGORIES
    if has_parts:
        shapes["part"] = ((A, V, S, S), np.int8)
    indices = completed_objects(root)
    textures = 0
    for i in indices:
        folder = root / OBJECTS_DIR / object_dir_name(i)
        arrays = {}
        for name, (shape, dtype) in shapes.items():
            try:
                arrays[name] = np.load(folder / f"{name}.npy", mmap_mode="r")
            except (OSError, ValueError) as err:
                raise DatasetError(f"{folder / name}.npy: unreadable ({err})") from None
            if arrays[name].shape != shape or arrays[name].dtype != dtype:
                raise DatasetError(f"{folder / name}.npy: {arrays[name].dtype} {arrays[name].shape}, "
                                   f"expected {np.dtype(dtype)} {shape}")
        meta = json.loads((folder / "meta.json").read_text())
        fronts = len(meta["parts"]) if has_parts else 1
        if np.shape(meta["q"]) != ((A, fronts) if has_parts else (A,)):
            raise DatasetError(f"{folder / 'meta.json'}: q has shape {np.shape(meta['q'])}")
        if has_parts:
            check_part_image(np.asarray(arrays["label"]), np.asarray(arrays["part"]), fronts,
                             str(folder / "part.npy"), DatasetError)
        textures += check_object_sdf(folder / "object.sdf", DatasetError)
    return (f"{root}: {spec.category} dataset, {len(indices)} of {spec.objects} objects complete, "
            f"{A} articulations x {V} views at {S} px, {textures} textures (all present)")


def validate_command(capture: Annotated[Path, tyro.conf.Positional]) -> None:
    """Validate the capture set (transforms.json and its images, gt.json if any) or the dataset
    (dataset.json and its objects) in CAPTURE; exit 2 if invalid.

    Args:
        capture: capture-set folder, or dataset folder written by `nfr-drake generate`.
    """
    if (capture / SPEC_FILE).is_file():
        print(check_dataset(capture))
        return
    cap = read_capture_set(capture)
    centres = np.array([f.X_OC[:3, 3] for f in cap.frames])
    sizes = sorted({(f.camera.width, f.camera.height) for f in cap.frames})
    fovs = sorted({round(np.degrees(f.camera.fov_y), 1) for f in cap.frames})
    print(f"{capture}: {len(cap.frames)} frames, image sizes {sizes}, vertical FOV {fovs} deg, "
          f"camera distance to origin {np.linalg.norm(centres, axis=1).min():.2f}-"
          f"{np.linalg.norm(centres, axis=1).max():.2f} m, {check_capture_ground_truth(cap)}")
