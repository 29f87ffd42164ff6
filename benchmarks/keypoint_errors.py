"""Which keypoint limits the keypoint RMSE: per-keypoint errors of the default fit, against gt.json.

Usage: python benchmarks/keypoint_errors.py --model models/closet
       --captures data/eval/closet_train_cams [--limit 20] [--no-handle-detector] [--threads 1]
Fits each capture (`nfr_drake.inference.infer.infer`, the default `FitConfig`) and prints, per
keypoint, the median and 90th percentile of its error at the observed state and the median of
the absolute error along each axis of the object frame O (+x out of the front, +z up), cm, as a
markdown table; then how high the fitted field's own surface reaches (99.5th percentile of z of
the surface points it renders in the first five views) against the object's true height: whether
the geometry or the keypoint head is off where a keypoint's height is.
"""

from __future__ import annotations

import argparse
import platform
from datetime import date
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.forward import render_view
from nfr_drake.inference.infer import FittedModel, infer


def field_top(fitted: FittedModel, outcome, capture, views: int = 5) -> float:
    """99.5th percentile of z (m) of the object surface the fitted field renders in the views."""
    tops = []
    for frame in capture.frames[:views]:
        view = render_view(fitted.model, outcome.z, outcome.q, frame.camera, frame.X_OC)
        tops.append(np.percentile(view.points[view.labels > 0][:, 2], 99.5))
    return float(np.median(tops))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--captures", type=Path, required=True)
    parser.add_argument("--limit", type=int, default=None)
    parser.add_argument("--no-handle-detector", action="store_true")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    fitted = FittedModel(args.model)
    config = FitConfig(handle_detector=not args.no_handle_detector)
    errors: dict[str, list[np.ndarray]] = {}
    top_errors = []
    dirs = capture_dirs(args.captures)[:args.limit]
    for d in dirs:
        capture = read_capture_set(d)
        result, outcome = infer(fitted, capture, config, np.linspace(0.0, 1.0, 3))
        top_errors.append(100.0 * (field_top(fitted, outcome, capture)
                                   - capture.gt["object"]["params"]["height"]))
        for name, true in capture.gt["keypoints"].items():
            errors.setdefault(name, []).append(100.0 * (result.keypoints[name] - np.asarray(true)))
    print(f"{date.today()}, {platform.processor() or platform.machine()}, {args.model}, "
          f"{args.captures.name}, {len(dirs)} captures"
          f"{', without the handle detector' if args.no_handle_detector else ''}")
    print("| keypoint | error median (cm) | p90 | abs x median | abs y median | abs z median |")
    print("|---|---|---|---|---|---|")
    for name, e in errors.items():
        e = np.array(e)
        norm = np.linalg.norm(e, axis=1)
        x, y, z = np.median(np.abs(e), axis=0)
        print(f"| {name} | {np.median(norm):.2f} | {np.percentile(norm, 90):.2f} | {x:.2f} | "
              f"{y:.2f} | {z:.2f} |")
    t = np.array(top_errors)
    print(f"\nfitted field's top minus the true height (cm): median {np.median(t):+.2f}, "
          f"median absolute deviation from it {np.median(np.abs(t - np.median(t))):.2f}, "
          f"range {t.min():+.2f} .. {t.max():+.2f}")


if __name__ == "__main__":
    main()
