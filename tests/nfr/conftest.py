"""Shared fixtures of the neural-field tests: a tiny architecture and a tiny rendered dataset."""

import pytest
import torch

from nfr_drake.nfr.config import NFRModelConfig

TINY = NFRModelConfig(latent_obj_dim=4, hyper_hidden=8, field_width=8, field_layers=2,
                      feature_dim=8, pe_frequencies=1, march_steps=3, lstm_hidden=4,
                      pixel_hidden=8, keypoint_hidden=8)
"""Small enough for float64 gradcheck and instant forward passes."""


@pytest.fixture
def tiny_config() -> NFRModelConfig:
    return TINY


@pytest.fixture(autouse=True)
def _one_thread():
    old = torch.get_num_threads()
    torch.set_num_threads(1)  # 2 threads stall when another process holds a core
    yield
    torch.set_num_threads(old)

