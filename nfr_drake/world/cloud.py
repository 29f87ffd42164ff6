"""A fitted object's labelled surface points, as the planner reads them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STATIC_CLASS = 1
"""The semantic class of the part that stays put (the carcass)."""
MOVING_CLASSES = (2, 3)
"""The semantic classes of the moving part: its panels and its handle (`SEMANTIC_CLASS_NAMES`:
background, carcass, moving, handle)."""


@dataclass(frozen=True)
class SemanticCloud:
    """Surface points of a fitted object in W, m, (N, 3), their semantic classes (N,), and the
    articulation q in [0, 1] they were rendered at."""

    points: np.ndarray
    classes: np.ndarray
    q: float

    def __post_init__(self):
        if self.points.ndim != 2 or self.points.shape[1:] != (3,) or len(self.classes) != len(self.points):
            raise ValueError(f"points {self.points.shape} and classes {self.classes.shape} do not pair up")

    def moving(self) -> np.ndarray:
        """The moving part's points (its panels and handle), (M, 3)."""
        return self.points[np.isin(self.classes, MOVING_CLASSES)]

    def static(self) -> np.ndarray:
        """The static part's points (the carcass), (S, 3)."""
        return self.points[self.classes == STATIC_CLASS]
