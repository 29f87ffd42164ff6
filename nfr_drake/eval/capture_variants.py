"""Capture sets made harder or stranger in memory, to test whether a fit knows when it is wrong.

Each variant maps a capture set and its images to another (frames, images) pair, drawn from a
seed so that it can be made again: fewer views, a box painted over every view, the object cut by
the image edge, another background, other colours on the object. The masks come from the capture's
rendered label images (labels/frame_NNN.png: 0 is background).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from nfr_drake.data.capture import CaptureFrame, CaptureSet
from nfr_drake.errors import ConfigError

VARIANTS = ("clean", "few_views", "occluded", "edge_cut", "background", "recoloured")
"""Names of the variants, `apply_variant`'s `variant`."""

FEW_VIEWS = 3
"""Views kept by "few_views"."""


def load_labels(capture: CaptureSet) -> list[np.ndarray]:
    """The label image (H, W) uint8 of every frame, from the capture's labels/ folder."""
    labels = []
    for frame in capture.frames:
        path = frame.image_path.parent.parent / "labels" / frame.image_path.name
        label = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if label is None:
            raise ConfigError(f"{path}: a capture variant needs the capture's label images")
        labels.append(label)
    return labels


def apply_variant(variant: str, capture: CaptureSet, images: list[np.ndarray], seed: int
                  ) -> tuple[CaptureSet, list[np.ndarray]]:
    """The capture set and its uint8 RGB images (H, W, 3) changed by `variant` (`VARIANTS`):

    - "clean": unchanged;
    - "few_views": the first `FEW_VIEWS` views only;
    - "occluded": a box of 35-55 % of the image side, of one random colour, centred on a random
      pixel of the object, painted over every view;
    - "edge_cut": every view cropped to 50-65 % of its width on the side away from the object's
      centre, intrinsics shifted to match (the object cut by the image edge);
    - "background": the background replaced by a random colour with a coarse random texture;
    - "recoloured": the object's colour channels permuted and scaled (another finish).
    """
    if variant not in VARIANTS:
        raise ConfigError(f"unknown capture variant {variant!r}; one of {', '.join(VARIANTS)}")
    rng = np.random.default_rng(seed)
    if variant == "clean":
        return capture, images
    if variant == "few_views":
        return replace(capture, frames=capture.frames[:FEW_VIEWS]), images[:FEW_VIEWS]
    labels = load_labels(capture)
    if variant == "edge_cut":
        frames, cut = [], []
        for frame, image, label in zip(capture.frames, images, labels, strict=True):
            crop_frame, crop_image = _edge_cut(frame, image, label, rng)
            frames.append(crop_frame)
            cut.append(crop_image)
        return replace(capture, frames=frames), cut
    out = []
    for image, label in zip(images, labels, strict=True):
        object_mask = label > 0
        changed = image.copy()
        if variant == "occluded":
            ys, xs = np.nonzero(object_mask) if object_mask.any() else np.nonzero(~object_mask)
            i = rng.integers(len(ys))
            h, w = image.shape[:2]
            half = (rng.uniform(0.35, 0.55) * np.array([h, w]) / 2).astype(int)
            changed[max(0, ys[i] - half[0]):ys[i] + half[0],
                    max(0, xs[i] - half[1]):xs[i] + half[1]] = rng.integers(0, 256, 3)
        elif variant == "background":
            h, w = image.shape[:2]
            coarse = rng.uniform(0, 255, (4, 4, 3)).astype(np.float32)
            texture = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR)
            colour = rng.uniform(0, 255, 3)
            background = (0.5 * texture + 0.5 * colour).clip(0, 255).astype(np.uint8)
            changed[~object_mask] = background[~object_mask]
        else:  # recoloured
            permuted = image[..., rng.permutation(3)].astype(np.float32) * rng.uniform(0.6, 1.2, 3)
            changed[object_mask] = permuted.clip(0, 255).astype(np.uint8)[object_mask]
        out.append(changed)
    return capture, out


def _edge_cut(frame: CaptureFrame, image: np.ndarray, label: np.ndarray,
              rng: np.random.Generator) -> tuple[CaptureFrame, np.ndarray]:
    """One view cropped to a window of 50-65 % of its width that cuts the object (see
    `apply_variant`); the principal point moves with the crop."""
    h, w = image.shape[:2]
    keep = int(round(rng.uniform(0.5, 0.65) * w))
    xs = np.nonzero(label > 0)[1]
    centre = xs.mean() if len(xs) else w / 2
    x0 = 0 if centre >= w / 2 else w - keep  # the window ends near the object's centre
    cam = frame.camera
    camera = replace(cam, cx=cam.cx - x0, width=keep)
    return replace(frame, camera=camera), np.ascontiguousarray(image[:, x0:x0 + keep])
