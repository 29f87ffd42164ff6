"""Where the furniture fit takes a training piece's code: one capture of a training object.

    OMP_NUM_THREADS=1 python scripts/furniture_fit_drift.py \
        --capture data/eval/furniture_train_pieces/furniture_000

For a capture of training object i (`nfr-drake captures --training-objects`, the object named
`furniture_<i:06d>`): the image MSE of every training code as a start (all slots shut and all
half open, on 4096 of the capture's rays) and the rank of the object's own code among them; then
the fit without handles from every training code (`FurnitureFitConfig(starts=N)`): the MSE of its
code on the same rays, how far its z_obj moved from the own code and from the nearest training
code (against the median distance between two training codes), and the keypoint RMSE of its
slots (cm) against gt.json. Prints one line per measure.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.inference.fit import observed_rays
from nfr_drake.inference.furniture_fit import FurnitureFitConfig, fit_furniture, image_mse, start_codes
from nfr_drake.inference.metrics import keypoint_rmse_cm
from nfr_drake.inference.result import PART_KEYPOINTS
from nfr_drake.nfr.checkpoint import load_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--capture", type=Path, required=True)
    parser.add_argument("--model", type=Path, default=Path("models/furniture"))
    parser.add_argument("--rays", type=int, default=4096)
    args = parser.parse_args()
    set_torch_threads(1)
    model, codes, _ = load_model(args.model)
    model.requires_grad_(False)
    gt = json.loads((args.capture / "gt.json").read_text())
    own = int(gt["object"]["name"].rpartition("_")[2])
    capture = read_capture_set(args.capture)
    rays = observed_rays(capture, capture.load_images())
    S = model.config.num_slots
    index = rays.sample(args.rays, 0.5, torch.Generator().manual_seed(0))
    with torch.no_grad():
        starts = start_codes(codes, S)
        mse = torch.cat([image_mse(model, starts[j:j + 64], rays, index) for j in range(0, len(starts), 64)])
    rank = int((mse.argsort() == own).nonzero())
    print(f"object {own}: its own code (all shut) ranks {rank + 1} of {len(starts)} starts, image MSE "
          f"{mse[own]:.4f} (best {mse.min():.4f})")
    fit = fit_furniture(model, rays, codes, FurnitureFitConfig(starts=len(codes)))
    with torch.no_grad():
        fitted_mse = float(image_mse(model, fit.z[None], rays, index))
        z_obj = fit.z[2 * S:]
        between = torch.cdist(codes, codes).fill_diagonal_(float("inf")).min(1).values.median()
    print(f"fit (no handles, every code a start): image MSE {fitted_mse:.4f}; z_obj moved "
          f"{(z_obj - codes[own]).norm():.2f} from its own code, {torch.cdist(z_obj[None], codes).min():.2f} "
          f"from the nearest training code (median between two training codes {between:.2f})")
    for part in gt["parts"]:
        names = PART_KEYPOINTS[part["type"]]
        pred = fit.keypoints[part["index"], [SLOT_KEYPOINTS.index(n) for n in names]]
        true = np.array([part["keypoints"][names[n]] for n in names])
        print(f"part {part['index']} ({part['type']}): keypoint RMSE {keypoint_rmse_cm(pred, true):.1f} cm")


if __name__ == "__main__":
    main()
