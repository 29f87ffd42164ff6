"""Figures of the evaluation: error distributions (handle paths: `nfr_drake.data.visualize`)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from nfr_drake.data.visualize import pyplot
from nfr_drake.eval.evaluate import COLUMNS, CaptureMetrics


def plot_error_distributions(results: Iterable[CaptureMetrics], unit: str, path: Path) -> None:
    """Box plots of articulation error, keypoint RMSE and handle error (paper's Fig. 5): one group
    of boxes per capture set, one colour per method."""
    plt = pyplot()
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
