"""Fit confidence: how well the fitted field explains the photos, and the probability that the
handle it gives is within 2 cm of the truth.

Features come from what the fit found plus one render pass over a grid of each view's pixels
(at most `VIEW_RAYS` per view): the image loss (mean and worst view), the agreement of the
rendered silhouette with the observed one, the distance between the keypoint head's handle and the
handle detector's triangulated handle, how clearly the best start won, and how far the fitted
object code z_obj lies from the training codes. A `ConfidenceModel` (logistic regression on a few
of them, read from the model folder's `confidence.json`) turns them into P(handle within 2 cm); a
fit in photos of a room is calibrated by the folder's `confidence_room.json` when it has one
(fitted on the pipeline's room fits, docs/CONFIDENCE.md "In rooms").

The observed silhouette of an object alone before a uniform background (the training world) is
the pixels off the colour of the image border (`uniform_background_mask`); in photos of a room it
is the room segmenter's mask, not compared along the image sides it touches (`edge_band`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import CaptureFrame
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.errors import NfrDrakeError
from nfr_drake.inference.fit import frame_ray_directions
from nfr_drake.nfr.latent import split_z
from nfr_drake.nfr.model import NFRModel
from nfr_drake.nfr.rays import Rays
from nfr_drake.objects import SemanticClass
from nfr_drake.perception.handle_triangulation import AGREE_PX, TriangulatedHandle, project

CONFIDENCE_FILE = "confidence.json"
"""The calibration in a model folder (fits of the object alone)."""

ROOM_CONFIDENCE_FILE = "confidence_room.json"
"""The calibration of the fits in photos of a room (the segmenter's masks) in a model folder; a
folder without it calibrates those by `CONFIDENCE_FILE`, whose refusals then say that the
confidence is not calibrated in rooms."""

VIEW_RAYS = 1024
"""Pixels per view rendered for the features: a regular grid over the image."""

NEAREST_CODES = 5
"""z_obj's distance to the training codes is the mean distance to this many nearest ones."""

SUCCESS_M = 0.02
"""A fit succeeds when its handle is within this distance of the truth, m."""

FAR_M = 0.05
"""A fit is far off when its handle is more than this from the truth, m: those must be refused."""

EDGE_BAND = 0.125
"""In a room, the silhouettes are not compared within this share of the image's width (height)
of an image side that the observed mask touches: the segmenter's mask of an object that the
image edge cuts stops short of the corners or spills onto the wall beside it (docs/ROOMS.md)."""


def uniform_background_mask(image: np.ndarray, threshold: float = 0.08) -> np.ndarray:
    """Object mask of a photo on a uniform background: pixels whose largest colour-channel
    difference to the median colour of the image border exceeds `threshold` (0..1 scale)."""
    rgb = image.astype(np.float32) / 255.0
    border = np.concatenate([rgb[0], rgb[-1], rgb[:, 0], rgb[:, -1]])
    return np.abs(rgb - np.median(border, axis=0)).max(-1) > threshold


def edge_band(mask: np.ndarray, band: float = EDGE_BAND) -> np.ndarray:
    """bool (H, W): the pixels within `band` of the image's size of each image side that the
    observed mask (bool (H, W)) touches; there the object may go on beyond the image."""
    h, w = mask.shape
    rows, cols = max(1, round(band * h)), max(1, round(band * w))
    near = np.zeros((h, w), bool)
    near[:rows] |= mask[0].any()
    near[h - rows:] |= mask[-1].any()
    near[:, :cols] |= mask[:, 0].any()
    near[:, w - cols:] |= mask[:, -1].any()
    return near


def silhouette_iou(rendered: np.ndarray, observed: np.ndarray, compared: np.ndarray) -> float:
    """IoU of two bool silhouettes (P,) over the pixels `compared` (P,) bool; 1 when both are
    empty there."""
    union = np.logical_or(rendered, observed)[compared].sum()
    return float(np.logical_and(rendered, observed)[compared].sum() / union) if union else 1.0


def code_scale(codes: torch.Tensor) -> float:
    """The training codes' own spacing: the median over codes (N, k) of the mean distance to
    their `NEAREST_CODES` nearest other codes (fewer when N is small; 1 for a single code), the
    unit of the "code_distance" feature."""
    if len(codes) < 2:
        return 1.0
    d = torch.cdist(codes.double(), codes.double())
    d.fill_diagonal_(math.inf)
    nearest = d.topk(min(NEAREST_CODES, len(codes) - 1), largest=False).values
    return max(float(nearest.mean(-1).median()), 1e-9)


def _grid(height: int, width: int) -> np.ndarray:
    """Row-major pixel indices of a regular grid of at most `VIEW_RAYS` pixels."""
    stride = max(1, math.ceil(math.sqrt(height * width / VIEW_RAYS)))
    rows, cols = np.meshgrid(np.arange(stride // 2, height, stride),
                             np.arange(stride // 2, width, stride), indexing="ij")
    return (rows * width + cols).reshape(-1)


@dataclass
class ViewRender:
    """The fit rendered on one view's pixel grid (`_grid`): the view's features (image_loss,
    silhouette_iou, edge_contact: `as_json`), the grid pixels' centres uv (P, 2), px, their
    squared colour error (P,) (mean over RGB, 0..1 scale) and which of them count in the image
    loss, counted (P,) bool."""

    image_loss: float
    silhouette_iou: float
    edge_contact: float
    uv: np.ndarray
    error: np.ndarray
    counted: np.ndarray

    def as_json(self) -> dict:
        return {"image_loss": self.image_loss, "silhouette_iou": self.silhouette_iou,
                "edge_contact": self.edge_contact}


def render_views(model: NFRModel, z: torch.Tensor, frames: list[CaptureFrame],
                 images: list[np.ndarray], room_masks: list[np.ndarray] | None = None
                 ) -> list[ViewRender]:
    """Render the fitted code z (D,) on each view's pixel grid and compare with the photo (uint8
    RGB (H, W, 3)); `room_masks` as in `fit_features`."""
    views = []
    z = z.detach().float()
    with torch.no_grad():
        for i, (frame, image) in enumerate(zip(frames, images, strict=True)):
            cam = frame.camera
            index = _grid(cam.height, cam.width)
            d = torch.from_numpy(frame_ray_directions(frame)[index]).float()
            o = torch.from_numpy(frame.X_OC[:3, 3]).float().expand_as(d)
            out = model.render(z[None], Rays(o[None], d[None]))
            observed = torch.from_numpy(image.reshape(-1, 3)[index] / 255.0).float()
            rendered_fg = (out.logits[0].argmax(-1) != int(SemanticClass.BACKGROUND)).numpy()
            if room_masks is None:
                mask = uniform_background_mask(image)
                observed_fg = mask.reshape(-1)[index]
                compared = counted = np.ones(len(index), bool)
            else:
                mask = np.asarray(room_masks[i]) > 0.5
                observed_fg = mask.reshape(-1)[index]
                compared = ~edge_band(mask).reshape(-1)[index]
                counted = observed_fg if observed_fg.any() else compared
            error = ((out.rgb[0] - observed) ** 2).mean(-1).numpy()
            border = np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])
            uv = np.stack([index % cam.width, index // cam.width], -1) + 0.5
            views.append(ViewRender(float(error[counted].mean()),
                                    silhouette_iou(rendered_fg, observed_fg, compared),
                                    float(border.mean()), uv, error, counted))
    return views


def fit_features(model: NFRModel, z: torch.Tensor, frames: list[CaptureFrame],
                 images: list[np.ndarray], start_losses: np.ndarray, codes: torch.Tensor,
                 scale: float, handle_keypoint: int, sighting_p_O: np.ndarray | None,
                 room_masks: list[np.ndarray] | None = None,
                 views: list[ViewRender] | None = None) -> tuple[dict, list[dict]]:
    """The features of a fit (dict name -> float) and per view {image_loss, silhouette_iou,
    edge_contact (share of the image border on the observed object)}.

    z (D,): the fitted code; frames and images (uint8 RGB (H, W, 3)): the views fitted;
    start_losses (S,): the starts' losses after exploration (`FitOutcome`); codes (N, k): the
    training z_obj, `scale` their spacing (`code_scale`); handle_keypoint: the handle's index
    among the keypoint head's outputs; sighting_p_O (3,) in O, m: the detector's triangulated
    handle, or None. room_masks: for photos of a room, the object's probability
    (H, W) per view (the segmenter's): the observed silhouette is where it exceeds 0.5, the
    image loss counts the pixels on it and the silhouette IoU leaves out the `edge_band` of the
    sides it touches; None: an object alone before a uniform background
    (`uniform_background_mask`, every pixel compared). views: `render_views` of z already made.
    """
    views = render_views(model, z, frames, images, room_masks) if views is None else views
    z = z.detach().float()
    with torch.no_grad():
        handle = model.keypoints(z[None])[0, handle_keypoint].double().numpy()
        z_obj = split_z(z, model.config.num_slots)[1]
        code_d = torch.cdist(z_obj[None].double(), codes.double())[0]
        code_distance = float(code_d.topk(min(NEAREST_CODES, len(code_d)), largest=False)
                              .values.mean()) / scale
    losses = np.array([v.image_loss for v in views])
    ious = np.array([v.silhouette_iou for v in views])
    ordered = np.sort(np.asarray(start_losses, float))
    gap = None if sighting_p_O is None else float(np.linalg.norm(handle - np.asarray(sighting_p_O)))
    features = {
        "image_loss": float(losses.mean()),
        "image_loss_worst_view": float(losses.max()),
        "silhouette_iou": float(ious.mean()),
        "silhouette_iou_worst_view": float(ious.min()),
        "edge_contact": max(v.edge_contact for v in views),
        "sighting_missing": float(gap is None),
        "sighting_gap_m": 0.0 if gap is None else gap,
        "start_loss_ratio": float(ordered[0] / ordered[1]) if len(ordered) > 1 and ordered[1] > 0
        else 0.0,
        "code_distance": code_distance,
        "views": float(len(frames)),
        "room": float(room_masks is not None),
    }
    return features, [v.as_json() for v in views]


PART_WINDOW = 0.08
"""A part's local image loss counts the grid pixels within this share of the image's larger side
of the projection of the part's handle."""


def part_features(model: NFRModel, z: torch.Tensor, start_z: torch.Tensor, slot: int,
                  frames: list[CaptureFrame], views: list[ViewRender],
                  sighted: list[TriangulatedHandle] | None = None) -> dict:
    """Features of one part (slot `slot`) of a fit of a model with several parts (furniture):

    part_exists_logit: the keypoint head's existence logit of the slot (> 0: the field finds
    the part); part_type_margin: |door logit - drawer logit|; start_spread_m: the largest
    distance, m, between the slot's handle in the starts fitted together (start_z (B, D), their
    final codes; 0 for one start); part_image_loss: the image loss (`ViewRender.error`) of the
    counted grid pixels within `PART_WINDOW` of the handle's projection, mean over the views
    where it falls in the image (the mean image loss when it falls in none); sighting_missing
    (1: the handle detector sighted no handle, `sighted` (M,) empty or None) and sighting_gap_m:
    the distance, m, from the slot's handle to the nearest sighted one (0 when none); the part's
    own sighting, with `sighted` in the fit's order (slot k paired with sighting k,
    `furniture_fit.sighting_order`): part_unsighted (1: no sighted handle is this slot's, k >= M,
    none sighted included: the part's keypoints are the head's alone), part_sighting_views (how
    many views agree on it; 0 without one) and part_sighting_rms_px (their reprojection RMS,
    scaled to a 128 px high image; without one, the triangulation's tolerance `AGREE_PX`, as
    loose as an agreeing sighting can be). z (D,): the fit.
    """
    with torch.no_grad():
        S = model.config.num_slots
        logits = model.slot_logits(z.detach().float()[None])[0, slot]
        handles = model.keypoints(torch.cat([z.detach().float()[None], start_z.detach().float()])
                                  ).view(-1, S, len(SLOT_KEYPOINTS), 3)[:, slot, 0].double().numpy()
    spread = float(np.linalg.norm(handles[1:, None] - handles[None, 1:], axis=-1).max())
    local = []
    for frame, view in zip(frames, views, strict=True):
        uv = project(frame, handles[0])
        cam = frame.camera
        if uv is None or not (0 <= uv[0] <= cam.width and 0 <= uv[1] <= cam.height):
            continue
        near = view.counted & (np.linalg.norm(view.uv - uv, axis=-1)
                               <= PART_WINDOW * max(cam.width, cam.height))
        if near.any():
            local.append(float(view.error[near].mean()))
    sighted = sighted or []
    sighted_O = np.array([h.p_O for h in sighted], float).reshape(-1, 3)
    gap = float(np.linalg.norm(sighted_O - handles[0], axis=-1).min()) if len(sighted) else 0.0
    own = sighted[slot] if slot < len(sighted) else None
    return {"sighting_missing": float(not sighted), "sighting_gap_m": gap,
            "part_unsighted": float(own is None),
            "part_sighting_views": 0.0 if own is None else float(len(own.views)),
            "part_sighting_rms_px": AGREE_PX if own is None else own.rms_reference_px(frames),
            "part_exists_logit": float(logits[0]),
            "part_type_margin": float(abs(logits[1] - logits[2])), "start_spread_m": spread,
            "part_image_loss": float(np.mean(local if local else [v.image_loss for v in views]))}


TRANSFORMS = {
    "identity": lambda x: x,
    "log10": lambda x: math.log10(max(x, 1e-6)),
    "one_minus": lambda x: 1.0 - x,
    "log10_cm": lambda x: math.log10(100.0 * x + 0.5),
    "inverse": lambda x: 1.0 / max(x, 1.0),
    "negative": lambda x: -x,
}
"""Transforms of a feature before the logistic regression (`ConfidenceModel.terms`)."""


@dataclass
class ConfidenceModel:
    """P(handle within 2 cm) = sigmoid(intercept + sum_i coef_i (t_i(x_i) - mean_i) / std_i) over
    the terms (feature name, transform name in `TRANSFORMS`); a fit is refused below `threshold`.
    `source` records the data and command the calibration came from."""

    terms: list[tuple[str, str]]
    mean: list[float]
    std: list[float]
    coef: list[float]
    intercept: float
    threshold: float
    source: dict

    def design(self, features: dict) -> np.ndarray:
        """The standardised terms (T,) of one fit's features."""
        x = np.array([TRANSFORMS[t](float(features[name])) for name, t in self.terms])
        return (x - np.array(self.mean)) / np.array(self.std)

    def weakest(self, features: dict) -> str | None:
        """The feature whose term lowers this fit's probability most (its coefficient times its
        standardised value, most negative): what a refusal names first; None when every
        coefficient is 0 (a calibration that is the success rate alone)."""
        if not any(self.coef):
            return None
        contributions = self.design(features) * np.array(self.coef)
        return self.terms[int(np.argmin(contributions))][0]

    def probability(self, features: dict) -> float:
        """P(handle within 2 cm) of one fit's features."""
        return float(1.0 / (1.0 + math.exp(-(self.intercept + self.design(features) @ self.coef))))

    def to_json(self) -> dict:
        return {"target": "P(handle within 2 cm of the truth)",
                "terms": [list(t) for t in self.terms], "mean": self.mean, "std": self.std,
                "coef": self.coef, "intercept": self.intercept, "threshold": self.threshold,
                "source": self.source}

    def write(self, folder: Path, name: str = CONFIDENCE_FILE) -> Path:
        path = Path(folder) / name
        path.write_text(json.dumps(self.to_json(), indent=2) + "\n")
        return path

    @classmethod
    def read(cls, folder: Path, name: str = CONFIDENCE_FILE) -> ConfidenceModel | None:
        """The calibration `name` of a model folder, or None when it has none."""
        path = Path(folder) / name
        if not path.exists():
            return None
        try:
            doc = json.loads(path.read_text())
            terms = [(str(n), str(t)) for n, t in doc["terms"]]
            unknown = [t for _, t in terms if t not in TRANSFORMS]
            if unknown:
                raise KeyError(f"unknown transform {unknown[0]}")
            return cls(terms, [float(v) for v in doc["mean"]], [float(v) for v in doc["std"]],
                       [float(v) for v in doc["coef"]], float(doc["intercept"]),
                       float(doc["threshold"]), doc.get("source", {}))
        except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
            raise NfrDrakeError(f"{path}: not a readable confidence calibration ({err})") from None


def fit_logistic(X: np.ndarray, y: np.ndarray, l2: float = 1.0, iterations: int = 50
                 ) -> tuple[np.ndarray, float]:
    """Logistic regression by Newton's method with an L2 penalty `l2` on the coefficients (not
    the intercept): X (N, T) standardised terms, y (N,) 0/1; returns (coef (T,), intercept)."""
    A = np.hstack([np.ones((len(X), 1)), X])
    w = np.zeros(A.shape[1])
    penalty = np.diag([0.0] + [l2] * X.shape[1])
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-(A @ w)))
        grad = A.T @ (p - y) + penalty @ w
        hess = A.T @ (A * (p * (1 - p))[:, None]) + penalty + 1e-9 * np.eye(len(w))
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.abs(step).max() < 1e-10:
            break
    return w[1:], float(w[0])


ADVICE = {
    "views": "too few views: photograph the object from more sides",
    "edge_contact": "the object is cut by the image edge: step back so it is whole in every view",
    "image_loss": ("the fitted field does not match the photos: check for occlusion, or use a "
                   "model of this kind of object"),
    "image_loss_worst_view": ("the fitted field does not match the photos in one view at least: "
                              "check that view for occlusion or glare, or use a model of this kind "
                              "of object"),
    "silhouette_iou": ("the fitted shape covers the object poorly: check for occlusion, or use a "
                       "model of this kind of object"),
    "start_loss_ratio": "the fit's starts explain the photos about equally well: take more views, closer",
    "silhouette_iou_worst_view": ("the fitted shape covers the object poorly (silhouette IoU {:.2f} "
                                  "in the worst view): check for occlusion, or use a model of this "
                                  "kind of object"),
    "sighting_missing": "the handle detector found no handle in 3 views: photograph the handle closer",
    "sighting_gap_m": ("the handle detector's handle and the fitted one disagree: photograph the "
                       "handle closer, or use a model of this kind of object"),
    "code_distance": "the object is unlike the model's training objects: use a model of this kind",
    "part_exists_logit": ("the model does not find this part in the photos: photograph it closer, "
                          "or use a model of this kind of object"),
    "start_spread_m": "the fit's starts disagree on this part's handle: take more views, closer",
    "part_unsighted": ("the handle detector sighted no handle of this part: photograph it closer, "
                       "from in front"),
    "part_sighting_views": ("few views agree on this part's handle, or none sighted it: photograph "
                            "it from more sides, closer, from in front"),
    "part_sighting_rms_px": ("the views agree on this part's handle only loosely: photograph it "
                             "closer, from in front"),
    "part_image_loss": ("the fitted part does not match the photos around its handle: photograph "
                        "this part closer, or use a model of this kind of object"),
    "room": ("in a room this model's fit confidence is not calibrated (no confidence_room.json in "
             "its folder; docs/CONFIDENCE.md, \"In rooms\"): photograph the object alone before a "
             "plain background, or act on the fit at your own risk with --min-confidence 0"),
    None: "take more views, closer, or use a model of this kind of object",
}
"""What to do, by the weakest feature of a refused fit (`ConfidenceModel.weakest`)."""


def refusal(confidence: dict | None, threshold: float | None = None) -> str | None:
    """Why a fit must not be acted on, in one line with what to do, or None when it may be:
    P(handle within 2 cm) of a result's `confidence` (`inference.infer.fit_confidence`) below
    `threshold` (None: the calibration's own); the advice follows its `weakest` feature (a room
    fit calibrated by the object-alone `CONFIDENCE_FILE`: that rooms are not calibrated). A fit
    without a calibration is never refused."""
    if confidence is None or confidence.get("p_handle_within_2cm") is None:
        return None
    p = confidence["p_handle_within_2cm"]
    threshold = confidence["threshold"] if threshold is None else threshold
    if p >= threshold:
        return None
    f = confidence["features"]
    # In a room the object-alone calibration does not hold at all; below 3 views the detector
    # cannot triangulate a handle; a furniture part without a sighting of its own has none to
    # weigh: those come before the weakest feature.
    uncalibrated_room = f.get("room") and confidence.get("calibration") != ROOM_CONFIDENCE_FILE
    weakest = ("room" if uncalibrated_room else "views" if f["views"] < 3
               else "part_unsighted" if f.get("part_unsighted") else confidence.get("weakest"))
    advice = ADVICE.get(weakest, ADVICE[None])
    if weakest == "silhouette_iou_worst_view":
        advice = advice.format(f["silhouette_iou_worst_view"])
    return (f"refused: P(handle within 2 cm) = {p:.2f} < {threshold:.2f} (image loss "
            f"{f['image_loss']:.4f}, worst view {f['image_loss_worst_view']:.4f}); {advice}")
