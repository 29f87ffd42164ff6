"""The paper's image-encoder baseline: encode each posed view, average, regress q and keypoints.

Each view goes through a small ResNet-style downward path (the paper used ResNet-34 in a U-Net;
this CPU-sized version keeps the residual stages and global pooling); its camera pose (rotation and
translation of X_OC) is appended to the pooled features and mixed by an MLP. The per-view codes are
averaged over views, and a head predicts, per part slot (one for closets and drawers; furniture's
`MAX_FRONTS`, slot k = front k in canonical order as the neural field's, docs/NEURAL_FIELD.md
"Furniture: several parts"), the current articulation q and the K keypoints in frame O; for
prismatic categories the joint travel at q = 1 (m), which the straight-pull assumption needs to
extrapolate keypoints to other q (`extrapolate_keypoints`); for furniture whether the slot holds
a front and whether it is a door or a drawer, the keypoints those of the field's slots
(`SLOT_KEYPOINTS`: a drawer's axis points give its pull line and travel,
`nfr_drake.data.slot_dataset.slot_trajectory`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS
from nfr_drake.errors import ConfigError

JOINT_TYPES = ("revolute", "prismatic", "per_slot")
"""A baseline's joint types: closets, drawers, and furniture (each slot's predicted type)."""


@dataclass(frozen=True)
class BaselineConfig:
    """Architecture of the image-encoder baseline.

    Attributes:
        category: object category the model was trained on.
        keypoint_names: keypoints predicted per slot, in this order.
        joint_type: "revolute" (closets), "prismatic" (drawers) or "per_slot" (furniture: each
            slot's predicted type, door or drawer; keypoint_names are `SLOT_KEYPOINTS`).
        channels: channels of the residual stages; each stage halves the resolution.
        embed_dim: width of the per-view code and the head.
        num_slots: part slots S (1 but for "per_slot").
    """

    category: str
    keypoint_names: tuple[str, ...]
    joint_type: str
    channels: tuple[int, ...] = (24, 48, 96, 192)
    embed_dim: int = 256
    num_slots: int = 1

    def __post_init__(self):
        if self.joint_type not in JOINT_TYPES:
            raise ConfigError(f"joint_type must be one of {JOINT_TYPES}, got {self.joint_type!r}")
        if not self.keypoint_names or "handle" not in self.keypoint_names:
            raise ConfigError("keypoint_names must include 'handle'")
        if (self.num_slots > 1) != (self.joint_type == "per_slot") or self.num_slots < 1:
            raise ConfigError("num_slots is 1, or more for joint_type 'per_slot'")
        if self.joint_type == "per_slot" and tuple(self.keypoint_names) != SLOT_KEYPOINTS:
            raise ConfigError(f"a 'per_slot' baseline predicts the slot keypoints {SLOT_KEYPOINTS}")
        if not self.channels or min(self.channels) < 1 or self.embed_dim < 1:
            raise ConfigError("channels and embed_dim must be positive")

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> BaselineConfig:
        return cls(**{**d, "keypoint_names": tuple(d["keypoint_names"]),
                      "channels": tuple(d["channels"])})


class _ResidualStage(nn.Module):
    """Strided residual block: (B, C_in, H, W) -> (B, C_out, H/2, W/2)."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride=2, padding=1, bias=False)
        self.norm1 = nn.GroupNorm(min(8, c_out), c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, padding=1, bias=False)
        self.norm2 = nn.GroupNorm(min(8, c_out), c_out)
        self.skip = nn.Conv2d(c_in, c_out, 1, stride=2, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = torch.relu(self.norm1(self.conv1(x)))
        return torch.relu(self.norm2(self.conv2(y)) + self.skip(x))


@dataclass
class BaselineOutput:
    """Per slot (S = `BaselineConfig.num_slots`): q (B, S) in [0, 1]; keypoints (B, S, K, 3) in O,
    m; travel (B, S) m (prismatic only, else 0); exists (B, S) and types (B, S, 2) logits (whether
    the slot holds a front; door or drawer, `PART_TYPES`), "per_slot" only, else None."""

    q: torch.Tensor
    keypoints: torch.Tensor
    travel: torch.Tensor
    exists: torch.Tensor | None = None
    types: torch.Tensor | None = None


class ImageEncoderBaseline(nn.Module):
    """images (B, V, 3, S, S) in [0, 1] and poses X_OC (B, V, 4, 4) -> BaselineOutput."""

    def __init__(self, config: BaselineConfig):
        super().__init__()
        self.config = config
        chans = (3, *config.channels)
        self.stages = nn.Sequential(*[_ResidualStage(a, b) for a, b in zip(chans[:-1], chans[1:],
                                                                            strict=True)])
        self.view_mlp = nn.Sequential(nn.Linear(config.channels[-1] + 12, config.embed_dim),
                                      nn.ReLU(), nn.Linear(config.embed_dim, config.embed_dim))
        # per slot: q, the keypoints, then the travel or (per_slot) the exists and type logits
        n_out = config.num_slots * (1 + 3 * len(config.keypoint_names)
                                    + (1 + len(PART_TYPES) if config.joint_type == "per_slot" else 1))
        self.head = nn.Sequential(nn.ReLU(), nn.Linear(config.embed_dim, config.embed_dim),
                                  nn.ReLU(), nn.Linear(config.embed_dim, n_out))

    def forward(self, images: torch.Tensor, X_OC: torch.Tensor) -> BaselineOutput:
        B, V = images.shape[:2]
        features = self.stages(images.flatten(0, 1)).mean(dim=(-2, -1))  # (B V, C)
        pose = torch.cat([X_OC[..., :3, :3].flatten(-2), X_OC[..., :3, 3]], -1).flatten(0, 1)
        codes = self.view_mlp(torch.cat([features, pose], -1)).view(B, V, -1).mean(1)
        out = self.head(codes).view(B, self.config.num_slots, -1)
        K = len(self.config.keypoint_names)
        q, keypoints, rest = out[..., 0], out[..., 1:1 + 3 * K].unflatten(-1, (K, 3)), out[..., 1 + 3 * K:]
        if self.config.joint_type == "per_slot":
            return BaselineOutput(torch.sigmoid(q), keypoints, torch.zeros_like(q), rest[..., 0],
                                  rest[..., 1:])
        travel = nn.functional.softplus(rest[..., 0])
        if self.config.joint_type == "revolute":
            travel = torch.zeros_like(travel)
        return BaselineOutput(torch.sigmoid(q), keypoints, travel)


def extrapolate_keypoints(keypoint_names: tuple[str, ...], joint_type: str, keypoints: np.ndarray,
                          q: float, travel: float, q_grid: np.ndarray) -> np.ndarray:
    """Keypoints at other articulations from one observed state, by explicit geometric assumption.

    Closets: the door turns about a vertical axis through the hinge keypoints by 90 degrees over
    q in [0, 1], opening outward (the axis points down when the hinge is on the -y side of O,
    up otherwise). Drawers: everything on the drawer moves along +x of O by `travel` over [0, 1].

    Args:
        keypoints: (K, 3) at articulation q, in O, m.
        q_grid: (N,) articulations to predict.
    Returns: (N, K, 3).
    """
    names = list(keypoint_names)
    out = np.repeat(np.asarray(keypoints, float)[None], len(q_grid), axis=0)
    dq = np.asarray(q_grid, float) - q
    if joint_type == "prismatic":
        moving = [names.index(n) for n in ("handle", "goal") if n in names]
        out[:, moving, 0] += (dq * travel)[:, None]
        return out
    hinge = np.mean([keypoints[names.index(n)] for n in ("hinge_top", "hinge_bottom")], axis=0)
    sign = -1.0 if hinge[1] < 0 else 1.0
    h = names.index("handle")
    d = keypoints[h, :2] - hinge[:2]
    for i, angle in enumerate(sign * dq * np.pi / 2):
        c, s = np.cos(angle), np.sin(angle)
        out[i, h, :2] = hinge[:2] + [c * d[0] - s * d[1], s * d[0] + c * d[1]]
    return out
