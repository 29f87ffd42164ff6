"""`nfr-drake infer`: fit a model to a capture set and forward-simulate the object's motion."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal, get_args

import cv2
import numpy as np
import torch
import tyro

from nfr_drake.cpu import set_torch_threads
from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import CaptureFrame, CaptureSet, read_capture_set
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.visualize import colorize_labels, image_grid, plot_handle_paths
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.inference.confidence import (
    CONFIDENCE_FILE,
    ROOM_CONFIDENCE_FILE,
    ConfidenceModel,
    code_scale,
    fit_features,
    part_features,
    refusal,
    render_views,
)
from nfr_drake.inference.fit import (
    FitConfig,
    FitOutcome,
    FocusTarget,
    PartSighting,
    fit_latent,
    observed_rays,
)
from nfr_drake.inference.forward import (
    geometric_keypoints,
    keypoint_trajectory,
    render_view,
    semantic_point_cloud,
)
from nfr_drake.inference.furniture_fit import (
    FurnitureFit,
    FurnitureFitConfig,
    fit_furniture,
    part_json,
    parts_json,
)
from nfr_drake.inference.pose_refine import in_refined_frame, refine_object_pose
from nfr_drake.inference.result import FitResult
from nfr_drake.nfr.checkpoint import load_model
from nfr_drake.nfr.model import NFRModel
from nfr_drake.objects import SemanticClass
from nfr_drake.paths import check_writable_file
from nfr_drake.perception.front_reading import SightedFront, read_front
from nfr_drake.perception.handle_detector.model import DETECTOR_DIR, HandleDetector, load_detector
from nfr_drake.perception.handle_triangulation import (
    MIN_VIEWS,
    TriangulatedHandle,
    inside_masks,
    locate_handle,
    locate_handles,
    project,
)
from nfr_drake.perception.object_pose import (
    HullConfig,
    background_mask,
    box_silhouette,
    estimate_object_pose_carcass_first,
)
from nfr_drake.perception.segmentation.refine import refine_masks as refined_by_colour

if TYPE_CHECKING:
    from nfr_drake.perception.segmentation.crop import RoomLooks


class FittedModel:
    """A loaded model folder: networks, the training codes (N, k) and their mean (the fit's
    start), its metadata, its 2D handle detector (`handle_detector/`) when it ships one, and its
    fit-confidence calibrations when it has them: `confidence.json` (the object alone) and
    `confidence_room.json` (photos of a room)."""

    def __init__(self, folder: Path, device: str = "cpu"):
        self.folder = Path(folder)
        self.model, self.codes, self.config = load_model(self.folder, device)
        self.z_obj_mean = self.codes.mean(0)
        self.category: str = self.config["category"]
        self.keypoint_names: tuple[str, ...] = tuple(self.config["keypoint_names"])
        self.handle_detector: HandleDetector | None = None
        if (self.folder / DETECTOR_DIR).is_dir() and ("handle" in self.keypoint_names
                                                      or self.num_slots > 1):
            self.handle_detector = load_detector(self.folder / DETECTOR_DIR)[0]
        self.confidence: ConfidenceModel | None = ConfidenceModel.read(self.folder)
        self.room_confidence: ConfidenceModel | None = ConfidenceModel.read(self.folder,
                                                                            ROOM_CONFIDENCE_FILE)
        self._code_scale: float | None = None

    @property
    def num_slots(self) -> int:
        """Articulation slots of the model: 1 for closets and drawers, one per part for furniture."""
        return self.model.config.num_slots

    @property
    def code_scale(self) -> float:
        """The training codes' spacing (`confidence.code_scale`), computed once."""
        if self._code_scale is None:
            self._code_scale = code_scale(self.codes)
        return self._code_scale

    @property
    def focus(self) -> FocusTarget | None:
        """The part the fit looks at closely: the handle, when the model has a handle keypoint."""
        if "handle" not in self.keypoint_names:
            return None
        return FocusTarget(self.keypoint_names.index("handle"), int(SemanticClass.HANDLE))

    def check_capture(self, capture: CaptureSet, category: str | None = None) -> None:
        """NfrDrakeError when the capture (its gt.json, or `category`) is of another category."""
        check_category(self.folder, self.category, category or (capture.gt or {}).get("category"),
                       str(capture.root), "capture")


def check_category(model_folder: Path, model_category: str, claimed: str | None, where: str,
                   thing: str) -> None:
    """NfrDrakeError "WHERE: a CLAIMED THING, but MODEL_FOLDER is a MODEL_CATEGORY model" when
    `claimed` (the category of what is perceived; None: unknown) is not the model's."""
    if claimed is not None and claimed != model_category:
        raise NfrDrakeError(f"{where}: a {claimed} {thing}, but {model_folder} is a "
                            f"{model_category} model; use a {claimed} model")


MASK_SIZE_PX = 256
"""Longer image side, pixels, at which the segmenter runs and the object's pose is estimated from
the masks: near the scale of the segmenter's training photos (96 px), and the visual hull of ten
1024 px masks took minutes."""


def shrunk(image: np.ndarray, size: int = MASK_SIZE_PX) -> np.ndarray:
    """`image` (H, W[, C]) scaled down (area interpolation) so that its longer side is at most `size`."""
    h, w = image.shape[:2]
    scale = size / max(h, w)
    if scale >= 1.0:
        return image
    return cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))),
                      interpolation=cv2.INTER_AREA)


RoomLoss = Literal["background", "masked"]
"""How the fit treats the pixels of a room photo off the object's mask: painted in the training
background, so that the field's silhouette must match the mask ("background"), or left out of the
image loss ("masked"; the field may then grow where the mask is not: an open door, a taller
carcass)."""


PAINT_THRESHOLD = 0.5
"""Object probability above which `paint_background` keeps a pixel of the photo (the segmenter's
decision threshold, at which its masks' IoU is measured) where the object can lie
(`paint_thresholds`). Keeping only the pixels it is sure of (`SURE_THRESHOLD`) there as well trims
the object's edges, which moves a door's hinge inwards: on seed 200 in rooms the closets' doors
ended short (docs/ROOMS.md, "Shut drawers fitted open")."""

SURE_THRESHOLD = 0.9
"""Object probability above which `paint_background` keeps a pixel off the region the object can
occupy (`paint_thresholds`): the segmenter's spill onto the floor and the neighbours beside an
object has p 0.56-0.98 (median 0.82), the object's own pixels a median of 0.95-0.995; kept, the
spill is fitted as a drawer pulled out (docs/ROOMS.md, "Shut drawers fitted open")."""

PAINT_MARGIN_M = 0.03
"""How far beyond the estimated carcass box and its fronts the object's pixels may lie, m, in
`paint_thresholds`: the pose's error (median 1.4-2.3 cm in rooms) and the masks' soft edges."""

