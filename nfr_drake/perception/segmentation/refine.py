"""The segmenter's masks refined by the photo's own colours (GrabCut), so that their edges follow
the object's.

The segmenter, trained at 96 px on random rooms, spills over the floor or the wall beside the
object with probabilities above one half, and its edges are a few pixels loose
(docs/ROOMS.md, "Mask edges by the photo's colours"). GrabCut (OpenCV: a Gaussian mixture of
the object's colours and one of the background's, and a graph cut that follows colour edges) is
started from the segmenter's probabilities: pixels above `sure_above` are the object for
certain, those at most `background_below` background for certain, the rest probably what the
segmenter says. A pixel GrabCut calls background gets probability 0; the others keep the
segmenter's, so the refinement only removes: it never makes a pixel the segmenter doubted the
object's. Where GrabCut would take more than `MAX_REMOVED` of the mask (p > 0.5) away, its colour
models are not the object's (a patchy mask with few sure pixels, the object's colours those of the
room): the mask is kept as it is.
"""

from __future__ import annotations

import cv2
import numpy as np

SURE_ABOVE = 0.95
"""Pixels above this probability are the object for GrabCut whatever their colour."""
BACKGROUND_BELOW = 0.2
"""Pixels at or below this are background for GrabCut whatever their colour."""
ITERATIONS = 4
"""GrabCut's rounds of colour models and graph cut."""
MAX_REMOVED = 0.5
"""The largest share of the mask's pixels (p > 0.5) the refinement may take away (module docstring)."""


def refine_mask(image: np.ndarray, mask: np.ndarray, sure_above: float = SURE_ABOVE,
                background_below: float = BACKGROUND_BELOW, iterations: int = ITERATIONS) -> np.ndarray:
    """The object probability `mask` (H, W) in [0, 1] of the uint8 RGB `image` (H, W, 3) with the
    pixels GrabCut calls background set to 0, float32 (H, W). Returned as it is (a copy) when no
    pixel is above one half or none at or below `background_below` (no colour model to learn), or
    when GrabCut would take more than `MAX_REMOVED` of the pixels above one half away."""
    image, mask = np.asarray(image), np.asarray(mask, np.float32)
    if image.ndim != 3 or image.shape[2] != 3 or image.shape[:2] != mask.shape:
        raise ValueError(f"refine_mask: an image (H, W, 3) and a mask (H, W), got {image.shape} and "
                         f"{mask.shape}")
    labels = np.where(mask > 0.5, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    labels[mask > sure_above] = cv2.GC_FGD
    labels[mask <= background_below] = cv2.GC_BGD
    if not (mask > 0.5).any() or not (mask <= background_below).any():
        return mask.copy()
    models = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.grabCut(np.ascontiguousarray(image[..., ::-1]), labels, None, *models, iterations,
                cv2.GC_INIT_WITH_MASK)
    kept = (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)
    on = mask > 0.5
    if np.count_nonzero(on & ~kept) > MAX_REMOVED * np.count_nonzero(on):
        return mask.copy()
    return np.where(kept, mask, 0.0).astype(np.float32)


def refine_masks(images: list[np.ndarray], masks: list[np.ndarray]) -> list[np.ndarray]:
    """`refine_mask` of each photo and its mask."""
    return [refine_mask(image, mask) for image, mask in zip(images, masks, strict=True)]
