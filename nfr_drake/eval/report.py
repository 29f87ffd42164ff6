"""One evaluation run written out: results.csv, summary.md, errors.png and handle-path plots."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nfr_drake.data.capture import CaptureSet, capture_dirs, read_capture_set
from nfr_drake.data.visualize import plot_handle_paths
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.evaluate import Method, Prediction, evaluate, summary_table
from nfr_drake.eval.parts import (
    HANDLE,
    PART_PANELS,
    PartMetrics,
    PartsPrediction,
    part_panel_values,
    parts_summary_table,
    score_parts,
)
from nfr_drake.eval.plots import plot_error_distributions, plot_panels


def set_categories(sets: list[Path]) -> set[str]:
    """The categories of capture sets (their first capture's gt.json). NfrDrakeError when sets of
    objects with several parts (furniture) are mixed with others."""
    categories = {read_capture_set(capture_dirs(p)[0]).gt["category"] for p in sets}
    if "furniture" in categories and len(categories) > 1:
        raise NfrDrakeError(f"sets of {', '.join(sorted(categories))}: furniture is evaluated part by "
                            "part, apart from other categories; give its sets alone")
    return categories


def run_evaluation(methods: dict[str, Method], sets: list[Path], out: Path, limit: int | None = None,
                   example_plots: int = 2) -> str:
    """Evaluate `methods` on the capture sets `sets` (each named by its folder); resumable (rows
    already in OUT/results.csv stay).

    Writes OUT/results.csv (one row per capture and method; furniture: per true part,
    `PartMetrics`), OUT/summary.md (medians and 90th percentiles per set and method), OUT/errors.png
    (error distributions) and handle-path plots of the first `example_plots` captures of each set
    (furniture: of each of their parts); returns the summary table (markdown).
    """
    named = {p.name: p for p in sets}
    categories = set_categories(sets)
    paths_dir = out / "handle_paths"

    def keep_handle_path(set_name: str, capture: CaptureSet, method: str, pred: Prediction | PartsPrediction):
        folder = paths_dir / set_name / capture.root.name
        folder.mkdir(parents=True, exist_ok=True)
        path = (pred.trajectories[:, :, HANDLE] if isinstance(pred, PartsPrediction)
                else pred.trajectory["handle"])
        np.save(folder / f"{method.replace(' ', '_')}.npy", np.asarray(path))

    if categories == {"furniture"}:
        results = evaluate(methods, named, out / "results.csv", limit, keep_handle_path, score_parts,
                           PartMetrics)
        table = parts_summary_table(results)
        plot_panels(results, [(title, lambda rows, t=t, a=a: part_panel_values(rows, t, a))
                              for title, t, a in PART_PANELS], out / "errors.png")
    else:
        results = evaluate(methods, named, out / "results.csv", limit, keep_handle_path)
        unit = "deg" if categories == {"closet"} else "cm" if categories == {"drawer"} else "deg or cm"
        table = summary_table(results, unit)
        plot_error_distributions(results, unit, out / "errors.png")
    (out / "summary.md").write_text(table + "\n")
    for name, root in named.items():
        for d in capture_dirs(root)[:example_plots]:
            _plot_handle_paths(read_capture_set(d), paths_dir / name / d.name, list(methods),
                               out / f"handle_{name}_{d.name}", f"{name}/{d.name}")
    return table


def _plot_handle_paths(capture: CaptureSet, saved: Path, methods: list[str], stem: Path, title: str) -> None:
    """Handle paths kept for `capture` (`saved`/<method>.npy) against its true one, as STEM.png;
    a piece of furniture's, per true part k, as STEM_part<k>.png."""
    paths = {m: np.load(saved / f"{m.replace(' ', '_')}.npy") for m in methods
             if (saved / f"{m.replace(' ', '_')}.npy").exists()}
    gt = capture.gt
    if "parts" not in gt:
        true = np.asarray(gt["trajectory"]["keypoints"]["handle"])
        plot_handle_paths(np.asarray(gt["trajectory"]["q"]), true, paths, stem.with_name(stem.name + ".png"),
                          f"{title}: true q = {gt['q']:.2f}")
        return
    for part in gt["parts"]:
        k = part["index"]
        plot_handle_paths(np.asarray(part["trajectory"]["q"]),
                          np.asarray(part["trajectory"]["keypoints"]["handle"]),
                          {m: p[k] for m, p in paths.items()}, stem.with_name(f"{stem.name}_part{k}.png"),
                          f"{title} part {k} ({part['type']}): true q = {part['q']:.2f}")
