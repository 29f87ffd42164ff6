"""The segmenter: a tiny U-Net that labels each pixel of a photo as background or one of the
target object's classes (carcass, moving part, handle; docs/CONVENTIONS.md).

The object's mask is the probability of "not background" (`object_mask`). A fifth output
(`SegmenterConfig.amodal`) is the probability that a pixel lies on the target's carcass as if
nothing hid it (no clutter, no neighbour, no arm, no fronts: `data.amodal`), `carcass_amodal`;
the object's pose is fitted to it (`perception.object_pose`). Each image is
standardised (its own mean and standard deviation per channel) before the network sees it, so an
exposure or white-balance change moves nothing; the network is fully convolutional and pads the
image to a multiple of 2^levels, so it runs on any image size.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from safetensors.torch import save_file
from torch import nn

from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import CheckpointError, load_strict, read_tensors

NUM_CLASSES = 4
"""Class outputs per pixel: background, carcass, moving part, handle (the semantic classes)."""
AMODAL_CHANNEL = NUM_CLASSES
"""The output holding the amodal carcass logit (sigmoid), in a model with `amodal`."""
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
SEGMENT_PX = 96
"""Photos are segmented at about this many pixels square: the training rooms' size
(`generate-rooms --size`), so that an object framed by the photo has the pixel scale that the
network's receptive field learnt. 128 px photos of closets in held-out rooms score a mean IoU of
0.39 segmented as they are and 0.56-0.61 at 96 px (docs/ROOMS.md, "The pipeline in a room")."""
CROP_MARGIN = 0.3
"""The crop stage's free border on each side of the object's box, as a fraction of the box's
longer side: the training photos frame the object with a border of 5-50 % of the half-image."""
Box = tuple[int, int, int, int]
"""A pixel rectangle (x0, y0, x1, y1): columns x0..x1-1 and rows y0..y1-1 of an image."""


@dataclass(frozen=True)
class SegmenterConfig:
    """Architecture: a stride-2 stem of `channels`, then `levels` stride-2 stages, channels
    doubling per stage (at most 4x), two 3x3 convolutions per stage, a bottleneck of dilated
    convolutions (`bottleneck_dilations`) for context, a decoder of the same stages with skip
    connections, and logits at half resolution upsampled (bilinear) to the image's. `amodal`:
    one more output, the amodal carcass logit (models saved without it have the 4 classes only)."""

    channels: int = 16
    levels: int = 3
    bottleneck_dilations: tuple[int, ...] = (2, 4)
    amodal: bool = True

    def __post_init__(self):
        if self.channels < 1 or self.levels < 1 or min(self.bottleneck_dilations, default=1) < 1:
            raise ConfigError("segmenter: channels, levels and dilations must be positive")

    @classmethod
    def from_json(cls, d: dict) -> SegmenterConfig:
        return cls(channels=int(d["channels"]), levels=int(d["levels"]),
                   bottleneck_dilations=tuple(int(x) for x in d["bottleneck_dilations"]),
                   amodal=bool(d.get("amodal", False)))

    @property
    def outputs(self) -> int:
        """Output channels: the classes, and the amodal carcass logit when `amodal`."""
        return NUM_CLASSES + int(self.amodal)


def _block(c_in: int, c_out: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, stride=stride, padding=dilation, dilation=dilation),
                         nn.ReLU(), nn.Conv2d(c_out, c_out, 3, padding=1), nn.ReLU())


class Segmenter(nn.Module):
    """(B, 3, H, W) RGB in [0, 1] -> logits (B, config.outputs, H, W): the classes (softmax),
    then the amodal carcass (sigmoid) when `config.amodal`; any H and W."""

    def __init__(self, config: SegmenterConfig):
        super().__init__()
        self.config = config
        c = [config.channels * min(2**i, 4) for i in range(config.levels + 1)]
        self.stem = _block(3, c[0], stride=2)
        self.down = nn.ModuleList(_block(c[i], c[i + 1], stride=2) for i in range(config.levels))
        self.bottleneck = nn.Sequential(*(_block(c[-1], c[-1], dilation=d)
                                          for d in config.bottleneck_dilations))
        self.up = nn.ModuleList(_block(c[i + 1] + c[i], c[i]) for i in reversed(range(config.levels)))
        self.head = nn.Conv2d(c[0], config.outputs, 1)

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        h, w = rgb.shape[-2:]
        mean = rgb.mean(dim=(2, 3), keepdim=True)
        std = rgb.std(dim=(2, 3), keepdim=True)
        x = (rgb - mean) / (std + 0.05)
        m = 2 ** (self.config.levels + 1)
        pad = (0, (-w) % m, 0, (-h) % m)
        x = nn.functional.pad(x, pad, mode="replicate")
        skips = [self.stem(x)]
        for stage in self.down:
            skips.append(stage(skips[-1]))
        y = self.bottleneck(skips.pop())
        for stage in self.up:
            skip = skips.pop()
            y = nn.functional.interpolate(y, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            y = stage(torch.cat([y, skip], dim=1))
        logits = nn.functional.interpolate(self.head(y), scale_factor=2.0, mode="bilinear",
                                           align_corners=False)
        return logits[..., :h, :w]

    @torch.no_grad()
    def class_probabilities(self, image: np.ndarray) -> np.ndarray:
        """Per-pixel class probabilities (H, W, NUM_CLASSES), float32, of a uint8 RGB image
        (H, W, 3) of any size; NfrDrakeError on anything else."""
        return self._probabilities(image)[..., :NUM_CLASSES]

    @torch.no_grad()
    def _probabilities(self, image: np.ndarray) -> np.ndarray:
        """(H, W, config.outputs) float32: the class probabilities, then the amodal carcass's."""
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise NfrDrakeError(f"segmenter: expected a uint8 RGB image (H, W, 3), got {image.dtype} "
                                f"{image.shape}")
        if min(image.shape[:2]) < 2:
            raise NfrDrakeError(f"segmenter: image of {image.shape[1]}x{image.shape[0]} px is too small")
        self.eval()
        x = torch.from_numpy(np.ascontiguousarray(image, np.float32) / 255.0).permute(2, 0, 1)[None]
        logits = self(x)[0]
        probs = [torch.softmax(logits[:NUM_CLASSES], dim=0)]
        if self.config.amodal:
            probs.append(torch.sigmoid(logits[AMODAL_CHANNEL:AMODAL_CHANNEL + 1]))
        return torch.cat(probs).permute(1, 2, 0).numpy()

    def object_mask(self, image: np.ndarray, size: int | None = SEGMENT_PX, box: Box | None = None
                    ) -> np.ndarray:
        """Probability that each pixel shows the target object, (H, W) float32 in [0, 1], of a
        uint8 RGB image (H, W, 3) of any size: segmented at about `size` x `size` pixels (the
        image scaled, its aspect kept, and the mask scaled back; None: as it is). With `box`
        (the crop stage, `close_look`): only that rectangle of the image (clipped to it) is
        segmented, scaled to about `size`, and the mask is 0 outside it."""
        return self._per_pixel(image, size, box, lambda im: 1.0 - self.class_probabilities(im)[..., 0])

    def carcass_amodal(self, image: np.ndarray, size: int | None = SEGMENT_PX, box: Box | None = None
                       ) -> np.ndarray:
        """Probability that each pixel lies on the target's carcass as if nothing hid it (no
        clutter, neighbour, arm or front in front of it), (H, W) float32 in [0, 1]; `size` and
        `box` as in `object_mask`. NfrDrakeError for a model without that output."""
        if not self.config.amodal:
            raise NfrDrakeError("segmenter: this model has no amodal carcass output (it was trained "
                                "before it existed); retrain it (`nfr-drake train-segmenter`, docs/ROOMS.md) "
                                "or use its visible mask (`object_mask`)")
        return self._per_pixel(image, size, box, lambda im: self._probabilities(im)[..., AMODAL_CHANNEL])

    def _per_pixel(self, image: np.ndarray, size: int | None, box: Box | None, pick) -> np.ndarray:
        """`pick` (a uint8 RGB image (h, w, 3) -> a probability (h, w)) over the image, at about
        `size` px, within `box` (0 outside it); `object_mask` says how."""
        image = np.asarray(image)
        h, w = image.shape[:2]
        if box is not None:
            x0, y0 = max(int(box[0]), 0), max(int(box[1]), 0)
            x1, y1 = min(int(box[2]), w), min(int(box[3]), h)
            mask = np.zeros((h, w), np.float32)
            if x1 - x0 >= 2 and y1 - y0 >= 2:
                mask[y0:y1, x0:x1] = self._per_pixel(image[y0:y1, x0:x1], size, None, pick)
            return mask
        usable = size is not None and image.ndim == 3 and image.dtype == np.uint8 and min(h, w) >= 2
        scale = size / np.sqrt(h * w) if usable else 1.0
        if abs(scale - 1.0) < 0.02:
            return np.ascontiguousarray(pick(image), np.float32)
        small = cv2.resize(image, (max(round(w * scale), 2), max(round(h * scale), 2)),
                           interpolation=cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR)
        mask = np.ascontiguousarray(pick(small), np.float32)
        return cv2.resize(mask, (w, h), interpolation=cv2.INTER_LINEAR)

    def close_look(self, image: np.ndarray, box: Box | None = None, size: int | None = SEGMENT_PX,
                   margin: float = CROP_MARGIN) -> np.ndarray:
        """The crop stage: the object's mask (H, W) float32 in [0, 1] from a second look at the
        crop around it, so that a small object fills the network's input as in its training
        photos. The crop is `box`, or (None) the square around the first look's mask
        (`object_mask`, `square_box` with `margin`); the first mask when that is empty."""
        if box is None:
            first = self.object_mask(image, size)
            box = square_box(first > 0.5, margin)
            if box is None:
                return first
        return self.object_mask(image, size, box)


