"""Fit a furniture model to furniture capture sets and compare every part with gt.json.

A quick check with the fitted q per part; `nfr-drake eval --category furniture` is the evaluation
(per-part CSV, tables, plots, unseen-camera sets: docs/FURNITURE.md).

Per capture: whether the part count is right (the slots the head says exist against the true
fronts) and, per true front k (slot k), its articulation error (degrees for doors, cm for drawers),
keypoint RMSE (handle, goal and the axis points a front has: a door's hinge_top and hinge_bottom),
handle trajectory RMSE (slot k swept over gt's q grid, the others held), and the fit time; the
keypoint, handle and trajectory figures also as the keypoint head gives them at the fitted code
(`*_head`: before the slots are moved onto the sighted handles, `FurnitureFitConfig.snap_to_handles`,
and a pair's hinges put outward, and the head's sweep rather than `slot_path`), from the same fit.
Handles (`--handles`): "detector", those triangulated from the 2D handle detector in `--detector`
(default MODEL/handle_detector) join the fit (part count, starts, handle term:
`nfr_drake.inference.furniture_fit`); "encoder", the handles of the slots the encoder baseline in
`--baseline` (default MODEL/baseline) finds, in their place (its prediction as the fit's start);
"none", the fit without them; "true", gt.json's handles and fronts (the ceiling of what sightings
and front reading can give, for diagnosis only). A detector with front outputs also reads each
sighted handle's front (type, face corners: `FurnitureFitConfig.read_fronts`; `--no-fronts` turns
it off; `--head-type-weight 0` takes the read type alone, `FurnitureFitConfig.head_type_weight`).
The handle count and the time to sight them are in each row.
On captures of the model's own training objects (`nfr-drake captures --training-objects`) each
part also gets the keypoint RMSE of the head at the object's training code and the true q
(`own_code_keypoint_rmse_cm`): what a fit that found the training code again would give.

    python benchmarks/furniture_fit.py --model MODEL --captures DIR [--n 10] [--out rows.json] [--starts S]
        [--handles detector|encoder|none|true] [--detector DIR] [--baseline DIR] [--pairing order|nearest]
        [--no-fronts] [--head-type-weight W]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from nfr_drake.baseline.predict import predict_capture
from nfr_drake.baseline.train import load_baseline
from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.inference.fit import observed_rays
from nfr_drake.inference.furniture_fit import FurnitureFitConfig, fit_furniture, part_trajectory, slot_path
from nfr_drake.inference.metrics import articulation_error, keypoint_rmse_cm, trajectory_rmse_cm
from nfr_drake.inference.result import PART_KEYPOINTS
from nfr_drake.nfr.checkpoint import load_model
from nfr_drake.nfr.latent import slots_q_to_z_art
from nfr_drake.perception.front_reading import SightedFront, read_front
from nfr_drake.perception.handle_detector.model import load_detector
from nfr_drake.perception.handle_triangulation import locate_handles

HANDLE = SLOT_KEYPOINTS.index("handle")


def evaluate(model, codes, capture_dir: Path, config: FurnitureFitConfig, handles: str = "none",
             detector=None, baseline=None) -> dict:
    """One capture's row; `detector` for handles "detector", `baseline` (model, image size) for
    "encoder"."""
    gt = json.loads((capture_dir / "gt.json").read_text())
    capture = read_capture_set(capture_dir)
    started = time.perf_counter()
    fronts = None
    if handles == "detector":
        images = capture.load_images()
        found = locate_handles(detector.detect(images), capture.frames)
        handles_O = np.array([h.p_O for h in found]).reshape(-1, 3)
        if detector.config.fronts:
            maps = detector.read_fronts(images)
            fronts = [read_front(h, maps, capture.frames) for h in found]
    elif handles == "encoder":
        pred = predict_capture(baseline[0], capture, baseline[1], np.zeros(1))
        handles_O = pred.keypoints[pred.exists, SLOT_KEYPOINTS.index("handle")]
    elif handles == "true":
        handles_O = np.array([p["keypoints"]["handle"] for p in gt["parts"]])
        fronts = [SightedFront(np.asarray(p["keypoints"]["handle"]), float(p["type"] == "door"),
                               np.asarray(p["face_corners"]), len(capture.frames)) for p in gt["parts"]]
    else:
        handles_O = None
    sight_seconds = time.perf_counter() - started
    fit = fit_furniture(model, observed_rays(capture), codes, config, handles_O, fronts)
    own = own_code_keypoints(model, codes, gt)
    head = model.keypoints(fit.z[None])[0].view(-1, len(SLOT_KEYPOINTS), 3).double().numpy()
    parts = []
    for part in gt["parts"]:
        k, names = part["index"], PART_KEYPOINTS[part["type"]]
        pick = [SLOT_KEYPOINTS.index(n) for n in names]
        pred = fit.keypoints[k, pick]
        true = np.array([part["keypoints"][names[n]] for n in names])
        traj_q = np.asarray(part["trajectory"]["q"])
        head_path = part_trajectory(model, fit.z, k, traj_q)[:, HANDLE]
        true_path = np.asarray(part["trajectory"]["keypoints"]["handle"])
        true_handle = np.asarray(part["keypoints"]["handle"])[None]
        parts.append({
            "index": k, "type": part["type"], "q_true": part["q"], "q": float(fit.q[k]),
            "found": bool(fit.exists[k]), "type_right": int(fit.types[k]) == (part["type"] == "drawer"),
            "articulation_error": articulation_error(fit.q[k], part["q"], part["joint_type"],
                                                     part["joint_upper"]),
            "keypoint_rmse_cm": keypoint_rmse_cm(pred, true),
            "keypoint_rmse_cm_head": keypoint_rmse_cm(head[k, pick], true),
            "handle_error_cm": keypoint_rmse_cm(fit.keypoints[k, [HANDLE]], true_handle),
            "handle_error_cm_head": keypoint_rmse_cm(head[k, [HANDLE]], true_handle),
            "trajectory_rmse_cm": trajectory_rmse_cm(slot_path(model, fit, k, traj_q)[:, HANDLE], true_path),
            "trajectory_rmse_cm_head": trajectory_rmse_cm(head_path, true_path),
            **({} if own is None else {"own_code_keypoint_rmse_cm": keypoint_rmse_cm(own[k, pick], true)})})
    return {"capture": capture_dir.name, "fronts": len(gt["parts"]),
            "found": int(fit.exists.sum()), "count_right": int(fit.exists.sum()) == len(gt["parts"]),
            "handles": len(fit.handles), "sight_seconds": sight_seconds, "seconds": fit.seconds,
            "image_loss": fit.image_loss, "parts": parts}


@torch.no_grad()
def own_code_keypoints(model, codes, gt: dict) -> np.ndarray | None:
    """The head's keypoints (S, 4, 3) at the training code of the capture's object and its true q
    per front, when the object is training object i (named `<category>_<i:06d>` as `generate`
    names it and i within the code table); else None."""
    prefix, _, index = gt["object"]["name"].rpartition("_")
    if prefix != gt["category"] or len(index) != 6 or not index.isdigit() or int(index) >= len(codes):
        return None
    S = model.config.num_slots
    q = torch.zeros(1, S)
    q[0, :len(gt["parts"])] = torch.tensor([p["q"] for p in gt["parts"]])
    z = torch.cat([slots_q_to_z_art(q, S), codes[int(index)][None]], -1)
    return model.keypoints(z)[0].view(S, len(SLOT_KEYPOINTS), 3).double().numpy()


def summary(rows: list[dict]) -> dict:
    parts = [p for r in rows for p in r["parts"]]
    med = lambda xs: statistics.median(xs) if xs else float("nan")  # noqa: E731
    return {
        "captures": len(rows), "parts": len(parts),
        "count_right": float(np.mean([r["count_right"] for r in rows])),
        "parts_found": float(np.mean([p["found"] for p in parts])),
        "type_right": float(np.mean([p["type_right"] for p in parts])),
        "door_error_deg_median": med([p["articulation_error"] for p in parts if p["type"] == "door"]),
        "drawer_error_cm_median": med([p["articulation_error"] for p in parts
                                       if p["type"] == "drawer"]),
        **{f"{m}_median": med([p[m] for p in parts]) for m in (
            "keypoint_rmse_cm", "keypoint_rmse_cm_head", "handle_error_cm", "handle_error_cm_head",
            "trajectory_rmse_cm", "trajectory_rmse_cm_head")},
        "handles_within_2cm": float(np.mean([p["handle_error_cm"] <= 2.0 for p in parts])),
        "handles_within_2cm_head": float(np.mean([p["handle_error_cm_head"] <= 2.0 for p in parts])),
        "own_code_keypoint_rmse_cm_median": med([p["own_code_keypoint_rmse_cm"] for p in parts
                                                 if "own_code_keypoint_rmse_cm" in p]),
        "fit_seconds_median": med([r["seconds"] for r in rows]),
        "handle_count_right": float(np.mean([r["handles"] == r["fronts"] for r in rows])),
        "sight_seconds_median": med([r["sight_seconds"] for r in rows])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--captures", type=Path, required=True)
    parser.add_argument("--n", type=int, default=10)
    parser.add_argument("--steps", type=int, default=FurnitureFitConfig.steps)
    parser.add_argument("--starts", type=int, default=FurnitureFitConfig.starts,
                        help="training codes looked up as starts (the code table's size: all of them)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--handles", choices=("detector", "encoder", "none", "true"), default="detector")
    parser.add_argument("--detector", type=Path, help="default: MODEL/handle_detector")
    parser.add_argument("--baseline", type=Path, help="default: MODEL/baseline")
    parser.add_argument("--pairing", choices=("order", "nearest"), default=FurnitureFitConfig.handle_pairing,
                        help="how sighted handles pair with slots (FurnitureFitConfig.handle_pairing)")
    parser.add_argument("--no-fronts", action="store_true",
                        help="not what the detector reads of the fronts (FurnitureFitConfig.read_fronts)")
    parser.add_argument("--head-type-weight", type=float, default=FurnitureFitConfig.head_type_weight,
                        help="the keypoint head's weight in a read front's type (0: the read type alone)")
    args = parser.parse_args()
    detector = baseline = None
    if args.handles == "detector":
        detector = load_detector(args.detector or args.model / "handle_detector")[0]
    if args.handles == "encoder":
        encoder, doc = load_baseline(args.baseline or args.model / "baseline")
        baseline = (encoder, doc["training"]["image_size"])
    set_torch_threads(args.threads)
    model, codes, _ = load_model(args.model)
    for p in model.parameters():
        p.requires_grad_(False)
    config = FurnitureFitConfig(steps=args.steps, starts=args.starts, handle_pairing=args.pairing,
                                read_fronts=not args.no_fronts, head_type_weight=args.head_type_weight)
    dirs = sorted(d for d in args.captures.iterdir() if (d / "gt.json").is_file())[:args.n]
    rows = []
    for d in dirs:
        rows.append(evaluate(model, codes, d, config, args.handles, detector, baseline))
        r = rows[-1]
        print(f"{r['capture']}: fronts {r['fronts']}, found {r['found']}, handles {r['handles']}, "
              f"{r['seconds']:.1f} s, " + ", ".join(
                  f"{p['type']}{p['index']} q {p['q']:.2f}/{p['q_true']:.2f}" for p in r["parts"]),
              flush=True)
    result = {"summary": summary(rows), "rows": rows}
    print(json.dumps(result["summary"], indent=2))
    if args.out:
        args.out.write_text(json.dumps(result, indent=2) + "\n")


if __name__ == "__main__":
    main()
