"""Shapes of every module, gradients to every parameter and code, float64 gradchecks."""

import math

import numpy as np
import pytest
import torch

from nfr_drake.data.camera_placement import look_at
from nfr_drake.errors import ConfigError
from nfr_drake.nfr.config import (
    LossConfig,
    NFRModelConfig,
    OptimConfig,
    SamplerConfig,
    TrainConfig,
)
from nfr_drake.nfr.field import Field, encoding_dim, positional_encoding
from nfr_drake.nfr.heads import KeypointHead, PixelGenerator
from nfr_drake.nfr.hyper import HyperNetwork
from nfr_drake.nfr.losses import nfr_loss
from nfr_drake.nfr.model import NFRAutoDecoder, NFRModel
from nfr_drake.nfr.raymarcher import LSTMRaymarcher, MarchState, march_step
from nfr_drake.nfr.rays import Rays, pixel_centers, pixel_rays, sphere_interval
from nfr_drake.nfr.render import render_images


def _cameras(B, dtype=torch.float32):
    X = np.stack([look_at(np.array([1.6, 0.3 * i - 0.3, 0.9]), np.array([0.0, 0, 0.4]))
                  for i in range(B)])
    X_OC = torch.tensor(X, dtype=dtype)
    K = torch.tensor([[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]], dtype=dtype).repeat(B, 1, 1)
    return K, X_OC


def _rays(B, R, dtype=torch.float32):
    K, X_OC = _cameras(B, dtype)
    uv = torch.rand(B, R, 2, dtype=dtype) * 32
    return pixel_rays(uv, K, X_OC)


def test_pixel_rays_geometry():
    K, X_OC = _cameras(2, torch.float64)
    uv = pixel_centers(32, 32, dtype=torch.float64).expand(2, -1, -1)
    rays = pixel_rays(uv, K, X_OC)
    assert rays.origins.shape == rays.directions.shape == (2, 1024, 3)
    torch.testing.assert_close(rays.directions.norm(dim=-1), torch.ones(2, 1024, dtype=torch.float64))
    # Project a point along each ray back into the image: it lands on its pixel.
    p_O = rays.origins + 1.3 * rays.directions
    R_OC, p_OC = X_OC[:, :3, :3], X_OC[:, :3, 3]
    p_C = (p_O - p_OC[:, None]) @ R_OC
    uv_back = (p_C[..., :2] / p_C[..., 2:]) @ K[:, :2, :2].transpose(1, 2) + K[:, None, :2, 2]
    torch.testing.assert_close(uv_back, uv)
    # The centre pixel of a centred camera looks along the optical axis.
    centre = pixel_rays(torch.tensor([[[16.0, 16.0]]], dtype=torch.float64), K[:1], X_OC[:1])
    torch.testing.assert_close(centre.directions[0, 0], X_OC[0, :3, 2])


def test_pixel_centers_convention():
    uv = pixel_centers(2, 3)
    assert uv.shape == (6, 2)
    torch.testing.assert_close(uv[0], torch.tensor([0.5, 0.5]))
    torch.testing.assert_close(uv[4], torch.tensor([1.5, 1.5]))  # row 1, column 1


def test_sphere_interval():
    rays = Rays(torch.tensor([[[3.0, 0, 0], [3.0, 0, 0]]]),
                torch.tensor([[[-1.0, 0, 0], [0.0, 1, 0]]]))
    near, far = sphere_interval(rays, torch.zeros(3), 1.0, 0.05)
    torch.testing.assert_close(near, torch.tensor([[2.0, 0.05]]))
    torch.testing.assert_close(far, torch.tensor([[4.0, 0.05]]))


def test_gradcheck_ray_generation():
    K, X_OC = _cameras(2, torch.float64)
    uv = (torch.rand(2, 5, 2, dtype=torch.float64) * 32).requires_grad_()
    K.requires_grad_()
    X_OC = X_OC.clone().requires_grad_()

    def f(uv, K, X):
        r = pixel_rays(uv, K, X)
        return r.origins, r.directions

    assert torch.autograd.gradcheck(f, (uv, K, X_OC))