OPEN_FRONT_SIDE_M = 0.08
"""How far an open front stands out beyond the carcass's sides and its own reach, m, in
`paint_thresholds`: a door opened 90 degrees lies beside its hinge side with its thickness and
its handle (up to 2.5 + 5.5 cm); a drawer's handle stands out past its front."""


def paint_background(images: list[np.ndarray], masks: list[np.ndarray],
                     background_rgb: tuple[float, float, float] = DEFAULT_BACKGROUND_RGB,
                     threshold: float | list[np.ndarray] = PAINT_THRESHOLD) -> list[np.ndarray]:
    """Each uint8 RGB image (H, W, 3) with the pixels off its object mask (H, W) in [0, 1] (at
    most `threshold`: one for all pixels, or one (H, W) map per image, `paint_thresholds`)
    painted in `background_rgb` (in [0, 1]) and those on it kept as they are, so that a photo of
    a room looks like the training renders of the object alone. Not a blend by the mask: an
    unsure mask's blend leaves floor and wall showing faintly through the background, which the
    field renders as more object (a drawer fitted open) and on which the handle detector fires
    (docs/ROOMS.md, "Why drawers fail in rooms")."""
    background = np.round(255.0 * np.asarray(background_rgb, np.float32)).astype(np.uint8)
    thresholds = threshold if isinstance(threshold, list) else [threshold] * len(images)
    return [np.where((m > t)[..., None], image, background).astype(np.uint8)
            for image, m, t in zip(images, masks, thresholds, strict=True)]


def paint_thresholds(X_WO: np.ndarray, size: np.ndarray, X_WCs: list[np.ndarray],
                     cameras: list[PinholeCamera], shapes: list[tuple[int, int]],
                     reach_m: float = 0.0, front_reach_m: float | None = None) -> list[np.ndarray]:
    """`paint_background`'s threshold (H, W) float32 per view (camera at X_WC (4, 4), image of
    shape (H, W)): `PAINT_THRESHOLD` where the object can lie, `SURE_THRESHOLD` elsewhere, so that
    the segmenter's unsure spill beside the object is painted and the object's own edges are kept.
    Where it can lie: the estimated carcass (X_WO (4, 4): O on the floor under the carcass's
    centre, +x out of the front; size (3,): depth, width, height, m) with its fronts
    (`HullConfig.front_thickness_m`), grown by `PAINT_MARGIN_M` on every side but the floor and by
    `reach_m` more along +x. With `front_reach_m` (how far open fronts reach out of the front, m),
    `SURE_THRESHOLD` holds only where they can lie (that far in front of it, `OPEN_FRONT_SIDE_M`
    wider on either side and further out) and nothing is kept beyond: a pixel whose ray passes
    neither box shows something else (a neighbour beside the object, the floor behind it)."""
    depth, width, height = np.asarray(size, float)
    front = depth / 2 + HullConfig.front_thickness_m
    yaw = np.arctan2(X_WO[1, 0], X_WO[0, 0])

    def floor_box(x0: float, x1: float, half_width: float, top: float) -> np.ndarray:
        centre_W = X_WO[:3, :3] @ np.array([(x0 + x1) / 2, 0.0, 0.0]) + X_WO[:3, 3]
        return np.array([centre_W[0], centre_W[1], yaw, x1 - x0, 2 * half_width, top])

    carcass = floor_box(-depth / 2 - PAINT_MARGIN_M, front + PAINT_MARGIN_M + reach_m,
                        width / 2 + PAINT_MARGIN_M, height + PAINT_MARGIN_M)
    fronts = None if front_reach_m is None else floor_box(
        -depth / 2 - PAINT_MARGIN_M, front + front_reach_m + OPEN_FRONT_SIDE_M,
        width / 2 + PAINT_MARGIN_M + OPEN_FRONT_SIDE_M, height + PAINT_MARGIN_M)
    thresholds = []
    for X_WC, camera, shape in zip(X_WCs, cameras, shapes, strict=True):
        elsewhere = SURE_THRESHOLD if fronts is None else np.where(
            box_silhouette(fronts, X_WC, camera, shape) > 0.5, SURE_THRESHOLD, 1.0)
        thresholds.append(np.where(box_silhouette(carcass, X_WC, camera, shape) > 0.5, PAINT_THRESHOLD,
                                   elsewhere).astype(np.float32))
    return thresholds


Painting = Literal["region", "fronts", "sure"]
"""How `paint_off_object` paints a room photo: "region", at the thresholds of the estimated
carcass's region (`paint_thresholds`); "fronts", those with nothing kept beyond where the open
fronts reach (the carcass's larger side: a door as wide as the carcass opened 90 degrees, a drawer
pulled out by most of its depth); "sure", at `SURE_THRESHOLD` everywhere."""

PAINTINGS: tuple[Painting, ...] = get_args(Painting)
"""Every painting: room perception fits each and keeps the most confident fit
(`systems.perception.NfrPerceptionSystem`; docs/ROOMS.md, "Several paintings")."""


def checked_paintings(paintings) -> tuple[Painting, ...]:
    """`paintings` as a tuple without repeats; ConfigError unless one or more of `PAINTINGS`."""
    paintings = tuple(paintings)
    if not paintings or any(p not in PAINTINGS for p in paintings):
        raise ConfigError(f"paintings must be one or more of {', '.join(PAINTINGS)}, got {list(paintings)}")
    return tuple(dict.fromkeys(paintings))


def painting_thresholds(painting: Painting, X_WCs: list[np.ndarray], cameras: list[PinholeCamera],
                        shapes: list[tuple[int, int]], X_WO: np.ndarray, size: np.ndarray | None
                        ) -> list[float | np.ndarray]:
    """`paint_background`'s threshold per view (one float, or an (H, W) map of `paint_thresholds`)
    for `painting` (X_WO (4, 4), size (3,) m: the estimated carcass; for a pose given without a
    size (None), "region" and "fronts" paint at `PAINT_THRESHOLD` everywhere)."""
    if painting == "sure":
        return [SURE_THRESHOLD] * len(shapes)
    if size is None:
        return [PAINT_THRESHOLD] * len(shapes)
    reach = float(max(size[0], size[1])) if painting == "fronts" else None
    return paint_thresholds(X_WO, size, X_WCs, cameras, shapes, front_reach_m=reach)


def paint_off_object(images: list[np.ndarray], masks: list[np.ndarray], X_WCs: list[np.ndarray],
                     cameras: list[PinholeCamera], X_WO: np.ndarray, size: np.ndarray | None,
                     background_rgb: tuple[float, float, float] = DEFAULT_BACKGROUND_RGB,
                     painting: Painting = "region") -> tuple[list[np.ndarray], list[np.ndarray]]:
    """`paint_background` as `painting` says (`painting_thresholds`): the painted uint8 RGB images
    and the pixels each keeps from its photo ((H, W) bool per image)."""
    shapes = [image.shape[:2] for image in images]
    thresholds = painting_thresholds(painting, X_WCs, cameras, shapes, X_WO, size)
    kept = [m > t for m, t in zip(masks, thresholds, strict=True)]
    return paint_background(images, masks, background_rgb, thresholds), kept


