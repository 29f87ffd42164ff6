"""What the detector reads of the front behind each sighted handle (`nfr_drake.perception.front_reading`)
against the gt.json of furniture capture sets.

Usage: python benchmarks/front_reading.py --detector models/furniture/handle_detector
       --sets data/eval/furniture_cams128 [--cm 3] [--threads 1] [--figure F.png --figure-capture DIR]
Handles are triangulated from the detector's maps as the fit does (`locate_handles`); each is
matched to the true handle nearest it (within `--cm`). Per matched handle: whether the read type
(door or drawer) is right; the median distance of its four face corners to the true ones (cm);
for true doors read as doors, the hinge points' error (`hinge_points`, on the side the fit
takes: a door of a pair away from its neighbour, `pair_sides`; mean of hinge_top and
hinge_bottom, cm), whether the hinge is on the right side (the read hinge nearer the true hinge
edge than the true free edge) and the door's angle read from its face (the top and bottom
edges' turn, `face_turn`; the fit takes its handle's turn, `handle_turn`, where both exceed
`read_turn_min_deg`) against the true angle (deg); and the error of the shut left and top
edges (`shut_edges`, cm); for true drawers, the read face's bottom edge less the true one
(signed median, cm: the fit places a drawer's goal from its handle, `drawer_goal`, not from that
edge); of the shut doors read as doors, how many the fit would take as open (face and handle
turned more than `read_turn_min_deg`, which would open them short), and of the open doors it
takes so, the handle turn's error.
`--figure` draws what is read of captures (`--figure-capture`, a row each) in their first five
views: each read front's face (red: door, blue: drawer, its hinge edge thick) over the photo, its
handle a white cross, the true faces thin green.
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
from nfr_drake.inference.furniture_fit import FurnitureFitConfig, pair_sides
from nfr_drake.perception.front_reading import face_turn, handle_turn, hinge_points, read_front, shut_edges
from nfr_drake.perception.handle_detector.model import load_detector
from nfr_drake.perception.handle_triangulation import locate_handles, project

ZOOM = 3


def _draw_face(image: np.ndarray, frame, corners: np.ndarray, colour, thickness: int,
               hinge_edge: tuple[int, int] | None = None) -> None:
    """The face (4, 3) in O as a quadrilateral over the zoomed image, its hinge edge (corner
    indices) thicker."""
    uv = [project(frame, c) for c in corners]
    if any(p is None for p in uv):
        return
    pts = [tuple(int(round(v)) for v in np.asarray(p) * ZOOM) for p in uv]
    for a, b in ((0, 1), (1, 3), (2, 3), (0, 2)):
        cv2.line(image, pts[a], pts[b], colour, thickness * (3 if (a, b) == hinge_edge else 1), cv2.LINE_AA)


def figure_row(detector, capture_dir: Path) -> np.ndarray:
    """What the detector reads of one capture's fronts, drawn in its first five views side by side."""
    capture = read_capture_set(capture_dir)
    images = capture.load_images()
    found = locate_handles(detector.detect(images), capture.frames)
    maps = detector.read_fronts(images)
    fronts = [f for h in found if (f := read_front(h, maps, capture.frames)) is not None]
    tiles = []
    for frame, image in list(zip(capture.frames, images, strict=True))[:5]:
        tile = cv2.resize(image, None, fx=ZOOM, fy=ZOOM, interpolation=cv2.INTER_CUBIC)
        for part in capture.gt["parts"]:
            _draw_face(tile, frame, np.asarray(part["face_corners"]), (0, 200, 0), 1)
        for f in fronts:
            colour = (230, 40, 40) if f.is_door else (40, 80, 230)
            left = np.allclose(hinge_points(f), f.corners[[0, 2]])
            _draw_face(tile, frame, f.corners, colour, 2, ((0, 2) if left else (1, 3)) if f.is_door else None)
            uv = project(frame, f.p_O)
            if uv is not None:
                cv2.drawMarker(tile, tuple(int(round(v)) for v in uv * ZOOM), (255, 255, 255),
                               cv2.MARKER_CROSS, 12, 2)
        tiles.append(tile)
    return np.concatenate(tiles, 1)


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
    parser.add_argument("--figure", type=Path)
    parser.add_argument("--figure-capture", type=Path, nargs="+")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    detector = load_detector(args.detector)[0]
    if args.figure:
        rows = [figure_row(detector, d) for d in args.figure_capture or capture_dirs(args.sets[0])[:1]]
        cv2.imwrite(str(args.figure), cv2.cvtColor(np.concatenate(rows, 0), cv2.COLOR_RGB2BGR))
    print(f"{date.today()}, {platform.processor() or platform.machine()}, {args.detector}")
    print("| set | handles matched | type right | corner error (cm) | hinge error (cm) | hinge side "
          "right | door angle error (deg) | left edge error (cm) | top edge error (cm) | "
          "drawers' bottom edge, read less true (cm) | shut doors whose face and handle are read "
          f"turned more than {FurnitureFitConfig.read_turn_min_deg:g} deg (the largest face turn) | "
          "open doors so read, their handle's turn error (deg) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for root in args.sets:
        matched = type_right = side_right = doors = 0
        corner_err, hinge_err, angle_err, left_err, top_err, drawer_bottom = [], [], [], [], [], []
        shut_turns, taken_open = [], []  # (face, handle) turns of shut doors; open doors' errors, deg
        for d in capture_dirs(root):
            capture = read_capture_set(d)
            parts = capture.gt["parts"]
            true_handles = np.array([p["keypoints"]["handle"] for p in parts])
            images = capture.load_images()
            found = locate_handles(detector.detect(images), capture.frames)
            maps = detector.read_fronts(images)
            fronts = [read_front(h, maps, capture.frames) for h in found]
            sides = pair_sides(np.array([h.p_O for h in found]).reshape(-1, 3), FurnitureFitConfig.pair_gap_m)
            for h, front, side in zip(found, fronts, sides, strict=True):
                dist = np.linalg.norm(true_handles - h.p_O, axis=1)
                k = int(np.argmin(dist))
                if dist[k] > args.cm / 100 or front is None:
                    continue
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
                if part["type"] == "drawer":
                    bottom = front.corners[2:, 2].mean() - true_corners[2:, 2].mean()
                    drawer_bottom.append(100 * float(bottom))
                if part["type"] == "door" and front.is_door:
                    doors += 1
                    true_hinge = np.array([part["keypoints"]["hinge_top"], part["keypoints"]["hinge_bottom"]])
                    read = hinge_points(front, None if side == 0 else side > 0)  # as the fit takes it
                    hinge_err.append(100 * float(np.linalg.norm(read - true_hinge, axis=1).mean()))
                    free = true_corners[[1, 3]] if np.allclose(true_corners[[0, 2]], true_hinge, atol=1e-6) \
                        else true_corners[[0, 2]]
                    side_right += np.linalg.norm(read - true_hinge) < np.linalg.norm(read - free)
                    angle_err.append(abs(np.degrees(face_turn(front)) - 90.0 * part["q"]))
                    turns = np.degrees([face_turn(front), handle_turn(front, read)])
                    if part["q"] < 0.01:
                        shut_turns.append(turns)
                    elif turns.min() > FurnitureFitConfig.read_turn_min_deg:
                        taken_open.append(abs(turns[1] - 90.0 * part["q"]))
        med = lambda xs: float(np.median(xs)) if xs else float("nan")  # noqa: E731
        print(f"| {root.name} | {matched} | {type_right / max(matched, 1):.3f} | {med(corner_err):.2f} | "
              f"{med(hinge_err):.2f} | {side_right} of {doors} | {med(angle_err):.1f} | "
              f"{med(left_err):.2f} | {med(top_err):.2f} | {med(drawer_bottom):+.2f} | "
              f"{sum(t.min() > FurnitureFitConfig.read_turn_min_deg for t in shut_turns)} of "
              f"{len(shut_turns)} "
              f"({max((t[0] for t in shut_turns), default=float('nan')):.1f}) | {len(taken_open)}, "
              f"{med(taken_open):.1f} |")


if __name__ == "__main__":
    main()
