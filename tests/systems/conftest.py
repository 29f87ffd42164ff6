"""Shared, expensive fixtures of the simulation tests: one planned and simulated drawer opening."""

import pytest
from pydrake.math import RigidTransform

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.systems.task import run_task


@pytest.fixture(scope="session")
def drawer_object():
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    return SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)


@pytest.fixture(scope="session")
def drawer_outcome(drawer_object, tmp_path_factory):
    """Open the drawer fully from ground-truth keypoints, recording an HTML replay."""
    return run_task(drawer_object, 1.0, replay=tmp_path_factory.mktemp("replay") / "drawer.html")
