"""Fitting and forward simulation mechanics on a small untrained model (no trained model needed)."""

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
import torch

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.capture import CaptureFrame, read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.inference.fit import (
    FitConfig,
    FocusTarget,
    PartSighting,
    fit_latent,
    frame_ray_directions,
    image_detail,
    observed_rays,
)
from nfr_drake.inference.forward import keypoint_trajectory, render_view
from nfr_drake.inference.infer import FittedModel, infer
from nfr_drake.inference.result import FitResult
from nfr_drake.nfr.latent import q_to_z_art, z_art_to_q
from nfr_drake.nfr.rays import pixel_centers
from nfr_drake.perception.handle_triangulation import HandleMap


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps")
    captures_command("closet", n=1, out=root, views=3, size=24)
    return read_capture_set(root / "closet_000")


def test_pinhole_rays_project_back_onto_their_pixel_centres():
    camera = PinholeCamera(30.0, 32.0, 11.0, 13.0, 20, 24)
    X_OC = look_at(np.array([1.5, 0.3, 0.8]), np.zeros(3))
    d_O = frame_ray_directions(CaptureFrame(None, X_OC, camera))
    d_C = d_O @ X_OC[:3, :3]  # R_CO d_O, row-wise
    uv = d_C[:, :2] / d_C[:, 2:] * [camera.fx, camera.fy] + [camera.cx, camera.cy]
    rows, cols = np.divmod(np.arange(24 * 20), 20)
    np.testing.assert_allclose(uv, np.stack([cols + 0.5, rows + 0.5], 1), atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(d_O, axis=1), 1.0)


def test_distorted_rays_pass_through_the_distorted_projection():
    camera = PinholeCamera(40.0, 40.0, 16.0, 12.0, 32, 24, (0.1, -0.05, 0.002, -0.001))
    X_OC = np.eye(4)
    d = frame_ray_directions(CaptureFrame(None, X_OC, camera))
    K_cv = camera.K.copy()
    K_cv[:2, 2] -= 0.5
    uv, _ = cv2.projectPoints(d.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K_cv,
                              np.array(camera.distortion))
    expected = pixel_centers(24, 32, dtype=torch.float64).numpy() - 0.5
    np.testing.assert_allclose(uv.reshape(-1, 2), expected, atol=1e-3)


def test_fit_moves_z_and_reports_every_start(model_folder, capture):
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    assert rays.rgb.shape == (3 * 24 * 24, 3)
    config = FitConfig(preset="thorough", restarts=3, explore_steps=10, max_steps=20, explore_rays=32,
                       rays_per_step=64, eval_rays=256, detail_fraction=0.0)  # one loss throughout
    outcome = fit_latent(fitted.model, rays, config, fitted.z_obj_mean)
    assert outcome.z.shape == (2 + 8,) and 0.0 <= outcome.q <= 1.0
    assert outcome.start_losses.shape == (3,) and outcome.steps == 20
    # Refining the best start does not make its loss worse (beyond sampling noise).
    assert outcome.image_loss <= 1.05 * outcome.start_losses.min()
    assert all(p.requires_grad for p in fitted.model.parameters())  # restored after the fit


def test_image_detail_marks_edges_and_thin_parts():
    image = np.full((32, 32, 3), 120, np.uint8)
    image[8:24, 8:24] = (40, 60, 200)  # a panel
    image[10:20, 15] = (250, 250, 250)  # a one-pixel bar on it
    detail = image_detail(image)
    assert detail.shape == (32, 32)
    assert detail[0:5, 0:5].max() == 0.0 and detail[12:20, 10:12].max() == 0.0  # flat regions
    assert detail[16, 15] > detail[16, 8] > 0  # the bar stands out more than the panel edge


