"""Evaluation over held-out capture sets: per-capture metrics, a summary table and error plots.

A method is anything that turns a capture set into a `Prediction`; the neural-field fit and the
image-encoder baseline both are. Metrics follow the paper's evaluation (articulation error,
keypoint RMSE at the observed state, handle trajectory over q in [0, 1]) plus render quality
(PSNR, segmentation mIoU) for methods that render, and the time per capture. Objects with several
parts (furniture) are scored part by part (`nfr_drake.eval.parts`) by the same driver.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from nfr_drake.data.capture import CaptureSet, capture_dirs, read_capture_set
from nfr_drake.errors import NfrDrakeError
from nfr_drake.inference.confidence import FAR_M, SUCCESS_M
from nfr_drake.inference.metrics import (
    articulation_error,
    keypoint_rmse_cm,
    mean_iou,
    psnr,
    trajectory_rmse_cm,
)


@dataclass
class Prediction:
    """One method's answer for one capture set, positions in O, metres.

    q: articulation in [0, 1]. keypoints: name -> (3,) at q. trajectory: name -> (N, 3) on the
    q grid it was asked for. renders / labels: per frame uint8 RGB (H, W, 3) / classes (H, W) at
    the observed state, or None for methods that do not render. seconds: wall time.
    confidence: the fit's P(handle within 2 cm) (`inference.confidence`), NaN for a method
    without one; refused: whether that is below the calibration's threshold (None: no confidence).
    """

    q: float
    keypoints: dict[str, np.ndarray]
    trajectory: dict[str, np.ndarray]
    seconds: float
    renders: list[np.ndarray] | None = None
    labels: list[np.ndarray] | None = None
    image_loss: float = math.nan
    confidence: float = math.nan
    refused: bool | None = None


Method = Callable[[CaptureSet, np.ndarray], Prediction]
"""(capture, q grid (N,)) -> Prediction (or another prediction its scorer reads, `evaluate`)."""


@dataclass
class CaptureMetrics:
    """Errors of one method on one capture set (NaN where a method has no such output).

    handle_error_cm: distance of the predicted handle from the true one at the observed state,
    what a grasp must absorb. confidence: the fit's P(handle within 2 cm); refused: 1 when it is
    below the calibration's threshold (`demo` and `eval-pipeline` would not act on it), 0 when
    not, NaN without a confidence.
    """

    capture: str
    set_name: str
    method: str
    articulation_error: float
    keypoint_rmse_cm: float
    handle_error_cm: float
    handle_trajectory_rmse_cm: float
    psnr_db: float
    miou: float
    seconds: float
    image_loss: float
    confidence: float
    refused: float


def score(capture: CaptureSet, prediction: Prediction, set_name: str, method: str) -> CaptureMetrics:
    """Compare a prediction with the capture's gt.json (and its label images)."""
    gt = capture.gt
    if gt is None:
        raise NfrDrakeError(f"{capture.root}: no gt.json, cannot evaluate")
    names = list(gt["keypoints"])
    kp_true = np.array([gt["keypoints"][n] for n in names])
    kp_pred = np.array([prediction.keypoints[n] for n in names])
    handle = names.index("handle")
    traj_true = np.asarray(gt["trajectory"]["keypoints"]["handle"])
    traj_pred = np.asarray(prediction.trajectory["handle"])
    obj = gt["object"]
    psnr_db = miou = math.nan
    if prediction.renders is not None:
        images = capture.load_images()
        psnr_db = float(np.mean([psnr(r / 255.0, i / 255.0) for r, i in zip(
            prediction.renders, images, strict=True)]))
    if prediction.labels is not None and "label_paths" in gt:
        true_labels = [cv2.imread(str(capture.root / p), cv2.IMREAD_UNCHANGED)
                       for p in gt["label_paths"]]
        miou = float(np.mean([mean_iou(p, t) for p, t in zip(prediction.labels, true_labels,
                                                             strict=True)]))
    return CaptureMetrics(
        capture=capture.root.name, set_name=set_name, method=method,
        articulation_error=articulation_error(prediction.q, gt["q"], obj["joint_type"],
                                              obj["joint_upper"]),
        keypoint_rmse_cm=keypoint_rmse_cm(kp_pred, kp_true),
        handle_error_cm=keypoint_rmse_cm(kp_pred[[handle]], kp_true[[handle]]),
        handle_trajectory_rmse_cm=trajectory_rmse_cm(traj_pred, traj_true),
        psnr_db=psnr_db, miou=miou, seconds=prediction.seconds,
        image_loss=prediction.image_loss, confidence=prediction.confidence,
        refused=math.nan if prediction.refused is None else float(prediction.refused))


def trajectory_grid(gt: dict) -> np.ndarray:
    """The q grid (N,) of a gt.json's trajectories (a furniture piece's: its parts')."""
    return np.asarray((gt["trajectory"] if "trajectory" in gt else gt["parts"][0]["trajectory"])["q"])


def read_row(row_type: type, row: dict[str, str]):
    """A CSV row (strings) as a `row_type` dataclass, each value of its field's type (str, int,
    bool or float)."""
    cast = {"str": str, "int": int, "bool": lambda v: v == "True"}
    return row_type(**{f.name: cast.get(f.type, float)(row[f.name]) for f in fields(row_type)})


