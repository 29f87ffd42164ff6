"""Fits with known errors for the fit confidence: run, resumable, one JSON line per fit.

A case is a model fitted to a capture set changed by a variant (`capture_variants`); its line
keeps what the fit found (z, q, the starts' losses and q, the triangulated handle) and the handle's
error against gt.json. The confidence features are computed from the line (`case_features`), so a
change of the features needs no new fit. The handle's truth is
the capture's handle at its q; for a furniture capture (several fronts) the nearest front's handle.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from nfr_drake.data.capture import CaptureSet, read_capture_set
from nfr_drake.eval.capture_variants import apply_variant
from nfr_drake.inference.confidence import fit_features
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import FittedModel, infer


@dataclass(frozen=True)
class Case:
    """One fit to make: model folder, capture-set folder, variant and its seed, and the split it
    belongs to ("calibration", "evaluation" or "ood")."""

    model: str
    capture: str
    variant: str
    seed: int
    split: str

    @property
    def key(self) -> str:
        return f"{self.model}|{self.capture}|{self.variant}|{self.seed}"


def true_handles(gt: dict) -> np.ndarray:
    """Handle positions (M, 3) in O at the captured state: one for a closet or drawer, one per
    front with a handle for furniture (gt.json's `parts`)."""
    if "parts" in gt:
        return np.array([p["keypoints"]["handle"] for p in gt["parts"] if "handle" in p["keypoints"]])
    return np.array([gt["keypoints"]["handle"]])


def load_case(case: Case | dict) -> tuple[CaptureSet, list[np.ndarray]]:
    """The capture set and images a case's fit sees (its capture set changed by its variant);
    `case` may be a line."""
    case = Case(**{k: case[k] for k in Case.__dataclass_fields__}) if isinstance(case, dict) else case
    capture = read_capture_set(case.capture)
    return apply_variant(case.variant, capture, capture.load_images(), case.seed)


def case_features(line: dict, fitted: FittedModel) -> tuple[dict, list[dict]]:
    """The confidence features of a line's fit (`inference.confidence.fit_features`), as `infer`
    computes them."""
    capture, images = load_case(line)
    return fit_features(fitted.model, torch.tensor(line["z"]), capture.frames, images,
                        np.array(line["start_losses"]), fitted.codes, fitted.code_scale,
                        fitted.keypoint_names.index("handle"), line["sighting_p_O"])


def run_case(case: Case, fitted: FittedModel, fit: FitConfig) -> dict:
    """Fit `case` and return its JSON line (see module docstring)."""
    capture, images = load_case(case)
    result, outcome = infer(fitted, capture, fit, np.linspace(0.0, 1.0, 2), images=images)
    handle = result.keypoints["handle"]
    truth = true_handles(capture.gt)
    error = float(np.linalg.norm(truth - handle, axis=1).min())
    same = capture.gt.get("category") == fitted.category
    keypoint_rmse = (float(np.sqrt(np.mean([np.sum((np.asarray(capture.gt["keypoints"][n]) - p) ** 2)
                                            for n, p in result.keypoints.items()])))
                     if same else None)
    seen = result.extra["handle_sighting"]
    return {**asdict(case), "key": case.key, "category": capture.gt.get("category"),
            "model_category": fitted.category, "q": result.q, "q_true": capture.gt.get("q"),
            "z": result.z.tolist(), "image_loss": result.image_loss,
            "start_losses": outcome.start_losses.tolist(), "start_q": outcome.start_q.tolist(),
            "sighting_p_O": seen.get("p_O"), "handle": handle.tolist(),
            "handle_error_m": error, "keypoint_rmse_m": keypoint_rmse,
            "seconds": result.seconds}


CALIBRATION_VARIANTS = ("clean", "clean", "few_views", "occluded", "edge_cut")
"""Variants of the calibration captures, by capture index modulo 5: the training world, with the
failures it can produce (too few views, occlusion, the object cut by the edge)."""

OOD_VARIANTS = ("background", "recoloured", "occluded", "edge_cut", "few_views", "wrong_category")
"""Variants of the out-of-distribution captures, by capture index modulo 6; "wrong_category" fits
the other category's model to the clean capture."""


def plan_cases(data: Path, calibration: int, evaluation: int, closed: int, shut128: int, ood: int,
               furniture: int) -> list[Case]:
    """The cases of the confidence study from the capture sets under `data` (docs/EVALUATION.md,
    "Fit confidence"): per category `calibration` captures of C_calib (seed 500), `evaluation` of
    C_train_cams (seed 0), `closed` of C_closed (seed 3) and `shut128` of C_shut128 (seed 200,
    128 px, the pipeline's objects), all clean, and `ood` of C_oodsrc
    (seed 600); and `furniture` captures of furniture_oodsrc, each fitted by both models. Models
    are models/C."""
    cases = []
    for c in ("closet", "drawer"):
        for i in range(calibration):
            cases.append(Case(f"models/{c}", str(data / f"{c}_calib" / f"{c}_{i:03d}"),
                              CALIBRATION_VARIANTS[i % 5], 500 + i, "calibration"))
    for i in range(max(evaluation, closed, shut128, ood, furniture)):
        for c, other in (("closet", "drawer"), ("drawer", "closet")):
            if i < ood:
                variant = OOD_VARIANTS[i % 6]
                model = other if variant == "wrong_category" else c
                cases.append(Case(f"models/{model}", str(data / f"{c}_oodsrc" / f"{c}_{i:03d}"),
                                  "clean" if variant == "wrong_category" else variant, 600 + i,
                                  "ood"))
            for folder, count in (("train_cams", evaluation), ("closed", closed),
                                  ("shut128", shut128)):
                if i < count:
                    cases.append(Case(f"models/{c}", str(data / f"{c}_{folder}" / f"{c}_{i:03d}"),
                                      "clean", i, "evaluation"))
            if i < furniture:
                cases.append(Case(f"models/{c}", str(data / "furniture_oodsrc" / f"furniture_{i:03d}"),
                                  "clean", 600 + i, "ood"))
    return cases


def run_cases(cases: list[Case], out: Path, fit: FitConfig = FitConfig()) -> list[dict]:
    """Fit every case not yet in `out` (JSON lines, appended as each fit ends); returns all lines."""
    done = set()
    if out.exists():
        done = {json.loads(line)["key"] for line in out.read_text().splitlines() if line.strip()}
    out.parent.mkdir(parents=True, exist_ok=True)
    models: dict[str, FittedModel] = {}
    for case in tqdm([c for c in cases if c.key not in done], desc="confidence fits", unit="fit"):
        if case.model not in models:
            models[case.model] = FittedModel(Path(case.model))
        line = run_case(case, models[case.model], fit)
        with open(out, "a") as f:
            f.write(json.dumps(line) + "\n")
    return [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