def refined_object_pose(X_WO_estimated: np.ndarray, result: FitResult,
                        outcome: FitOutcome) -> tuple[np.ndarray, dict]:
    """X_WO (4, 4) after the fit's pose refinement (the estimate moved by the kept refinement's
    X_OP, `FitConfig.refine_pose`; the estimate itself when none was kept) and the entries of
    `extra["object_pose"]` that say so: X_WO, X_WO_estimated and the refinement's report (taken
    out of `result.extra["pose_refinement"]`; None when the fit did not refine)."""
    X_WO = X_WO_estimated if outcome.X_OP is None else X_WO_estimated @ outcome.X_OP
    return X_WO, {"X_WO": X_WO.tolist(), "X_WO_estimated": X_WO_estimated.tolist(),
                  "refinement": result.extra.pop("pose_refinement", None)}


MIN_FIT_VIEWS = 3
"""Fewer views than this leave q and the object's shape poorly constrained: the fit warns."""

KeypointSource = Literal["head", "geometry"]
"""Where keypoints come from: the keypoint head Gamma(z) (the paper), or the fitted field's
rendered geometry where it shows them (`forward.geometric_keypoints`)."""


def infer(fitted: FittedModel, capture: CaptureSet, fit_config: FitConfig, q_grid: np.ndarray,
          images: list[np.ndarray] | None = None, keypoint_source: KeypointSource = "head",
          masks: list[np.ndarray] | None = None, masked_loss: bool = True, room: bool = True,
          refine_pose: bool = False, kept: list[np.ndarray] | None = None) -> tuple[FitResult, FitOutcome]:
    """Fit z to the capture and forward-simulate keypoints over q_grid (N,).

    `images` (uint8 RGB per frame) replaces reading the capture's image files (Drake cameras).
    `masks` ((H, W) object probability per frame): with `masked_loss`, only pixels on the object
    count in the image loss (`observed_rays`); with `room` (photos of a room, the segmenter's
    masks) they are the fit confidence's observed silhouette (`confidence.fit_features`), else
    that is the pixels off the image border's colour (an object alone), and the handle detector
    counts only well inside them (`inside_masks`), or inside `kept` when given ((H, W) bool per
    frame: the pixels a painted photo keeps, `paint_off_object`).
    `refine_pose` (the capture's O an estimate, `FitConfig.refine_pose`): the fit is followed by
    the pose refinement (`pose_refine`); kept, the result's positions, the fitted code and the
    confidence are in its frame P, `outcome.X_OP` is P in O; `extra["pose_refinement"]` says what
    it did.
    The result's `extra["warnings"]` lists what makes it doubtful (too few views); its
    `confidence` holds the fit's confidence features and, when the model folder has a calibration,
    P(handle within 2 cm) (`fit_confidence`).
    """
    started = time.perf_counter()
    warnings = []
    if len(capture.frames) < MIN_FIT_VIEWS:
        warnings.append(f"{capture.root}: only {len(capture.frames)} view(s); q and the keypoints "
                        f"are poorly constrained below {MIN_FIT_VIEWS} views")
    images = capture.load_images() if images is None else images
    rays = observed_rays(capture, images, masks=masks if masked_loss else None)
    handle = None
    if fitted.handle_detector is not None and fit_config.uses_sightings:
        maps = fitted.handle_detector.detect(images)
        region = kept if kept is not None else masks if room else None
        handle = locate_handle(maps if region is None else inside_masks(maps, region), capture.frames)
    sighting = None if handle is None else PartSighting(
        fitted.keypoint_names.index("handle"), torch.as_tensor(handle.p_O, dtype=rays.rgb.dtype))
    outcome = fit_latent(fitted.model, rays, fit_config, fitted.z_obj_mean, fitted.focus, sighting,
                         fitted.codes)
    refinement = None
    if refine_pose and fit_config.refine_pose and fit_config.pose_steps > 0:
        refinement = refine_object_pose(fitted.model, outcome.z, rays, fit_config, sighting)
        capture, outcome = in_refined_frame(refinement, capture, outcome)
        if handle is not None and refinement.kept:
            handle = replace(handle, p_O=np.linalg.inv(refinement.X_OP)[:3] @ np.append(handle.p_O, 1.0))
    confidence = fit_confidence(fitted, outcome, capture, images, handle,
                                masks if room else None)
    names = fitted.keypoint_names
    if keypoint_source == "geometry":
        views = [(f.camera, f.X_OC) for f in capture.frames]
        now, trajectory = geometric_keypoints(fitted.model, outcome.z, outcome.q, q_grid, names,
                                              views)
    else:
        now = keypoint_trajectory(fitted.model, outcome.z, np.array([outcome.q]))[0]
        trajectory = keypoint_trajectory(fitted.model, outcome.z, q_grid)
    result = FitResult(
        category=fitted.category, q=outcome.q,
        keypoints={n: now[i] for i, n in enumerate(names)},
        trajectory_q=np.asarray(q_grid, float),
        trajectory={n: trajectory[:, i] for i, n in enumerate(names)},
        image_loss=outcome.image_loss, seconds=time.perf_counter() - started,
        z=outcome.z.double().cpu().numpy(), confidence=confidence,
        extra={"model": str(fitted.folder), "steps": outcome.steps, "focus": outcome.focus,
               "handle_sighting": _sighting_json(fitted, fit_config, handle),
               "sighted_start": outcome.sighted_start,
               "keypoint_source": keypoint_source,
               "start_q": outcome.start_q.tolist(), "start_losses": outcome.start_losses.tolist(),
               "warnings": warnings})
    if refinement is not None:
        result.extra["pose_refinement"] = refinement.to_json()
    return result, outcome


