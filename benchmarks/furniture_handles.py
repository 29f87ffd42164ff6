"""Several handles per piece: the 2D handle detector's sightings and the handles triangulated from
them (`sightings`, `triangulate_handles`, then the upright bars they leave unexplained:
`bar_sightings`, `triangulate_bars`), against the gt.json of furniture capture sets.

Usage: python benchmarks/furniture_handles.py --detector models/furniture/handle_detector
       --sets data/eval/furniture_cams128 [--true-maps] [--px 3] [--cm 3] [--min-share 0.5]
       [--loose-share 0.6] [--loose-rms-px 1.2]
       [--merged-px 4] [--no-bars]
Per set, in 2D: the visible handles of each view (a front whose handle label has a pixel there)
against the view's sightings, matched one to one by distance, a match within `--px` px (scaled
to a 128 px high image): recall, precision, median distance of the matches. In 3D: the
triangulated handles against every front's handle, matched one to one within `--cm` cm: recall,
precision, median distance, and on how many pieces the count of triangulated handles is the count
of fronts. `--true-maps` uses the capture's own labels (probability 1 on handle pixels, each
pixel's offset to its front's projected handle): the ceiling of the sightings and triangulation.
"""

from __future__ import annotations

import argparse
import json
import platform
from datetime import date
from pathlib import Path

import cv2
import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.objects import SemanticClass
from nfr_drake.perception.handle_detector.model import load_detector
from nfr_drake.perception.handle_triangulation import (
    FURNITURE_BAR_SHARE,
    FURNITURE_LOOSE,
    FURNITURE_MERGED_PX,
    FURNITURE_MIN_SHARE,
    HandleMap,
    bar_sightings,
    project,
    sightings,
    triangulate_bars,
    triangulate_handles,
)


def _read(capture, key: str, i: int) -> np.ndarray:
    return cv2.imread(str(capture.root / capture.gt[key][i]), cv2.IMREAD_UNCHANGED)


def part_image(capture, i: int) -> np.ndarray:
    """Front index per pixel (H, W) of frame i, -1 where none (the part PNG holds the int8 index
    as uint8)."""
    return _read(capture, "part_paths", i).view(np.int8).astype(np.int64)


def true_maps(capture, handles_O: np.ndarray) -> list[HandleMap]:
    """The capture's handle labels as maps whose offsets point at each pixel's front's handle."""
    maps = []
    for i, frame in enumerate(capture.frames):
        handle = _read(capture, "label_paths", i) == SemanticClass.HANDLE
        part = part_image(capture, i)
        uv = np.array([project(frame, p) for p in handles_O])
        H, W = handle.shape
        centres = np.stack(np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5), -1)
        offset = np.where((handle & (part >= 0))[..., None], uv[np.clip(part, 0, None)] - centres, 0.0)
        maps.append(HandleMap(handle.astype(np.float32), offset.astype(np.float32)))
    return maps


def match(a: np.ndarray, b: np.ndarray, within: float) -> list[float]:
    """Distances of a greedy one-to-one matching of points a (n, d) and b (m, d), nearest first,
    pairs within `within` only."""
    if len(a) == 0 or len(b) == 0:
        return []
    d = np.linalg.norm(a[:, None] - b[None], axis=-1)
    out, used_a, used_b = [], set(), set()
    for i, j in zip(*np.unravel_index(np.argsort(d, axis=None), d.shape), strict=True):
        if d[i, j] > within:
            break
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            out.append(float(d[i, j]))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--detector", type=Path)
    parser.add_argument("--sets", type=Path, nargs="+", required=True)
    parser.add_argument("--true-maps", action="store_true")
    parser.add_argument("--px", type=float, default=3.0)
    parser.add_argument("--cm", type=float, default=3.0)
    parser.add_argument("--min-share", type=float, default=FURNITURE_MIN_SHARE,
                        help="triangulate_handles' min_share (the share of views a handle must agree with)")
    parser.add_argument("--loose-share", type=float, default=FURNITURE_LOOSE[0],
                        help="triangulate_handles' loose_share (0: no loose-point rule)")
    parser.add_argument("--loose-rms-px", type=float, default=FURNITURE_LOOSE[1])
    parser.add_argument("--merged-px", type=float, default=FURNITURE_MERGED_PX,
                        help="triangulate_handles' merged_px (0: every view counts in a point's share)")
    parser.add_argument("--no-bars", action="store_true",
                        help="without the views' bar segments (`bar_sightings`, `triangulate_bars`)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, help="per-piece rows as JSON")
    args = parser.parse_args()
    if not args.true_maps and args.detector is None:
        parser.error("give --detector or --true-maps")
    torch.set_num_threads(args.threads)
    detector = None if args.true_maps else load_detector(args.detector)[0]
    print(f"{date.today()}, {platform.processor() or platform.machine()}, "
          f"{'true maps' if args.true_maps else args.detector}")
    print("| set | pieces | 2D recall | 2D precision | 2D error median (px) | 3D recall | "
          "3D precision | 3D error median (cm) | count right |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for root in args.sets:
        seen = sighted = true_visible = 0
        d2, d3, n_true, n_found, count_right, dirs = [], [], 0, 0, 0, capture_dirs(root)
        for d in dirs:
            capture = read_capture_set(d)
            handles = np.array([p["keypoints"]["handle"] for p in capture.gt["parts"]])
            maps = true_maps(capture, handles) if detector is None else detector.detect(capture.load_images())
            found = []
            for i, (m, frame) in enumerate(zip(maps, capture.frames, strict=True)):
                s = sightings(m, i)
                found += s
                labels, part = _read(capture, "label_paths", i), part_image(capture, i)
                visible = sorted(set(part[labels == SemanticClass.HANDLE].tolist()) - {-1})
                uv = np.array([project(frame, handles[k]) for k in visible]).reshape(-1, 2)
                scale = frame.camera.height / 128.0
                dist = match(uv, np.array([x.uv for x in s]).reshape(-1, 2), args.px * scale)
                seen += len(dist)
                sighted += len(s)
                true_visible += len(visible)
                d2 += [x / scale for x in dist]
            segments = None if args.no_bars else [b for i, m in enumerate(maps) for b in bar_sightings(m, i)]
            points = triangulate_handles(capture.frames, found, min_share=args.min_share,
                                         loose_share=args.loose_share, loose_rms_px=args.loose_rms_px,
                                         merged_px=args.merged_px, bars=segments)
            if segments is not None:
                points += triangulate_bars(capture.frames, segments, points, min_share=FURNITURE_BAR_SHARE)
            dist3 = match(handles, np.array([h.p_O for h in points]).reshape(-1, 3), args.cm / 100)
            d3 += dist3
            n_true += len(handles)
            n_found += len(points)
            count_right += len(points) == len(handles)
            rows.append({"set": root.name, "capture": d.name, "fronts": len(handles),
                         "triangulated": len(points), "matched": len(dist3)})
        print(f"| {root.name} | {len(dirs)} | {seen / max(true_visible, 1):.3f} | "
              f"{seen / max(sighted, 1):.3f} | {np.median(d2) if d2 else float('nan'):.2f} | "
              f"{len(d3) / max(n_true, 1):.3f} | {len(d3) / max(n_found, 1):.3f} | "
              f"{100 * np.median(d3) if d3 else float('nan'):.2f} | {count_right} of {len(dirs)} |")
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
