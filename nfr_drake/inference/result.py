"""The fit result file of `nfr-drake infer` (docs/CONVENTIONS.md), read and written."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nfr_drake.errors import NfrDrakeError


@dataclass
class FitResult:
    """What a fit found, positions in the frame of the capture's camera poses (frame O), metres.

    Attributes:
        category: the model's category.
        q: estimated articulation in [0, 1].
        keypoints: name -> (3,) at q.
        trajectory_q: (N,) articulation grid over [0, 1].
        trajectory: name -> (N, 3) keypoints along `trajectory_q`.
        image_loss: mean squared RGB error of the final fit on the observed pixels (0..1 scale).
        seconds: wall time of the fit.
        z: the fitted latent code [z_art, z_obj], for re-rendering.
        confidence: how well the fit explains the photos and P(handle within 2 cm)
            (`inference.infer.fit_confidence`), or None.
        extra: anything else worth keeping (restarts, steps, model path).
    """

    category: str
    q: float
    keypoints: dict[str, np.ndarray]
    trajectory_q: np.ndarray
    trajectory: dict[str, np.ndarray]
    image_loss: float
    seconds: float
    z: np.ndarray | None = None
    confidence: dict | None = None
    extra: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        doc = {
            "category": self.category,
            "q": float(self.q),
            "keypoints": {k: np.asarray(v, float).tolist() for k, v in self.keypoints.items()},
            "trajectory": {
                "q": np.asarray(self.trajectory_q, float).tolist(),
                "keypoints": {k: np.asarray(v, float).tolist() for k, v in self.trajectory.items()},
            },
            "image_loss": float(self.image_loss),
            "seconds": float(self.seconds),
        }
        if self.z is not None:
            doc["z"] = np.asarray(self.z, float).tolist()
        if self.confidence is not None:
            doc["confidence"] = self.confidence
        if self.extra:
            doc["extra"] = self.extra
        return doc

    def write(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=2))

    @classmethod
    def from_json(cls, doc: dict) -> FitResult:
        return cls(
            category=doc["category"],
            q=float(doc["q"]),
            keypoints={k: np.asarray(v, float) for k, v in doc["keypoints"].items()},
            trajectory_q=np.asarray(doc["trajectory"]["q"], float),
            trajectory={k: np.asarray(v, float) for k, v in doc["trajectory"]["keypoints"].items()},
            image_loss=float(doc["image_loss"]),
            seconds=float(doc["seconds"]),
            z=np.asarray(doc["z"], float) if "z" in doc else None,
            confidence=doc.get("confidence"),
            extra=doc.get("extra", {}),
        )

    @classmethod
    def read(cls, path: str | Path) -> FitResult:
        try:
            return cls.from_json(json.loads(Path(path).read_text()))
        except (OSError, json.JSONDecodeError, KeyError, TypeError) as err:
            raise NfrDrakeError(f"{path}: not a readable fit result ({err})") from None
