"""Figures of the evaluation: error distributions and predicted against true handle paths."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from nfr_drake.eval.evaluate import COLUMNS, CaptureMetrics


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_error_distributions(results: Iterable[CaptureMetrics], unit: str, path: Path) -> None:
    """Box plots of articulation error, keypoint RMSE and handle error (paper's Fig. 5): one group
    of boxes per capture set, one colour per method."""
    plt = _pyplot()
    results = list(results)
    sets = sorted({r.set_name for r in results})
    methods = sorted({r.method for r in results})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    width = 0.8 / len(methods)
    fig, axes = plt.subplots(1, 3, figsize=(max(15.0, 1.6 * len(sets) * len(methods)), 4.8))
    for ax, (attr, title) in zip(axes, COLUMNS[:3], strict=False):
        for j, method in enumerate(methods):
            data = [[getattr(r, attr) for r in results if (r.set_name, r.method) == (s, method)]
                    for s in sets]
            at = [i + (j - (len(methods) - 1) / 2) * width for i in range(len(sets))]
            kept = [(x, d) for x, d in zip(at, data, strict=True) if d]
            box = ax.boxplot([d for _, d in kept], positions=[x for x, _ in kept], widths=0.9 * width,
                             patch_artist=True, manage_ticks=False,
                             medianprops={"color": "black"})
            for patch in box["boxes"]:
                patch.set(facecolor=colours[j % len(colours)], alpha=0.6)
            ax.plot([], [], "s", color=colours[j % len(colours)], alpha=0.6, label=method)
        ax.set_xticks(range(len(sets)), sets, rotation=20, ha="right", fontsize=8)
        ax.set_title(title.format(unit=unit))
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_handle_paths(q: np.ndarray, true: np.ndarray, predictions: dict[str, np.ndarray],
                      path: Path, title: str = "") -> None:
    """Handle positions over q (paper's Fig. 6): top view (x, y) and height (z) against q.

    Args:
        q: (N,) articulation grid.
        true: (N, 3) true handle positions in O, m.
        predictions: method name -> (N, 3) predicted handle positions in O, m.
    """
    plt = _pyplot()
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
