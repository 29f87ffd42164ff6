"""Image and figure helpers shared by contact sheets, validation grids, fit reports and evaluations."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# RGB of each semantic class (docs/CONVENTIONS.md): background, carcass, moving part, handle.
SEMANTIC_PALETTE = np.array([[0, 0, 0], [70, 110, 200], [240, 170, 40], [230, 40, 60]], np.uint8)


def colorize_labels(label: np.ndarray) -> np.ndarray:
    """Semantic class images (..., H, W) of ints in [0, 3] -> uint8 RGB (..., H, W, 3)."""
    return SEMANTIC_PALETTE[np.clip(label, 0, len(SEMANTIC_PALETTE) - 1)]


# RGB of each front index (docs/FURNITURE.md), 0 to 7; black where no front (-1).
PART_PALETTE = np.array([[230, 25, 75], [60, 180, 75], [255, 225, 25], [0, 130, 200], [245, 130, 48],
                         [145, 30, 180], [70, 240, 240], [240, 50, 230], [0, 0, 0]], np.uint8)


def colorize_parts(part: np.ndarray) -> np.ndarray:
    """Part-index image (H, W) of ints in [-1, 7] (-1: no front) -> uint8 RGB (H, W, 3)."""
    return PART_PALETTE[np.where(part < 0, len(PART_PALETTE) - 1, np.clip(part, 0, len(PART_PALETTE) - 2))]


def as_uint8(image: np.ndarray) -> np.ndarray:
    """An RGB image as uint8: uint8 unchanged, float in [0, 1] (clipped) scaled to [0, 255]."""
    image = np.asarray(image)
    if image.dtype == np.uint8:
        return image
    return (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def image_grid(rows: list[list[np.ndarray]], pad: int = 2, fill: int = 255, scale: int = 1) -> np.ndarray:
    """Tile RGB images (each (h, w, 3) or RGBA, equal sizes; uint8, or float in [0, 1]) into one uint8
    image: rows of columns, each pixel repeated `scale` times both ways, `pad` px of `fill` between."""
    h, w = rows[0][0].shape[0] * scale, rows[0][0].shape[1] * scale
    n_cols = max(len(r) for r in rows)
    grid = np.full((len(rows) * (h + pad) + pad, n_cols * (w + pad) + pad, 3), fill, np.uint8)
    for i, row in enumerate(rows):
        for j, image in enumerate(row):
            y, x = pad + i * (h + pad), pad + j * (w + pad)
            grid[y:y + h, x:x + w] = np.repeat(np.repeat(as_uint8(image)[..., :3], scale, 0), scale, 1)
    return grid


def pyplot():
    """matplotlib.pyplot on the Agg backend, imported on first use (the CLI starts without it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_handle_paths(q: np.ndarray, true: np.ndarray, predictions: dict[str, np.ndarray],
                      path: Path, title: str = "") -> None:
    """Handle positions over q (paper's Fig. 6): top view (x, y) and height (z) against q.

    Args:
        q: (N,) articulation grid.
        true: (N, 3) true handle positions in O, m.
        predictions: method name -> (N, 3) predicted handle positions in O, m.
    """
    plt = pyplot()
    fig, (top, side) = plt.subplots(1, 2, figsize=(10, 4.5))
    top.plot(true[:, 1], true[:, 0], "k-", lw=2, label="true")
    top.plot(true[0, 1], true[0, 0], "ko")
    side.plot(q, true[:, 2], "k-", lw=2, label="true")
    for (name, pred), colour in zip(predictions.items(), ("tab:red", "tab:blue", "tab:green"),
                                    strict=False):
        top.plot(pred[:, 1], pred[:, 0], "--", color=colour, label=name)
        top.plot(pred[0, 1], pred[0, 0], "o", color=colour)
        side.plot(q, pred[:, 2], "--", color=colour, label=name)
    top.invert_xaxis()  # a true view from above: +x up, +y to the left
    top.set_xlabel("y (m)")
    top.set_ylabel("x (m), out of the front")
    top.set_aspect("equal", adjustable="datalim")
    top.set_title("handle path seen from above (dot: q = 0)")
    side.set_xlabel("q")
    side.set_ylabel("handle height z (m)")
    for ax in (top, side):
        ax.grid(True, alpha=0.3)
        ax.legend()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
