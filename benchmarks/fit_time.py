"""Fit time of the neural field per 10-view capture set (issue target: at most 20 s on 2 cores).

Usage: python benchmarks/fit_time.py --model models/closet --captures data/eval/closet_train_cams
       [--n 5] [--threads 2] [--max-steps 400] [--restarts 4] [--focus-steps 150]
       [--no-handle-detector]
Create the captures with `nfr-drake captures --category closet --n 5 --out DIR --size 64`.
Prints seconds per capture (fit + forward simulation of 21 keypoint sets), steps run, and the
articulation error against gt.json, as a markdown table with its median.
"""

from __future__ import annotations

import argparse
import os
import platform
from datetime import date
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import FittedModel, infer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--captures", type=Path, required=True)
    parser.add_argument("--n", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--max-steps", type=int, default=400)
    parser.add_argument("--restarts", type=int, default=4)
    parser.add_argument("--focus-steps", type=int, default=FitConfig.focus_steps,
                        help="steps of the close look at the handle (0: none)")
    parser.add_argument("--no-handle-detector", action="store_true",
                        help="fit without the model's handle detector")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    fitted = FittedModel(args.model)
    config = FitConfig(restarts=args.restarts, max_steps=args.max_steps,
                       explore_steps=min(FitConfig.explore_steps, args.max_steps),
                       focus_steps=args.focus_steps, handle_detector=not args.no_handle_detector)
    print(f"{date.today()}, {platform.machine()}, {os.cpu_count()} CPUs, {args.threads} threads, "
          f"load average before: {os.getloadavg()[0]:.2f}, model {args.model}, "
          f"close look {args.focus_steps} steps, handle detector "
          f"{'off' if args.no_handle_detector or fitted.handle_detector is None else 'on'}")
    print("| capture | views | image size | seconds | steps | q error |")
    print("|---|---|---|---|---|---|")
    seconds = []
    for d in capture_dirs(args.captures)[:args.n]:
        capture = read_capture_set(d)
        result, outcome = infer(fitted, capture, config, np.linspace(0, 1, 21))
        seconds.append(result.seconds)
        cam = capture.frames[0].camera
        q_err = abs(result.q - capture.gt["q"]) if capture.gt else float("nan")
        print(f"| {d.name} | {len(capture.frames)} | {cam.width}x{cam.height} | "
              f"{result.seconds:.1f} | {outcome.steps} | {q_err:.3f} |", flush=True)
    print(f"\nmedian {np.median(seconds):.1f} s per capture, max {np.max(seconds):.1f} s")


if __name__ == "__main__":
    main()
