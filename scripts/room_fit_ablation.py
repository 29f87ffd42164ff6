"""Which stage loses an object's fit in a room: the pipeline's room photos fitted stage by stage.

    OMP_NUM_THREADS=1 python scripts/room_fit_ablation.py --category drawer --seed 200 --objects 0 3 8
    OMP_NUM_THREADS=1 python scripts/room_fit_ablation.py --category drawer --seed 901 --objects 7 \
        --settings pipeline pipeline_p90 --figure docs/images/room_drawer_paint.png

For each object of the seed, the perception diagram of `nfr-drake eval-pipeline --perceive room
--object-pose estimated` (`pipeline.perception_simulator`: ten 128 px cameras around a coarse
look, the held-out room) photographs it in its room; the same cameras photograph it alone before
the training background (training lights), and alone under the room's lights (the room's
geometry left out). The true visible mask: the alone photo's pixels off the background where the
room's depth agrees with the alone depth (within 2 cm: not hidden by the arm or clutter).
Settings, each one fit (`infer`, the scenario's fit options) in the frame O of the pose named:

- ``alone``: the alone photos, the true pose (the paper's setting);
- ``alone_roomlight``: alone under the room's lights, the true pose;
- ``true_mask``: the room photos painted in the training background off the true visible mask, the
  true pose;
- ``seg_mask``: painted off the segmenter's masks as the pipeline makes them (crop stage;
  `paint_background`: the pixels at p <= `PAINT_THRESHOLD` painted, the rest kept, the pipeline's
  painting before commit d55c294), the true pose;
- ``seg_mask_nodet``: ``seg_mask`` without the handle detector's sighting;
- ``seg_mask_masked``: ``seg_mask`` with the pixels off the mask left out of the loss instead;
- ``pipeline``: ``seg_mask`` in the pose the pipeline estimates (the amodal carcass);
- ``pipeline_refined``: ``pipeline`` with that pose refined with the fitted field after the fit
  (`inference.pose_refine`, as `eval-pipeline` does by default); its pose columns are the
  refined pose's;
- ``seg_mask_p90``, ``pipeline_p90``: ``seg_mask`` and ``pipeline`` painted at p <= 0.9, so that
  only the pixels the segmenter is sure of are kept (docs/ROOMS.md, "Shut drawers fitted open");
- ``pipeline_region``: ``pipeline`` painted at p <= 0.9 off the region the shut object can occupy
  in the estimated pose (its carcass box and fronts grown by a margin) and at p <= 0.5 on it
  (`paint_thresholds`, the pipeline's one painting from commit d55c294 to 5538832);
  ``pipeline_region_refined``: that, the pose then refined (the pipeline's "region" painting);
  ``pipeline_fronts_refined``: ``pipeline_region_refined`` with the pixels beyond the open fronts'
  reach all painted (`paint_off_object(..., painting="fronts")`; the pipeline fits its three
  paintings and keeps the most confident fit, docs/ROOMS.md, "Several paintings");
  ``pipeline_paintings_refined``: the pipeline's fit: the three paintings, the most confident
  fit kept, the pose refined (`infer_painted`);
  ``pipeline_region_reach``:
  that region grown toward the cameras by the fronts' reach (the carcass's larger side: a drawer
  pulls out by less than its depth, a door swings out by its width);
- ``seg_mask_blend``, ``pipeline_blend``: ``seg_mask`` and ``pipeline`` with the photo blended
  into the background by the mask's probability (m photo + (1 - m) background, the painting
  before commit f4d43af); ``seg_mask_blend_nodet``: ``seg_mask_blend`` without the handle
  detector's sighting.

Per setting: keypoint RMSE at the observed state and handle error (cm, in W; and the handle's
error along the true object's axes, `handle_d{x,y,z}_cm`: x out of the front, z up), q error, the
handle detector's triangulated handle error (cm; nan when fewer than 3 views agree; counted, as
`infer` does, inside a painted setting's kept pixels, else inside its masks: `inside_masks`), the fit's
seconds. Per object: the detector's handle pixels (p > 0.5) on the raw room photos and the share
of them off the true (whole) silhouette, and the object's extent in the photos (its silhouette's
bounding box's longer side over the image side, median over the views). The segmenter's masks and
the pose from them come from `--segmenter` (a model folder, `models/segmenter` by default). Prints
a line per setting and object, then medians; `--csv-path` writes the rows.
"""

