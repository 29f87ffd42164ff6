"""What the detector reads of the front behind each sighted handle (`nfr_drake.perception.front_reading`)
against the gt.json of furniture capture sets.

Usage: python benchmarks/front_reading.py --detector models/furniture/handle_detector
       --sets data/eval/furniture_cams128 [--cm 3] [--threads 1]
Handles are triangulated from the detector's maps as the fit does (`locate_handles`); each is
matched to the true handle nearest it (within `--cm`). Per matched handle: whether the read type
(door or drawer) is right; the median distance of its four face corners to the true ones (cm);
for true doors read as doors, the hinge points' error (`hinge_points`, mean of hinge_top and
hinge_bottom, cm), whether the hinge is on the right side (the read hinge nearer the true hinge
edge than the true free edge) and the door's angle read from its face (the top and bottom edges'
turn, `opening_angle`) against the true angle (deg); and the error of the shut left and top
edges (`shut_edges`, cm). Per piece whose every front was sighted and matched: whether
`front_order` (the read fronts) and `sighting_order` (the handles alone) give the canonical order.
"""

from __future__ import annotations

import argparse
import platform
from datetime import date
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.inference.furniture_fit import FurnitureFitConfig, front_order, sighting_order
from nfr_drake.perception.front_reading import hinge_points, opening_angle, read_front, shut_edges
from nfr_drake.perception.handle_detector.model import load_detector
from nfr_drake.perception.handle_triangulation import locate_handles


def true_shut_edges(part: dict) -> tuple[float, float]:
    """gt's left and top edge of a front's face when shut, m."""
    c = np.asarray(part["face_corners"])
    if part["type"] == "door":
        hinge = np.asarray(part["keypoints"]["hinge_top"])
        width = np.linalg.norm(c[0, :2] - c[1, :2])
        left_hinged = np.linalg.norm(c[0, :2] - hinge[:2]) < np.linalg.norm(c[1, :2] - hinge[:2])
        return (float(hinge[1]) if left_hinged else float(hinge[1] - width)), float(c[0, 2])
    return float(c[0, 1]), float(c[0, 2])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--detector", type=Path, required=True)
    parser.add_argument("--sets", type=Path, nargs="+", required=True)
    parser.add_argument("--cm", type=float, default=3.0)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    detector = load_detector(args.detector)[0]
    print(f"{date.today()}, {platform.processor() or platform.machine()}, {args.detector}")
    print("| set | handles matched | type right | corner error (cm) | hinge error (cm) | hinge side "
          "right | door angle error (deg) | left edge error (cm) | top edge error (cm) | order right: "
          "fronts / handles |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for root in args.sets:
        matched = type_right = side_right = doors = pieces_all = order_fronts = order_handles = 0
        corner_err, hinge_err, angle_err, left_err, top_err = [], [], [], [], []
        for d in capture_dirs(root):
            capture = read_capture_set(d)
            parts = capture.gt["parts"]
            true_handles = np.array([p["keypoints"]["handle"] for p in parts])
            images = capture.load_images()
            found = locate_handles(detector.detect(images), capture.frames)
            maps = detector.read_fronts(images)
            fronts = [read_front(h, maps, capture.frames) for h in found]
            index = []
            for h, front in zip(found, fronts, strict=True):
                dist = np.linalg.norm(true_handles - h.p_O, axis=1)
                k = int(np.argmin(dist))
                if dist[k] > args.cm / 100 or front is None:
                    index.append(-1)
                    continue
                index.append(k)
                part = parts[k]
                true_corners = np.asarray(part["face_corners"])
                matched += 1
                type_right += front.is_door == (part["type"] == "door")
                corner_err.append(100 * float(np.median(np.linalg.norm(front.corners - true_corners,
                                                                       axis=1))))
                left, top = shut_edges(front)
                true_left, true_top = true_shut_edges(part)
                left_err.append(100 * abs(left - true_left))
                top_err.append(100 * abs(top - true_top))
                if part["type"] == "door" and front.is_door:
                    doors += 1
                    true_hinge = np.array([part["keypoints"]["hinge_top"], part["keypoints"]["hinge_bottom"]])
                    read = hinge_points(front)
                    hinge_err.append(100 * float(np.linalg.norm(read - true_hinge, axis=1).mean()))
                    free = true_corners[[1, 3]] if np.allclose(true_corners[[0, 2]], true_hinge, atol=1e-6) \
                        else true_corners[[0, 2]]
                    side_right += np.linalg.norm(read - true_hinge) < np.linalg.norm(read - free)
                    angle_err.append(abs(np.degrees(opening_angle(front)) - 90.0 * part["q"]))
            if len(found) == len(parts) and sorted(index) == list(range(len(parts))):
                pieces_all += 1
                idx = np.array(index)
                order_fronts += idx[front_order(fronts)].tolist() == list(range(len(parts)))
                handles_O = np.array([h.p_O for h in found])
                order_handles += idx[sighting_order(handles_O, FurnitureFitConfig.column_gap_m)].tolist() \
                    == list(range(len(parts)))
        med = lambda xs: float(np.median(xs)) if xs else float("nan")  # noqa: E731
        print(f"| {root.name} | {matched} | {type_right / max(matched, 1):.3f} | {med(corner_err):.2f} | "
              f"{med(hinge_err):.2f} | {side_right} of {doors} | {med(angle_err):.1f} | "
              f"{med(left_err):.2f} | {med(top_err):.2f} | "
              f"{order_fronts} / {order_handles} of {pieces_all} |")


if __name__ == "__main__":
    main()
