"""Figures of the evaluation: error distributions (handle paths: `nfr_drake.data.visualize`)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

from nfr_drake.data.visualize import pyplot
from nfr_drake.eval.evaluate import COLUMNS, CaptureMetrics

Panel = tuple[str, Callable[[list], list[float]]]
"""A panel of an error plot: its title, and the values it shows of a list of result rows."""


def plot_error_distributions(results: Iterable[CaptureMetrics], unit: str, path: Path) -> None:
    """Box plots of articulation error, keypoint RMSE and handle error (paper's Fig. 5): one group
    of boxes per capture set, one colour per method."""
    plot_panels(results, [(title.format(unit=unit), lambda rows, attr=attr: [getattr(r, attr) for r in rows])
                          for attr, title in COLUMNS[:3]], path)


def plot_panels(results: Iterable, panels: Sequence[Panel], path: Path) -> None:
    """One box-plot panel per `panels` entry of result rows (with set_name and method): one group
    of boxes per capture set, one colour per method, log scale (where there are values above 0)."""
    plt = pyplot()
    results = list(results)
    sets = sorted({r.set_name for r in results})
    methods = sorted({r.method for r in results})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    width = 0.8 / len(methods)
    fig, axes = plt.subplots(1, len(panels), figsize=(max(5.0 * len(panels), 1.6 * len(sets) * len(methods)),
                                                      4.8))
    for ax, (title, values) in zip(axes, panels, strict=True):
        positive = False
        for j, method in enumerate(methods):
            data = [values([r for r in results if (r.set_name, r.method) == (s, method)]) for s in sets]
            positive |= any(v > 0 for d in data for v in d)
            at = [i + (j - (len(methods) - 1) / 2) * width for i in range(len(sets))]
            kept = [(x, d) for x, d in zip(at, data, strict=True) if d]
            if kept:  # a panel may have no values (no drawers among the parts, say)
                box = ax.boxplot([d for _, d in kept], positions=[x for x, _ in kept], widths=0.9 * width,
                                 patch_artist=True, manage_ticks=False, medianprops={"color": "black"})
                for patch in box["boxes"]:
                    patch.set(facecolor=colours[j % len(colours)], alpha=0.6)
            ax.plot([], [], "s", color=colours[j % len(colours)], alpha=0.6, label=method)
        ax.set_xticks(range(len(sets)), sets, rotation=20, ha="right", fontsize=8)
        ax.set_title(title)
        if positive:
            ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
