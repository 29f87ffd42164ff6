"""One evaluation run written out: results.csv, summary.md, errors.png and handle-path plots."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nfr_drake.data.capture import CaptureSet, capture_dirs, read_capture_set
from nfr_drake.data.visualize import plot_handle_paths
from nfr_drake.eval.evaluate import Method, Prediction, evaluate, summary_table
from nfr_drake.eval.plots import plot_error_distributions


def run_evaluation(methods: dict[str, Method], sets: list[Path], out: Path, limit: int | None = None,
                   example_plots: int = 2) -> str:
    """Evaluate `methods` on the capture sets `sets` (each named by its folder); resumable (rows
    already in OUT/results.csv stay).

    Writes OUT/results.csv (one row per capture and method), OUT/summary.md (medians and 90th
    percentiles per set and method), OUT/errors.png (error distributions) and handle-path plots
    of the first `example_plots` captures of each set; returns the summary table (markdown).
    """
    named = {p.name: p for p in sets}
    paths_dir = out / "handle_paths"

    def keep_handle_path(set_name: str, capture: CaptureSet, method: str, pred: Prediction):
        folder = paths_dir / set_name / capture.root.name
        folder.mkdir(parents=True, exist_ok=True)
        np.save(folder / f"{method.replace(' ', '_')}.npy", np.asarray(pred.trajectory["handle"]))

    results = evaluate(methods, named, out / "results.csv", limit, keep_handle_path)
    categories = {read_capture_set(capture_dirs(p)[0]).gt["category"] for p in sets}
    unit = "deg" if categories == {"closet"} else "cm" if categories == {"drawer"} else "deg or cm"
    table = summary_table(results, unit)
    (out / "summary.md").write_text(table + "\n")
    plot_error_distributions(results, unit, out / "errors.png")
    for name, root in named.items():
        for d in capture_dirs(root)[:example_plots]:
            capture = read_capture_set(d)
            grid = np.asarray(capture.gt["trajectory"]["q"])
            saved = paths_dir / name / d.name
            paths = {m: np.load(saved / f"{m.replace(' ', '_')}.npy") for m in methods
                     if (saved / f"{m.replace(' ', '_')}.npy").exists()}
            plot_handle_paths(grid, np.asarray(capture.gt["trajectory"]["keypoints"]["handle"]),
                              paths, out / f"handle_{name}_{d.name}.png",
                              f"{name}/{d.name}: true q = {capture.gt['q']:.2f}")
    return table
