"""Shared fixtures of the simulation tests: one planned and simulated drawer opening, the Panda
alone with its tool's pose, and a tiny closet model for the perception system."""

import pytest
import torch
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant

from nfr_drake.inference.fit import FitConfig
from nfr_drake.nfr.checkpoint import write_model_folder
from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.model import NFRAutoDecoder
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.systems.scene_objects import SceneObject
from nfr_drake.systems.task import run_task
from nfr_drake.world.robot import TOOL_FRAME, add_panda


@pytest.fixture(scope="session")
def panda():
    """The Panda arm and hand alone (as the controller's plant), finalized."""
    plant = MultibodyPlant(0.0)
    add_panda(plant)
    plant.Finalize()
    return plant


@pytest.fixture(scope="session")
def tool_pose(panda):
    """The tool frame's pose in W (RigidTransform) at the Panda's positions q (9,)."""
    context = panda.CreateDefaultContext()
    tool = panda.GetFrameByName(TOOL_FRAME)

    def pose(q):
        panda.SetPositions(context, q)
        return tool.CalcPoseInWorld(context)
    return pose


@pytest.fixture(scope="session")
def drawer_object():
    obj = sample_object("drawer", object_rng(SEED_DOMAIN_TRAIN, 3, 0))
    return SceneObject.from_articulated_object(obj, RigidTransform(), 0.0)


@pytest.fixture(scope="session")
def drawer_outcome(drawer_object, tmp_path_factory):
    """Open the drawer fully from ground-truth keypoints, recording an HTML replay."""
    return run_task(drawer_object, 1.0, replay=tmp_path_factory.mktemp("replay") / "drawer.html")


TINY_MODEL = NFRModelConfig(latent_obj_dim=8, hyper_hidden=16, field_width=16, feature_dim=16,
                            pe_frequencies=2, march_steps=3, lstm_hidden=8, pixel_hidden=16,
                            keypoint_hidden=16)
"""An untrained field small enough that a perception test fits it in seconds."""
TINY_FIT = FitConfig(preset="thorough", restarts=2, explore_steps=2, max_steps=5, explore_rays=32,
                     rays_per_step=32, eval_rays=64)
"""A fit of a few steps: what the perception tests check is the plumbing, not the accuracy."""


def write_tiny_closet_model(tmp_path_factory, codes: int):
    """A closet model folder holding the untrained `TINY_MODEL` with `codes` training codes."""
    folder = tmp_path_factory.mktemp("m") / "closet"
    torch.manual_seed(0)
    write_model_folder(folder, NFRAutoDecoder(TINY_MODEL, codes),
                       {"category": "closet",
                        "keypoint_names": ["handle", "hinge_top", "hinge_bottom", "goal"]})
    return folder


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory):
    """`write_tiny_closet_model` with 2 training codes."""
    return write_tiny_closet_model(tmp_path_factory, 2)