from __future__ import annotations

import datetime
import math
import os
import time
from dataclasses import replace
from pathlib import Path
from unittest import mock

import cv2
import numpy as np
import torch
import tyro
from pydrake.math import RigidTransform

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.capture import CaptureFrame, CaptureSet
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.rooms import Room
from nfr_drake.data.visualize import image_grid
from nfr_drake.eval.pipeline_eval import object_scenario
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import (
    SURE_THRESHOLD,
    infer,
    infer_painted,
    paint_background,
    paint_off_object,
    paint_thresholds,
)
from nfr_drake.jsonio import write_rows_csv
from nfr_drake.nfr.render import render_images
from nfr_drake.perception.handle_triangulation import inside_masks, locate_handle
from nfr_drake.perception.object_pose import ObjectPoseError, background_mask
from nfr_drake.perception.segmentation.refine import refine_masks as refined
from nfr_drake.systems.pipeline import perception_simulator, visible_silhouettes
from nfr_drake.systems.scenario import Scenario
from nfr_drake.world.keypoints import KeypointTrajectory

SETTINGS = ("alone", "alone_roomlight", "true_mask", "seg_mask", "seg_mask_nodet", "seg_mask_masked",
            "pipeline", "pipeline_refined", "seg_mask_p90", "pipeline_p90", "seg_mask_blend",
            "seg_mask_blend_nodet",
            "pipeline_blend", "pipeline_region", "pipeline_region_reach", "pipeline_region_refined",
            "pipeline_fronts_refined", "pipeline_paintings_refined")


def shots(scenario: Scenario, room_geometry: bool = True):
    """Colour (H, W, 3) uint8 and depth (H, W) m photos of the scenario's perception cameras, and
    its perception system; `room_geometry` False: the room's lights without its geometry."""
    with mock.patch.object(Room, "add_to", Room.add_to if room_geometry else lambda *a, **k: None):
        simulator, perception = perception_simulator(scenario, scenario.sample_object())
    diagram, context = simulator.get_system(), simulator.get_context()
    colour, depth = [], []
    for i in range(len(perception.cameras)):
        sensor = diagram.GetSubsystemByName(f"nfr_camera_{i}")
        sensor_context = sensor.GetMyContextFromRoot(context)
        colour.append(sensor.color_image_output_port().Eval(sensor_context).data[..., :3].copy())
        depth.append(sensor.depth_image_32F_output_port().Eval(sensor_context).data[..., 0].copy())
    return colour, depth, perception


def blend(images: list[np.ndarray], masks: list[np.ndarray]) -> list[np.ndarray]:
    """Each photo blended into the training background by its mask: m photo + (1 - m) background."""
    background = 255.0 * np.asarray(DEFAULT_BACKGROUND_RGB, np.float32)
    return [np.clip(m[..., None] * image + (1.0 - m[..., None]) * background, 0, 255).round().astype(np.uint8)
            for image, m in zip(images, masks, strict=True)]


def painted_in_region(images: list[np.ndarray], masks: list[np.ndarray], X_WO: RigidTransform, size: list,
                      perception, reach: bool) -> list[np.ndarray]:
    """The photos painted at p <= 0.5 where the object of carcass `size` (depth, width, height, m) at
    X_WO can lie, at p <= 0.9 elsewhere (`paint_thresholds`); `reach`: that region grown along +x by
    the carcass's larger side (where its fronts reach when open)."""
    size = np.asarray(size, float)
    X_WCs = [X.GetAsMatrix4() for X in perception.camera_poses]
    thresholds = paint_thresholds(X_WO.GetAsMatrix4(), size, X_WCs, perception.cameras,
                                  [image.shape[:2] for image in images],
                                  reach_m=float(max(size[:2])) if reach else 0.0)
    return paint_background(images, masks, threshold=thresholds)


def handle_error_cm(handle_O, p_O: np.ndarray) -> float:
    """Distance (cm) of a triangulated handle from the true one p_O (3,), both in the fit's O; nan
    without a handle."""
    return math.nan if handle_O is None else 100.0 * float(np.linalg.norm(handle_O.p_O - p_O))