def test_detail_sampling_draws_edge_pixels(capture):
    rays = observed_rays(capture)
    gen = torch.Generator().manual_seed(0)
    edge = rays.detail > 0.1 * rays.detail.max()
    uniform = edge[rays.sample(4000, 0.0, gen)].float().mean()
    weighted = edge[rays.sample(4000, 0.5, gen)].float().mean()
    assert abs(uniform - edge.float().mean()) < 0.03  # uniform draws hit edges at their share
    assert weighted > 0.5 * uniform + 0.5 * 0.9  # the weighted half lands on edges
    flat = replace(rays, detail=torch.zeros_like(rays.detail))  # a blank photo: no edges
    assert not flat.detail.any()  # all draws uniform, no error
    assert flat.sample(100, 0.5, gen).shape == (100,)


@pytest.mark.parametrize("bad", [{"restarts": 0}, {"explore_steps": 500}, {"detail_fraction": 1.5},
                                 {"lr": 0.0}, {"focus_steps": -1}, {"focus_radius_m": 0.0},
                                 {"focus_agreement_m": -0.01}, {"sighting_weight": -1.0},
                                 {"sighting_scale_m": 0.0}])
def test_fit_config_rejects_bad_values(bad):
    with pytest.raises(ConfigError):
        FitConfig(**bad)


def test_rays_near_a_point_are_those_within_the_radius(capture):
    rays = observed_rays(capture, dtype=torch.float64)
    p = torch.tensor([0.25, -0.1, 0.5], dtype=torch.float64)
    near = rays.near(p, 0.1)
    o, d = rays.origins.numpy(), rays.directions.numpy()
    t = np.einsum("ij,ij->i", p.numpy() - o, d)
    distance = np.linalg.norm(o + t[:, None] * d - p.numpy(), axis=1)  # every point is in front
    assert (t > 0).all()
    np.testing.assert_array_equal(near.numpy(), distance < 0.1)
    assert 0 < near.sum() < len(near)


def test_close_look_is_kept_only_when_head_and_render_agree(model_folder, capture):
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    small = FitConfig(preset="thorough", restarts=2, explore_steps=3, max_steps=6, explore_rays=32,
                      rays_per_step=32, eval_rays=64, focus_steps=4, focus_radius_m=0.5)
    without = fit_latent(fitted.model, rays, replace(small, focus_steps=0), fitted.z_obj_mean)
    # The class this untrained model renders most near its "handle" stands in for the handle.
    handle = fitted.model.keypoints(without.z[None])[0, 0].detach()
    index = torch.nonzero(rays.near(handle, 0.5)).squeeze(-1)
    with torch.no_grad():
        labels = fitted.model.render(without.z[None], rays.take(index, 1)[0]).logits[0].argmax(-1)
    target = FocusTarget(keypoint=0, label=int(torch.mode(labels).values))
    kept = fit_latent(fitted.model, rays, replace(small, focus_agreement_m=100.0),
                      fitted.z_obj_mean, target)
    assert kept.focus == "kept" and kept.steps == without.steps + 4
    assert not torch.equal(kept.z, without.z)
    discarded = fit_latent(fitted.model, rays, replace(small, focus_agreement_m=1e-6),
                           fitted.z_obj_mean, target)
    assert discarded.focus.startswith("discarded: keypoint head and rendered part")
    assert torch.equal(discarded.z, without.z)  # the fit before the look, unchanged
    assert without.focus == "off"
    nowhere = fit_latent(fitted.model, rays, replace(small, focus_radius_m=1e-9),
                         fitted.z_obj_mean, target)  # no ray passes that close: no look runs
    assert nowhere.focus == "discarded: no ray passes near the part"
    assert nowhere.steps == without.steps and torch.equal(nowhere.z, without.z)


def test_stopping_rule_ends_a_flat_fit_early(model_folder, capture):
    fitted = FittedModel(model_folder)
    config = FitConfig(preset="thorough", restarts=2, explore_steps=5, max_steps=500, patience=5,
                       min_improvement=0.5, explore_rays=32, rays_per_step=32, eval_rays=64)
    outcome = fit_latent(fitted.model, observed_rays(capture), config, fitted.z_obj_mean)
    assert outcome.steps < 500


