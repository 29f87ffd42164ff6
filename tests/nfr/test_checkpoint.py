"""Model folders: identical outputs after a round trip, clear errors, never unpickling."""

import json
import pickle

import pytest
import torch

from nfr_drake.nfr.checkpoint import (
    CheckpointError,
    init_from_model_folder,
    load_model,
    read_checkpoint,
    write_checkpoint,
    write_model_folder,
)
from nfr_drake.nfr.model import NFRAutoDecoder
from nfr_drake.nfr.rays import Rays

INFO = {"category": "closet", "keypoint_names": ["handle", "hinge_top", "hinge_bottom", "goal"]}


def _rays(B=2, R=10):
    o = torch.tensor([1.8, 0.1, 0.7]).expand(B, R, 3)
    d = torch.nn.functional.normalize(torch.randn(B, R, 3) * 0.2 + torch.tensor([-1.0, 0, -0.2]),
                                      dim=-1)
    return Rays(o, d)


@pytest.fixture
def no_unpickling(monkeypatch):
    """Any attempt to unpickle (or torch.load) during the test fails it."""
    def refuse(*a, **k):
        raise AssertionError("a checkpoint was unpickled")

    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(torch, "load", refuse)


def test_round_trip_gives_identical_outputs(tmp_path, tiny_config, no_unpickling):
    torch.manual_seed(0)
    module = NFRAutoDecoder(tiny_config, num_objects=3).eval()
    write_model_folder(tmp_path / "m", module, INFO)
    assert sorted(p.name for p in (tmp_path / "m").iterdir()) == ["config.json", "model.safetensors"]
    model, codes, config = load_model(tmp_path / "m")
    assert config["category"] == "closet" and config["num_objects"] == 3
    torch.testing.assert_close(codes, module.codes.weight.detach(), rtol=0, atol=0)
    z = module.code(torch.tensor([0, 2]), torch.tensor([0.2, 0.8])).detach()
    rays = _rays()
    a, b = module.model.render(z, rays), model.render(z, rays)
    for x, y in zip(a, b, strict=True):
        torch.testing.assert_close(x, y, rtol=0, atol=0)
    torch.testing.assert_close(module.model.keypoints(z), model.keypoints(z), rtol=0, atol=0)


def test_resumable_checkpoint_round_trip(tmp_path, tiny_config, no_unpickling):
    torch.manual_seed(0)
    module = NFRAutoDecoder(tiny_config, num_objects=2)
    opt = torch.optim.Adam(module.parameters(), 1e-3)
    render, kp, _ = module(torch.tensor([0, 1]), torch.tensor([0.3, 0.6]), _rays())
    (render.rgb.sum() + kp.sum()).backward()
    opt.step()
    write_checkpoint(tmp_path / "c", module, opt, INFO, {"step": 1, "seconds": 0.5})
    other = NFRAutoDecoder(tiny_config, num_objects=2)
    opt2 = torch.optim.Adam(other.parameters(), 1e-3)
    trainer = read_checkpoint(tmp_path / "c", other, opt2)
    assert trainer["step"] == 1
    for p, q in zip(module.parameters(), other.parameters(), strict=True):
        torch.testing.assert_close(p, q, rtol=0, atol=0)
    s1, s2 = opt.state_dict(), opt2.state_dict()
    for k in s1["state"]:
        for name in ("exp_avg", "exp_avg_sq", "step"):
            torch.testing.assert_close(s1["state"][k][name], s2["state"][k][name], rtol=0, atol=0)


def test_corrupt_weights_give_a_clear_error(tmp_path, tiny_config):
    write_model_folder(tmp_path / "m", NFRAutoDecoder(tiny_config, 2), INFO)
    path = tmp_path / "m" / "model.safetensors"
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(CheckpointError, match="not a readable safetensors"):
        load_model(tmp_path / "m")
    path.write_bytes(pickle.dumps({"evil": 1}))
    with pytest.raises(CheckpointError, match="not a readable safetensors"):
        load_model(tmp_path / "m")


