"""The fast fit's mechanics on a small untrained model: the looked-up starts, the codes nearest a
sighting, early stopping on fixed rays, the refinement's valley coordinate, the valley scan and
where it runs, and the presets."""

from dataclasses import replace

import pytest
import torch
import tyro

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import (
    FitConfig,
    PartSighting,
    _adam,
    _lookup_starts,
    _nearest_codes,
    _slides,
    _valley_direction,
    _valley_scan,
    _valley_tangent,
    fit_latent,
    observed_rays,
)
from nfr_drake.inference.infer import FittedModel
from nfr_drake.nfr.latent import q_to_z_art, z_art_to_q

SMALL = FitConfig(preset="thorough", start="lookup", restarts=2, explore_steps=2, max_steps=6,
                  explore_rays=32, rays_per_step=32, eval_rays=64, lookup_q=6, lookup_rays=256,
                  focus_steps=0)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps")
    captures_command("closet", n=1, out=root, views=3, size=24)
    return read_capture_set(root / "closet_000")


def test_nearest_codes_are_those_whose_part_is_nearest_the_sighting(model_folder):
    fitted = FittedModel(model_folder)
    z_art = q_to_z_art(torch.tensor([0.2, 0.7]))
    with torch.no_grad():  # the part of training code 2 at q = 0.2
        p = fitted.model.keypoints(torch.cat([z_art[:1], fitted.codes[2:3]], -1))[0, 0]
    near = _nearest_codes(fitted.model, z_art, fitted.codes, PartSighting(0, p), count=1)
    assert near.shape == (2, fitted.codes.shape[1])
    torch.testing.assert_close(near[0], fitted.codes[2])
    everything = _nearest_codes(fitted.model, z_art, fitted.codes, PartSighting(0, p), count=3)
    torch.testing.assert_close(everything, fitted.codes.mean(0).expand(2, -1))


def test_the_lookup_keeps_the_best_candidate_of_each_band_of_q(model_folder, capture):
    """Photos rendered by the model at one candidate code: the lookup keeps that code for its band
    of q, and one start per band."""
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    config = replace(SMALL, restarts=3)  # 6 articulations: bands {0, 1}, {2, 3}, {4, 5}
    q = (torch.arange(config.lookup_q) + 0.5) / config.lookup_q
    truth = torch.cat([q_to_z_art(q[4]), fitted.z_obj_mean])
    with torch.no_grad():
        all_rays, _ = rays.take(torch.arange(rays.rgb.shape[0]), 1)
        rgb = fitted.model.render(truth[None], all_rays).rgb[0]
    starts, sighted = _lookup_starts(fitted.model, replace(rays, rgb=rgb), config,
                                     torch.Generator().manual_seed(0), fitted.z_obj_mean, None,
                                     fitted.codes)
    assert starts.shape == (3, truth.shape[0]) and not sighted.any()  # no sighting: no codes
    torch.testing.assert_close(starts[2], truth)
    start_q = z_art_to_q(starts[:, :2])
    for band, q_start in enumerate(start_q):
        assert band / 3 <= float(q_start) <= (band + 1) / 3
    torch.testing.assert_close(starts[:, 2:], fitted.z_obj_mean.expand(3, -1))


def test_a_sighting_adds_candidates_from_the_codes_near_it(model_folder, capture):
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    z = torch.cat([q_to_z_art(torch.tensor(0.25)), fitted.codes[1]])  # q = 0.25: candidate 1
    with torch.no_grad():
        p = fitted.model.keypoints(z[None])[0, 0]
    # A sighting term that outweighs any image loss: the start must be the code near the sighting.
    config = replace(SMALL, restarts=1, sighting_codes=1, sighting_weight=100.0,
                     sighting_scale_m=1e-4)
    starts, sighted = _lookup_starts(fitted.model, rays, config, torch.Generator().manual_seed(0),
                                     fitted.z_obj_mean, PartSighting(0, p), fitted.codes)
    assert sighted.tolist() == [True]
    torch.testing.assert_close(starts[0], z)
    outcome = fit_latent(fitted.model, rays, config, fitted.z_obj_mean, sighting=PartSighting(0, p),
                         codes=fitted.codes)
    assert outcome.sighted_start
    without_codes = fit_latent(fitted.model, rays, config, fitted.z_obj_mean,
                               sighting=PartSighting(0, p))
    assert not without_codes.sighted_start