def square_box(mask: np.ndarray, margin: float = CROP_MARGIN) -> Box | None:
    """The square pixel rectangle centred on the bounding box of a boolean mask (H, W), its side
    the box's longer side plus `margin` of it on each side (it may reach beyond the image); None
    for an empty mask."""
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return None
    return square_around(cols.min(), rows.min(), cols.max() + 1, rows.max() + 1, margin)


def square_around(x0: float, y0: float, x1: float, y1: float, margin: float = CROP_MARGIN) -> Box:
    """The square pixel rectangle centred on the rectangle (x0, y0)-(x1, y1) (pixels, ends
    exclusive), its side the longer side plus `margin` of it on each side, at least 4 px."""
    half = max(max(x1 - x0, y1 - y0) * (0.5 + margin), 2.0)
    cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
    return (int(np.floor(cx - half)), int(np.floor(cy - half)), int(np.ceil(cx + half)),
            int(np.ceil(cy + half)))


def save_segmenter(folder: Path, net: Segmenter, record: dict) -> None:
    """Write `model.safetensors` and `config.json` (`record` plus the architecture under "model")
    into `folder`, each atomically."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    save_file({k: v.contiguous() for k, v in net.state_dict().items()}, str(folder / f"{WEIGHTS_FILE}.tmp"))
    (folder / f"{WEIGHTS_FILE}.tmp").replace(folder / WEIGHTS_FILE)
    doc = {**record, "model": asdict(net.config)}
    (folder / f"{CONFIG_FILE}.tmp").write_text(json.dumps(doc, indent=2) + "\n")
    (folder / f"{CONFIG_FILE}.tmp").replace(folder / CONFIG_FILE)


def load_segmenter(folder: Path) -> tuple[Segmenter, dict]:
    """A trained segmenter and its record from a folder (`models/segmenter`); CheckpointError
    naming the file that is missing or damaged."""
    folder = Path(folder)
    record = read_json(folder / CONFIG_FILE, CheckpointError, "segmenter config")
    try:
        net = Segmenter(SegmenterConfig.from_json(record["model"]))
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{folder / CONFIG_FILE}: not a segmenter ({err})") from None
    load_strict(net, read_tensors(folder / WEIGHTS_FILE), folder / WEIGHTS_FILE)
    net.eval()
    return net, record