def infer_painted(fitted: FittedModel, capture: CaptureSet, fit_config: FitConfig, q_grid: np.ndarray,
                  images: list[np.ndarray], masks: list[np.ndarray], X_WCs: list[np.ndarray],
                  X_WO: np.ndarray, size: np.ndarray | None, paintings: tuple[Painting, ...] = PAINTINGS,
                  keypoint_source: KeypointSource = "head", room: bool = True, refine_pose: bool = False,
                  background_rgb: tuple[float, float, float] = DEFAULT_BACKGROUND_RGB,
                  refine_masks: bool = False) -> tuple[FitResult, FitOutcome]:
    """`infer` (`capture` in the object's frame O) on the photos `images` painted off the object's
    `masks` each way `paintings` says (`paint_off_object`: the cameras X_WCs (4, 4) and the
    estimated carcass X_WO (4, 4), `size` (3,) m or None, in one frame W; without a size "fronts"
    paints as "region"), the fit with the highest P(handle within 2 cm) kept (the first where
    none has a P); with more than one
    painting the result's `extra["paintings"]` says which was kept and each one's P (docs/ROOMS.md,
    "Several paintings"). `refine_masks`: the masks' pixels the photo's colours call background
    removed first (`perception.segmentation.refine`; docs/ROOMS.md, "Mask edges by the photo's
    colours")."""
    cameras = [frame.camera for frame in capture.frames]
    masks = refined_by_colour(images, masks) if refine_masks else masks
    fits = {}
    for name in checked_paintings("region" if size is None and p == "fronts" else p
                                  for p in checked_paintings(paintings)):
        painted, kept = paint_off_object(images, masks, X_WCs, cameras, X_WO, size, background_rgb, name)
        fits[name] = infer(fitted, capture, fit_config, q_grid, painted, keypoint_source, masks=masks,
                           masked_loss=False, room=room, refine_pose=refine_pose, kept=kept)

    def p_of(result: FitResult) -> float:
        p = (result.confidence or {}).get("p_handle_within_2cm")
        return -1.0 if p is None else float(p)

    chosen = max(fits, key=lambda name: p_of(fits[name][0]))
    result, outcome = fits[chosen]
    if len(fits) > 1:
        result.extra["paintings"] = {"chosen": chosen,
                                     "p_handle_within_2cm": {name: p_of(r) for name, (r, _) in fits.items()}}
    return result, outcome


def infer_in_world(fitted: FittedModel, capture: CaptureSet, fit_config: FitConfig,
                   q_grid: np.ndarray, masks: list[np.ndarray], room_loss: RoomLoss = "background",
                   keypoint_source: KeypointSource = "head", room: bool = True,
                   carcass: list[np.ndarray] | None = None, paintings: tuple[Painting, ...] = ("region",),
                   refine_masks: bool = False) -> tuple[FitResult, FitOutcome, CaptureSet]:
    """`infer` for a capture whose poses are in a floor frame W (z up, the floor at z = 0): the
    object's pose X_WO is estimated from the views' object `masks` (`estimate_object_pose`), or
    from the carcass's amodal masks `carcass` when given (`carcass_masks`: the box is the carcass;
    when they give no pose, from `masks`, with a warning), the
    fit runs in that O (the pixels off the masks painted in the training background as each of
    `paintings` says, the most confident fit kept, `infer_painted`, or left out of the image loss,
    `room_loss`; `room`: the masks are a room segmenter's, the confidence's
    silhouette, see `infer`; with `refine_masks` the masks' edges by the photos' colours,
    `infer_painted`; the pose then refined with the fitted field, `FitConfig.refine_pose`),
    and the result's positions are moved into W (`extra["object_pose"]`: X_WO, the estimate before
    the refinement X_WO_estimated, the refinement's report or None, the carcass size; a size outside
    the model's category joins `extra["warnings"]`). Returns the result, the fit and the capture
    with its poses in O (for reports). ObjectPoseError when the masks give no object."""
    images = capture.load_images()
    estimate, amodal, warnings = estimate_object_pose_carcass_first(
        [shrunk(m) for m in masks], None if carcass is None else [shrunk(m) for m in carcass],
        [f.X_OC for f in capture.frames], [f.camera for f in capture.frames], category=fitted.category)

    def in_frame(X_WO: np.ndarray) -> CaptureSet:
        """The capture with its poses in the object frame at X_WO."""
        X_OW = np.linalg.inv(X_WO)
        return CaptureSet(capture.root, [replace(f, X_OC=X_OW @ f.X_OC) for f in capture.frames],
                          capture.gt, capture.extra)

    in_O = in_frame(estimate.X_WO)
    if room_loss == "background":
        result, outcome = infer_painted(fitted, in_O, fit_config, q_grid, images, masks,
                                        [f.X_OC for f in capture.frames], estimate.X_WO, estimate.size,
                                        paintings, keypoint_source, room, refine_pose=True,
                                        refine_masks=refine_masks)
    else:
        result, outcome = infer(fitted, in_O, fit_config, q_grid, images, keypoint_source, masks,
                                masked_loss=True, room=room, refine_pose=True)
    X_WO, pose = refined_object_pose(estimate.X_WO, result, outcome)
    if outcome.X_OP is not None:  # the fit ended in the refined frame
        in_O = in_frame(X_WO)
    R, t = X_WO[:3, :3], X_WO[:3, 3]
    result.keypoints = {n: R @ p + t for n, p in result.keypoints.items()}
    result.trajectory = {n: p @ R.T + t for n, p in result.trajectory.items()}
    result.extra["object_pose"] = {**pose, "size": estimate.size.tolist(), "room_loss": room_loss,
                                   "amodal": amodal}
    problem = estimate.size_problem(fitted.category)
    result.extra["warnings"] += warnings + ([problem] if problem else [])
    return result, outcome, in_O


def infer_parts(fitted: FittedModel, capture: CaptureSet, config: FurnitureFitConfig,
                q_grid: np.ndarray, images: list[np.ndarray] | None = None, part: int | None = None,
                masks: list[np.ndarray] | None = None, kept: list[np.ndarray] | None = None
                ) -> tuple[FitResult, FurnitureFit, list[dict]]:
    """`infer` for a model with several parts (furniture): the furniture fit (`fit_furniture`, with
    the handles the model's detector sights, `sighted_handles`, reported in `extra["handles"]`);
    the result lists the parts the field finds (`parts`, each swept over q_grid (N,) with the
    others held, each with its `confidence`, `parts_confidence`) and its single-part fields and
    `confidence` are those of `part` (default: the first part found, slot 0 when none is; a part
    the field does not find adds a warning); then the fit, and every slot's confidence (S,), the
    slots the field does not find included. `images`, `masks` and `kept` as in `infer` (the
    handle detector counts only well inside `kept`, else inside `masks` when given). NfrDrakeError
    for a part outside the model's slots."""
    started = time.perf_counter()
    if part is not None and not 0 <= part < fitted.num_slots:
        raise NfrDrakeError(f"part {part} is out of range: {fitted.folder} has {fitted.num_slots} part "
                            f"slots, 0 to {fitted.num_slots - 1}")
    warnings = []
    if len(capture.frames) < MIN_FIT_VIEWS:
        warnings.append(f"{capture.root}: only {len(capture.frames)} view(s); q and the keypoints "
                        f"are poorly constrained below {MIN_FIT_VIEWS} views")
    images = capture.load_images() if images is None else images
    handles = sighted_handles(fitted, capture, images, config, kept if kept is not None else masks)
    fronts = sighted_fronts(fitted, capture, images, handles)
    fit = fit_furniture(fitted.model, observed_rays(capture, images, masks=masks), fitted.codes, config,
                        None if handles is None else np.array([h.p_O for h in handles]).reshape(-1, 3),
                        fronts)
    found = [int(k) for k in np.flatnonzero(fit.exists)]
    chosen = part if part is not None else (found[0] if found else 0)
    if chosen not in found:
        warnings.append(f"the field finds no part {chosen} (parts found: {found or 'none'}); its "
                        "keypoints are the slot's all the same")
    confidence, per_view = parts_confidence(fitted, fit, capture, images, handles)
    parts = parts_json(fitted.model, fit, q_grid)
    for p in parts:
        p["confidence"] = confidence[p["index"]]
    result = FitResult(
        category=fitted.category, q=0.0, keypoints={}, trajectory_q=np.asarray(q_grid, float),
        trajectory={}, image_loss=fit.image_loss, seconds=0.0, z=fit.z.double().cpu().numpy(),
        confidence={"per_view": per_view}, parts=parts,
        extra={"model": str(fitted.folder), "steps": fit.steps, "warnings": warnings,
               "handles": _handles_json(fitted, config, handles, fronts)})
    chosen_part = next((p for p in parts if p["index"] == chosen), None)
    result = result.with_part(chosen_part or {**part_json(fitted.model, fit, chosen, q_grid),
                                              "confidence": confidence[chosen]})
    result.seconds = time.perf_counter() - started
    return result, fit, confidence


