"""Fits with known errors for the fit confidence: run, resumable, one JSON line per fit.

A case is a model fitted to a capture set changed by a variant (`capture_variants`); its line
keeps what the fit found (z, q, the starts' losses and q, the triangulated handle) and the handle's
error against gt.json. The confidence features are computed from the line (`case_features`), so a
change of the features needs no new fit. The handle's truth is
the capture's handle at its q; for a furniture capture (several fronts) the nearest front's handle.
A room capture (`confidence_rooms`) is fitted with the segmenter's masks as `infer --estimate-pose`
fits it (the pixels off the masks painted in the training background, `infer.paint_background`),
with the given pose ("room") or the pose estimated from the masks ("room_pose", the line keeps
X_WO; the handle is compared in the room's frame). A room fit of the pipeline (`PIPELINE_ROOM`) is
made as `eval-pipeline --perceive room --object-pose estimated` makes it, by the pipeline's own
perception (`systems.pipeline.perceive_scene`), and its line keeps the features that perception
computed.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from nfr_drake.data.capture import CaptureSet, read_capture_set
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.capture_variants import apply_variant
from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.inference.confidence import fit_features
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import (
    FittedModel,
    infer,
    infer_in_world,
    infer_parts,
    object_masks,
    paint_background,
    slot_features,
)
from nfr_drake.perception.handle_triangulation import TriangulatedHandle
from nfr_drake.perception.object_pose import ObjectPoseError
from nfr_drake.systems.pipeline import perceive_scene
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.keypoints import KeypointTrajectory

SEGMENTER = Path("models/segmenter")
"""The room segmenter whose masks the room fits and their confidence use."""

ROOM_VARIANTS = ("room", "room_pose")
"""Fits of a room capture: with the given pose, and with the pose estimated from the masks."""

PIPELINE_ROOM = "pipeline_room"
"""The variant of a room fit of the pipeline: the object of a scenario's seed and index in its
room, perceived as `eval-pipeline --perceive room --object-pose estimated` perceives it
(`room_scenario`). Its case's capture names the scenario, pipeline_rooms/<category>_<seed>_<index>
(`pipeline_room_case`)."""


@dataclass(frozen=True)
class Case:
    """One fit to make: model folder, capture-set folder, variant and its seed, and the split it
    belongs to ("calibration", "evaluation" or "ood")."""

    model: str
    capture: str
    variant: str
    seed: int
    split: str

    @property
    def key(self) -> str:
        return f"{self.model}|{self.capture}|{self.variant}|{self.seed}"


def true_handles(gt: dict) -> np.ndarray:
    """Handle positions (M, 3) in O at the captured state: one for a closet or drawer, one per
    front with a handle for furniture (gt.json's `parts`)."""
    if "parts" in gt:
        return np.array([p["keypoints"]["handle"] for p in gt["parts"] if "handle" in p["keypoints"]])
    return np.array([gt["keypoints"]["handle"]])


def load_case(case: Case | dict) -> tuple[CaptureSet, list[np.ndarray]]:
    """The capture set and images a case's fit sees (its capture set changed by its variant);
    `case` may be a line; a room capture as it is."""
    case = Case(**{k: case[k] for k in Case.__dataclass_fields__}) if isinstance(case, dict) else case
    capture = read_capture_set(case.capture)
    if case.variant in ROOM_VARIANTS:
        return capture, capture.load_images()
    return apply_variant(case.variant, capture, capture.load_images(), case.seed)


def case_features(line: dict, fitted: FittedModel, room: bool = True) -> tuple[dict, list[dict]]:
    """The confidence features of a line's fit (`inference.confidence.fit_features`), as `infer`
    computes them: for a room capture in the fit's frame (the estimated O of "room_pose") with the
    segmenter's masks as the observed silhouette, or with `room` False the image border's colour
    (as for an object alone)."""
    capture, images = load_case(line)
    frames, masks = capture.frames, None
    if line["variant"] in ROOM_VARIANTS:
        masks = object_masks(images, SEGMENTER) if room else None
        if line.get("X_WO") is not None:
            X_OW = np.linalg.inv(np.array(line["X_WO"]))
            frames = [replace(f, X_OC=X_OW @ f.X_OC) for f in frames]
    return fit_features(fitted.model, torch.tensor(line["z"]), frames, images,
                        np.array(line["start_losses"]), fitted.codes, fitted.code_scale,
                        fitted.keypoint_names.index("handle"), line["sighting_p_O"], masks)


def part_errors(gt: dict, slot_handles: np.ndarray) -> dict[str, float]:
    """Per true part with a handle of a furniture gt.json (`parts`), its index (a string, as JSON
    keys are) -> the distance, m, of the handle of the field's slot of that index (slot_handles
    (S, 3) in O) to the part's true handle."""
    return {str(p["index"]): float(np.linalg.norm(slot_handles[p["index"]] - p["keypoints"]["handle"]))
            for p in gt["parts"] if "handle" in p["keypoints"]}


def run_furniture_case(case: Case, fitted: FittedModel, config: FurnitureFitConfig) -> dict:
    """Fit `case` with a model of several parts (`infer_parts`) and return its JSON line: the fit
    (z, the starts' final codes start_z and losses start_losses), each true part's handle error
    (`part_errors`) and, as handle_error_m, the smallest of them."""
    capture, images = load_case(case)
    result, fit, _ = infer_parts(fitted, capture, config, np.linspace(0.0, 1.0, 2), images=images)
    errors = part_errors(capture.gt, fit.keypoints[:, SLOT_KEYPOINTS.index("handle")])
    return {**asdict(case), "key": case.key, "category": capture.gt.get("category"),
            "model_category": fitted.category, "z": result.z.tolist(),
            "start_z": fit.start_z.double().tolist(), "start_losses": fit.start_losses.tolist(),
            "exists": fit.exists.tolist(), "image_loss": result.image_loss,
            "handles": np.asarray(fit.handles).tolist(), "part_errors": errors,
            "sightings": result.extra["handles"], "handle_order": fit.handle_order.tolist(),
            "handle_error_m": min(errors.values()) if errors else None,
            "failure": "" if errors else "no part with a handle in gt.json",
            "seconds": result.seconds}


def case_part_features(line: dict, fitted: FittedModel) -> list[dict]:
    """Per true part of a furniture line's fit (`run_furniture_case`), as `infer_parts` computes
    them (`slot_features`): the fit's features and those of the part's slot,
    with `part` its index and `handle_error_m` its handle's error."""
    if "handle_order" not in line:
        raise NfrDrakeError(f"{line['key']}: a fit line written before the sightings' support was "
                            "kept; fit it again (remove the fits file or that line)")
    capture, images = load_case(line)
    seen = line["sightings"]
    sighted = [TriangulatedHandle(np.array(seen["p_O"][i]), tuple(seen["views"][i]), seen["rms_px"][i],
                                  seen["sightings"][i]) for i in line["handle_order"]]
    parts = [int(k) for k in line["part_errors"]]
    features, _ = slot_features(fitted, torch.tensor(line["z"]), torch.tensor(line["start_z"]),
                                np.array(line["start_losses"]), capture.frames, images, sighted, parts)
    return [{"part": k, "handle_error_m": line["part_errors"][str(k)], **f}
            for k, f in zip(parts, features, strict=True)]


def room_scenario(category: str, seed: int, index: int, fit: FitConfig) -> Scenario:
    """The scenario that `eval-pipeline --perceive room --object-pose estimated` runs on object
    `index` of capture seed `seed` with models/CATEGORY and the fit `fit` (the room, the cameras
    and the coarse look drawn from the seed and index), never refused."""
    base = Scenario(category=category, model=f"models/{category}", seed=seed, fit=fit,
                    min_confidence=0.0, object_pose="estimated", perceive="room")
    return object_scenario(base, index)


def pipeline_room_case(category: str, seed: int, index: int, split: str) -> Case:
    """The `PIPELINE_ROOM` case of object `index` of capture seed `seed` (`room_scenario`)."""
    return Case(f"models/{category}", f"pipeline_rooms/{category}_{seed}_{index}", PIPELINE_ROOM,
                seed, split)


def run_pipeline_room_case(case: Case, fit: FitConfig) -> dict:
    """Perceive a `PIPELINE_ROOM` case's scenario with the pipeline's perception
    (`perceive_scene`: the segmenter's masks with its close look, the pose from its amodal
    carcass, the background painted) and return its JSON line: q, the handle's error in W at the
    observed state (as eval-pipeline's handle_error_cm), the estimated X_WO (4, 4) and the
    confidence `features` the perception system computed; a scenario whose masks give no object
    pose (ObjectPoseError), a line without a fit (handle_error_m None, `failure` why)."""
    category, seed, index = Path(case.capture).name.rsplit("_", 2)
    scenario = room_scenario(category, int(seed), int(index), fit)
    obj, part = scenario.sample_piece()
    truth = KeypointTrajectory.from_articulated_object(obj, scenario.X_WO, scenario.q_start, part=part)
    line = {**asdict(case), "key": case.key, "category": category, "model_category": category}
    try:
        perceived = perceive_scene(scenario, obj)
    except ObjectPoseError as err:
        return {**line, "handle_error_m": None, "failure": f"{type(err).__name__}: {err}"}
    predicted, confidence = perceived.trajectory, perceived.confidence
    error = np.linalg.norm(predicted.point("handle", predicted.q_current)
                           - truth.point("handle", truth.q_current))
    return {**line, "q": predicted.q_current, "q_true": scenario.q_start,
            "handle_error_m": float(error), "X_WO": perceived.X_WO.GetAsMatrix4().tolist(),
            "features": confidence["features"], "seconds": perceived.seconds}


def run_case(case: Case, fitted: FittedModel, fit: FitConfig) -> dict:
    """Fit `case` and return its JSON line (see module docstring); a room whose masks give no
    object pose returns a line without a fit (handle_error_m None, `failure` why). A model of
    several parts (furniture) is fitted with the furniture fit's defaults (`run_furniture_case`),
    a room fit of the pipeline by its perception (`run_pipeline_room_case`)."""
    if case.variant == PIPELINE_ROOM:
        return run_pipeline_room_case(case, fit)
    if fitted.num_slots > 1:
        return run_furniture_case(case, fitted, FurnitureFitConfig())
    capture, images = load_case(case)
    grid, X_WO = np.linspace(0.0, 1.0, 2), None
    if case.variant in ROOM_VARIANTS:
        masks = object_masks(images, SEGMENTER)
        if case.variant == "room_pose":
            try:
                result, outcome, _ = infer_in_world(fitted, capture, fit, grid, masks)
            except ObjectPoseError as err:
                return {**asdict(case), "key": case.key, "category": capture.gt.get("category"),
                        "model_category": fitted.category, "handle_error_m": None,
                        "failure": str(err)}
            X_WO = result.extra["object_pose"]["X_WO"]
        else:
            result, outcome = infer(fitted, capture, fit, grid, paint_background(images, masks),
                                    masks=masks, masked_loss=False)
    else:
        result, outcome = infer(fitted, capture, fit, grid, images=images)
    handle = result.keypoints["handle"]
    truth = true_handles(capture.gt)
    error = float(np.linalg.norm(truth - handle, axis=1).min())
    same = capture.gt.get("category") == fitted.category
    keypoint_rmse = (float(np.sqrt(np.mean([np.sum((np.asarray(capture.gt["keypoints"][n]) - p) ** 2)
                                            for n, p in result.keypoints.items()])))
                     if same else None)
    seen = result.extra["handle_sighting"]
    return {**asdict(case), "key": case.key, "category": capture.gt.get("category"),
            "model_category": fitted.category, "q": result.q, "q_true": capture.gt.get("q"),
            "z": result.z.tolist(), "image_loss": result.image_loss,
            "start_losses": outcome.start_losses.tolist(), "start_q": outcome.start_q.tolist(),
            "sighting_p_O": seen.get("p_O"), "handle": handle.tolist(),
            "handle_error_m": error, "keypoint_rmse_m": keypoint_rmse, "X_WO": X_WO,
            "seconds": result.seconds}


CALIBRATION_VARIANTS = ("clean", "clean", "few_views", "occluded", "edge_cut")
"""Variants of the calibration captures, by capture index modulo 5: the training world, with the
failures it can produce (too few views, occlusion, the object cut by the edge)."""

OOD_VARIANTS = ("background", "recoloured", "occluded", "edge_cut", "few_views", "wrong_category")
"""Variants of the out-of-distribution captures, by capture index modulo 6; "wrong_category" fits
the other category's model to the clean capture."""


def plan_cases(data: Path, calibration: int, evaluation: int, closed: int, shut128: int, ood: int,
               furniture: int, rooms: dict[str, list[Path]] | None = None) -> list[Case]:
    """The cases of the confidence study from the capture sets under `data` (docs/EVALUATION.md,
    "Fit confidence"): per category `calibration` captures of C_calib (seed 500), `evaluation` of
    C_train_cams (seed 0), `closed` of C_closed (seed 3) and `shut128` of C_shut128 (seed 200,
    128 px, the pipeline's objects), all clean, and `ood` of C_oodsrc
    (seed 600); `furniture` captures of furniture_oodsrc, each fitted by both models; and the
    room captures `rooms` (set name <category>_<set> -> capture folders, `confidence_rooms`),
    each fitted with the given and the estimated pose, index by index across the sets. Models
    are models/C."""
    cases = []
    for c in ("closet", "drawer"):
        for i in range(calibration):
            cases.append(Case(f"models/{c}", str(data / f"{c}_calib" / f"{c}_{i:03d}"),
                              CALIBRATION_VARIANTS[i % 5], 500 + i, "calibration"))
    for i in range(max(evaluation, closed, shut128, ood, furniture)):
        for c, other in (("closet", "drawer"), ("drawer", "closet")):
            if i < ood:
                variant = OOD_VARIANTS[i % 6]
                model = other if variant == "wrong_category" else c
                cases.append(Case(f"models/{model}", str(data / f"{c}_oodsrc" / f"{c}_{i:03d}"),
                                  "clean" if variant == "wrong_category" else variant, 600 + i,
                                  "ood"))
            for folder, count in (("train_cams", evaluation), ("closed", closed),
                                  ("shut128", shut128)):
                if i < count:
                    cases.append(Case(f"models/{c}", str(data / f"{c}_{folder}" / f"{c}_{i:03d}"),
                                      "clean", i, "evaluation"))
            if i < furniture:
                cases.append(Case(f"models/{c}", str(data / "furniture_oodsrc" / f"furniture_{i:03d}"),
                                  "clean", 600 + i, "ood"))
    rooms = rooms or {}
    for i in range(max((len(v) for v in rooms.values()), default=0)):
        for name, captures in rooms.items():
            if i < len(captures):
                category = name.split("_")[0]
                cases += [Case(f"models/{category}", str(captures[i]), variant, i, "rooms")
                          for variant in ROOM_VARIANTS]
    return cases


EVALUATION_SEED = 200
"""The capture seed of eval-pipeline's evaluation: a room calibration is checked on it, never
fitted on it."""


def plan_room_cases(calibration: range, evaluation: range, seed: int) -> list[Case]:
    """The room calibration's cases (`PIPELINE_ROOM`), per category (closet, drawer): the
    objects `calibration` of capture seed `seed` (split "calibration") and `evaluation` of
    `EVALUATION_SEED` (split "evaluation"), index by index across the categories and splits, so
    that a run stopped early leaves them balanced."""
    if seed == EVALUATION_SEED:
        raise NfrDrakeError(f"--room-seed {seed}: the pipeline's evaluation seed; calibrate on another")
    cases = []
    for i in sorted(set(calibration) | set(evaluation)):
        for c in ("closet", "drawer"):
            if i in calibration:
                cases.append(pipeline_room_case(c, seed, i, "calibration"))
            if i in evaluation:
                cases.append(pipeline_room_case(c, EVALUATION_SEED, i, "evaluation"))
    return cases


FURNITURE_OOD_VARIANTS = ("background", "recoloured", "occluded", "edge_cut", "few_views")
"""Variants of the out-of-distribution furniture captures (seed 600) fitted by the furniture
model, by capture index modulo 5."""


def plan_furniture_cases(data: Path, calibration: int, evaluation: int, ood: int,
                         calibration_captures: Path | None = None) -> list[Case]:
    """The cases of the furniture model's confidence (models/furniture): `calibration` captures
    of `calibration_captures` (default DATA/furniture_calib; capture seed 500,
    `CALIBRATION_VARIANTS` by index), `evaluation` of furniture_cams128 (seed 7, 128 px, clean)
    and `ood` of furniture_oodsrc (seed 600, `FURNITURE_OOD_VARIANTS` by index)."""
    model = "models/furniture"
    calib = data / "furniture_calib" if calibration_captures is None else calibration_captures
    cases = [Case(model, str(calib / f"furniture_{i:03d}"),
                  CALIBRATION_VARIANTS[i % 5], 500 + i, "calibration") for i in range(calibration)]
    for i in range(max(evaluation, ood)):
        if i < evaluation:
            cases.append(Case(model, str(data / "furniture_cams128" / f"furniture_{i:03d}"),
                              "clean", i, "evaluation"))
        if i < ood:
            cases.append(Case(model, str(data / "furniture_oodsrc" / f"furniture_{i:03d}"),
                              FURNITURE_OOD_VARIANTS[i % 5], 600 + i, "ood"))
    return cases


def run_cases(cases: list[Case], out: Path, fit: FitConfig = FitConfig()) -> list[dict]:
    """Fit every case not yet in `out` (JSON lines, appended as each fit ends); returns all lines."""
    done = set()
    if out.exists():
        done = {json.loads(line)["key"] for line in out.read_text().splitlines() if line.strip()}
    out.parent.mkdir(parents=True, exist_ok=True)
    models: dict[str, FittedModel] = {}
    for case in tqdm([c for c in cases if c.key not in done], desc="confidence fits", unit="fit"):
        if case.model not in models:
            models[case.model] = FittedModel(Path(case.model))
        line = run_case(case, models[case.model], fit)
        with open(out, "a") as f:
            f.write(json.dumps(line) + "\n")
    return [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
