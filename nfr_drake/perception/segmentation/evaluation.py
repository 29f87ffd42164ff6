"""How well a segmenter finds the object: mask IoU on room datasets, and a figure of its masks.

Per dataset: the mean and median IoU of the thresholded mask (probability > 0.5) against the
true one (label > 0), the pooled IoU (all pixels of all images), the same on the images whose
true mask touches the image border (the object cut by the image edge) and on the others, and the
false-positive area (predicted object pixels outside the true mask, relative to the true mask's
area): what a twin beside the object or a similar neighbour adds to the mask. For scale, the
mean IoU of a fixed guess, the centre box (the middle half of the image in each direction). For a
model with the amodal carcass output and a dataset with its labels (`carcass_amodal.npy`), the
same IoU (mean, median, pooled) of the amodal carcass (probability > 0.5, first look) against
them.
The masks are the first look (`crop` "none"), the single-photo second look ("mask",
`Segmenter.close_look`) or the posed crop stage over the views of one articulation ("posed",
`crop.posed_close_look`, with the room's camera poses and the floor at z = 0 of frame O).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.room_dataset import read_room_spec
from nfr_drake.perception.segmentation.crop import posed_close_look
from nfr_drake.perception.segmentation.data import RoomImages
from nfr_drake.perception.segmentation.model import Segmenter

THRESHOLD = 0.5
Crop = Literal["none", "mask", "posed"]
"""Which masks are measured: the first look, the single-photo second look, the posed crop stage."""


def mask_iou(pred: np.ndarray, true: np.ndarray) -> float:
    """Intersection over union of two boolean masks of one shape; 1 when both are empty."""
    union = np.count_nonzero(pred | true)
    return float(np.count_nonzero(pred & true) / union) if union else 1.0


def touches_border(mask: np.ndarray) -> bool:
    """Whether a boolean mask (H, W) has a pixel in the outermost row or column."""
    return bool(mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())


def predicted_masks(net: Segmenter, data: RoomImages, crop: Crop = "none") -> list[np.ndarray]:
    """The segmenter's object probability (S, S) of every image of `data`, in its order, as `crop`
    says (module docstring)."""
    if crop == "none":
        return [net.object_mask(data.image(i)[0]) for i in range(len(data))]
    if crop == "mask":
        return [net.close_look(data.image(i)[0]) for i in range(len(data))]
    masks: list[np.ndarray] = [None] * len(data)  # type: ignore[list-item]
    groups: dict[tuple[str, int], list[int]] = {}
    for i, (rec, a, _) in enumerate(data.index):
        groups.setdefault((str(rec.path), a), []).append(i)
    for members in groups.values():
        rec, a, _ = data.index[members[0]]
        camera = PinholeCamera.from_json(rec.meta["camera"])
        views = [data.index[i][2] for i in members]
        found = posed_close_look(net, [data.image(i)[0] for i in members], [rec.X_OC[a, v] for v in views],
                                 [camera] * len(members), data.category[members[0]])
        for i, mask in zip(members, found, strict=True):
            masks[i] = mask
    return masks


def evaluate_dataset(net: Segmenter, root: Path, crop: Crop = "none") -> dict:
    """The measures of the module docstring on every image of the room dataset `root`."""
    spec = read_room_spec(root)
    data = RoomImages([root])
    masks = predicted_masks(net, data, crop)
    ious, cut, false_pos, centre = [], [], [], []
    inter = union = 0
    for i in range(len(data)):
        rgb, label = data.image(i)
        true = label > 0
        if not true.any():
            continue  # the object is hidden (behind the arm or clutter) in this view
        pred = masks[i] > THRESHOLD
        ious.append(mask_iou(pred, true))
        centre.append(mask_iou(centre_box(true.shape), true))
        cut.append(touches_border(true))
        false_pos.append(np.count_nonzero(pred & ~true) / np.count_nonzero(true))
        inter += np.count_nonzero(pred & true)
        union += np.count_nonzero(pred | true)
    ious_a, cut_a = np.asarray(ious), np.asarray(cut, bool)
    amodal = amodal_iou(net, data) if crop == "none" else {}

    def mean(x: np.ndarray) -> float | None:
        return float(x.mean()) if x.size else None

    return {"dataset": str(root), "category": spec.category, "style": spec.room.style, "crop": crop,
            "images": len(ious), "iou_mean": mean(ious_a), "iou_median": float(np.median(ious_a)),
            "iou_pooled": inter / union if union else 1.0, "cut_images": int(cut_a.sum()),
            "iou_mean_cut": mean(ious_a[cut_a]), "iou_mean_whole": mean(ious_a[~cut_a]),
            "false_positive_area": mean(np.asarray(false_pos)),
            "iou_below_0.5": int((ious_a < 0.5).sum()), "iou_mean_centre_box": mean(np.asarray(centre)),
            **amodal}


def amodal_iou(net: Segmenter, data: RoomImages) -> dict:
    """IoU of the amodal carcass (`Segmenter.carcass_amodal` > 0.5) against the amodal labels of
    every image of `data` whose label is not empty: {"amodal_iou_mean", "amodal_iou_median",
    "amodal_iou_pooled"}; {} for a model without that output or data without those labels."""
    if not (net.config.amodal and data.has_amodal):
        return {}
    ious, inter, union = [], 0, 0
    for i in range(len(data)):
        true = data.amodal(i) > 0
        if not true.any():
            continue
        pred = net.carcass_amodal(data.image(i)[0]) > THRESHOLD
        ious.append(mask_iou(pred, true))
        inter += np.count_nonzero(pred & true)
        union += np.count_nonzero(pred | true)
    return {"amodal_iou_mean": float(np.mean(ious)), "amodal_iou_median": float(np.median(ious)),
            "amodal_iou_pooled": inter / union if union else 1.0}


def centre_box(shape: tuple[int, int]) -> np.ndarray:
    """Boolean mask (H, W) of the middle half of the image in each direction."""
    h, w = shape
    box = np.zeros(shape, bool)
    box[h // 4:h - h // 4, w // 4:w - w // 4] = True
    return box


def _overlay(rgb: np.ndarray, mask: np.ndarray, colour: tuple[int, int, int]) -> np.ndarray:
    out = rgb.astype(np.float32)
    out[mask] = 0.45 * out[mask] + 0.55 * np.asarray(colour, np.float32)
    edge = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    out[edge] = colour
    return out.clip(0, 255).astype(np.uint8)


def mask_figure(net: Segmenter, roots: list[Path], per_dataset: int, out: Path, columns: int = 2,
                seed: int = 0, crop: Crop = "none") -> None:
    """PNG of `per_dataset` random images of each dataset, `columns` per row, each as a triplet:
    the photo, the true mask (green) and the predicted mask (magenta), 2x enlarged, with the
    category and the IoU written on the photo; the masks as `crop` says (module docstring)."""
    rng = np.random.default_rng(seed)
    triplets = []
    for root in roots:
        data = RoomImages([root])
        chosen = rng.choice(len(data), min(per_dataset, len(data)), replace=False)
        look = net.object_mask if crop == "none" else net.close_look
        masks = predicted_masks(net, data, crop) if crop == "posed" else {
            int(i): look(data.image(int(i))[0]) for i in chosen}
        for i in chosen:
            rgb, label = data.image(int(i))
            true, pred = label > 0, masks[int(i)] > THRESHOLD
            tiles = [rgb, _overlay(rgb, true, (0, 220, 0)), _overlay(rgb, pred, (230, 0, 230))]
            row = cv2.resize(np.concatenate(tiles, 1), None, fx=2, fy=2, interpolation=cv2.INTER_NEAREST)
            text = f"{data.category[int(i)]} IoU {mask_iou(pred, true):.2f}"
            cv2.putText(row, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                        cv2.LINE_AA)
            triplets.append(np.pad(row, ((0, 4), (0, 8), (0, 0)), constant_values=255))
    h, w = max(t.shape[0] for t in triplets), max(t.shape[1] for t in triplets)
    triplets = [np.pad(t, ((0, h - t.shape[0]), (0, w - t.shape[1]), (0, 0)), constant_values=255)
                for t in triplets]
    triplets += [np.full_like(triplets[0], 255)] * (-len(triplets) % columns)
    grid = np.concatenate([np.concatenate(triplets[k:k + columns], 1)
                           for k in range(0, len(triplets), columns)], 0)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(grid, cv2.COLOR_RGB2BGR))
