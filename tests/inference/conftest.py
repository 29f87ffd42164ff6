"""A tiny closet model folder shared by the inference tests (random weights, fits in seconds)."""

import pytest
import torch

from nfr_drake.nfr.checkpoint import write_model_folder
from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.model import NFRAutoDecoder

SMALL = NFRModelConfig(latent_obj_dim=8, hyper_hidden=16, field_width=16, feature_dim=16,
                       pe_frequencies=2, march_steps=3, lstm_hidden=8, pixel_hidden=16,
                       keypoint_hidden=16)


@pytest.fixture(scope="module")
def model_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("model") / "closet"
    torch.manual_seed(0)
    write_model_folder(folder, NFRAutoDecoder(SMALL, num_objects=3),
                       {"category": "closet",
                        "keypoint_names": ["handle", "hinge_top", "hinge_bottom", "goal"]})
    return folder
