"""What the furniture fit reads from the handles alone: the fronts' order and the doors of a pair.

The furniture field's slot k is front k in canonical order (by panel left edge, then top edge;
docs/FURNITURE.md), and the fit pairs sighted handles with slots by putting them in the order
their fronts most likely have (`nfr_drake.inference.furniture_fit.sighting_order`). This runs it
on the true shut handles of generated pieces, shuffled, and counts the fronts that get their own
index and the pieces whose fronts all do, for several column gaps (0: every handle its own
column), with and without a split cell's right half put after its column's other fronts
(`right_halves_last`). Then the doors of a pair (`pair_hinges`: a door's handle with another
level one within the pair gap): how many doors are such, and for how many the hinge lies on the
side away from that handle, as the fit then puts it; and how much being one of a pair says of a
front's type: the log-likelihood ratio of door against drawer for a front in a pair and for one
not (`FurnitureFitConfig.pair_type_log_odds`); and where each front's handle sits across its
face (`FurnitureFitConfig.offset_type_log_odds`). No rendering: a few seconds.

    python benchmarks/handle_layout.py [--pieces 400] [--seed 123] [--gaps 0 0.1 0.2 0.3]
"""

from __future__ import annotations

import argparse
import inspect
import platform
from datetime import date

import numpy as np

from nfr_drake.data.slot_dataset import PART_TYPES
from nfr_drake.inference.furniture_fit import (
    FurnitureFitConfig,
    drawer_goal,
    pair_hinges,
    pair_sides,
    sighting_order,
)
from nfr_drake.objects import sample_object


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pieces", type=int, default=400)
    parser.add_argument("--seed", type=int, default=123)
    parser.add_argument("--gaps", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3])
    parser.add_argument("--pair-gap", type=float, default=FurnitureFitConfig.pair_gap_m)
    args = parser.parse_args()
    centred = inspect.signature(sighting_order).parameters["centred_m"].default
    rng = np.random.default_rng(args.seed)
    objects = [sample_object("furniture", rng) for _ in range(args.pieces)]
    pieces = [obj.front_keypoints(0.0) for obj in objects]
    handles = [np.array([k["handle"] for k in kps]) for kps in pieces]
    print(f"{date.today()}, {platform.machine()}, {args.pieces} pieces of seed {args.seed}, "
          f"{sum(map(len, handles))} fronts")
    print("| column gap (m) | split cells' right halves last | fronts given their index | "
          "pieces with every front right |")
    print("|---|---|---|---|")
    for gap in args.gaps:
        for centred_m in (0.0, centred):  # 0: no right half is moved (`right_halves_last`)
            right = []
            for h in handles:
                shuffled = rng.permutation(len(h))
                order = sighting_order(h[shuffled], gap, centred_m=centred_m)
                right.append(shuffled[order] == np.arange(len(h)))
            fronts, whole = np.mean(np.concatenate(right)), np.mean([r.all() for r in right])
            print(f"| {gap:.2f} | {'yes' if centred_m else 'no'} | {fronts:.1%} | {whole:.1%} |")
    # pair_hinges on every piece's true slot keypoints, and with every door's hinge mirrored
    moved = fixed = doors = 0
    for kps in pieces:
        keypoints, types = slot_keypoints(kps)
        is_door = types == PART_TYPES.index("door")
        doors += int(is_door.sum())
        moved += int((pair_hinges(keypoints, types, len(kps), args.pair_gap) != keypoints).any((1, 2)).sum())
        wrong = keypoints.copy()
        wrong[is_door, 1:, 1] = 2.0 * keypoints[is_door, :1, 1] - keypoints[is_door, 1:, 1]
        put_right = np.isclose(pair_hinges(wrong, types, len(kps), args.pair_gap), keypoints).all((1, 2))
        fixed += int(put_right[is_door].sum())
    print(f"doors {doors}: with every hinge on the wrong side, {fixed} ({fixed / doors:.1%}) put right "
          f"by pair_hinges (pair gap {args.pair_gap} m); with every hinge right, {moved} moved")
    in_pair = {"door": [0, 0], "drawer": [0, 0]}  # [in a pair, fronts]
    for kps in pieces:
        keypoints, types = slot_keypoints(kps)
        paired = pair_sides(keypoints[:, 0], args.pair_gap) != 0
        for kind in in_pair:
            of_kind = types == PART_TYPES.index(kind)
            in_pair[kind][0] += int((paired & of_kind).sum())
            in_pair[kind][1] += int(of_kind.sum())
    (d_pair, d_all), (w_pair, w_all) = in_pair["door"], in_pair["drawer"]
    offsets = {"door": [], "drawer": []}  # the handle's distance from its face's middle / half width
    for obj in objects:
        for front in obj.fronts:
            corners = np.asarray(front.face_corners(0.0))
            y0, y1 = corners[:, 1].min(), corners[:, 1].max()
            handle_y = front.keypoints(0.0)["handle"][1]
            offsets[front.kind].append(abs(handle_y - (y0 + y1) / 2) / ((y1 - y0) / 2))
    edges = (0.1, 0.2, 0.5)
    bins = " / ".join(f"{lo:g}-{hi:g}" for lo, hi in zip((0.0, *edges), (*edges, np.inf), strict=True))
    print(f"where the handle sits across its face (0: the middle, 1: an edge), fronts per bin {bins}: "
          + "; ".join(f"{kind}s " + " / ".join(map(str, np.bincount(np.searchsorted(edges, o, side="right"),
                                                                       minlength=len(edges) + 1)))
                      for kind, o in offsets.items()))
    print(f"in a pair: doors {d_pair} of {d_all}, drawers {w_pair} of {w_all}; log-likelihood ratio, "
          f"door against drawer: in a pair {np.log((d_pair / d_all) / (w_pair / w_all)):+.2f}, not "
          f"{np.log((1 - d_pair / d_all) / (1 - w_pair / w_all)):+.2f}")
    below, depth_error = [], []  # a shut drawer's goal under its handle; drawer_goal's x error
    for obj in objects:
        for front in obj.fronts:
            if front.kind == "drawer":
                kp = front.keypoints(0.0)
                below.append(kp["handle"][2] - kp["goal"][2])
                depth_error.append(drawer_goal(np.asarray(kp["handle"]), front.joint_upper,
                                               FurnitureFitConfig.handle_standoff_m, 0.0)[0] - kp["goal"][0])
    print(f"drawers {len(below)}: the goal under the handle {np.median(below):.3f} m (median; p10-p90 "
          f"{np.percentile(below, 10):.3f}-{np.percentile(below, 90):.3f}); drawer_goal's x with the true "
          f"travel less the true x {np.median(depth_error):+.3f} m (median; |.| "
          f"{np.median(np.abs(depth_error)):.3f})")


def slot_keypoints(kps: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """One piece's fronts as slot keypoints (F, 4, 3) in `SLOT_KEYPOINTS` order (a drawer's axis
    points at its handle: not used here) and types (F,) indexing `PART_TYPES`."""
    rows, types = [], []
    for kp in kps:
        door = "hinge_top" in kp
        rows.append([kp["handle"], kp["goal"], kp["hinge_top"] if door else kp["handle"],
                     kp["hinge_bottom"] if door else kp["handle"]])
        types.append(PART_TYPES.index("door" if door else "drawer"))
    return np.array(rows, float), np.array(types)

if __name__ == "__main__":
    main()