def sighted_handles(fitted: FittedModel, capture: CaptureSet, images: list[np.ndarray],
                    config: FurnitureFitConfig, region: list[np.ndarray] | None = None
                    ) -> list[TriangulatedHandle] | None:
    """The handles of a piece of furniture triangulated from the model's handle detector in the
    capture's views (`locate_handles`), counted only well inside `region` ((H, W) per view, the
    object's pixels of a room photo, `inside_masks`) when given; None when the model ships no
    detector or the fit is told not to use it (`FurnitureFitConfig.handle_detector`)."""
    if fitted.handle_detector is None or not config.handle_detector:
        return None
    maps = fitted.handle_detector.detect(images)
    return locate_handles(maps if region is None else inside_masks(maps, region), capture.frames)


def sighted_fronts(fitted: FittedModel, capture: CaptureSet, images: list[np.ndarray],
                   handles: list[TriangulatedHandle] | None) -> list[SightedFront | None] | None:
    """What the model's detector reads of the front behind each sighted handle (`read_front`;
    None where it reads nothing); None without handles or for a detector without front outputs."""
    if handles is None or not fitted.handle_detector.config.fronts:
        return None
    maps = fitted.handle_detector.read_fronts(images)
    return [read_front(h, maps, capture.frames) for h in handles]


def _handles_json(fitted: FittedModel, config: FurnitureFitConfig,
                  handles: list[TriangulatedHandle] | None,
                  fronts: list[SightedFront | None] | None = None) -> dict:
    """What the handle detector gave a furniture fit (the handles: p_O, the views agreeing on
    each and their reprojection RMS, px of the photos, how many views saw a handle; and what it
    read of their fronts: door probability, face corners in O), for the result's `extra`."""
    if handles is None:
        return {"used": False, "why": ("the model ships no handle detector"
                                       if fitted.handle_detector is None else "turned off")}
    out = {"used": bool(handles), "count": len(handles), "p_O": [h.p_O.tolist() for h in handles],
           "views": [list(h.views) for h in handles],
           "rms_px": [h.rms_px for h in handles], "sightings": [h.sightings for h in handles]}
    if fronts is not None:
        out["fronts"] = [None if f is None else {"door_probability": f.door_probability,
                                                 "face_corners": f.corners.tolist()} for f in fronts]
    return out


def _at_photo_size(masks: list[np.ndarray], images: list[np.ndarray]) -> list[np.ndarray]:
    """Masks made on shrunk photos (`shrunk`), scaled back to their photos' sizes (H, W)."""
    return [cv2.resize(m, image.shape[1::-1], interpolation=cv2.INTER_LINEAR)
            for m, image in zip(masks, images, strict=True)]


def object_masks(images: list[np.ndarray], segmenter: Path | None) -> list[np.ndarray]:
    """Object probability (H, W) per uint8 RGB image (H, W, 3): the segmenter's in `segmenter` (a
    model folder; run on the image shrunk to `MASK_SIZE_PX` and scaled back up), or, with None, the
    pixels off the image border's median colour (an object alone before a uniform background)."""
    if segmenter is None:
        return [background_mask(image) for image in images]
    from nfr_drake.perception.segmentation.model import load_segmenter

    net, _ = load_segmenter(segmenter)
    return _at_photo_size([net.object_mask(shrunk(image)) for image in images], images)


def carcass_masks(images: list[np.ndarray], segmenter: Path) -> list[np.ndarray] | None:
    """The segmenter's amodal carcass probability (H, W) per uint8 RGB image (H, W, 3): the
    carcass as if nothing hid it (`Segmenter.carcass_amodal`, run as in `object_masks`); None
    for a model without that output (trained before it existed)."""
    from nfr_drake.perception.segmentation.model import load_segmenter

    net, _ = load_segmenter(segmenter)
    if not net.config.amodal:
        return None
    return _at_photo_size([net.carcass_amodal(shrunk(image)) for image in images], images)


def cropped_masks(images: list[np.ndarray], capture: CaptureSet, segmenter: Path, category: str,
                  after: RoomLooks | None = None
                  ) -> tuple[list[np.ndarray], list[np.ndarray] | None, RoomLooks] | None:
    """The segmenter's object masks and amodal carcass masks (H, W) per uint8 RGB photo (H, W, 3)
    of a capture whose poses are in a floor frame, as `eval-pipeline --mask-crop` looks
    (`segmentation.crop.room_looks`: the crop stage over whole photos, or the aimed look where
    their pose is not of the piece the cameras aim at), run on the photos shrunk to `MASK_SIZE_PX`
    and scaled back up, and the look itself (on the shrunk photos); the carcass None for a model
    without that output. With `after` (the look an earlier call returned), the look that did not
    give it instead (`other_look`), None where that gives no pose. ObjectPoseError when no look
    gives a pose."""
    from nfr_drake.perception.segmentation.crop import other_look, room_looks
    from nfr_drake.perception.segmentation.model import load_segmenter

    net, _ = load_segmenter(segmenter)
    small = [shrunk(image) for image in images]
    X_WCs, cameras = [f.X_OC for f in capture.frames], [f.camera for f in capture.frames]
    looks = (room_looks(net, small, X_WCs, cameras, category) if after is None
             else other_look(net, small, X_WCs, cameras, category, after))
    if looks is None:
        return None
    return (_at_photo_size(looks.masks, images),
            None if looks.carcass is None else _at_photo_size(looks.carcass, images), looks)


