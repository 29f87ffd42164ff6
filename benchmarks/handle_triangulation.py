"""Accuracy of the handle triangulated from the 2D handle detector, against gt.json.

Usage: python benchmarks/handle_triangulation.py --detector models/closet/handle_detector
       --sets data/eval/closet_train_cams data/eval/closet_shut128 [--true-masks | --centroids]
       [--threads 1]
Per capture set: how many captures gave a point (at least 3 views agreeing), and the distance from
that point to the true handle keypoint (median, 90th percentile, largest, count over 5 cm), as a
markdown table, with the mean signed error along x, y, z of O (cm) and the mean offset (u, v) of the
views' sightings from the projected keypoint (px): a bias there is systematic, not noise.
`--centroids` drops the detector's offsets (each view's sighting is its blob's
centroid); `--true-masks` triangulates the centroids of the capture's own label images (the
ceiling of centroids: a handle's visible middle, posts included, is not its grip centre).
"""

from __future__ import annotations

import argparse
import platform
from datetime import date
from pathlib import Path

import cv2
import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.objects import SemanticClass
from nfr_drake.perception.handle_detector.model import load_detector
from nfr_drake.perception.handle_triangulation import HandleMap, locate_handle, project, sighting


def true_masks(capture) -> list[HandleMap]:
    """The capture's handle labels as maps (probability 1 on handle pixels, no offsets)."""
    return [HandleMap.centroid_only((cv2.imread(str(capture.root / p), cv2.IMREAD_UNCHANGED)
                                     == SemanticClass.HANDLE).astype(np.float32))
            for p in capture.gt["label_paths"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--detector", type=Path, required=True)
    parser.add_argument("--sets", type=Path, nargs="+", required=True)
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--true-masks", action="store_true")
    mode.add_argument("--centroids", action="store_true")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    detector, _ = load_detector(args.detector)
    source = ("true masks" if args.true_masks
              else f"{args.detector}{', centroids' if args.centroids else ''}")
    print(f"{date.today()}, {platform.processor() or platform.machine()}, {source}")
    print("| set | captures | triangulated | error median (cm) | p90 | max | over 5 cm "
          "| mean error x, y, z (cm) | mean sighting offset u, v (px) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for root in args.sets:
        errors, offsets, dirs = [], [], capture_dirs(root)
        for d in dirs:
            capture = read_capture_set(d)
            if args.true_masks:
                maps = true_masks(capture)
            else:
                maps = detector.detect(capture.load_images())
                if args.centroids:
                    maps = [HandleMap.centroid_only(m.probability) for m in maps]
            handle = np.asarray(capture.gt["keypoints"]["handle"])
            for i, m in enumerate(maps):
                seen, uv = sighting(m, i), project(capture.frames[i], handle)
                if seen is not None and uv is not None:
                    offsets.append(seen.uv - uv)
            found = locate_handle(maps, capture.frames)
            if found is not None:
                errors.append(found.p_O - handle)
        d = 100.0 * np.array(errors).reshape(-1, 3)
        e = np.linalg.norm(d, axis=1)
        o = np.array(offsets).reshape(-1, 2)
        stats = (f"{np.median(e):.2f} | {np.percentile(e, 90):.2f} | {e.max():.2f} | "
                 f"{int((e > 5).sum())} | {', '.join(f'{v:+.2f}' for v in d.mean(0))} | "
                 f"{', '.join(f'{v:+.2f}' for v in o.mean(0))}") if len(e) else " | ".join(["n/a"] * 6)
        print(f"| {root.name} | {len(dirs)} | {len(e)} | {stats} |")


if __name__ == "__main__":
    main()