def evaluate(methods: dict[str, Method], sets: dict[str, Path], csv_path: Path,
             limit: int | None = None,
             on_prediction: Callable[[str, CaptureSet, str, Prediction], None] | None = None,
             scorer: Callable[..., list] | None = None, row_type: type = CaptureMetrics) -> list:
    """Run every method on every capture of every set, appending rows to `csv_path`.

    `scorer(capture, prediction, set_name, method)` gives a capture's rows, `row_type` dataclasses
    with capture, set_name and method fields (default: one `score` row, `CaptureMetrics`).
    Rows already in the CSV (same capture, set and method) are kept and not recomputed, so an
    interrupted evaluation resumes. `on_prediction(set_name, capture, method, prediction)` is
    called for each new prediction (to keep trajectories for plots, say).
    """
    scorer = scorer or (lambda *args: [score(*args)])
    columns = [f.name for f in fields(row_type)]
    results = []
    if csv_path.exists():
        with open(csv_path) as f:
            reader = csv.DictReader(f)
            if reader.fieldnames is not None and reader.fieldnames != columns:
                raise NfrDrakeError(f"{csv_path}: written by another version (columns "
                                    f"{reader.fieldnames}); choose another --out")
            results = [read_row(row_type, row) for row in reader]
    done = {(m.capture, m.set_name, m.method) for m in results}
    new_file = not csv_path.exists()
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with open(csv_path, "a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        if new_file:
            writer.writeheader()
        for set_name, root in sets.items():
            # Capture-major, so that methods sharing work on a capture (one fit) run back to back.
            for d in tqdm(capture_dirs(root)[:limit], desc=set_name, unit="capture"):
                todo = [m for m in methods if (d.name, set_name, m) not in done]
                if not todo:
                    continue
                capture = read_capture_set(d)
                grid = trajectory_grid(capture.gt)
                for method_name in todo:
                    prediction = methods[method_name](capture, grid)
                    if on_prediction is not None:
                        on_prediction(set_name, capture, method_name, prediction)
                    rows = scorer(capture, prediction, set_name, method_name)
                    writer.writerows(asdict(r) for r in rows)
                    f.flush()
                    results += rows
    return results


COLUMNS = (("articulation_error", "articulation error ({unit})"),
            ("keypoint_rmse_cm", "keypoint RMSE (cm)"),
            ("handle_error_cm", "handle error (cm)"),
            ("handle_trajectory_rmse_cm", "handle trajectory RMSE (cm)"),
            ("psnr_db", "PSNR (dB)"), ("miou", "mIoU"), ("seconds", "time (s)"))


REFUSAL_COLUMNS = ("refused", "good fits refused", "fits > 5 cm off kept")
"""The summary's refusal columns (`refusal_cells`)."""


def refusal_cells(rows: list[CaptureMetrics]) -> list[str]:
    """The `REFUSAL_COLUMNS` of one set and method: fits refused, good fits (handle within 2 cm,
    `inference.confidence.SUCCESS_M`) refused and fits more than 5 cm off (`FAR_M`) kept, each
    "k of n"; "n/a" for a method without a confidence."""
    refused = np.array([r.refused for r in rows], float)
    if np.all(np.isnan(refused)):
        return ["n/a"] * len(REFUSAL_COLUMNS)
    error_m = np.array([r.handle_error_cm for r in rows], float) / 100.0
    good, far, said = error_m <= SUCCESS_M, error_m > FAR_M, ~np.isnan(refused)
    refused = refused == 1.0
    return [f"{refused.sum()} of {said.sum()}", f"{(refused & good).sum()} of {(good & said).sum()}",
            f"{(~refused & far & said).sum()} of {(far & said).sum()}"]


def summary_table(results: Iterable[CaptureMetrics], unit: str) -> str:
    """Markdown table of medians (and 90th percentiles of the errors) per set and method, and
    the fits refused by the fit confidence (`refusal_cells`)."""
    results = list(results)
    header = ("| set | method | n | " + " | ".join(t.format(unit=unit) for _, t in COLUMNS) + " | "
              + " | ".join(REFUSAL_COLUMNS) + " |")
    lines = [header, "|" + "---|" * (3 + len(COLUMNS) + len(REFUSAL_COLUMNS))]
    keys = sorted({(r.set_name, r.method) for r in results})
    for set_name, method in keys:
        rows = [r for r in results if r.set_name == set_name and r.method == method]
        cells = []
        for attr, _ in COLUMNS:
            values = np.array([getattr(r, attr) for r in rows], float)
            if np.all(np.isnan(values)):
                cells.append("n/a")
            elif attr in ("psnr_db", "miou", "seconds"):
                cells.append(f"{np.nanmedian(values):.3g}")
            else:
                cells.append(f"{np.nanmedian(values):.2f} (p90 {np.nanpercentile(values, 90):.2f})")
        cells += refusal_cells(rows)
        lines.append(f"| {set_name} | {method} | {len(rows)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
