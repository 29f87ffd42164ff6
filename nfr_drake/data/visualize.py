"""Image helpers shared by contact sheets, validation grids and fit reports."""

from __future__ import annotations

import numpy as np

# RGB of each semantic class (DESIGN.md): background, carcass, moving part, handle.
SEMANTIC_PALETTE = np.array([[0, 0, 0], [70, 110, 200], [240, 170, 40], [230, 40, 60]], np.uint8)


def colorize_labels(label: np.ndarray) -> np.ndarray:
    """Semantic class image (H, W) of ints in [0, 3] -> uint8 RGB (H, W, 3)."""
    return SEMANTIC_PALETTE[np.clip(label, 0, len(SEMANTIC_PALETTE) - 1)]


def image_grid(rows: list[list[np.ndarray]], pad: int = 2, fill: int = 255) -> np.ndarray:
    """Tile uint8 RGB images (each (h, w, 3), equal sizes) into one image, rows of equal length."""
    h, w = rows[0][0].shape[:2]
    n_cols = max(len(r) for r in rows)
    grid = np.full((len(rows) * (h + pad) + pad, n_cols * (w + pad) + pad, 3), fill, np.uint8)
    for i, row in enumerate(rows):
        for j, image in enumerate(row):
            y, x = pad + i * (h + pad), pad + j * (w + pad)
            grid[y:y + h, x:x + w] = image
    return grid
