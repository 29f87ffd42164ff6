"""How often the furniture fit's order of sighted handles gives each front its index.

The furniture field's slot k is front k in canonical order (by panel left edge, then top edge;
docs/FURNITURE.md), and the fit pairs sighted handles with slots by putting them in the order
their fronts most likely have (`nfr_drake.inference.furniture_fit.sighting_order`). This runs it
on the true shut handles of generated pieces, shuffled, and counts the fronts that get their own
index and the pieces whose fronts all do, for several column gaps (0: every handle its own
column). No rendering: a few seconds.

    python benchmarks/sighting_order.py [--pieces 400] [--seed 123] [--gaps 0 0.1 0.2 0.3]
"""

from __future__ import annotations

import argparse
import platform
from datetime import date

import numpy as np

from nfr_drake.inference.furniture_fit import sighting_order
from nfr_drake.objects import sample_object


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pieces", type=int, default=400)
    parser.add_argument("--seed", type=int, default=123)
    parser.add_argument("--gaps", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3])
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    handles = [np.array([k["handle"] for k in sample_object("furniture", rng).front_keypoints(0.0)])
               for _ in range(args.pieces)]
    print(f"{date.today()}, {platform.machine()}, {args.pieces} pieces of seed {args.seed}, "
          f"{sum(map(len, handles))} fronts")
    print("| column gap (m) | fronts given their index | pieces with every front right |")
    print("|---|---|---|")
    for gap in args.gaps:
        right = []
        for h in handles:
            shuffled = rng.permutation(len(h))
            right.append(shuffled[sighting_order(h[shuffled], gap)] == np.arange(len(h)))
        fronts, pieces = np.mean(np.concatenate(right)), np.mean([r.all() for r in right])
        print(f"| {gap:.2f} | {fronts:.1%} | {pieces:.1%} |")


if __name__ == "__main__":
    main()