def test_early_stopping_on_fixed_rays_checks_every_stop_every_steps(model_folder, capture):
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    config = replace(SMALL, patience=6, stop_every=3, min_improvement=0.1)
    calls = []

    def improving(z):  # each check 20 % better than the last: never stops
        calls.append(z.shape)
        return 0.8 ** len(calls)

    def flat(z):
        calls.append(z.shape)
        return 1.0

    def run(held_loss, steps=30):
        z = torch.cat([q_to_z_art(torch.tensor([0.5])), fitted.z_obj_mean[None]], -1)
        calls.clear()
        return _adam(fitted.model, z, rays, config, torch.Generator().manual_seed(0), steps, 32,
                     stop_early=True, held_loss=held_loss)

    assert run(improving) == 30 and len(calls) == 1 + 30 // 3  # one before the first step
    assert run(flat) == 7 and len(calls) == 1 + 7 // 3  # best at step 1, then 6 steps without
    assert run(flat, steps=4) == 4  # at most `steps`


def test_the_fit_stops_early_on_a_flat_loss(model_folder, capture):
    fitted = FittedModel(model_folder)
    config = replace(SMALL, max_steps=500, patience=10, stop_every=5, min_improvement=0.9)
    outcome = fit_latent(fitted.model, observed_rays(capture), config, fitted.z_obj_mean)
    assert outcome.steps == config.explore_steps + config.patience + 1


def test_presets():
    fast, thorough = FitConfig.fast().resolved(), FitConfig(preset="thorough").resolved()
    assert FitConfig().preset == "fast"  # the default
    for name, value in FitConfig.PRESETS["fast"].items():
        assert getattr(FitConfig(), name) is None  # left to the preset
        assert getattr(fast, name) == value != getattr(thorough, name)
        assert getattr(thorough, name) == FitConfig.PRESETS["thorough"][name]
    assert FitConfig.fast(max_steps=300).resolved().max_steps == 300  # a field set is kept
    assert FitConfig.fast(max_steps=300).resolved().focus_steps == FitConfig.PRESETS["fast"]["focus_steps"]
    on_top = FitConfig.fast(focus_steps=150, valley_first=False).resolved()  # thorough's values
    assert (on_top.focus_steps, on_top.valley_first, on_top.start) == (150, False, "lookup")
    assert fast.resolved() is fast  # resolving twice changes nothing

    def command(fit: FitConfig = FitConfig()) -> FitConfig:
        return fit

    assert tyro.cli(command, args=["--fit.preset", "fast"]) == FitConfig.fast()
    assert tyro.cli(command, args=[]) == FitConfig()
    with pytest.raises(ConfigError, match="preset"):
        FitConfig(preset="slow")
    with pytest.raises(ConfigError, match="start"):
        FitConfig(start="random")
    with pytest.raises(ConfigError, match="lookup_q"):
        FitConfig(lookup_q=0)
    with pytest.raises(ConfigError, match="stop_every"):
        FitConfig(stop_every=-1)
    with pytest.raises(ConfigError, match="lookup_q"):
        FitConfig.fast(restarts=5, lookup_q=4)  # a band of q without a candidate
    assert FitConfig(preset="thorough", restarts=5, lookup_q=4).restarts == 5  # spread: no lookup
    with pytest.raises(ConfigError, match="explore_lr"):
        FitConfig(explore_lr=0.0)
    with pytest.raises(ConfigError, match="explore_steps"):  # fast's 30 exploration steps
        FitConfig.fast(max_steps=20)