def test_infer_writes_the_design_result_format(model_folder, capture, tmp_path):
    fitted = FittedModel(model_folder)
    result, outcome = infer(fitted, capture, FitConfig(preset="thorough", restarts=2, explore_steps=2,
                                                       max_steps=5, explore_rays=32, rays_per_step=32,
                                                       eval_rays=64),
                            np.linspace(0, 1, 5))
    result.write(tmp_path / "r.json")
    doc = json.loads((tmp_path / "r.json").read_text())
    assert set(doc) >= {"category", "q", "keypoints", "trajectory", "image_loss", "seconds"}
    assert set(doc["keypoints"]) == {"handle", "hinge_top", "hinge_bottom", "goal"}
    assert np.array(doc["trajectory"]["keypoints"]["handle"]).shape == (5, 3)
    assert doc["trajectory"]["q"] == [0.0, 0.25, 0.5, 0.75, 1.0]
    again = FitResult.read(tmp_path / "r.json")
    np.testing.assert_allclose(again.trajectory["goal"], result.trajectory["goal"])
    traj = keypoint_trajectory(fitted.model, outcome.z, np.array([outcome.q]))
    np.testing.assert_allclose(traj[0, 0], result.keypoints["handle"], atol=1e-6)


def test_render_view_any_resolution(model_folder):
    fitted = FittedModel(model_folder)
    z = torch.cat([torch.tensor([1.0, 0.0]), fitted.z_obj_mean])
    camera = PinholeCamera.from_fov(17, 11, 0.9)
    view = render_view(fitted.model, z, 0.4, camera, look_at(np.array([1.6, 0, 1]), np.zeros(3)))
    assert view.rgb.shape == (11, 17, 3) and view.labels.shape == (11, 17)
    assert view.rgb.dtype == np.uint8 and view.labels.max() < 4


def test_wrong_category_is_refused(model_folder, capture):
    fitted = FittedModel(model_folder)
    fitted.check_capture(capture)  # a closet capture for a closet model
    with pytest.raises(NfrDrakeError, match="drawer capture, but .* closet model"):
        fitted.check_capture(capture, category="drawer")


def _cli(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "nfr_drake.cli", "infer", *map(str, args)],
                          capture_output=True, text=True)


def test_cli_errors_exit_2_without_traceback(model_folder, capture, tmp_path):
    bad_model = tmp_path / "bad"
    bad_model.mkdir()
    (bad_model / "config.json").write_text("{")
    cases = [
        (_cli(capture.root, "--model", bad_model, "--out", tmp_path / "r.json"), "malformed JSON"),
        (_cli(tmp_path / "nowhere", "--model", model_folder), "capture set folder not found"),
        (_cli(capture.root, "--model", model_folder, "--category", "drawer"), "closet model"),
    ]
    for result, message in cases:
        assert result.returncode == 2, result.stderr
        assert message in result.stderr and "Traceback" not in result.stderr


def test_rotation_axis_of_a_noisy_arc():
    from nfr_drake.inference.forward import rotation_axis_from_path

    t = np.linspace(0.0, np.pi / 2, 15)
    arc = np.stack([0.3 + 0.45 * np.sin(t), -0.2 + 0.45 * np.cos(t), np.full_like(t, 0.5)], 1)
    arc += np.random.default_rng(0).normal(0.0, 0.002, arc.shape)
    np.testing.assert_allclose(rotation_axis_from_path(arc), [0.3, -0.2], atol=0.01)


def test_geometric_keypoints_keep_the_head_where_the_handle_is_never_seen(model_folder):
    from nfr_drake.inference.forward import geometric_keypoints

    fitted = FittedModel(model_folder)
    z = torch.cat([torch.tensor([1.0, 0.0]), fitted.z_obj_mean])
    camera = PinholeCamera.from_fov(16, 16, 0.9)
    views = [(camera, look_at(np.array([1.6, 0.2 * i, 1.0]), np.zeros(3))) for i in range(3)]
    grid = np.linspace(0, 1, 4)
    now, path = geometric_keypoints(fitted.model, z, 0.3, grid, fitted.keypoint_names, views)
    head = keypoint_trajectory(fitted.model, z, grid)
    assert now.shape == (4, 3) and path.shape == (4, 4, 3)
    goal = fitted.keypoint_names.index("goal")
    np.testing.assert_allclose(path[:, goal], head[:, goal], atol=1e-6)  # goal always from the head
    assert np.isfinite(path).all()


