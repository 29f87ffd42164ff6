"""Several articulation slots (furniture): the slot code, the keypoint head's slot outputs, the
one-slot models unchanged, a tiny furniture model that learns, and bit-exact resume."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from nfr_drake.cli import main
from nfr_drake.data.slot_dataset import SlotDataset
from nfr_drake.nfr.checkpoint import WEIGHTS_FILE, load_model, read_tensors
from nfr_drake.nfr.config import LossConfig, SamplerConfig
from nfr_drake.nfr.latent import compose_z, slots_q_to_z_art, split_z, z_art_to_q
from nfr_drake.nfr.losses import nfr_loss
from nfr_drake.nfr.model import NFRAutoDecoder, NFRModel
from nfr_drake.nfr.rays import Rays, pixel_rays
from nfr_drake.nfr.sampling import RaySampler

REPO = Path(__file__).resolve().parents[2]
S = 8


def test_slot_codes_are_normalised_per_slot_and_round_trip():
    q = torch.rand(5, S, dtype=torch.float64)
    z_art = slots_q_to_z_art(q, S)
    assert z_art.shape == (5, 2 * S)
    torch.testing.assert_close(z_art[:, 6:8], torch.stack([torch.cos(math.pi * q[:, 3]),
                                                            torch.sin(math.pi * q[:, 3])], -1))
    lengths = 0.1 + 3 * torch.rand(5, S, dtype=torch.float64)
    raw = z_art * lengths.repeat_interleave(2, -1)
    z = compose_z(raw, torch.randn(5, 7, dtype=torch.float64))
    art, obj = split_z(z, S)
    assert art.shape == (5, 2 * S) and obj.shape == (5, 7)
    torch.testing.assert_close(art.unflatten(-1, (S, 2)).norm(dim=-1),
                               torch.ones(5, S, dtype=torch.float64))
    torch.testing.assert_close(z_art_to_q(art.unflatten(-1, (S, 2))), q)
    # Scaling one slot changes nothing.
    scaled = raw.clone()
    scaled[:, 4:6] *= 10
    torch.testing.assert_close(compose_z(scaled, obj), z)


def test_keypoint_head_gives_keypoints_and_slot_logits(tiny_config):
    cfg = replace(tiny_config, num_slots=S, num_keypoints=4 * S)
    assert (cfg.latent_dim, cfg.slot_logits) == (2 * S + cfg.latent_obj_dim, 3)
    model = NFRModel(cfg)
    z = torch.randn(3, cfg.latent_dim)
    assert model.keypoints(z).shape == (3, 4 * S, 3)
    assert model.slot_logits(z).shape == (3, S, 3)
    rays = Rays(torch.zeros(3, 5, 3) + torch.tensor([2.0, 0, 0.5]),
                torch.tensor([-1.0, 0, 0]).expand(3, 5, 3))
    out = model.render(z, rays)
    assert out.rgb.shape == (3, 5, 3) and out.logits.shape == (3, 5, 4)
    # The networks see each slot on its circle: a longer z_art gives the same read-outs.
    longer = z.clone()
    longer[:, :2 * S] *= 4
    torch.testing.assert_close(model.keypoints(longer), model.keypoints(z))
    one = NFRModel(tiny_config)
    assert one.slot_logits(torch.randn(2, tiny_config.latent_dim)).shape == (2, 1, 0)


@pytest.mark.parametrize("name", ["closet", "drawer"])
def test_shipped_one_slot_models_load_bit_exactly(name):
    folder = REPO / "models" / name
    model, codes, config = load_model(folder)
    assert model.config.num_slots == 1 and model.config.latent_dim == 2 + codes.shape[1]
    stored = read_tensors(folder / WEIGHTS_FILE)
    for key, value in model.state_dict().items():
        assert torch.equal(value, stored[key]), key
    # Gamma reads [z_art / |z_art|, z_obj], exactly as the paper's one-slot head.
    z = torch.cat([torch.tensor([[0.3, 0.4]]), codes[:1]], -1)
    net = model.keypoint_head.net
    expected = net(torch.cat([z[:, :2] / 0.5, z[:, 2:]], -1)).view(1, -1, 3)
    assert torch.equal(model.keypoints(z), expected)


def test_tiny_furniture_model_learns_slots(furniture_dataset, tiny_config):
    """One fixed batch of a furniture dataset: every loss term with slots falls."""
    torch.manual_seed(0)
    data = SlotDataset(furniture_dataset)
    cfg = replace(tiny_config, num_slots=S, num_keypoints=len(data.keypoint_names),
                  bound_center=(0.35, 0.0, 1.0), bound_radius=1.6)
    module = NFRAutoDecoder(cfg, data.num_objects)
    sampler = RaySampler(data.records, data.camera.K,
                         SamplerConfig(images_per_batch=4, rays_per_image=64), 0, slots=data.slots)
    b = sampler.sample()
    assert b.q.shape == (4, S) and b.exists.shape == (4, S) and b.keypoints.shape == (4, 4 * S, 3)
    opt = torch.optim.Adam(module.parameters(), lr=3e-3)
    history = []
    for _ in range(150):
        render, kp, z = module(b.object_index, b.q, pixel_rays(b.uv, b.K, b.X_OC))
        terms = nfr_loss(render, kp, z[:, cfg.art_dim:], b.rgb, b.labels, b.keypoints,
                         LossConfig(), module.model.slot_logits(z), b.exists, b.types)
        opt.zero_grad()
        terms.total.backward()
        opt.step()
        history.append(terms)
    first, last = history[0], history[-1]
    assert last.total < 0.2 * first.total, (first, last)
    assert last.slots < 0.5 * first.slots and last.keypoint < 0.1 * first.keypoint, (first, last)


def test_keypoint_loss_ignores_slots_without_a_front(tiny_config):
    from nfr_drake.nfr.losses import keypoint_loss

    pred, target = torch.zeros(1, 8, 3), torch.zeros(1, 8, 3)
    target[0, 4:] = 1.0  # slot 1 (keypoints 4..7) is wrong but absent
    mask = torch.tensor([[True, False]]).repeat_interleave(4, 1)
    assert keypoint_loss(pred, target, mask) == 0
    assert keypoint_loss(pred, target) == 1.5


def test_furniture_training_resumes_bit_exactly(furniture_dataset, tmp_path):
    tiny = ["--model.field-width", "8", "--model.feature-dim", "8", "--model.hyper-hidden", "8",
            "--model.march-steps", "3", "--model.latent-obj-dim", "4", "--model.keypoint-hidden",
            "8", "--model.bound-center", "0.35", "0", "1.0", "--model.bound-radius", "1.6",
            "--sampler.images-per-batch", "2", "--sampler.rays-per-image", "16",
            "--log-every", "2", "--val-every", "4", "--ckpt-every", "2", "--val-images", "2",
            "--threads", "1", "--keep-checkpoints", "5"]
    data = ["--data", str(furniture_dataset)]
    assert main(["train", *data, "--out", str(tmp_path / "straight"), "--optim.steps", "4",
                 *tiny]) == 0
    assert main(["train", *data, "--out", str(tmp_path / "split"), "--optim.steps", "2",
                 *tiny]) == 0
    assert main(["train", *data, "--out", str(tmp_path / "split"), "--optim.steps", "4",
                 "--resume", *tiny]) == 0
    a = read_tensors(tmp_path / "straight" / "checkpoints" / "step_0000004" / WEIGHTS_FILE)
    b = read_tensors(tmp_path / "split" / "checkpoints" / "step_0000004" / WEIGHTS_FILE)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    _, _, config = load_model(tmp_path / "split" / "best")
    assert config["architecture"]["num_slots"] == S
    assert config["keypoint_names"][:2] == ["front0/handle", "front0/goal"]
    assert "slot_exists_acc" in (tmp_path / "split" / "val.csv").read_text()


def test_fresh_runs_start_the_keypoint_head_at_the_mean_keypoints(furniture_dataset, tiny_config):
    from nfr_drake.nfr.train import _start_keypoints_at_mean

    data = SlotDataset(furniture_dataset)
    cfg = replace(tiny_config, num_slots=S, num_keypoints=len(data.keypoint_names))
    module = NFRAutoDecoder(cfg, data.num_objects)
    _start_keypoints_at_mean(module, data)
    bias = module.model.keypoint_head.net[-1].bias.detach()
    assert bias.shape == (3 * 4 * S + 3 * S,)
    handles = [t.keypoints[:, 0, 0] for t in data.slots if t.exists[0]]  # slot 0's handle
    torch.testing.assert_close(bias[:3], torch.from_numpy(np.concatenate(handles).mean(0)))
    absent = [k for k in range(S) if not any(t.exists[k] for t in data.slots)]
    if absent:  # a slot no object has starts at the mean of all keypoints
        k = absent[0]
        assert torch.isfinite(bias[12 * k:12 * k + 12]).all()


def test_march_init_step_moves_the_first_steps_forward(tiny_config):
    """Furniture cameras sit inside the bounding sphere: with march_init_step the untrained
    marcher advances about that far per step instead of staying near its start."""
    torch.manual_seed(0)
    R = 256
    rays = Rays(torch.zeros(1, R, 3), torch.nn.functional.normalize(torch.randn(1, R, 3), dim=-1))
    near, far = torch.full((1, R), 0.5), torch.full((1, R), 3.0)
    feature = lambda p: torch.zeros(*p.shape[:-1], tiny_config.feature_dim)  # noqa: E731
    config = replace(tiny_config, march_max_step=0.35, march_init_step=0.1)
    with torch.no_grad():
        trace = NFRModel(config).marcher(feature, rays, near, far).depth_trace
    advance = (trace[..., -1] - trace[..., 0]).mean().item()
    assert advance == pytest.approx(0.1 * config.march_steps, rel=0.3)
    with pytest.raises(Exception, match="march_init_step"):
        replace(tiny_config, march_max_step=0.3, march_init_step=0.3)


def test_shipped_furniture_model_has_eight_slots_and_fits_the_size_limit():
    folder = REPO / "models" / "furniture"
    model, codes, config = load_model(folder)
    assert model.config.num_slots == S and model.config.num_keypoints == 4 * S
    assert config["keypoint_names"][4:6] == ["front1/handle", "front1/goal"]
    assert sum(f.stat().st_size for f in folder.rglob("*") if f.is_file()) < 25e6  # baseline/ too
    z = torch.cat([slots_q_to_z_art(torch.zeros(1, S), S), codes[:1]], -1)
    assert model.slot_logits(z).shape == (1, S, 3) and torch.isfinite(model.keypoints(z)).all()