def capture_in(X_WO: RigidTransform, X_WCs: list[RigidTransform], cameras: list) -> CaptureSet:
    """The cameras as a capture set with their poses in O (the object at X_WO)."""
    X_OW = X_WO.inverse()
    return CaptureSet(Path("cameras"), [CaptureFrame(Path(f"camera_{i}"), (X_OW @ X_WC).GetAsMatrix4(), c)
                                        for i, (X_WC, c) in enumerate(zip(X_WCs, cameras, strict=True))])


def pose_error(X_WO: RigidTransform, X_WO_hat: RigidTransform | None) -> tuple[float, float]:
    """Position (cm, on the floor) and yaw (degrees) error of X_WO_hat; inf without one."""
    if X_WO_hat is None:
        return math.inf, math.inf
    d = X_WO.inverse() @ X_WO_hat
    R = d.rotation().matrix()
    return 100.0 * float(np.linalg.norm(d.translation()[:2])), abs(math.degrees(math.atan2(R[1, 0], R[0, 0])))


def median(values: list[float]) -> float:
    """Median of the values that are not nan (nan when none is)."""
    kept = [v for v in values if not math.isnan(v)]
    return float(np.median(kept)) if kept else math.nan


def rendered(fitted, z: torch.Tensor, frame: CaptureFrame) -> np.ndarray:
    """The field of code z (D,) rendered in a view, uint8 RGB (H, W, 3)."""
    cam = frame.camera
    with torch.no_grad():
        images = render_images(fitted.model, z[None].float(), torch.from_numpy(cam.K)[None].float(),
                               torch.from_numpy(frame.X_OC)[None].float(), cam.height, cam.width)
    return np.round(255 * images.rgb[0].numpy()).astype(np.uint8)


