"""Held-out rooms as capture sets, for the fit confidence in photos of a room.

A room of `nfr-drake generate-rooms` (docs/ROOMS.md) is drawn around its target object in the
object's frame O, the floor at z = 0, so one capture set serves both fits: with the given pose
(the fit in O) and with the pose estimated from the segmenter's masks (`infer --estimate-pose`,
the capture's frame taken as the floor frame W). Its gt.json holds the category, q and the
keypoints in O of the target's first front at the room's first articulation.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import write_capture_set
from nfr_drake.data.room_dataset import room_dirs

ROOM_SETS = ("heldout", "heldout_cut", "heldout_twin")
"""The held-out room sets per category (`data/rooms/<category>_<set>`, docs/ROOMS.md)."""


def room_capture(room: Path, out: Path) -> Path:
    """Write the room folder `room` (its first articulation) as the capture set `out`, with its
    gt.json; an existing `out` is kept. Returns `out`."""
    if out.exists():
        return out
    meta = json.loads((room / "meta.json").read_text())
    images = list(np.load(room / "rgb.npy")[0])
    gt = {"category": meta["category"], "q": float(meta["q"][0][0]),
          "keypoints": {name: fronts[0] for name, fronts in meta["keypoints"][0].items()},
          "room": str(room)}
    out.parent.mkdir(parents=True, exist_ok=True)
    return write_capture_set(out, images, list(np.array(meta["X_OC"])[0]),
                             PinholeCamera.from_json(meta["camera"]), gt)


def room_captures(rooms: Path, out: Path, category: str, count: int) -> dict[str, list[Path]]:
    """The first `count` rooms of each held-out set of `category` under `rooms` as capture sets
    under OUT/<category>_<set>/ (written once): set name -> capture folders."""
    captures = {}
    for name in ROOM_SETS:
        folder = rooms / f"{category}_{name}"
        captures[folder.name] = [room_capture(d, out / folder.name / d.name)
                                 for d in room_dirs(folder)[:count]]
    return captures
