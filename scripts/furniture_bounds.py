"""The numbers behind the furniture field's bounds (docs/NEURAL_FIELD.md, "Furniture: several parts").

Distances (m) from a sphere centre to the corners of the swept bounds of sampled pieces
(percentiles 50, 90, 99, 100), and the nearest surface (z-depth, m) in a dataset's depth images.

    python scripts/furniture_bounds.py --pieces 300 --center 0.35 0 1.0 \
        --data data/furniture_train --objects 200
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from nfr_drake.data.dataset import DEPTH_SCALE, RenderedDataset
from nfr_drake.objects.furniture import sample_furniture


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pieces", type=int, default=300)
    parser.add_argument("--seed", type=int, default=99)
    parser.add_argument("--center", type=float, nargs=3, default=(0.35, 0.0, 1.0))
    parser.add_argument("--data", type=Path)
    parser.add_argument("--objects", type=int, default=200)
    args = parser.parse_args()
    corners = []
    for i in range(args.pieces):
        lo, hi = sample_furniture(np.random.default_rng([0, args.seed, i])).swept_bounds(9)
        corners += [np.where(np.array(s, bool), hi, lo) for s in np.ndindex(2, 2, 2)]
    dist = np.linalg.norm(np.array(corners) - np.array(args.center), axis=1)
    print("corner distance from", args.center, "percentiles 50/90/99/100:",
          np.percentile(dist, [50, 90, 99, 100]).round(3))
    if args.data:
        data = RenderedDataset(args.data, objects=args.objects)
        nearest = [r.depth_mm[r.depth_mm > 0].min() / DEPTH_SCALE for r in data.records]
        print(f"nearest surface (z-depth) over {len(nearest)} objects: min {min(nearest):.3f} m, "
              f"median {np.median(nearest):.3f} m")


if __name__ == "__main__":
    main()