def test_gradcheck_one_raymarch_step(tiny_config):
    c = tiny_config
    torch.manual_seed(0)
    hyper = HyperNetwork(c.latent_dim, [(encoding_dim(c.pe_frequencies), c.field_width),
                                        (c.field_width, c.feature_dim)], c.hyper_hidden,
                         0.5).double()
    field = Field(c.bound_center, c.pe_frequencies, c.pe_base_frequency, True).double()
    marcher = LSTMRaymarcher(c.feature_dim, c.lstm_hidden, 1, 0.3).double()
    rays = _rays(2, 3, torch.float64)
    near, far = sphere_interval(rays, torch.tensor(c.bound_center, dtype=torch.float64), 0.9, 0.05)
    z = torch.randn(2, c.latent_dim, dtype=torch.float64, requires_grad=True)
    depth0 = (near + 0.2 * (far - near)).detach().requires_grad_()
    h0 = torch.randn(6, c.lstm_hidden, dtype=torch.float64, requires_grad=True)
    c0 = torch.randn(6, c.lstm_hidden, dtype=torch.float64, requires_grad=True)
    origins = rays.origins.clone().requires_grad_()

    def f(z, depth, h, cc, origins):
        weights = hyper(z)
        s = march_step(lambda p: field(p, weights), Rays(origins, rays.directions),
                       MarchState(depth, h, cc), marcher.cell, marcher.step_head, 0.3, near, far)
        return s.depth, s.h, s.c

    assert torch.autograd.gradcheck(f, (z, depth0, h0, c0, origins))


def test_module_shapes(tiny_config):
    c = tiny_config
    B, R = 3, 7
    z = torch.randn(B, c.latent_dim)
    sizes = [(encoding_dim(c.pe_frequencies), c.field_width), (c.field_width, c.feature_dim)]
    weights = HyperNetwork(c.latent_dim, sizes, c.hyper_hidden, 0.1)(z)
    assert [tuple(w.weight.shape) for w in weights] == [(B, i, o) for i, o in sizes]
    assert [tuple(w.bias.shape) for w in weights] == [(B, 1, o) for _, o in sizes]
    assert positional_encoding(torch.zeros(B, R, 3), 4, math.pi).shape == (B, R, encoding_dim(4))
    v = Field(c.bound_center, c.pe_frequencies, math.pi, True)(torch.randn(B, R, 3), weights)
    assert v.shape == (B, R, c.feature_dim)
    assert PixelGenerator(c.feature_dim, 5, 3)(v).shape == (B, R, 3)
    keypoints, slot_logits = KeypointHead(c.latent_dim, 5, 4)(z)
    assert keypoints.shape == (B, 4, 3) and slot_logits.shape == (B, 1, 0)
    model = NFRModel(c)
    out = model.render(z, _rays(B, R))
    assert out.rgb.shape == (B, R, 3) and out.logits.shape == (B, R, c.num_classes)
    assert out.points.shape == (B, R, 3) and out.depth.shape == (B, R)
    assert out.depth_trace.shape == (B, R, c.march_steps + 1)
    assert model.keypoints(z).shape == (B, c.num_keypoints, 3)
    K, X_OC = _cameras(B)
    imgs = render_images(model, z, K, X_OC, 6, 5, chunk=7)
    assert imgs.rgb.shape == (B, 6, 5, 3) and imgs.labels.shape == (B, 6, 5)
    assert imgs.depth.shape == (B, 6, 5) and imgs.points.shape == (B, 6, 5, 3)


def test_march_stays_in_the_bounding_sphere(tiny_config):
    model = NFRModel(tiny_config)
    rays = _rays(2, 50)
    near, far = model.depth_bounds(rays)
    out = model.render(torch.randn(2, tiny_config.latent_dim) * 5, rays)
    assert (out.depth_trace >= near[..., None] - 1e-6).all()
    assert (out.depth_trace <= far[..., None] + 1e-6).all()