def test_the_valley_direction_keeps_the_part_in_place(model_folder):
    """Moving q by dq and z_obj by the direction times dq moves the head's part far less than
    moving q alone (first order: the change left is of order dq^2)."""
    fitted = FittedModel(model_folder)
    z = torch.cat([q_to_z_art(torch.tensor(0.4)), fitted.codes[1]]).double()
    model = fitted.model.double()
    direction = _valley_direction(model, z, keypoint=0)
    assert direction.shape == (z.shape[0] - 2,)

    def part(q, z_obj):
        with torch.no_grad():
            return model.keypoints(torch.cat([q_to_z_art(torch.tensor(q, dtype=z.dtype)),
                                              z_obj])[None])[0, 0]

    dq = 1e-3
    q_alone = (part(0.4 + dq, z[2:]) - part(0.4, z[2:])).norm()
    along = (part(0.4 + dq, z[2:] + dq * direction) - part(0.4, z[2:])).norm()
    assert q_alone > 0 and along < 0.01 * q_alone


def test_the_valley_scan_holds_q_and_goes_on_from_the_minimum_of_its_losses(model_folder, capture):
    """Losses on fixed rays that are a parabola in q with its minimum between two of the grid's
    articulations: the scan goes on from that minimum; its codes' q do not move in its steps."""
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    config = replace(SMALL, valley_codes=5, valley_span=0.2, valley_steps=3)
    z = torch.cat([q_to_z_art(torch.tensor(0.5)), fitted.z_obj_mean])
    seen = []

    def parabola(codes):
        seen.append(z_art_to_q(codes[:, :2]))
        return (z_art_to_q(codes[:, :2]) - 0.53) ** 2

    out, steps = _valley_scan(fitted.model, rays, config, torch.Generator().manual_seed(0), z, 0,
                              None, parabola)
    assert steps == 3
    torch.testing.assert_close(seen[0], torch.tensor([0.4, 0.45, 0.5, 0.55, 0.6]), atol=1e-5,
                               rtol=0)  # the grid, q held through the steps
    assert abs(float(z_art_to_q(out[:2])) - 0.53) < 1e-4
    near_top = replace(config, valley_span=0.4)  # grid shifted to [0.6, 1.0] from q = 0.9
    z_top = torch.cat([q_to_z_art(torch.tensor(0.9)), fitted.z_obj_mean])
    seen.clear()
    _valley_scan(fitted.model, rays, near_top, torch.Generator().manual_seed(0), z_top, 0, None,
                 parabola)
    torch.testing.assert_close(seen[0], torch.tensor([0.6, 0.7, 0.8, 0.9, 1.0]), atol=1e-5, rtol=0)
    with pytest.raises(ConfigError, match="valley_codes"):
        FitConfig(valley_codes=1)


class _PartOnPath:
    """A stand-in model whose keypoint head puts part 0 on a straight line (a drawer's pull) or on
    a quarter circle (a door's handle) as q goes from 0 to 1."""

    def __init__(self, path: str):
        self.path = path

    def keypoints(self, z):
        q = z_art_to_q(z[:, :2])
        if self.path == "line":
            p = torch.stack([0.3 * q, torch.zeros_like(q), torch.zeros_like(q)], -1)
        else:
            angle = 0.5 * torch.pi * q
            p = torch.stack([0.5 * torch.cos(angle), 0.5 * torch.sin(angle), torch.zeros_like(q)], -1)
        return p[:, None]


def test_a_part_slides_on_a_line_not_on_an_arc():
    z = torch.cat([q_to_z_art(torch.tensor(0.3)), torch.zeros(4)])
    assert _slides(_PartOnPath("line"), z, 0)
    assert not _slides(_PartOnPath("arc"), z, 0)


