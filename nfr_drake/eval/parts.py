"""Evaluation of objects with several parts (furniture): per-part rows and their table.

A piece's prediction holds every articulation slot of the field (slot k = front k in canonical
order, docs/NEURAL_FIELD.md "Furniture: several parts"); each true part of gt.json is scored
against the slot of its index: articulation error (doors in degrees, drawers in cm), keypoint
RMSE at the observed state, handle error, and the handle's path with that part swept and the others
held. Per piece: whether the field finds the right number of parts, and the fit time.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from nfr_drake.data.capture import CaptureSet
from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS
from nfr_drake.eval.evaluate import REFUSAL_COLUMNS, refusal_cells
from nfr_drake.inference.metrics import articulation_error, keypoint_rmse_cm, trajectory_rmse_cm
from nfr_drake.inference.result import PART_KEYPOINTS

HANDLE = SLOT_KEYPOINTS.index("handle")


@dataclass
class PartsPrediction:
    """One method's answer for a piece with S part slots, positions in O, metres: q (S,) in
    [0, 1]; exists bool (S,); types (S,) index into `PART_TYPES`; keypoints (S, 4, 3) at the
    observed state (`SLOT_KEYPOINTS`); trajectories (S, N, 4, 3), each slot swept over the q grid
    asked for with the others held; seconds of wall time; confidence (S,) P(the slot's handle
    within 2 cm) (`inference.confidence`) and refused (S,) bool (below the calibration's
    threshold), both None without a calibration."""

    q: np.ndarray
    exists: np.ndarray
    types: np.ndarray
    keypoints: np.ndarray
    trajectories: np.ndarray
    seconds: float
    confidence: np.ndarray | None = None
    refused: np.ndarray | None = None


@dataclass
class PartMetrics:
    """Errors of one method on one true part of a piece (slot `part`).

    found: the field finds the slot; type_right: its door/drawer type is right; parts_found and
    count_right (per piece, repeated on its parts): slots found, and whether that is the true part
    count. articulation_error in degrees (doors) or cm (drawers); keypoint RMSE over the part's
    keypoints in gt.json (handle, goal and a door's hinge points); handle error at the observed
    state; handle trajectory RMSE over the q grid; seconds: the piece's fit; goal_error_cm and
    hinge_error_cm: the goal's error and a door's two hinge points' RMSE (NaN for a drawer) at the
    observed state, the parts of the keypoint RMSE besides the handle; confidence: the
    fit's P(the part's handle within 2 cm) and refused: 1 when it is below the calibration's
    threshold, 0 when not (both NaN without a calibration).
    """

    capture: str
    set_name: str
    method: str
    part: int
    part_type: str
    found: bool
    type_right: bool
    parts_found: int
    count_right: bool
    articulation_error: float
    keypoint_rmse_cm: float
    handle_error_cm: float
    handle_trajectory_rmse_cm: float
    seconds: float
    goal_error_cm: float = math.nan
    hinge_error_cm: float = math.nan
    confidence: float = math.nan
    refused: float = math.nan


def score_parts(capture: CaptureSet, prediction: PartsPrediction, set_name: str, method: str
                ) -> list[PartMetrics]:
    """Compare a prediction with the capture's gt.json `parts`, one row per true part."""
    parts = capture.gt["parts"]
    found = int(np.sum(prediction.exists))
    rows = []
    for part in parts:
        k, names = part["index"], PART_KEYPOINTS[part["type"]]
        slots = [SLOT_KEYPOINTS.index(n) for n in names]
        true = np.array([part["keypoints"][names[n]] for n in names])
        pred = prediction.keypoints[k, slots]
        goal = [list(names).index("goal")]
        hinge = [i for i, n in enumerate(names) if n.startswith("axis_")]
        rows.append(PartMetrics(
            capture=capture.root.name, set_name=set_name, method=method, part=k,
            part_type=part["type"], found=bool(prediction.exists[k]),
            type_right=PART_TYPES[int(prediction.types[k])] == part["type"], parts_found=found,
            count_right=found == len(parts),
            articulation_error=articulation_error(prediction.q[k], part["q"], part["joint_type"],
                                                  part["joint_upper"]),
            keypoint_rmse_cm=keypoint_rmse_cm(pred, true),
            handle_error_cm=keypoint_rmse_cm(prediction.keypoints[k, [HANDLE]],
                                             np.array([part["keypoints"]["handle"]])),
            handle_trajectory_rmse_cm=trajectory_rmse_cm(
                prediction.trajectories[k, :, HANDLE], np.asarray(part["trajectory"]["keypoints"]["handle"])),
            seconds=prediction.seconds,
            goal_error_cm=keypoint_rmse_cm(pred[goal], true[goal]),
            hinge_error_cm=keypoint_rmse_cm(pred[hinge], true[hinge]) if hinge else math.nan,
            confidence=math.nan if prediction.confidence is None else float(prediction.confidence[k]),
            refused=math.nan if prediction.refused is None else float(prediction.refused[k])))
    return rows