def more_confident_look(first: FitResult, other: FitResult, aimed: tuple[bool, bool]) -> FitResult:
    """Of a fit its confidence refused at the first look and the fit at the other look
    (`segmentation.crop.other_look`; `aimed`: whether each look was the aimed one), the one with
    the higher P(handle within 2 cm); its `extra["object_pose"]["looked_again"]` says which was
    kept and both P, and a warning names the other look when that is kept."""
    p = [r.confidence["p_handle_within_2cm"] for r in (first, other)]
    kept = "other" if p[1] > p[0] else "first"
    result = other if kept == "other" else first
    if kept == "other":
        result.extra["warnings"].append(
            f"the fit at the first look's pose was not confident (P {p[0]:.2f} below "
            f"{first.confidence['threshold']:.2f}); the {'aimed' if aimed[1] else 'whole-photo'} look's "
            f"fit is kept (P {p[1]:.2f})")
    result.extra["object_pose"]["looked_again"] = {"kept": kept, "p_handle_within_2cm": p,
                                                   "aimed": list(aimed)}
    return result


def fit_confidence(fitted: FittedModel, outcome: FitOutcome, capture: CaptureSet,
                   images: list[np.ndarray], handle: TriangulatedHandle | None,
                   room_masks: list[np.ndarray] | None = None) -> dict | None:
    """The result's `confidence`: {p_handle_within_2cm, threshold and weakest (the feature that
    lowers p most; all three None without a calibration), calibration, features, per_view}
    (docs/CONVENTIONS.md); None for a model without a handle keypoint. `room_masks`: the object's
    probability per view in photos of a room (`confidence.fit_features`); p is then the room
    calibration's (`FittedModel.room_confidence`), or the object-alone one's when the model
    folder has none."""
    if "handle" not in fitted.keypoint_names:
        return None
    features, per_view = fit_features(
        fitted.model, outcome.z, capture.frames, images, outcome.start_losses, fitted.codes,
        fitted.code_scale, fitted.keypoint_names.index("handle"),
        None if handle is None else handle.p_O, room_masks)
    if room_masks is not None and fitted.room_confidence is not None:
        return calibrated(fitted.room_confidence, features, per_view, ROOM_CONFIDENCE_FILE)
    return calibrated(fitted.confidence, features, per_view)


def calibrated(calibration: ConfidenceModel | None, features: dict, per_view: list[dict],
               name: str = CONFIDENCE_FILE) -> dict:
    """A result's `confidence` of a fit's features: {p_handle_within_2cm, threshold, weakest,
    calibration (the file `name` of the model folder that calibrated it; all four None without a
    calibration), features, per_view}."""
    return {"p_handle_within_2cm": None if calibration is None else calibration.probability(features),
            "threshold": None if calibration is None else calibration.threshold,
            "weakest": None if calibration is None else calibration.weakest(features),
            "calibration": None if calibration is None else name,
            "features": features, "per_view": per_view}


def parts_confidence(fitted: FittedModel, fit: FurnitureFit, capture: CaptureSet,
                     images: list[np.ndarray], sighted: list[TriangulatedHandle] | None
                     ) -> tuple[list[dict], list[dict]]:
    """Per slot of a model with several parts (furniture), the `confidence` of its part
    ({p_handle_within_2cm, threshold, weakest, features}, `calibrated`): P(the part's handle
    within 2 cm) from the fit's features (`fit_features`) and the part's
    (`confidence.part_features`, with the handles the detector sighted, `sighted` as
    `sighted_handles` gave them to the fit: `fit.handle_order` pairs them with the slots); and the
    per-view figures, shared by the parts."""
    in_fit_order = [sighted[i] for i in fit.handle_order] if sighted else []
    features, per_view = slot_features(fitted, fit.z, fit.start_z, fit.start_losses, capture.frames,
                                       images, in_fit_order, range(fitted.num_slots))
    parts = [calibrated(fitted.confidence, f, []) for f in features]
    return [{k: v for k, v in c.items() if k != "per_view"} for c in parts], per_view


def slot_features(fitted: FittedModel, z: torch.Tensor, start_z: torch.Tensor, start_losses: np.ndarray,
                  frames: list[CaptureFrame], images: list[np.ndarray],
                  sighted: list[TriangulatedHandle], slots: Iterable[int]) -> tuple[list[dict], list[dict]]:
    """The confidence features of each slot in `slots` of a furniture fit (code z, its starts'
    final codes start_z and losses start_losses): the fit's (`fit_features`) and the slot's
    (`part_features`, `sighted` the sighted handles in the fit's order, `FurnitureFit.handle_order`);
    and the per-view figures, shared by the slots."""
    views = render_views(fitted.model, z, frames, images)
    features, per_view = fit_features(fitted.model, z, frames, images, start_losses, fitted.codes,
                                      fitted.code_scale, 0, None, views=views)
    return [{**features, **part_features(fitted.model, z, start_z, k, frames, views, sighted)}
            for k in slots], per_view


def _sighting_json(fitted: FittedModel, config: FitConfig, handle: TriangulatedHandle | None
                   ) -> dict:
    """What the handle detector contributed, for the result's `extra`."""
    if fitted.handle_detector is None:
        return {"used": False, "why": "the model ships no handle detector"}
    if not config.uses_sightings:
        return {"used": False, "why": "turned off"}
    if handle is None:
        return {"used": False, "why": f"fewer than {MIN_VIEWS} views agree on a handle"}
    return {"used": True, "p_O": handle.p_O.tolist(), "views": list(handle.views),
            "sightings": handle.sightings, "rms_px": handle.rms_px}


def confidence_line(confidence: dict) -> str:
    """One line on a result's `confidence`: P(handle within 2 cm) against the threshold and the
    calibration file that gave them, the image loss and the silhouette agreement (worst view)."""
    f = confidence["features"]
    p = confidence["p_handle_within_2cm"]
    head = ("confidence: no calibration (confidence.json) in the model folder" if p is None else
            f"confidence: P(handle within 2 cm) = {p:.2f} (refused below {confidence['threshold']:.2f}; "
            f"{confidence.get('calibration') or CONFIDENCE_FILE})")
    return (f"{head}; image loss {f['image_loss']:.4f} (worst view {f['image_loss_worst_view']:.4f}), "
            f"silhouette IoU {f['silhouette_iou']:.2f} (worst {f['silhouette_iou_worst_view']:.2f})")


