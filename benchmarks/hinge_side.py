"""How often fitting a shut closet gets its hinge side right, for several ways of fitting.

A shut door shows its hinge side only through its handle, and a fit on the wrong side puts the
handle about 30 cm off (docs/EVALUATION.md). This script measures, on capture sets of shut closets,
the share of fits whose keypoint head puts the hinge on the true side of the handle, for:

- `mean`: the default fit, started from the mean training code (with its close look at the
  handle; `--focus-steps 0` for the fit without it);
- `sides`: one fit from the mean code of each hinge side's training codes (the side read from the
  keypoint head at q = 0), the one with the lower image MSE over every pixel of every view kept;
- `vote`: three default fits with different ray-sampling seeds, majority side;
- `no-prior`: the default fit without the latent prior (`latent_weight` 0).

Usage:
  nfr-drake captures --category closet --n 24 --seed 200 --q 0 --size 64 --out data/eval/closet_shut64
  python benchmarks/hinge_side.py --model models/closet --captures data/eval/closet_shut64
Prints one line per capture and a markdown table: fits with the right side, median handle error.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.inference.fit import FitConfig, ObservedRays, fit_latent, observed_rays
from nfr_drake.inference.forward import keypoint_trajectory
from nfr_drake.inference.infer import FittedModel
from nfr_drake.nfr.latent import q_to_z_art
from nfr_drake.nfr.rays import Rays

VARIANTS = ("mean", "sides", "vote", "no-prior")


def hinge_side(keypoints: np.ndarray, names: list[str]) -> float:
    """+1 or -1: the sign of the handle's y minus the hinge's y in O (keypoints (K, 3))."""
    return float(np.sign(keypoints[names.index("handle"), 1]
                         - keypoints[names.index("hinge_bottom"), 1]))


def full_image_mse(fitted: FittedModel, z: torch.Tensor, rays: ObservedRays,
                   chunk: int = 8192) -> float:
    """Image MSE of code z (D,) over every observed pixel, no sampling."""
    total = 0.0
    with torch.no_grad():
        for s in range(0, rays.rgb.shape[0], chunk):
            sub = Rays(rays.origins[None, s:s + chunk], rays.directions[None, s:s + chunk])
            rgb = fitted.model.render(z[None], sub).rgb[0]
            total += float(((rgb - rays.rgb[s:s + chunk]) ** 2).sum())
    return total / (3 * rays.rgb.shape[0])


def side_start_codes(fitted: FittedModel) -> list[torch.Tensor]:
    """Mean training code of each hinge side (sides from the keypoint head at q = 0)."""
    codes = fitted.codes
    with torch.no_grad():
        z = torch.cat([q_to_z_art(torch.zeros(len(codes))), codes], -1)
        kp = fitted.model.keypoints(z)
    names = list(fitted.keypoint_names)
    side = torch.sign(kp[:, names.index("handle"), 1] - kp[:, names.index("hinge_bottom"), 1])
    return [codes[side == s].mean(0) for s in (-1.0, 1.0)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--captures", type=Path, required=True)
    parser.add_argument("--n", type=int, default=None, help="first n capture sets only")
    parser.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--focus-steps", type=int, default=FitConfig().resolved().focus_steps,
                        help="steps of the fit's close look at the handle (0: none)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    fitted = FittedModel(args.model)
    names = list(fitted.keypoint_names)
    starts = side_start_codes(fitted) if "sides" in args.variants else []
    print(f"{date.today()}, model {args.model}, captures {args.captures}, "
          f"close look {args.focus_steps} steps")

    default = FitConfig(focus_steps=args.focus_steps)

    def fit(rays: ObservedRays, config: FitConfig = default, start=None):
        out = fit_latent(fitted.model, rays, config, fitted.z_obj_mean if start is None else start,
                         fitted.focus)
        return out, keypoint_trajectory(fitted.model, out.z, np.array([out.q]))[0]

    right = {v: 0 for v in args.variants}
    handle_errors = {v: [] for v in args.variants}
    dirs = capture_dirs(args.captures)[:args.n]
    for d in dirs:
        capture = read_capture_set(d)
        gt = capture.gt["keypoints"]
        true_side = float(np.sign(gt["handle"][1] - gt["hinge_bottom"][1]))
        rays = observed_rays(capture)
        fits: dict[str, np.ndarray] = {}
        if "mean" in args.variants or "vote" in args.variants:
            fits["mean"] = fit(rays)[1]
        if "sides" in args.variants:
            candidates = [fit(rays, start=s) for s in starts]
            fits["sides"] = min(candidates, key=lambda c: full_image_mse(fitted, c[0].z, rays))[1]
        if "vote" in args.variants:
            votes = [fits["mean"]] + [fit(rays, replace(default, seed=s))[1] for s in (1, 2)]
            majority = np.sign(sum(hinge_side(k, names) for k in votes))
            fits["vote"] = next(k for k in votes if hinge_side(k, names) == majority)
        if "no-prior" in args.variants:
            fits["no-prior"] = fit(rays, replace(default, latent_weight=0.0))[1]
        cells = []
        for v in args.variants:
            ok = hinge_side(fits[v], names) == true_side
            error = 100 * float(np.linalg.norm(fits[v][names.index("handle")] - gt["handle"]))
            right[v] += ok
            handle_errors[v].append(error)
            cells.append(f"{v} {'right' if ok else 'WRONG'} {error:.1f} cm")
        print(f"{d.name}: " + ", ".join(cells), flush=True)
    print("\n| fit | hinge side right | handle error, median (cm) |\n|---|---|---|")
    for v in args.variants:
        print(f"| {v} | {right[v]} / {len(dirs)} | {np.median(handle_errors[v]):.1f} |")


if __name__ == "__main__":
    main()
