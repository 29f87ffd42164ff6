"""The detector network (`HandleDetector`), its architecture (`HandleDetectorConfig`), and a
detector folder (`model.safetensors` + `config.json`) written and read."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import save_file
from torch import nn

from nfr_drake.errors import ConfigError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.checkpoint import CheckpointError, load_strict, read_tensors
from nfr_drake.perception.handle_triangulation import HandleMap

DETECTOR_DIR = "handle_detector"
"""The detector's folder inside a model folder."""
OFFSET_SCALE_PX = 4.0
"""The offset outputs are in units of this many pixels (keeps them near 1 for the optimiser)."""


@dataclass(frozen=True)
class HandleDetectorConfig:
    """Architecture: 3x3 convolutions of `channels` channels with these dilations, then a 1x1
    convolution to three outputs per pixel (handle logit, du, dv)."""

    channels: int = 32
    dilations: tuple[int, ...] = (1, 1, 2, 4, 8, 16, 1)

    def __post_init__(self):
        if self.channels < 1 or not self.dilations or min(self.dilations) < 1:
            raise ConfigError("handle detector: channels and dilations must be positive")

    @classmethod
    def from_json(cls, d: dict) -> HandleDetectorConfig:
        return cls(channels=int(d["channels"]), dilations=tuple(int(x) for x in d["dilations"]))


class HandleDetector(nn.Module):
    """(B, 3, H, W) RGB in [0, 1] -> handle logits (B, H, W) and offsets to the projected grip
    centre (B, 2, H, W), pixels (du right, dv down); any H and W."""

    def __init__(self, config: HandleDetectorConfig):
        super().__init__()
        self.config = config
        layers, c_in = [], 3
        for d in config.dilations:
            layers += [nn.Conv2d(c_in, config.channels, 3, padding=d, dilation=d), nn.ReLU()]
            c_in = config.channels
        layers.append(nn.Conv2d(c_in, 3, 1))
        self.net = nn.Sequential(*layers)

    def forward(self, rgb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.net(rgb - 0.5)
        return out[:, 0], out[:, 1:] * OFFSET_SCALE_PX

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