def test_render_is_batched_over_codes(tiny_config):
    """Codes of one batch do not interact: rendering z_i alone gives the same pixels."""
    model = NFRModel(tiny_config)
    z = torch.randn(3, tiny_config.latent_dim)
    rays = _rays(1, 9)
    rays3 = Rays(rays.origins.expand(3, -1, -1), rays.directions.expand(3, -1, -1))
    together = model.render(z, rays3).rgb
    alone = model.render(z[1:2], rays).rgb
    torch.testing.assert_close(together[1:2], alone, atol=1e-5, rtol=1e-5)


def test_gradients_reach_every_parameter_and_the_codes(tiny_config):
    torch.manual_seed(0)
    module = NFRAutoDecoder(tiny_config, num_objects=3)
    B, R = 3, 16
    rays = _rays(B, R)
    idx = torch.tensor([0, 1, 2])
    render, kp, z = module(idx, torch.tensor([0.1, 0.5, 0.9]), rays)
    terms = nfr_loss(render, kp, z[:, 2:], torch.rand(B, R, 3), torch.randint(0, 4, (B, R)),
                     torch.randn(B, 4, 3), LossConfig())
    terms.total.backward()
    for name, p in module.named_parameters():
        assert p.grad is not None, name
        assert p.grad.abs().sum() > 0, f"zero gradient for {name}"
    assert (module.codes.weight.grad.abs().sum(-1) > 0).all()


def test_z_art_gradient_when_fitting(tiny_config):
    """With the networks frozen, the image loss moves a free z (the fit of issue 4)."""
    model = NFRModel(tiny_config).requires_grad_(False)
    z = torch.randn(4, tiny_config.latent_dim, requires_grad=True)
    rays = _rays(4, 8)
    model.render(z, rays).rgb.sum().backward()
    assert z.grad[:, :2].abs().sum() > 0 and z.grad[:, 2:].abs().sum() > 0


def test_config_validation():
    with pytest.raises(ConfigError, match="field_width"):
        NFRModelConfig(field_width=0)
    with pytest.raises(ConfigError, match="sum"):
        SamplerConfig(foreground_fraction=0.6, moving_fraction=0.3, handle_fraction=0.2)
    with pytest.raises(ConfigError, match="seg_weight"):
        LossConfig(seg_weight=-1)
    with pytest.raises(ConfigError, match="decay_at"):
        OptimConfig(decay_at=2.0)
    with pytest.raises(ConfigError, match="unknown"):
        NFRModelConfig.from_json({"nonsense": 1})
    ref = NFRModelConfig.srn_reference()
    assert ref.latent_obj_dim == 256 and ref.field_width == 256 and ref.march_steps == 10
    cfg = TrainConfig()
    assert TrainConfig.from_json(cfg.to_json()) == cfg


def test_render_without_logits_and_field_in_float64(tiny_config):
    """An image-loss render skips psi_2 and gives the same colours; the field's frequencies,
    made once per dtype, are those of `positional_encoding` (float32 and float64 alike)."""
    torch.manual_seed(0)
    model = NFRModel(tiny_config)
    z, rays = torch.randn(2, tiny_config.latent_dim), _rays(2, 9)
    full, lean = model.render(z, rays), model.render(z, rays, logits=False)
    assert lean.logits is None and full.logits.shape == (2, 9, tiny_config.num_classes)
    assert torch.equal(lean.rgb, full.rgb) and torch.equal(lean.depth, full.depth)
    assert tiny_config.layer_norm  # the layers below
    weights = model.hyper(z)
    for dtype in (torch.float32, torch.float64):
        p = torch.randn(2, 9, 3, dtype=dtype)
        w = [type(x)(x.weight.to(dtype), x.bias.to(dtype)) for x in weights]
        h = positional_encoding(p - model.field.center.to(dtype), tiny_config.pe_frequencies,
                                tiny_config.pe_base_frequency)
        expected = torch.relu(torch.nn.functional.layer_norm(
            torch.baddbmm(w[0].bias, h, w[0].weight), (tiny_config.field_width,)))
        for x in w[1:-1]:
            expected = torch.relu(torch.nn.functional.layer_norm(
                torch.baddbmm(x.bias, expected, x.weight), (tiny_config.field_width,)))
        expected = torch.baddbmm(w[-1].bias, expected, w[-1].weight)
        assert torch.equal(model.field(p, w), expected)
