"""How still the held parts stay while `nfr-drake explore` sweeps one part of a several-slot
model (docs/NEURAL_FIELD.md, "Furniture"): the keypoint head sees the whole code, so sweeping one
slot's q moves the other parts' keypoints too.

    python scripts/explore_held_parts.py [MODEL] [EVERY]   # default models/furniture, 8

For every EVERY-th training code, all slots shut, each part the head finds (`object_parts`) is
swept over q in [0, 1] (21 steps, `keypoint_trajectory`, the others held): how far its handle
moves from where it is shut, and how far the held parts' keypoints move (the farthest of them),
cm; medians and 90th percentiles over the parts.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

from nfr_drake.eval.explore import ExploredObject, object_parts
from nfr_drake.inference.forward import keypoint_trajectory
from nfr_drake.inference.infer import FittedModel


def main() -> None:
    model = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("models/furniture")
    every = int(sys.argv[2]) if len(sys.argv) > 2 else 8
    torch.set_num_threads(1)
    fitted = FittedModel(model)
    if fitted.num_slots < 2:
        raise SystemExit(f"{model}: a one-part model; this measures models of several part slots")
    q_grid = np.linspace(0.0, 1.0, 21)
    swept, held = [], []
    for i in range(0, len(fitted.codes), every):
        z = ExploredObject(f"code {i}", fitted.codes[i], np.zeros(fitted.num_slots)).z
        parts = object_parts(fitted, z)
        for part in parts:
            path = keypoint_trajectory(fitted.model, z, q_grid, part.slot)  # (N, K, 3) in O, m
            moved = np.linalg.norm(path - path[:1], axis=-1).max(0)  # (K,) farthest from shut
            swept.append(moved[part.indices[part.names.index("handle")]])
            others = [k for p in parts if p.slot != part.slot for k in p.indices]
            if others:
                held.append(moved[others].max())
    for name, values in (("swept part's handle", swept), ("held parts' farthest keypoint", held)):
        cm = 100.0 * np.array(values)
        print(f"{name}: median {np.median(cm):.1f} cm, 90th percentile {np.percentile(cm, 90):.1f} cm "
              f"({len(cm)} parts)")
    print(f"{len(range(0, len(fitted.codes), every))} training codes of {len(fitted.codes)}, "
          f"{len(swept)} parts")


if __name__ == "__main__":
    main()
