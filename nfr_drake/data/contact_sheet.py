"""`nfr-drake sheet`: a contact sheet of a dataset: per object, RGB and labels across q (and, for
furniture, the part indices: one colour per front)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.visualize import colorize_labels, colorize_parts, image_grid
from nfr_drake.errors import ConfigError


def contact_sheet(dataset: RenderedDataset, objects: int = 6, articulations: int = 6,
                  view: int = 0, per_row: int = 1) -> np.ndarray:
    """uint8 RGB image: for each of the first `objects` objects a row of renders at
    `articulations` evenly spread articulations (one camera view each), below it their labels
    and, for furniture, a row of their part indices (`colorize_parts`); `per_row` objects side
    by side, 8 px apart."""
    blocks = []
    A = dataset.spec.articulations
    picks = np.unique(np.linspace(0, A - 1, min(articulations, A)).round().astype(int))
    v = min(view, dataset.spec.views - 1)
    for rec in dataset.records[:objects]:
        rows = [[np.asarray(rec.rgb[a, v]) for a in picks],
                [colorize_labels(np.asarray(rec.label[a, v])) for a in picks]]
        if dataset.has_parts:
            rows.append([colorize_parts(np.asarray(rec.part[a, v])) for a in picks])
        blocks.append(image_grid(rows))
    if per_row == 1:
        return np.concatenate(blocks)
    return image_grid([blocks[i:i + per_row] for i in range(0, len(blocks), per_row)], pad=6)


def contact_sheet_command(data: Path, out: Path, objects: int = 6, articulations: int = 6,
                          scale: int = 2, per_row: int = 1) -> None:
    """Write a contact sheet PNG of the dataset in DATA.

    Args:
        data: dataset folder written by `nfr-drake generate`.
        out: PNG file to write.
        objects: number of objects (rows of RGB and label images, and part images for furniture).
        articulations: q values per object, evenly spread over the object's articulations.
        scale: integer upscaling of each image, for legibility.
        per_row: objects side by side.
    """
    if per_row < 1 or scale < 1:
        raise ConfigError("--per-row and --scale must be at least 1")
    sheet = contact_sheet(RenderedDataset(data), objects, articulations, per_row=per_row)
    sheet = np.repeat(np.repeat(sheet, scale, axis=0), scale, axis=1)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(f"wrote {out}")