def test_other_architecture_gives_a_clear_error(tmp_path, tiny_config):
    from dataclasses import replace

    write_model_folder(tmp_path / "m", NFRAutoDecoder(tiny_config, 2), INFO)
    cfg = json.loads((tmp_path / "m" / "config.json").read_text())
    cfg["architecture"] = replace(tiny_config, field_width=12).to_json()
    (tmp_path / "m" / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(CheckpointError, match="do not match the architecture.*shape mismatch"):
        load_model(tmp_path / "m")


def test_bad_config_json(tmp_path, tiny_config):
    with pytest.raises(CheckpointError, match="not a model folder"):
        load_model(tmp_path)
    write_model_folder(tmp_path / "m", NFRAutoDecoder(tiny_config, 2), INFO)
    (tmp_path / "m" / "config.json").write_text("{broken")
    with pytest.raises(CheckpointError, match="config.json: malformed JSON"):
        load_model(tmp_path / "m")
    (tmp_path / "m" / "config.json").write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(CheckpointError, match="format"):
        load_model(tmp_path / "m")


def test_init_from_adds_octaves_without_changing_the_field(tmp_path, tiny_config):
    """Fine-tuning with more positional-encoding octaves starts from the same function, and the
    new octaves' weights are free parameters (they receive gradients)."""
    from dataclasses import replace

    torch.manual_seed(0)
    old = NFRAutoDecoder(tiny_config, num_objects=3).eval()
    with torch.no_grad():  # make the hypernetwork's z-dependence non-trivial
        for p in old.parameters():
            p.add_(0.05 * torch.randn_like(p))
    write_model_folder(tmp_path / "m", old, INFO)
    new = NFRAutoDecoder(replace(tiny_config, pe_frequencies=3), num_objects=3).eval()
    init_from_model_folder(tmp_path / "m", new)
    z = old.code(torch.tensor([0, 2]), torch.tensor([0.2, 0.8])).detach()
    rays = _rays()
    a, b = old.model.render(z, rays), new.model.render(z, rays)
    for x, y in zip(a, b, strict=True):
        torch.testing.assert_close(x, y, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(new.codes.weight, old.codes.weight, rtol=0, atol=0)
    b.rgb.sum().backward()
    grad = new.model.hyper.layers[0].base_weight.grad  # (out, 3 + 6 * 3)
    highest_octave = [3 + 3 * 2, 3 + 9 + 3 * 2]  # sin and cos of octave 2, x component
    assert grad[:, highest_octave].abs().sum() > 0


def test_init_from_refuses_other_architectures(tmp_path, tiny_config):
    from dataclasses import replace

    write_model_folder(tmp_path / "m", NFRAutoDecoder(tiny_config, 2), INFO)
    for other in (replace(tiny_config, field_width=12), replace(tiny_config, pe_frequencies=0)):
        with pytest.raises(CheckpointError, match="cannot start from this model"):
            init_from_model_folder(tmp_path / "m", NFRAutoDecoder(other, 2))


def test_init_from_grows_the_object_codes(tmp_path, tiny_config):
    """A grown dataset keeps the model's codes for its first objects; new objects start near the
    mean code; fewer objects than the model's are refused."""
    torch.manual_seed(0)
    old = NFRAutoDecoder(tiny_config, num_objects=3, code_init_std=0.5)
    write_model_folder(tmp_path / "m", old, INFO)
    grown = NFRAutoDecoder(tiny_config, num_objects=5, code_init_std=0.0)
    init_from_model_folder(tmp_path / "m", grown)
    torch.testing.assert_close(grown.codes.weight[:3], old.codes.weight, rtol=0, atol=0)
    mean = old.codes.weight.detach().mean(0)
    torch.testing.assert_close(grown.codes.weight[3:], mean.expand(2, -1), rtol=0, atol=1e-7)
    with pytest.raises(CheckpointError, match="the run has only 2 objects"):
        init_from_model_folder(tmp_path / "m", NFRAutoDecoder(tiny_config, num_objects=2))
