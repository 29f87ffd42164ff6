"""Obstacle boxes."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from nfr_drake.world.plan import ObstacleBox


def test_a_boxs_top_is_its_highest_corner():
    """Level, a box's top is its centre plus half its height; tipped 90 degrees about x, half its
    width; at any pose, the highest of its eight corners."""
    size = np.array([0.2, 0.4, 0.1])
    assert ObstacleBox("level", size, RigidTransform([0.0, 0.0, 1.0])).top == pytest.approx(1.05)
    tipped = ObstacleBox("tipped", size, RigidTransform(RollPitchYaw(np.pi / 2, 0.0, 0.0), [0.0, 0.0, 1.0]))
    assert tipped.top == pytest.approx(1.2)
    turned = ObstacleBox("turned", size, RigidTransform(RollPitchYaw(0.3, -0.7, 1.1), [0.5, 0.2, 0.4]))
    signs = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    assert turned.top == pytest.approx(max((turned.X_WB @ (np.array(s) * size / 2))[2] for s in signs))