def test_a_sighting_pulls_the_head_part_towards_the_sighted_point(model_folder, capture):
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    config = FitConfig(preset="thorough", restarts=2, explore_steps=20, max_steps=60, explore_rays=32,
                       rays_per_step=32, eval_rays=64, focus_steps=0, sighting_weight=1.0)
    torch.manual_seed(1)  # a point the head can reach: its part for another code
    other = torch.cat([torch.zeros(2), fitted.z_obj_mean + torch.randn(8)])
    target = fitted.model.keypoints(other[None])[0, 0].detach()
    sighting = PartSighting(keypoint=0, p_O=target)
    free = fit_latent(fitted.model, rays, config, fitted.z_obj_mean)
    pulled = fit_latent(fitted.model, rays, config, fitted.z_obj_mean, sighting=sighting)

    def gap(z):
        with torch.no_grad():
            return float((fitted.model.keypoints(z[None])[0, 0] - target).norm())

    assert gap(pulled.z) < 0.5 * gap(free.z)
    off = fit_latent(fitted.model, rays, replace(config, sighting_weight=0.0), fitted.z_obj_mean,
                     sighting=sighting)
    assert torch.equal(off.z, free.z)  # weight 0: the sighting changes nothing


def test_a_start_code_of_the_wrong_shape_is_refused(model_folder, capture):
    fitted = FittedModel(model_folder)
    config = FitConfig(preset="thorough", restarts=3, explore_steps=0, max_steps=1, explore_rays=32,
                       rays_per_step=32, eval_rays=64, focus_steps=0)
    with pytest.raises(ConfigError, match="z_obj_init has shape"):
        fit_latent(fitted.model, observed_rays(capture), config, fitted.codes[:3])


def test_infer_uses_a_shipped_handle_detector(model_folder, tmp_path):
    import shutil

    from safetensors.torch import save_file

    from nfr_drake.perception.handle_detector.model import (
        DETECTOR_DIR,
        HandleDetector,
        HandleDetectorConfig,
    )

    folder = tmp_path / "closet"
    shutil.copytree(model_folder, folder)
    (folder / DETECTOR_DIR).mkdir()
    save_file(HandleDetector(HandleDetectorConfig(channels=4, dilations=(1,))).state_dict(),
              str(folder / DETECTOR_DIR / "model.safetensors"))
    (folder / DETECTOR_DIR / "config.json").write_text(json.dumps({"model": {
        "channels": 4, "dilations": [1]}}))
    fitted = FittedModel(folder)
    assert fitted.handle_detector is not None
    captures_command("closet", n=1, out=tmp_path / "caps", views=6, size=64)
    capture = read_capture_set(tmp_path / "caps" / "closet_000")

    class TrueMasks:  # a perfect mask detector: the capture's own handle labels, no offsets
        def detect(self, images):
            return [HandleMap.centroid_only((cv2.imread(str(capture.root / p), cv2.IMREAD_UNCHANGED)
                                             == 3).astype(np.float32))
                    for p in capture.gt["label_paths"]]

    fitted.handle_detector = TrueMasks()
    small = FitConfig(preset="thorough", restarts=2, explore_steps=2, max_steps=4, explore_rays=32,
                      rays_per_step=32, eval_rays=64, focus_steps=0)
    result, _ = infer(fitted, capture, small, np.linspace(0, 1, 3))
    seen = result.extra["handle_sighting"]
    assert seen["used"] and seen["sightings"] >= len(seen["views"]) >= 3
    # A bar's visible middle is within about its radius of the grip centre.
    assert np.linalg.norm(np.array(seen["p_O"]) - capture.gt["keypoints"]["handle"]) < 0.03
    result, _ = infer(fitted, capture, replace(small, sighting_weight=0.0), np.linspace(0, 1, 3))
    assert result.extra["handle_sighting"] == {"used": False, "why": "turned off"}
    result, _ = infer(FittedModel(model_folder), capture, small, np.linspace(0, 1, 3))
    assert result.extra["handle_sighting"]["why"] == "the model ships no handle detector"


