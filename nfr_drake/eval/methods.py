"""The methods an evaluation compares: each turns a capture set and a q grid into a `Prediction`."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from nfr_drake.data.capture import CaptureSet
from nfr_drake.eval.evaluate import Method, Prediction
from nfr_drake.eval.parts import PartsPrediction
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.furniture_fit import FurnitureFitConfig


def neural_field_methods(model_dir: Path, config: FitConfig,
                         furniture_config: FurnitureFitConfig = FurnitureFitConfig()) -> dict[str, Method]:
    """Fit + forward simulation, keypoints from the head ("neural field") and from the fitted
    geometry ("neural field, geometric keypoints"); both share one fit per capture, and its
    confidence (P(handle within 2 cm), refused below the calibration's threshold). Renders of the
    observed views give PSNR and mIoU. A model with several parts (furniture) has the first only,
    fitted with `furniture_config` (`furniture_method`)."""
    from nfr_drake.inference.confidence import refusal
    from nfr_drake.inference.forward import geometric_keypoints, render_view
    from nfr_drake.inference.infer import FittedModel, infer

    fitted = FittedModel(model_dir)
    if fitted.num_slots > 1:
        return {"neural field": furniture_method(fitted, furniture_config)}
    names = fitted.keypoint_names
    last: dict[str, tuple] = {}  # capture root -> (prediction with head keypoints, fitted z)

    def head(capture: CaptureSet, grid: np.ndarray) -> Prediction:
        fitted.check_capture(capture)
        result, outcome = infer(fitted, capture, config, grid)
        views = [render_view(fitted.model, outcome.z, outcome.q, f.camera, f.X_OC)
                 for f in capture.frames]
        p = (result.confidence or {}).get("p_handle_within_2cm")
        prediction = Prediction(result.q, result.keypoints, result.trajectory, result.seconds,
                                renders=[v.rgb for v in views], labels=[v.labels for v in views],
                                image_loss=result.image_loss,
                                confidence=math.nan if p is None else p,
                                refused=None if p is None else refusal(result.confidence) is not None)
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
                          labels=base.labels, image_loss=base.image_loss,
                          confidence=base.confidence, refused=base.refused)

    return {"neural field": head, "neural field, geometric keypoints": geometry}


def furniture_method(fitted, config: FurnitureFitConfig) -> Method:
    """The furniture fit of a model with several parts (`inference.infer.infer_parts`, a
    `FittedModel`): a `PartsPrediction` with every slot swept over the q grid, the others held,
    and every slot's confidence (refused below the calibration's threshold; None without one)."""
    from nfr_drake.inference.confidence import refusal
    from nfr_drake.inference.furniture_fit import slot_path
    from nfr_drake.inference.infer import infer_parts

    def method(capture: CaptureSet, grid: np.ndarray) -> PartsPrediction:
        fitted.check_capture(capture)
        result, fit, slots = infer_parts(fitted, capture, config, grid)
        paths = np.stack([slot_path(fitted.model, fit, k, grid) for k in range(fitted.num_slots)])
        confidence = slots if fitted.confidence is not None else None
        return PartsPrediction(
            fit.q, fit.exists, fit.types, fit.keypoints, paths, result.seconds,
            None if confidence is None else np.array([c["p_handle_within_2cm"] for c in confidence]),
            None if confidence is None else np.array([refusal(c) is not None for c in confidence]))

    return method


def baseline_method(baseline_dir: Path) -> tuple[str, Method]:
    """The image-encoder baseline's category and method, keypoints along q by the explicit
    geometric assumption; a furniture baseline's method gives a `PartsPrediction` (every slot)."""
    from nfr_drake.baseline.predict import predict_capture
    from nfr_drake.baseline.train import load_baseline

    model, doc = load_baseline(baseline_dir)
    size = doc["training"]["image_size"]
    names = model.config.keypoint_names

    def method(capture: CaptureSet, grid: np.ndarray) -> Prediction:
        started = time.perf_counter()
        pred = predict_capture(model, capture, size, grid)
        return Prediction(float(pred.q[0]), {n: pred.keypoints[0, i] for i, n in enumerate(names)},
                          {n: pred.trajectory[0, :, i] for i, n in enumerate(names)},
                          time.perf_counter() - started)

    def parts_method(capture: CaptureSet, grid: np.ndarray) -> PartsPrediction:
        started = time.perf_counter()
        pred = predict_capture(model, capture, size, grid)
        return PartsPrediction(pred.q, pred.exists, pred.types, pred.keypoints, pred.trajectory,
                               time.perf_counter() - started)

    return model.config.category, parts_method if model.config.num_slots > 1 else method
