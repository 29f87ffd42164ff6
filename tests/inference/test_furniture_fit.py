"""The furniture fit: z of a model with several slots from a capture set, and forward simulation
of one part with the others held."""

from dataclasses import replace

import numpy as np
import pytest
import torch

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import observed_rays
from nfr_drake.inference.furniture_fit import (
    FurnitureFitConfig,
    fit_furniture,
    part_trajectory,
    parts_json,
)
from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.model import NFRModel

S = 8
TINY = NFRModelConfig(latent_obj_dim=4, hyper_hidden=8, field_width=8, field_layers=2,
                      feature_dim=8, pe_frequencies=1, march_steps=3, lstm_hidden=4,
                      pixel_hidden=8, keypoint_hidden=8, num_slots=S, num_keypoints=4 * S,
                      bound_center=(0.35, 0.0, 1.0), bound_radius=1.6)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("furniture_captures")
    captures_command(category="furniture", n=1, out=out, views=2, size=24, seed=3)
    return read_capture_set(out / "furniture_000")


def test_fit_gives_every_slot_and_moves_z(capture):
    torch.manual_seed(0)
    model = NFRModel(TINY).eval().requires_grad_(False)
    codes = torch.randn(5, TINY.latent_obj_dim) * 0.1
    config = FurnitureFitConfig(starts=3, keep=2, steps=5, rays_per_step=64, lookup_rays=64)
    fit = fit_furniture(model, observed_rays(capture), codes, config)
    assert fit.z.shape == (TINY.latent_dim,) and fit.q.shape == (S,)
    assert fit.exists.shape == (S,) and fit.keypoints.shape == (S, 4, 3)
    assert ((fit.q >= 0) & (fit.q <= 1)).all() and np.isfinite(fit.image_loss)
    assert not any(torch.allclose(fit.z[2 * S:], c) for c in codes), "z_obj did not move"
    fit.exists[:] = [True, False, True] + [False] * (S - 3)
    parts = parts_json(model, fit, np.linspace(0, 1, 5))
    assert [p["index"] for p in parts] == [0, 2]
    assert set(parts[0]) == {"index", "type", "q", "keypoints", "trajectory"}
    assert parts[0]["type"] in PART_TYPES and list(parts[0]["keypoints"]) == list(SLOT_KEYPOINTS)
    assert np.asarray(parts[1]["trajectory"]["keypoints"]["handle"]).shape == (5, 3)


def test_part_trajectory_sweeps_one_slot_and_holds_the_others():
    torch.manual_seed(1)
    model = NFRModel(TINY).eval()
    z = torch.randn(TINY.latent_dim)
    grid = np.linspace(0, 1, 4)
    path = part_trajectory(model, z, 3, grid)
    assert path.shape == (4, 4, 3)
    # The same as the head on codes whose slot 3 alone is set to each q.
    for i, q in enumerate(grid):
        code = z.clone()
        code[6:8] = torch.tensor([np.cos(np.pi * q), np.sin(np.pi * q)])
        np.testing.assert_allclose(path[i], model.keypoints(code[None])[0, 12:16].detach().numpy(),
                                   atol=1e-6)


def test_fit_refuses_a_one_slot_model(capture):
    model = NFRModel(replace(TINY, num_slots=1, num_keypoints=4))
    with pytest.raises(ConfigError, match="several articulation slots"):
        fit_furniture(model, observed_rays(capture), torch.zeros(2, 4))
