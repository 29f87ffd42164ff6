"""The detector network (`HandleDetector`), its architecture (`HandleDetectorConfig`), and a
detector folder (`model.safetensors` + `config.json`) written and read."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from safetensors.torch import save_file
from torch import nn

from nfr_drake.errors import ConfigError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import CheckpointError, load_strict, read_tensors
from nfr_drake.perception.front_reading import FRONT_HEIGHT_PX, FrontMap
from nfr_drake.perception.handle_triangulation import HandleMap

DETECTOR_DIR = "handle_detector"
"""The detector's folder inside a model folder."""
OFFSET_SCALE_PX = 4.0
"""The offset outputs are in units of this many pixels (keeps them near 1 for the optimiser)."""
CORNER_SCALE_PX = 16.0
"""The corner offset outputs are in units of this many pixels."""


@dataclass(frozen=True)
class HandleDetectorConfig:
    """Architecture: 3x3 convolutions of `channels` channels with these dilations, then a 1x1
    convolution to three outputs per pixel (handle logit, du, dv); with `fronts` also a
    `FrontNet` of `front_channels` base channels (`nfr_drake.perception.front_reading`)."""

    channels: int = 32
    dilations: tuple[int, ...] = (1, 1, 2, 4, 8, 16, 1)
    fronts: bool = False
    front_channels: int = 32

    def __post_init__(self):
        if min(self.channels, self.front_channels) < 1 or not self.dilations or min(self.dilations) < 1:
            raise ConfigError("handle detector: channels and dilations must be positive")

    @classmethod
    def from_json(cls, d: dict) -> HandleDetectorConfig:
        return cls(channels=int(d["channels"]), dilations=tuple(int(x) for x in d["dilations"]),
                   fronts=bool(d.get("fronts", False)), front_channels=int(d.get("front_channels", 32)))


def _conv(c_in: int, c_out: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, stride=stride, padding=dilation, dilation=dilation),
                         nn.ReLU())