def observed_vs_rendered(model: NFRModel, z: torch.Tensor, q: float | None, capture: CaptureSet,
                         max_views: int = 10, detector: HandleDetector | None = None,
                         sighted_p_O: np.ndarray | None = None,
                         handle_p_O: np.ndarray | None = None) -> np.ndarray:
    """uint8 RGB figure: observed views (top row), renders of the fit at q (None: z as fitted,
    `render_view`; second), segmentation (third) and, with a `detector`, its handle probability
    over the photo (bottom row) with the triangulated handles `sighted_p_O` (green crosses) and
    the fitted ones `handle_p_O` (magenta squares), (3,) or (M, 3) in O."""
    images = capture.load_images()[:max_views]
    frames = capture.frames[:max_views]
    rows = [[], [], [], []]
    probs = ([m.probability for m in detector.detect(images)] if detector is not None
             else [None] * len(images))
    for frame, image, prob in zip(frames, images, probs, strict=True):
        view = render_view(model, z, q, frame.camera, frame.X_OC)
        size = (view.rgb.shape[1], view.rgb.shape[0])
        rows[0].append(cv2.resize(image, size, interpolation=cv2.INTER_AREA))
        rows[1].append(view.rgb)
        rows[2].append(colorize_labels(view.labels))
        if prob is not None:
            rows[3].append(_detector_view(image, prob, frame, size, sighted_p_O, handle_p_O))
    return image_grid([r for r in rows if r])


def _detector_view(image: np.ndarray, prob: np.ndarray, frame: CaptureFrame, size: tuple[int, int],
                   sighted_p_O: np.ndarray | None, handle_p_O: np.ndarray | None) -> np.ndarray:
    """The photo greyed, the handle probability in red, and the handle points marked ((3,) or
    (M, 3) each)."""
    grey = np.repeat(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)[..., None], 3, -1) * 0.6
    overlay = (grey + prob[..., None] * np.array([255.0, -150.0, -150.0])).clip(0, 255)
    overlay = np.ascontiguousarray(overlay.astype(np.uint8))
    for points, colour, marker in ((sighted_p_O, (0, 255, 0), cv2.MARKER_CROSS),
                                   (handle_p_O, (255, 0, 255), cv2.MARKER_SQUARE)):
        for point in [] if points is None else np.asarray(points, float).reshape(-1, 3):
            uv = project(frame, point)
            if uv is not None:
                centre = (int(round(uv[0] - 0.5)), int(round(uv[1] - 0.5)))
                cv2.drawMarker(overlay, centre, colour, marker, markerSize=7, thickness=1)
    return cv2.resize(overlay, size, interpolation=cv2.INTER_NEAREST)


