"""`nfr-drake eval`: the neural field and the baseline on held-out capture sets."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.capture import CaptureSet, capture_dirs, read_capture_set
from nfr_drake.data.visualize import plot_handle_paths
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.evaluate import Method, Prediction, evaluate, summary_table
from nfr_drake.eval.plots import plot_error_distributions
from nfr_drake.inference.fit import FitConfig


def neural_field_methods(model_dir: Path, config: FitConfig) -> dict[str, Method]:
    """Fit + forward simulation, keypoints from the head ("neural field") and from the fitted
    geometry ("neural field, geometric keypoints"); both share one fit per capture. Renders of the
    observed views give PSNR and mIoU."""
    from nfr_drake.inference.forward import geometric_keypoints, render_view
    from nfr_drake.inference.infer import FittedModel, infer

    fitted = FittedModel(model_dir)
    names = fitted.keypoint_names
    last: dict[str, tuple] = {}  # capture root -> (prediction with head keypoints, fitted z)

    def head(capture: CaptureSet, grid: np.ndarray) -> Prediction:
        fitted.check_capture(capture)
        result, outcome = infer(fitted, capture, config, grid)
        views = [render_view(fitted.model, outcome.z, outcome.q, f.camera, f.X_OC)
                 for f in capture.frames]
        prediction = Prediction(result.q, result.keypoints, result.trajectory, result.seconds,
                                renders=[v.rgb for v in views], labels=[v.labels for v in views],
                                image_loss=result.image_loss)
        last.clear()
        last[str(capture.root)] = (prediction, outcome)
        return prediction

    def geometry(capture: CaptureSet, grid: np.ndarray) -> Prediction:
        if str(capture.root) not in last:
            head(capture, grid)
        base, outcome = last[str(capture.root)]
        started = time.perf_counter()
        now, path = geometric_keypoints(fitted.model, outcome.z, outcome.q, grid, names,
                                        [(f.camera, f.X_OC) for f in capture.frames])
        return Prediction(base.q, {n: now[i] for i, n in enumerate(names)},
                          {n: path[:, i] for i, n in enumerate(names)},
                          base.seconds + time.perf_counter() - started, renders=base.renders,
                          labels=base.labels, image_loss=base.image_loss)

    return {"neural field": head, "neural field, geometric keypoints": geometry}


def baseline_method(baseline_dir: Path) -> Method:
    """The image-encoder baseline, keypoints along q by the explicit geometric assumption."""
    from nfr_drake.baseline.predict import predict_capture
    from nfr_drake.baseline.train import load_baseline

    model, doc = load_baseline(baseline_dir)
    size = doc["training"]["image_size"]
    names = model.config.keypoint_names

    def method(capture: CaptureSet, grid: np.ndarray) -> Prediction:
        started = time.perf_counter()
        pred = predict_capture(model, capture, size, grid)
        return Prediction(pred.q, {n: pred.keypoints[i] for i, n in enumerate(names)},
                          {n: pred.trajectory[:, i] for i, n in enumerate(names)},
                          time.perf_counter() - started)

    return method


def eval_command(
    sets: list[Path],
    out: Path,
    model: Path | None = None,
    baseline: Path | None = None,
    limit: int | None = None,
    fit: FitConfig = FitConfig(),
    example_plots: int = 2,
    threads: int | None = None,
) -> None:
    """Evaluate methods on held-out capture sets; resumable (rows already in OUT/results.csv stay).

    Writes OUT/results.csv (one row per capture and method), OUT/summary.md (medians and 90th
    percentiles per set and method), OUT/errors.png (error distributions) and handle-path plots
    of the first captures of each set.

    Args:
        sets: folders of capture sets (each a set; its folder name names it in the tables).
        out: output folder.
        model: neural-field model folder.
        baseline: image-encoder baseline folder.
        limit: use only the first n captures of each set.
        fit: options of the neural field's fit.
        example_plots: handle-path plots per set.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    methods: dict[str, Method] = {}
    if model is not None:
        methods.update(neural_field_methods(model, fit))
    if baseline is not None:
        methods["baseline"] = baseline_method(baseline)
    if not methods:
        raise NfrDrakeError("give --model and/or --baseline")
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
    print(table)