@pytest.mark.parametrize("first", [False, True])
def test_the_valley_scan_runs_before_or_after_the_refinement(model_folder, capture, monkeypatch,
                                                             first):
    """`valley_first`: the scan starts from the exploration's winner and the refinement from the
    scan's code; otherwise the scan starts from the refined code. The valley coordinate joins
    the refinement only (not the exploration)."""
    from nfr_drake.inference import fit

    fitted = FittedModel(model_folder)
    events = []
    adam, scan = fit._adam, fit._valley_scan

    def logged_adam(*args, **kwargs):
        name = ("refine" if kwargs["stop_early"] else "scan steps" if kwargs.get("hold_q")
                else "explore")
        events.append((name, kwargs.get("valley") is not None, args[1].detach().clone()))
        steps = adam(*args, **kwargs)
        events.append(("after", None, args[1].detach().clone()))
        return steps

    def logged_scan(model, rays, config, generator, z, *rest):
        events.append(("scan", None, z.clone()))
        out, steps = scan(model, rays, config, generator, z, *rest)
        events.append(("scanned", None, out.clone()))
        return out, steps

    monkeypatch.setattr(fit, "_adam", logged_adam)
    monkeypatch.setattr(fit, "_valley_scan", logged_scan)
    monkeypatch.setattr(fit, "_slides", lambda *args: True)  # as a drawer's front
    config = replace(SMALL, valley_codes=3, valley_steps=2, valley_first=first, valley_lr=0.01,
                     stop_every=1)
    outcome = fit_latent(fitted.model, observed_rays(capture), config, fitted.z_obj_mean,
                         focus=fitted.focus)
    names = [name for name, _, _ in events if name != "after"]
    scan_stages = ["scan", "scan steps", "scanned"]
    assert names == (["explore"] + scan_stages + ["refine"] if first
                     else ["explore", "refine"] + scan_stages)
    assert [v for n, v, _ in events if n in ("explore", "refine")] == [False, True]
    at = {name: i for i, (name, _, _) in enumerate(events)}
    if first:  # the refinement goes on from the scan's code
        torch.testing.assert_close(events[at["refine"]][2][0], events[at["scanned"]][2])
    else:  # the scan starts from the refined code
        torch.testing.assert_close(events[at["scan"]][2], events[at["refine"] + 1][2][0])
    assert outcome.steps <= config.max_steps + config.valley_steps

def test_the_valley_coordinate_moves_q_and_z_obj_along_the_valley(model_folder, capture):
    """With the code's own steps negligible, the steps move z along the valley tangent only: q
    changes, and the keypoint head's part moves far less than q's change alone would move it."""
    fitted = FittedModel(model_folder)
    model = fitted.model.double()
    rays = observed_rays(capture, dtype=torch.float64)
    config = replace(SMALL, lr=1e-12, valley_lr=0.02)
    z0 = torch.cat([q_to_z_art(torch.tensor([0.4])), fitted.codes[1:2]], -1).double()
    z = z0.clone()
    tangent = _valley_tangent(model, z0, 0)
    assert tangent.shape == z0.shape
    _adam(model, z, rays, config, torch.Generator().manual_seed(0), 3, 32, stop_early=False,
          valley=lambda c: _valley_tangent(model, c, 0))
    step = (z.detach() - z0)[0]
    cosine = float(step @ tangent[0] / (step.norm() * tangent[0].norm()))
    assert abs(cosine) > 0.999  # along the tangent (renewed at step 1 only: _VALLEY_RENEW > 3)
    dq = float(z_art_to_q(z.detach()[:, :2]) - 0.4)
    assert 1e-3 < abs(dq) <= 3 * 0.02 * 1.01  # at most valley_lr per Adam step
    with torch.no_grad():
        q_alone = torch.cat([q_to_z_art(torch.tensor([0.4 + dq], dtype=z.dtype)), z0[:, 2:]], -1)
        part = lambda c: model.keypoints(c)[0, 0]  # noqa: E731
        assert (part(z.detach()) - part(z0)).norm() < 0.1 * (part(q_alone) - part(z0)).norm()
    unmoved = z0.clone()
    _adam(model, unmoved, rays, replace(config, valley_lr=0.0), torch.Generator().manual_seed(0),
          3, 32, stop_early=False, valley=lambda c: _valley_tangent(model, c, 0))
    torch.testing.assert_close(unmoved, z0)  # valley_lr 0: no valley coordinate
    with pytest.raises(ConfigError, match="valley_lr"):
        FitConfig(valley_lr=-0.1)