def write_report(path: Path, fitted: FittedModel, capture: CaptureSet, result: FitResult,
                 z: torch.Tensor, q: float | None, with_detector: bool = True) -> np.ndarray:
    """Write `observed_vs_rendered` of the fit (its code z at q; None: z as fitted, every part
    slot at its own articulation), pixels doubled, as a PNG at `path`; the detector's row when
    `with_detector` and the model ships one, with the sighted handles and the fitted ones (every
    part's for a piece of furniture). `capture` has its poses in O (a result in W,
    `infer_in_world`, is moved back). Returns the written uint8 RGB image."""
    if result.parts is not None:
        handle = np.array([p["keypoints"]["handle"] for p in result.parts]).reshape(-1, 3)
        sighted = result.extra["handles"].get("p_O")
    else:
        handle, sighted = result.keypoints.get("handle"), result.extra["handle_sighting"].get("p_O")
    if handle is not None and "object_pose" in result.extra:  # the result is in W, the capture in O
        X_OW = np.linalg.inv(np.array(result.extra["object_pose"]["X_WO"]))
        handle = X_OW[:3, :3] @ handle + X_OW[:3, 3]
    figure = observed_vs_rendered(
        fitted.model, z, q, capture, detector=fitted.handle_detector if with_detector else None,
        sighted_p_O=sighted, handle_p_O=handle)
    figure = np.repeat(np.repeat(figure, 2, 0), 2, 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
    return figure


def write_point_cloud(path: Path, fitted: FittedModel, capture: CaptureSet, z: torch.Tensor,
                      q: float | None) -> int:
    """Write the fitted object's semantically labelled points, its code z at articulation q (None:
    z as fitted, every part slot at its own articulation), seen from the capture's cameras, as a
    PLY at `path`. Returns the number of points."""
    from nfr_drake.perception.pointcloud import write_semantic_ply

    views = [(f.camera, f.X_OC) for f in capture.frames]
    points, classes = semantic_point_cloud(fitted.model, z, q, views)
    write_semantic_ply(path, points, classes)
    return len(points)


def handle_path_on(q: np.ndarray, result: FitResult) -> np.ndarray:
    """The result's handle path (N, 3) in O, m, linearly interpolated at the articulations q (N,)."""
    return np.array([np.interp(q, result.trajectory_q, result.trajectory["handle"][:, j])
                     for j in range(3)]).T


def write_handle_plot(path: Path, capture: CaptureSet, result: FitResult) -> None:
    """Plot the result's handle path against the capture's true one (its gt.json) as a PNG at `path`."""
    grid = np.asarray(capture.gt["trajectory"]["q"])
    plot_handle_paths(grid, np.asarray(capture.gt["trajectory"]["keypoints"]["handle"]),
                      {"neural field": handle_path_on(grid, result)}, path,
                      f"{capture.root.name}: true q = {capture.gt['q']:.2f}, fitted q = {result.q:.2f}")


def _write_result(result: FitResult, out: Path, headline: str) -> None:
    """Write the result to `out`; print `headline`, its confidence and warnings."""
    out.parent.mkdir(parents=True, exist_ok=True)
    result.write(out)
    print(headline)
    if result.confidence is not None:
        print(confidence_line(result.confidence))
    for warning in result.extra["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)


def infer_command(
    capture: Annotated[Path, tyro.conf.Positional],
    model: Path = Path("models/closet"),
    out: Path = Path("result.json"),
    report: Path | None = None,
    point_cloud: Path | None = None,
    handle_plot: Path | None = None,
    category: str | None = None,
    fit: FitConfig = FitConfig(),
    trajectory_points: int = 21,
    keypoints: KeypointSource = "head",
    estimate_pose: bool = False,
    masks: Literal["segmenter", "background"] = "segmenter",
    segmenter: Path = Path("models/segmenter"),
    mask_crop: bool = False,
    look_again: bool = True,
    room_loss: RoomLoss = "background",
    paintings: tuple[Painting, ...] = ("region",),
    refine_masks: bool = False,
    part: int | None = None,
    furniture_fit: FurnitureFitConfig = FurnitureFitConfig(),
    threads: int | None = None,
) -> None:
    """Fit MODEL to the capture set CAPTURE and write the fit result (docs/CONVENTIONS.md).

    Args:
        capture: capture-set folder (transforms.json + images).
        model: model folder (model.safetensors + config.json).
        out: result JSON to write.
        report: optional PNG: observed views, renders of the fit, its segmentation and, with a
            handle detector, its handle probability with the triangulated and fitted handle.
        point_cloud: optional PLY: semantically labelled points of the object at the fitted q (a
            piece of furniture: every part at its fitted state).
        handle_plot: optional PNG: predicted handle path over q against gt.json's (needs gt.json).
        category: the capture's category, checked against the model's (gt.json's when omitted).
        fit: options of the fit.
        trajectory_points: points of the forward-simulated q grid over [0, 1].
        keypoints: "head" (the keypoint head, as in the paper) or "geometry" (handle and hinge
            axis read from the fitted field's rendered segmentation, the head for the rest).
        estimate_pose: the capture's poses are in a floor frame W (z up, the floor at z = 0: `poses`
            with a board lying on the floor, a room capture): the object's pose is estimated from
            its masks, the fit runs in that frame and the result's positions are in W.
        masks: with --estimate-pose, the object's masks: "segmenter" (`--segmenter`, a photo of
            a room; they are also the fit confidence's observed silhouette; the pose comes from
            its amodal carcass output when it has one) or "background" (an object alone before a
            uniform background).
        segmenter: the segmenter's model folder (`nfr-drake train-segmenter`).
        mask_crop: with --masks segmenter, its masks and its carcass's from a second look at the
            crop around the box the first look gives in each photo (as `eval-pipeline`'s crop
            stage; off by default here: docs/ROOMS.md, tutorial 3).
        look_again: with --mask-crop, a fit its confidence refuses is followed by one at the other
            look (the aimed look after whole photos, or the reverse), the more confident kept
            (as `eval-pipeline`).
        room_loss: with --estimate-pose, the pixels off the object's mask are painted in the
            training background ("background": the field's silhouette must match the mask) or
            left out of the image loss ("masked").
        paintings: with --room-loss background, how the photos are painted, one fit each, the
            most confident kept (`infer_painted`; "region" alone by default here, as tutorial 3
            was measured; `eval-pipeline` fits all three).
        refine_masks: with --room-loss background and --masks segmenter, the masks' pixels that
            the photo's colours call background (GrabCut started from the segmenter's
            probabilities) are removed before the painting (docs/ROOMS.md, "Mask edges by the
            photo's colours").
        part: a model with several parts (furniture): the part whose q, keypoints and trajectory
            are the result's single-part fields (default: the first part found); every part found
            is listed under `parts`.
        furniture_fit: options of the fit of a model with several parts (furniture).
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    for option, path in (("--out", out), ("--report", report), ("--point-cloud", point_cloud),
                         ("--handle-plot", handle_plot)):
        if path is not None:
            check_writable_file(path, option)
    cap = read_capture_set(capture)
    fitted = FittedModel(model)
    fitted.check_capture(cap, category)
    if handle_plot is not None and cap.gt is None:
        raise NfrDrakeError(f"--handle-plot needs ground truth, and {capture} has no gt.json")
    q_grid = np.linspace(0.0, 1.0, trajectory_points)
    if fitted.num_slots > 1:
        asked = [name for name, on in (("--handle-plot", handle_plot), ("--estimate-pose", estimate_pose),
                                       ("--keypoints geometry", keypoints == "geometry")) if on]
        if asked:
            raise NfrDrakeError(f"{', '.join(asked)}: not available for a model with several parts "
                                f"({fitted.folder}) yet")
        result, parts_fit, _ = infer_parts(fitted, cap, furniture_fit, q_grid, part=part)
        found = "; ".join(f"{p['index']} {p['type']} q = {p['q']:.3f}" for p in result.parts) or "none"
        _write_result(result, out, f"parts found: {found}; part {result.part['index']} in the single-part "
                      f"fields; image loss {result.image_loss:.5f}, {result.seconds:.1f} s -> {out}")
        if report is not None:
            write_report(report, fitted, cap, result, parts_fit.z, None, furniture_fit.handle_detector)
            print(f"report: {report}")
        if point_cloud is not None:
            count = write_point_cloud(point_cloud, fitted, cap, parts_fit.z, None)
            print(f"point cloud: {point_cloud} ({count} points, every part at its fitted state)")
        return
    if part is not None:
        raise NfrDrakeError(f"--part is for models with several parts (furniture); {model} has one")
    if estimate_pose:
        if masks == "segmenter" and not (segmenter / "config.json").is_file():
            raise NfrDrakeError(f"no segmenter in {segmenter}; train one (nfr-drake train-segmenter) or, "
                                "for an object alone before a uniform background, use --masks background")
        photos = cap.load_images()
        cropped = masks == "segmenter" and mask_crop
        if cropped:
            views, carcass, looks = cropped_masks(photos, cap, segmenter, fitted.category)
        else:
            views = object_masks(photos, segmenter if masks == "segmenter" else None)
            carcass = carcass_masks(photos, segmenter) if masks == "segmenter" else None
        refine = refine_masks and masks == "segmenter"
        in_world = infer_in_world(fitted, cap, fit, q_grid, views, room_loss, keypoints,
                                  room=masks == "segmenter", carcass=carcass, paintings=paintings,
                                  refine_masks=refine)
        refused = refusal(in_world[0].confidence) if cropped and look_again else None
        if refused and (other := cropped_masks(photos, cap, segmenter, fitted.category, after=looks)):
            print(f"{refused}\nlooking again, at the {'aimed' if other[2].aimed else 'whole-photo'} look")
            again = infer_in_world(fitted, cap, fit, q_grid, other[0], room_loss, keypoints, room=True,
                                   carcass=other[1], paintings=paintings, refine_masks=refine)
            kept = more_confident_look(in_world[0], again[0], (looks.aimed, other[2].aimed))
            in_world = again if kept is again[0] else in_world
        result, outcome, cap = in_world
        pose = np.array(result.extra["object_pose"]["X_WO"])
        print(f"object pose: x {pose[0, 3]:.3f} m, y {pose[1, 3]:.3f} m, yaw "
              f"{np.degrees(np.arctan2(pose[1, 0], pose[0, 0])):.1f} deg; size (depth x width x "
              f"height) {' x '.join(f'{v:.2f}' for v in result.extra['object_pose']['size'])} m")
    else:
        result, outcome = infer(fitted, cap, fit, q_grid, keypoint_source=keypoints)
    _write_result(result, out, f"q = {result.q:.3f}, image loss {result.image_loss:.5f}, "
                  f"{result.seconds:.1f} s ({outcome.steps} steps, {fit.restarts} starts; close look "
                  f"at the handle: {outcome.focus}) -> {out}")
    if report is not None:
        write_report(report, fitted, cap, result, outcome.z, outcome.q, fit.handle_detector)
        print(f"report: {report}")
    if point_cloud is not None:
        count = write_point_cloud(point_cloud, fitted, cap, outcome.z, outcome.q)
        print(f"point cloud: {point_cloud} ({count} points)")
    if handle_plot is not None:
        write_handle_plot(handle_plot, cap, result)
        print(f"handle plot: {handle_plot}")
