"""Amodal carcass labels over the photos of a room dataset: a check that they are right.

    python scripts/amodal_labels_figure.py --data data/rooms/closet_heldout data/rooms/drawer_heldout \
        --rooms 0 1 2 --out docs/images/amodal_labels.png

Per room (`rooms` of each dataset) one row of its views: the photo with the target's visible
pixels (`label.npy`) tinted green and the outline of its amodal carcass label
(`carcass_amodal.npy`, `nfr-drake label-amodal`) in yellow; where the yellow outline runs over
clutter, a neighbour, the arm or a front, the label holds the carcass that these hide.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import tyro

from nfr_drake.data.amodal import AMODAL_FILE
from nfr_drake.data.dataset import ObjectRecord
from nfr_drake.data.room_dataset import room_dirs


def overlay(rgb: np.ndarray, label: np.ndarray, amodal: np.ndarray, scale: int = 3) -> np.ndarray:
    """The photo (S, S, 3) scaled by `scale`, visible pixels tinted green, the amodal label's
    outline in yellow."""
    big = cv2.resize(rgb, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST).astype(np.float32)
    vis = cv2.resize((label > 0).astype(np.uint8), None, fx=scale, fy=scale,
                     interpolation=cv2.INTER_NEAREST) > 0
    big[vis] = 0.6 * big[vis] + 0.4 * np.array([0, 220, 0], np.float32)
    am = cv2.resize(amodal, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
    edge = cv2.morphologyEx(am, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    big[edge] = (255, 230, 0)
    return big.clip(0, 255).astype(np.uint8)


def main(data: list[Path] = [Path("data/rooms/drawer_heldout")], rooms: list[int] = [0, 1, 2],  # noqa: B006
         articulation: int = 0, scale: int = 2, out: Path = Path("amodal_labels.png")) -> None:
    rows = []
    for root, i in [(root, i) for root in data for i in rooms]:
        rec = ObjectRecord(room_dirs(root)[i])
        amodal = np.load(rec.path / AMODAL_FILE)
        tiles = [overlay(np.asarray(rec.rgb[articulation, v]), np.asarray(rec.label[articulation, v]),
                         amodal[articulation, v], scale) for v in range(amodal.shape[1])]
        row = np.concatenate([np.pad(t, ((2, 2), (2, 2), (0, 0)), constant_values=255) for t in tiles], 1)
        cv2.putText(row, f"{root.name} {i}", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                    cv2.LINE_AA)
        rows.append(row)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(np.concatenate(rows, 0), cv2.COLOR_RGB2BGR))
    print(f"wrote {out}")


if __name__ == "__main__":
    tyro.cli(main)