class FrontNet(nn.Module):
    """(B, 3, H, W) RGB in [0, 1] (the image scaled to `FRONT_HEIGHT_PX` rows) -> front logits
    (the pixel shows a door or a drawer) and door logits (its front is a door), (B, H, W) each,
    and offsets to its front's projected face corners (B, 4, 2, H, W), pixels. An encoder-decoder:
    three stride-2 stages (channels c, 1.5 c, 2 c, 3 c) and two dilated convolutions at 1/8 scale
    see the whole image (a front is read from its edges and gaps, far from the handle); each
    decoder stage doubles the scale and joins the encoder's features there."""

    def __init__(self, c: int):
        super().__init__()
        widths = (c, c * 3 // 2, 2 * c, 3 * c)
        self.down = nn.ModuleList([nn.Sequential(_conv(3, widths[0]), _conv(widths[0], widths[0]))]
                                  + [nn.Sequential(_conv(a, b, stride=2), _conv(b, b))
                                     for a, b in zip(widths[:-1], widths[1:], strict=True)])
        self.middle = nn.Sequential(_conv(widths[-1], widths[-1], dilation=2),
                                    _conv(widths[-1], widths[-1], dilation=4))
        self.up = nn.ModuleList([_conv(a + b, b) for a, b in zip(widths[:0:-1], widths[-2::-1], strict=True)])
        self.out = nn.Conv2d(widths[0], 10, 1)

    def forward(self, rgb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        x, skips = rgb - 0.5, []
        for stage in self.down:
            x = stage(x)
            skips.append(x)
        x = self.middle(x)
        for stage, skip in zip(self.up, skips[-2::-1], strict=True):
            x = stage(torch.cat([nn.functional.interpolate(x, size=skip.shape[2:], mode="bilinear",
                                                           align_corners=False), skip], 1))
        out = self.out(x)
        B, _, H, W = out.shape
        return out[:, 0], out[:, 1], out[:, 2:].view(B, 4, 2, H, W) * CORNER_SCALE_PX


TUNABLE = ("fronts", "handles")
"""What `HandleDetector.start_from` can go on training: the front network or the handle network."""


class HandleDetector(nn.Module):
    """(B, 3, H, W) RGB in [0, 1] -> handle logits (B, H, W) and offsets to the projected grip
    centre (B, 2, H, W), pixels (du right, dv down); any H and W. With front outputs also a
    `FrontNet` (`fronts`), run on the image scaled to `FRONT_HEIGHT_PX` rows (`read_fronts`)."""

    def __init__(self, config: HandleDetectorConfig):
        super().__init__()
        self.config = config
        layers, c_in = [], 3
        for d in config.dilations:
            layers += [nn.Conv2d(c_in, config.channels, 3, padding=d, dilation=d), nn.ReLU()]
            c_in = config.channels
        layers.append(nn.Conv2d(c_in, 3, 1))
        self.net = nn.Sequential(*layers)
        self.fronts = FrontNet(config.front_channels) if config.fronts else None

    def forward(self, rgb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.net(rgb - 0.5)
        return out[:, 0], out[:, 1:] * OFFSET_SCALE_PX

    def start_from(self, other: HandleDetector, tune: str = "fronts") -> None:
        """Take another detector's handle network (same channels and dilations) and, where both
        have front outputs of the same width, its front network; `tune` names the one that goes
        on training, the other is kept fixed: "fronts" (front outputs added to a trained handle
        detector, or trained further) or "handles" (the handle network trained further, the
        front network as it was)."""
        if tune not in TUNABLE:
            raise ConfigError(f"handle detector: tune is one of {TUNABLE}, not {tune!r}")
        if (other.config.channels, other.config.dilations) != (self.config.channels, self.config.dilations):
            raise ConfigError("handle detector: the detector to start from has another architecture "
                              f"({other.config.channels} channels, dilations {other.config.dilations})")
        self.net.load_state_dict(other.net.state_dict())
        if self.fronts is not None and other.fronts is not None:
            if other.config.front_channels != self.config.front_channels:
                raise ConfigError("handle detector: the detector to start from has front outputs of "
                                  f"another width ({other.config.front_channels} channels)")
            self.fronts.load_state_dict(other.fronts.state_dict())
        elif self.fronts is not None and tune == "handles":
            raise ConfigError("handle detector: the detector to start from has no front outputs to "
                              "keep while its handle network trains")
        self.net.requires_grad_(tune == "handles")
        if self.fronts is not None:
            self.fronts.requires_grad_(tune == "fronts")

    @torch.no_grad()
    def detect(self, images: list[np.ndarray]) -> list[HandleMap]:
        """The handle map of each uint8 RGB image (H, W, 3)."""
        self.eval()
        out = []
        for img in images:
            x = torch.from_numpy(np.ascontiguousarray(img, np.float32) / 255.0).permute(2, 0, 1)
            logits, offsets = self(x[None])
            out.append(HandleMap(torch.sigmoid(logits)[0].numpy(),
                                 offsets[0].permute(1, 2, 0).numpy()))
        return out

    @torch.no_grad()
    def read_fronts(self, images: list[np.ndarray]) -> list[FrontMap]:
        """The front map of each uint8 RGB image (H, W, 3), read on the image scaled to
        `FRONT_HEIGHT_PX` rows; ConfigError for a detector without front outputs."""
        if self.fronts is None:
            raise ConfigError("this handle detector has no front outputs (train it with --fronts)")
        self.eval()
        out = []
        for img in images:
            width = max(8, round(img.shape[1] * FRONT_HEIGHT_PX / img.shape[0]))
            small = cv2.resize(img, (width, FRONT_HEIGHT_PX), interpolation=cv2.INTER_AREA)
            x = torch.from_numpy(np.ascontiguousarray(small, np.float32) / 255.0).permute(2, 0, 1)
            front, door, corners = self.fronts(x[None])
            out.append(FrontMap(torch.sigmoid(front)[0].numpy(), torch.sigmoid(door)[0].numpy(),
                                corners[0].permute(2, 3, 0, 1).numpy(),
                                np.array([img.shape[1] / width, img.shape[0] / FRONT_HEIGHT_PX])))
        return out


def save_detector(folder: Path, net: HandleDetector, record: dict) -> None:
    """Write `model.safetensors` and `config.json` (`record`, with the architecture under
    "model") into `folder`, each atomically."""
    folder.mkdir(parents=True, exist_ok=True)
    save_file(net.state_dict(), str(folder / "model.safetensors.tmp"))
    (folder / "model.safetensors.tmp").replace(folder / "model.safetensors")
    (folder / "config.json.tmp").write_text(json.dumps(record, indent=2) + "\n")
    (folder / "config.json.tmp").replace(folder / "config.json")


def load_detector(folder: Path) -> tuple[HandleDetector, dict]:
    """A trained detector and its record from a `handle_detector/` folder; CheckpointError
    naming the file that is missing or damaged."""
    folder = Path(folder)
    record = read_json(folder / "config.json", CheckpointError, "handle detector config")
    try:
        net = HandleDetector(HandleDetectorConfig.from_json(record["model"]))
    except (KeyError, TypeError, ValueError) as err:
        raise CheckpointError(f"{folder / 'config.json'}: not a handle detector ({err})") from None
    load_strict(net, read_tensors(folder / "model.safetensors"), folder / "model.safetensors")
    net.eval()
    return net, record