def _median(values: list[float], p90: bool = True) -> str:
    if not values:
        return "n/a"
    text = f"{np.median(values):.2f}"
    return text + (f" (p90 {np.percentile(values, 90):.2f})" if p90 else "")


def parts_summary_table(results: Iterable[PartMetrics]) -> str:
    """Markdown table per set and method: pieces, parts, part count right (share of pieces),
    parts found and type right (share of parts), medians (and 90th percentiles) of the door and
    drawer articulation errors, keypoint RMSE, handle, goal and door hinge errors and handle
    trajectory RMSE, the median fit time, the parts refused by the fit confidence
    (`evaluate.refusal_cells`)."""
    results = list(results)
    lines = ["| set | method | pieces | parts | part count right | parts found | type right | "
             "door error (deg) | drawer error (cm) | keypoint RMSE (cm) | handle error (cm) | "
             "goal error (cm) | door hinge error (cm) | handle trajectory RMSE (cm) | time (s) | "
             + " | ".join(REFUSAL_COLUMNS) + " |",
             "|" + "---|" * (15 + len(REFUSAL_COLUMNS))]
    for set_name in sorted({r.set_name for r in results}):
        for method in sorted({r.method for r in results if r.set_name == set_name}):
            rows = [r for r in results if (r.set_name, r.method) == (set_name, method)]
            pieces = {r.capture: r for r in rows}.values()
            share = lambda flags: f"{100 * np.mean(list(flags)):.0f} %"  # noqa: E731
            cells = [str(len(pieces)), str(len(rows)), share(r.count_right for r in pieces),
                     share(r.found for r in rows), share(r.type_right for r in rows),
                     _median([r.articulation_error for r in rows if r.part_type == "door"]),
                     _median([r.articulation_error for r in rows if r.part_type == "drawer"]),
                     _median([r.keypoint_rmse_cm for r in rows]),
                     _median([r.handle_error_cm for r in rows]),
                     _median([r.goal_error_cm for r in rows]),
                     _median([r.hinge_error_cm for r in rows if r.part_type == "door"]),
                     _median([r.handle_trajectory_rmse_cm for r in rows]),
                     _median([r.seconds for r in pieces], p90=False)] + refusal_cells(rows)
            lines.append(f"| {set_name} | {method} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


PART_PANELS = (("door articulation error (deg)", "door", "articulation_error"),
               ("drawer articulation error (cm)", "drawer", "articulation_error"),
               ("keypoint RMSE (cm)", None, "keypoint_rmse_cm"),
               ("handle trajectory RMSE (cm)", None, "handle_trajectory_rmse_cm"))
"""Panels of the furniture error plot: title, the part type it shows (None: all), the value."""


def part_panel_values(results: Iterable[PartMetrics], part_type: str | None, attr: str) -> list[float]:
    """The finite values of `attr` of the rows of one part type (None: all)."""
    values = [getattr(r, attr) for r in results if part_type in (None, r.part_type)]
    return [v for v in values if math.isfinite(v)]
