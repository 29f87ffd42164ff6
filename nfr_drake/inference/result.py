"""The fit result file of `nfr-drake infer` (docs/CONVENTIONS.md), read and written."""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from nfr_drake.errors import NfrDrakeError

PART_KEYPOINTS = {"door": {"handle": "handle", "goal": "goal", "axis_0": "hinge_top",
                           "axis_1": "hinge_bottom"},
                  "drawer": {"handle": "handle", "goal": "goal"}}
"""Per part type, a part's keypoints (named as the field's slots name them,
`data.slot_dataset.SLOT_KEYPOINTS`) -> their names in the single-part fields, gt.json and the
planner: a door's axis points are its hinge_top and hinge_bottom; a drawer's (its handle shut and
fully open) have no counterpart."""


@dataclass
class FitResult:
    """What a fit found, positions in the frame of the capture's camera poses (frame O), metres.

    A model with several parts (furniture) lists every part it finds in `parts`; its single-part
    fields (q, keypoints, trajectory) are those of one of them, `part` (`with_part`).

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
        parts: furniture: the parts the field finds, [{index, type, q, keypoints: name -> (3,),
            trajectory: {q (N,), keypoints: name -> (N, 3)}}], keypoints named as the slots name
            them (`PART_KEYPOINTS`), each part swept with the others held; None for one part.
        part: furniture: which part the single-part fields are, {index, type ("door" or
            "drawer"), found (whether it is among `parts`)}; None for one part.
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
    parts: list[dict] | None = None
    part: dict | None = None

    def with_part(self, part: dict) -> FitResult:
        """This result with its single-part fields those of `part` (an entry of `parts`, or one
        alike of a slot the field does not find), keypoints renamed by `PART_KEYPOINTS`, and its
        `confidence` the part's (`part["confidence"]`, the per-view figures kept) when it has one."""
        names = PART_KEYPOINTS[part["type"]]
        path = part["trajectory"]
        confidence = self.confidence
        if part.get("confidence") is not None:
            confidence = {**(self.confidence or {}), **part["confidence"]}
        return replace(
            self, q=float(part["q"]), confidence=confidence,
            keypoints={to: np.asarray(part["keypoints"][n], float) for n, to in names.items()},
            trajectory_q=np.asarray(path["q"], float),
            trajectory={to: np.asarray(path["keypoints"][n], float) for n, to in names.items()},
            part={"index": int(part["index"]), "type": part["type"],
                  "found": any(p["index"] == part["index"] for p in self.parts or [])})

    def part_of(self, index: int) -> FitResult:
        """`with_part` of the part numbered `index` among `parts`; NfrDrakeError when the fit
        found no such part."""
        for part in self.parts or []:
            if part["index"] == index:
                return self.with_part(part)
        found = ", ".join(f"{p['index']} ({p['type']})" for p in self.parts or []) or "none"
        raise NfrDrakeError(f"the fit finds no part {index}; parts found: {found}")

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
        if self.parts is not None:
            doc["parts"] = self.parts
            doc["part"] = self.part
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
            parts=doc.get("parts"),
            part=doc.get("part"),
        )

    @classmethod
    def read(cls, path: str | Path) -> FitResult:
        try:
            return cls.from_json(json.loads(Path(path).read_text()))
        except (OSError, json.JSONDecodeError, KeyError, TypeError) as err:
            raise NfrDrakeError(f"{path}: not a readable fit result ({err})") from None