def test_the_reported_q_is_the_articulation_that_was_fitted(model_folder, capture):
    """A code below q = 0 (the lower half circle, never trained) is put back on the upper half
    by the first step, so keypoints at the reported q are those of the fitted code."""
    from nfr_drake.inference.fit import _adam

    fitted = FittedModel(model_folder)
    z = torch.cat([q_to_z_art(torch.tensor([-0.2, -0.05])), fitted.z_obj_mean.expand(2, -1)], -1)
    config = FitConfig(preset="thorough", restarts=2, explore_rays=32, focus_steps=0)
    _adam(fitted.model, z, observed_rays(capture), config, torch.Generator().manual_seed(0),
          steps=1, rays_per_step=32, stop_early=False)
    z = z.detach()
    assert (z[:, 1] >= 0.0).all()
    with torch.no_grad():
        fitted_keypoints = fitted.model.keypoints(z).double().numpy()
    for code, keypoints in zip(z, fitted_keypoints, strict=True):
        q = float(z_art_to_q(code[:2]))
        np.testing.assert_allclose(keypoint_trajectory(fitted.model, code, np.array([q]))[0],
                                   keypoints, atol=1e-5)


def test_the_start_near_the_sighting_runs_only_with_codes_and_a_sighting(model_folder, capture):
    fitted = FittedModel(model_folder)
    rays = observed_rays(capture)
    config = FitConfig(preset="thorough", start="spread", restarts=2, explore_steps=10, max_steps=12,
                       explore_rays=32, rays_per_step=32, eval_rays=64, focus_steps=0)
    z0 = torch.cat([torch.zeros(2), fitted.codes[0]])
    sighting = PartSighting(0, fitted.model.keypoints(z0[None])[0, 0].detach())
    plain = fit_latent(fitted.model, rays, config, fitted.z_obj_mean, sighting=sighting)
    assert not plain.sighted_start
    with_codes = fit_latent(fitted.model, rays, config, fitted.z_obj_mean, sighting=sighting,
                            codes=fitted.codes)
    assert isinstance(with_codes.sighted_start, bool) and not torch.equal(with_codes.z, plain.z)
    assert plain.steps == with_codes.steps == 12  # the second start stays within max_steps
    off = fit_latent(fitted.model, rays, replace(config, sighting_codes=0), fitted.z_obj_mean,
                     sighting=sighting, codes=fitted.codes)
    assert torch.equal(off.z, plain.z) and not off.sighted_start
    with pytest.raises(ConfigError):
        FitConfig(sighting_codes=-1)


def test_report_adds_the_detector_row_with_both_handles_marked(model_folder, capture):
    from nfr_drake.inference.infer import observed_vs_rendered
    from nfr_drake.perception.handle_detector.model import HandleDetector, HandleDetectorConfig

    fitted = FittedModel(model_folder)
    z = torch.cat([torch.zeros(2), fitted.z_obj_mean])
    plain = observed_vs_rendered(fitted.model, z, 0.0, capture)
    detector = HandleDetector(HandleDetectorConfig(channels=4, dilations=(1,)))
    handle = np.array(capture.gt["keypoints"]["handle"])
    with_row = observed_vs_rendered(fitted.model, z, 0.0, capture, detector=detector,
                                    sighted_p_O=handle, handle_p_O=handle + 0.05)
    assert with_row.shape[0] > plain.shape[0] and with_row.shape[1] == plain.shape[1]
    bottom = with_row[plain.shape[0]:]
    assert (np.all(bottom == [0, 255, 0], axis=-1)).any()  # the green cross is drawn
    assert (np.all(bottom == [255, 0, 255], axis=-1)).any()  # and the magenta square
