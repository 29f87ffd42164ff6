"""The photo folder: which files are photos, reading them upright, resizing to the working size."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.errors import NfrDrakeError

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp")


class PhotoFolderError(NfrDrakeError):
    """The photo folder is missing, holds no photos, or a photo cannot be read."""


@dataclass(frozen=True)
class WorkingPhoto:
    """A photo resized for structure from motion.

    name: file name in the photo folder (the key of anchors and of the report);
    work_name: file name of the resized copy in the working image folder;
    original_size, size: (width, height) in pixels before and after resizing.
    """

    name: str
    work_name: str
    original_size: tuple[int, int]
    size: tuple[int, int]


def list_photos(photos_dir: Path) -> list[Path]:
    """The photos in `photos_dir` (not recursive), sorted by name."""
    if not photos_dir.is_dir():
        raise PhotoFolderError(f"{photos_dir}: photo folder not found")
    photos = sorted(p for p in photos_dir.iterdir()
                    if p.is_file() and p.suffix.lower() in PHOTO_SUFFIXES)
    if not photos:
        raise PhotoFolderError(f"{photos_dir}: no photos ({', '.join(PHOTO_SUFFIXES)})")
    return photos


def read_photo(path: Path) -> np.ndarray:
    """A photo as uint8 BGR (H, W, 3), turned upright by its EXIF orientation."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise PhotoFolderError(f"{path}: cannot be read as an image")
    return image


def working_size(size: tuple[int, int], max_size: int) -> tuple[int, int]:
    """(width, height) scaled so that the longer side is at most `max_size`; never enlarged."""
    w, h = size
    scale = min(1.0, max_size / max(w, h))
    return max(1, round(w * scale)), max(1, round(h * scale))


def prepare_photos(photos_dir: Path, work_dir: Path, max_size: int) -> list[WorkingPhoto]:
    """Write every photo of `photos_dir` into `work_dir` as PNG, resized to `max_size` at most.

    Resizing uses area interpolation (no aliasing). Raises PhotoFolderError for an empty folder,
    an unreadable photo, or two photos whose names differ only by the suffix.
    """
    work_dir.mkdir(parents=True, exist_ok=True)
    photos = list_photos(photos_dir)
    stems = [p.stem for p in photos]
    duplicates = sorted({s for s in stems if stems.count(s) > 1})
    if duplicates:
        raise PhotoFolderError(f"{photos_dir}: photos share a name but not the suffix: "
                               f"{', '.join(duplicates)}")
    prepared = []
    for path in photos:
        image = read_photo(path)
        original = (image.shape[1], image.shape[0])
        size = working_size(original, max_size)
        if size != original:
            image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
        work_name = f"{path.stem}.png"
        if not cv2.imwrite(str(work_dir / work_name), image):
            raise OSError(f"could not write {work_dir / work_name}")
        prepared.append(WorkingPhoto(path.name, work_name, original, size))
    return prepared
