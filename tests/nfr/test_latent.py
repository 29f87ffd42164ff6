"""The structured latent code: q -> z_art -> q, the mirrored half, normalisation."""

import math

import torch

from nfr_drake.nfr.latent import (
    ObjectCodes,
    compose_z,
    normalize_z_art,
    q_to_z_art,
    split_z,
    z_art_to_q,
)


def test_round_trip_upper_half():
    q = torch.linspace(0, 1, 101, dtype=torch.float64)
    z = q_to_z_art(q)
    assert z.shape == (101, 2)
    torch.testing.assert_close(z.norm(dim=-1), torch.ones(101, dtype=torch.float64))
    assert (z[:, 1] >= -1e-12).all()  # q in [0, 1] lies on the upper half
    torch.testing.assert_close(z_art_to_q(z), q)


def test_lower_half_mirrors_upper_half():
    q = torch.linspace(0, 1, 51, dtype=torch.float64)
    z = q_to_z_art(q)
    mirrored = torch.stack([z[:, 0], -z[:, 1]], dim=-1)
    torch.testing.assert_close(z_art_to_q(mirrored), q)


def test_normalisation_scale_invariance_and_round_trip_of_raw_codes():
    raw = torch.randn(200, 2, dtype=torch.float64) * 3
    unit = normalize_z_art(raw)
    torch.testing.assert_close(unit.norm(dim=-1), torch.ones(200, dtype=torch.float64))
    torch.testing.assert_close(z_art_to_q(raw), z_art_to_q(unit))
    q = z_art_to_q(raw)
    assert ((q >= 0) & (q <= 1)).all()
    # Raw code -> q -> canonical code -> q again.
    torch.testing.assert_close(z_art_to_q(q_to_z_art(q)), q)


def test_endpoints():
    assert float(z_art_to_q(torch.tensor([1.0, 0.0]))) == 0.0
    assert math.isclose(float(z_art_to_q(torch.tensor([-1.0, 0.0]))), 1.0)
    assert math.isclose(float(z_art_to_q(torch.tensor([0.0, -2.0]))), 0.5)


def test_compose_and_codes():
    codes = ObjectCodes(5, 3, init_std=0.01)
    idx = torch.tensor([0, 4, 4])
    z = codes.z(idx, torch.tensor([0.0, 0.5, 1.0]))
    assert z.shape == (3, 5)
    art, obj = split_z(z)
    torch.testing.assert_close(obj, codes.weight[idx])
    torch.testing.assert_close(z_art_to_q(art), torch.tensor([0.0, 0.5, 1.0]))
    torch.testing.assert_close(compose_z(2 * art, obj), z)