def outlined(image: np.ndarray, mask: np.ndarray, silhouette: np.ndarray) -> np.ndarray:
    """The photo (H, W, 3) tinted magenta where the segmenter's mask (H, W) exceeds 0.5, the
    object's true silhouette (H, W) bool outlined in green."""
    out = image.copy()
    on = mask > 0.5
    out[on] = (0.5 * out[on] + 0.5 * np.array([255, 0, 255])).astype(np.uint8)
    contours, _ = cv2.findContours(silhouette.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return cv2.drawContours(out, contours, -1, (0, 255, 0), 1)


def main(category: str = "drawer", seed: int = 200, objects: tuple[int, ...] = (0, 3, 8),
         settings: tuple[str, ...] = SETTINGS, segmenter: str = Scenario.segmenter,
         csv_path: Path | None = None, threads: int = 1, q_start: float = 0.0,
         figure: Path | None = None, figure_views: tuple[int, ...] = (0, 3, 6, 9),
         refine_masks: bool = False) -> None:
    """`q_start`: the objects' articulation when photographed (0: shut, as in eval-pipeline).
    `refine_masks`: the segmenter's masks refined by the photos' colours (`segmentation.refine`)
    after the pose is estimated from them, for every setting that uses them.
    `figure`: a PNG of the first object, one row per view of `figure_views`: the room photo with
    the segmenter's mask (magenta, p > 0.5) and the true silhouette (green), then per setting the
    photo the fit gets and the fitted field rendered in the view."""
    set_torch_threads(threads)
    base = Scenario(category=category, model=f"models/{category}", seed=seed, object_pose="estimated",
                    perceive="room", segmenter=segmenter, fit=FitConfig(preset="fast"), min_confidence=0.0,
                    q_start=q_start)
    rows = []
    panels = None
    for index in objects:
        started = time.perf_counter()
        scenario = object_scenario(base, index)
        obj = scenario.sample_object()
        room, room_depth, perception = shots(scenario)
        lit, _, _ = shots(scenario, room_geometry=False)
        alone, alone_depth, _ = shots(replace(scenario, perceive="alone"))
        fitted = perception._model
        whole = [background_mask(image, DEFAULT_BACKGROUND_RGB) > 0.5 for image in alone]
        visible = [v.astype(np.float32) for v in visible_silhouettes(alone, alone_depth, room_depth)]
        X_WO = scenario.X_WO
        try:  # the pipeline's first look: its masks and the pose from them
            seg, X_WO_hat, pose, _ = perception._looked(room, perception._room_looks(room))
        except ObjectPoseError:  # the pipeline plans nothing; its row is left out
            seg, X_WO_hat, pose = perception._masks(room), None, {"amodal": None}
        if refine_masks:
            seg = refined(room, seg)
        truth = KeypointTrajectory.from_articulated_object(obj, X_WO, scenario.q_start)
        X_WCs = [X.GetAsMatrix4() for X in perception.camera_poses]
        handle_W = truth.point("handle", truth.q_current)
        sure = paint_background(room, seg, threshold=SURE_THRESHOLD)
        region = region_reach = fronts = None
        if X_WO_hat is not None:
            region = painted_in_region(room, seg, X_WO_hat, pose["size"], perception, reach=False)
            region_reach = painted_in_region(room, seg, X_WO_hat, pose["size"], perception, reach=True)
            fronts, _ = paint_off_object(room, seg, X_WCs, perception.cameras, X_WO_hat.GetAsMatrix4(),
                                         np.asarray(pose["size"]), painting="fronts")
        runs = {"alone": (alone, None, X_WO, False, True), "alone_roomlight": (lit, None, X_WO, False, True),
                "true_mask": (paint_background(room, visible), visible, X_WO, False, True),
                "seg_mask": (paint_background(room, seg), seg, X_WO, False, True),
                "seg_mask_nodet": (paint_background(room, seg), seg, X_WO, False, False),
                "seg_mask_masked": (room, seg, X_WO, True, True),
                "pipeline": (paint_background(room, seg), seg, X_WO_hat, False, True),
                "pipeline_refined": (paint_background(room, seg), seg, X_WO_hat, False, True),
                "seg_mask_p90": (sure, seg, X_WO, False, True),
                "pipeline_p90": (sure, seg, X_WO_hat, False, True),
                "seg_mask_blend": (blend(room, seg), seg, X_WO, False, True),
                "seg_mask_blend_nodet": (blend(room, seg), seg, X_WO, False, False),
                "pipeline_blend": (blend(room, seg), seg, X_WO_hat, False, True),
                "pipeline_region": (region, seg, X_WO_hat, False, True),
                "pipeline_region_reach": (region_reach, seg, X_WO_hat, False, True),
                "pipeline_region_refined": (region, seg, X_WO_hat, False, True),
                "pipeline_fronts_refined": (fronts, seg, X_WO_hat, False, True),
                "pipeline_paintings_refined": (room, seg, X_WO_hat, False, True)}
        detector = fitted.handle_detector
        maps = detector.detect(room)
        fired = [m.probability > 0.5 for m in maps]
        near = [cv2.dilate(w.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0 for w in whole]
        fired_px = sum(int(f.sum()) for f in fired)
        off = sum(int((f & ~n).sum()) for f, n in zip(fired, near, strict=True))
        sides = [max(np.ptp(r), np.ptp(c)) / max(w.shape) for w in whole if (rc := np.nonzero(w))[0].size
                 for r, c in [rc]]
        pose_cm, pose_deg = pose_error(X_WO, X_WO_hat)
        common = {"index": index, "pose_cm": pose_cm, "pose_deg": pose_deg,
                  "amodal_pose": pose.get("amodal"), "detector_px_room": fired_px,
                  "detector_off_object": off / fired_px if fired_px else math.nan,
                  "extent": float(np.median(sides)),
                  "visible_share": float(sum(v.sum() for v in visible) / max(1, sum(w.sum() for w in whole)))}
        for name in settings:
            images, masks, X, masked, use_detector = runs[name]
            if X is None:
                continue
            cap = capture_in(X, perception.camera_poses, perception.cameras)
            # a painted setting's kept pixels (those equal to the room photo), as `infer_painted` passes them
            painted = masks is not None and not masked and "blend" not in name
            kept = [np.all(i == r, axis=-1) for i, r in zip(images, room, strict=True)] if painted else None
            t0 = time.perf_counter()
            config = replace(scenario.fit, handle_detector=use_detector)
            if name == "pipeline_paintings_refined":  # the masks already refined as `refine_masks` says
                size = np.asarray(pose["size"])
                result, outcome = infer_painted(fitted, cap, config, np.linspace(0, 1, 21), room, seg, X_WCs,
                                                X_WO_hat.GetAsMatrix4(), size, refine_pose=True,
                                                refine_masks=False)
                images, kept = paint_off_object(room, seg, X_WCs, perception.cameras, X_WO_hat.GetAsMatrix4(),
                                                size, painting=result.extra["paintings"]["chosen"])
            else:
                result, outcome = infer(fitted, cap, config, np.linspace(0, 1, 21), images, masks=masks,
                                        masked_loss=masked, room=masks is not None,
                                        refine_pose=name.endswith("_refined"), kept=kept)
            seconds = time.perf_counter() - t0
            if figure is not None and index == objects[0]:
                if panels is None:
                    panels = [[outlined(room[v], seg[v], whole[v])] for v in figure_views]
                for panel, v in zip(panels, figure_views, strict=True):
                    panel += [images[v], rendered(fitted, outcome.z, cap.frames[v])]
            X_fit = X if outcome.X_OP is None else X @ RigidTransform(outcome.X_OP)  # refined
            R, t = X_fit.rotation().matrix(), X_fit.translation()
            names = [n for n in truth.names if n in result.keypoints]
            predicted = np.stack([R @ result.keypoints[n] + t for n in names])
            true_now = np.stack([truth.point(n, truth.q_current) for n in names])
            X_OW = X.inverse()
            maps = detector.detect(images) if use_detector else None
            region = kept if kept is not None else masks  # as `infer` does
            sighted = None if maps is None else locate_handle(
                maps if region is None else inside_masks(maps, region), cap.frames)
            fit_cm, fit_deg = pose_error(X_WO, X_fit)
            row = {**common, "pose_cm": fit_cm, "pose_deg": fit_deg, "setting": name,
                   "q_true": scenario.q_start, "q": result.q,
                   "q_error": abs(result.q - scenario.q_start),
                   "keypoint_rmse_cm": 100 * float(np.sqrt(np.mean(np.sum((predicted - true_now) ** 2, -1)))),
                   "handle_cm": 100 * float(np.linalg.norm(predicted[names.index("handle")] - handle_W)),
                   **dict(zip(("handle_dx_cm", "handle_dy_cm", "handle_dz_cm"),
                              100 * X_WO.rotation().matrix().T
                              @ (predicted[names.index("handle")] - handle_W), strict=True)),
                   "sighting_cm": handle_error_cm(sighted, X_OW.multiply(handle_W)),
                   "sighting_views": 0 if sighted is None else len(sighted.views), "seconds": seconds}
            rows.append(row)
            print(f"{category} {index} {name:16s} q {result.q:.3f} (true {scenario.q_start:.2f}); keypoints "
                  f"{row['keypoint_rmse_cm']:.2f} cm, handle {row['handle_cm']:.2f} cm; detector's handle "
                  f"{row['sighting_cm']:.1f} cm ({row['sighting_views']} views); {seconds:.0f} s", flush=True)
        print(f"{category} {index}: pose {common['pose_cm']:.2f} cm {common['pose_deg']:.2f} deg (amodal "
              f"{common['amodal_pose']}); extent {common['extent']:.2f} of the image side; visible share "
              f"of the silhouette {common['visible_share']:.2f}; detector on the raw room photos "
              f"{fired_px} px, {100 * common['detector_off_object']:.0f} % off the object "
              f"({time.perf_counter() - started:.0f} s)", flush=True)
    print(f"{category}, objects {list(objects)} of seed {seed}, medians (handle within 2 cm: count; "
          "shut fitted open: q error above 0.1):")
    for name in settings:
        sub = [r for r in rows if r["setting"] == name]
        med = lambda key, sub=sub: median([r[key] for r in sub])  # noqa: E731
        print(f"  {name:16s} pose {med('pose_cm'):.2f} cm {med('pose_deg'):.2f} deg, keypoints "
              f"{med('keypoint_rmse_cm'):.2f} cm, handle {med('handle_cm'):.2f} cm, "
              f"q error {med('q_error'):.3f}, detector's handle {med('sighting_cm'):.1f} cm, "
              f"handle within 2 cm {sum(r['handle_cm'] <= 2 for r in sub)} / {len(sub)}, q error above 0.1 "
              f"{sum(r['q_error'] > 0.1 for r in sub)}, detector's handle within 2 cm "
              f"{sum(r['sighting_cm'] <= 2 for r in sub)} "
              f"(none {sum(math.isnan(r['sighting_cm']) for r in sub)})")
    if csv_path is not None:
        write_rows_csv(csv_path, rows)
    if panels is not None:
        figure.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(figure), image_grid(panels)[..., ::-1])
    print(f"{datetime.date.today()}, {os.cpu_count()}-core CPU, torch threads {torch.get_num_threads()}, "
          f"segmenter {segmenter}")


if __name__ == "__main__":
    tyro.cli(main)
