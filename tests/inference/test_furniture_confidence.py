"""Fit confidence of a model with several parts (furniture): the part's features, P(the part's
handle within 2 cm) in the result of `infer` for each part, and the calibration's rows and file."""

import json
import shutil

import numpy as np
import pytest
import torch

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.eval.confidence_calibration import FURNITURE_TERMS, calibrate, featurize
from nfr_drake.eval.confidence_data import Case, run_case
from nfr_drake.inference.confidence import (
    ConfidenceModel,
    fit_features,
    part_features,
    refusal,
    render_views,
)
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import FittedModel, infer_command
from nfr_drake.nfr.latent import slots_q_to_z_art
from nfr_drake.perception.handle_triangulation import AGREE_PX, TriangulatedHandle

QUICK = FurnitureFitConfig(starts=2, keep=2, steps=3, rays_per_step=32, lookup_rays=32)
S = 8


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("furniture_conf")
    captures_command(category="furniture", n=1, out=out, views=3, size=24, seed=3)
    return out / "furniture_000"


def _code(fitted, i, q=0.0):
    """z (D,) of training code i with every slot at q."""
    return torch.cat([slots_q_to_z_art(torch.full((1, S), q), S)[0], fitted.codes[i]])


def _slot_handle(fitted, z, slot):
    with torch.no_grad():
        kp = fitted.model.keypoints(z[None].float())[0]
    return kp.view(S, len(SLOT_KEYPOINTS), 3)[slot, 0].double().numpy()


def test_part_features_measure_the_starts_spread_the_sighting_and_the_existence(
        furniture_model_folder, capture_dir):
    fitted = FittedModel(furniture_model_folder)
    capture = read_capture_set(capture_dir)
    images = capture.load_images()
    z, other = _code(fitted, 0), _code(fitted, 1, 0.5)
    views = render_views(fitted.model, z, capture.frames, images)
    with torch.no_grad():
        one = part_features(fitted.model, z, z[None], 1, capture.frames, views)
        two = part_features(fitted.model, z, torch.stack([z, other]), 1, capture.frames, views)
        handle = _slot_handle(fitted, z, 1)
        sighted = part_features(fitted.model, z, z[None], 1, capture.frames, views,
                                _sightings([handle + [0.03, 0.04, 0.0], handle + [1.0, 0.0, 0.0]]))
        absent = part_features(fitted.model, z, z[None], 5, capture.frames, views)
    assert one["start_spread_m"] == 0.0
    assert two["start_spread_m"] == pytest.approx(np.linalg.norm(handle - _slot_handle(fitted, other, 1)))
    assert two["start_spread_m"] > 0.0
    assert one["sighting_missing"] == 1.0 and one["sighting_gap_m"] == 0.0
    assert sighted["sighting_missing"] == 0.0 and sighted["sighting_gap_m"] == pytest.approx(0.05, abs=1e-6)
    # The tiny model's head says slot 1 exists (a drawer) and slot 5 does not, whatever the code.
    assert one["part_exists_logit"] == pytest.approx(5.0, abs=1e-4)
    assert absent["part_exists_logit"] == pytest.approx(-5.0, abs=1e-4)
    errors = np.concatenate([v.error for v in views])
    assert errors.min() <= one["part_image_loss"] <= errors.max()


def _sightings(points, views=(0, 1, 2), rms_px=0.5):
    """Triangulated handles at `points` (M, 3) in O, each agreed on by `views`, RMS `rms_px`."""
    return [TriangulatedHandle(np.asarray(p, float), tuple(views), rms_px, len(views)) for p in points]


def test_part_features_say_whether_the_part_has_a_sighting_of_its_own(furniture_model_folder, capture_dir):
    """Slot k is paired with sighting k: with 2 sightings slot 1 has one and slot 5 not; without
    sightings no slot has one. The own sighting's agreeing views and their RMS (scaled from the
    24 px photos to 128 px) are the part's; without one, 0 views and the agreement tolerance."""
    fitted = FittedModel(furniture_model_folder)
    capture = read_capture_set(capture_dir)
    z = _code(fitted, 0)
    views = render_views(fitted.model, z, capture.frames, capture.load_images())
    two = _sightings([[0.3, 0.0, 0.5], [0.3, 0.3, 0.5]][:1]) + _sightings([[0.3, 0.3, 0.5]], (0, 2), 0.3)
    with torch.no_grad():
        paired, unpaired, none = (part_features(fitted.model, z, z[None], k, capture.frames, views, h)
                                  for k, h in ((1, two), (5, two), (5, None)))
    assert (paired["part_unsighted"], unpaired["part_unsighted"], none["part_unsighted"]) == (0.0, 1.0, 1.0)
    assert none["sighting_missing"] == 1.0
    assert paired["part_sighting_views"] == 2.0
    assert paired["part_sighting_rms_px"] == pytest.approx(0.3 * 128 / 24)
    assert (unpaired["part_sighting_views"], unpaired["part_sighting_rms_px"]) == (0.0, AGREE_PX)


def test_the_code_distance_of_a_furniture_fit_is_that_of_its_z_obj(furniture_model_folder, capture_dir):
    # z_obj follows 2 S entries of z_art; reading it from entry 2 on (as for one slot) mixed the
    # other slots' z_art into the distance.
    fitted = FittedModel(furniture_model_folder)
    capture = read_capture_set(capture_dir)
    z = _code(fitted, 0, 0.7)
    features, _ = fit_features(fitted.model, z, capture.frames, capture.load_images(), np.ones(2),
                               fitted.codes, fitted.code_scale, 0, None)
    expected = torch.cdist(fitted.codes[:1].double(), fitted.codes.double())[0].mean() / fitted.code_scale
    assert features["code_distance"] == pytest.approx(float(expected))


def _furniture_calibration(threshold=0.5) -> ConfidenceModel:
    return ConfidenceModel([("part_exists_logit", "negative"), ("part_image_loss", "log10")],
                           [0.0, -1.5], [5.0, 0.5], [-1.5, -1.0], -0.5, threshold, {"command": "test"})


def test_infer_gives_each_part_its_probability_and_the_part_asked_for_in_the_result(
        furniture_model_folder, capture_dir, tmp_path, capsys):
    calibrated = tmp_path / "furniture"
    shutil.copytree(furniture_model_folder, calibrated)
    model = _furniture_calibration()
    model.write(calibrated)
    out = tmp_path / "r.json"
    infer_command(capture_dir, model=calibrated, out=out, furniture_fit=QUICK, trajectory_points=3,
                  part=2, threads=1)
    doc = json.loads(out.read_text())
    for p in doc["parts"]:
        c = p["confidence"]
        assert c["p_handle_within_2cm"] == pytest.approx(model.probability(c["features"]))
        assert c["threshold"] == 0.5 and "per_view" not in c
    confidence = doc["confidence"]
    assert confidence["features"] == doc["parts"][2]["confidence"]["features"]
    assert len(confidence["per_view"]) == 3 and confidence["features"]["views"] == 3
    assert f"P(handle within 2 cm) = {confidence['p_handle_within_2cm']:.2f}" in capsys.readouterr().out
    # A part the field does not find (slot 6: existence logit -5) is far less likely right.
    infer_command(capture_dir, model=calibrated, out=out, furniture_fit=QUICK, trajectory_points=3,
                  part=6, threads=1)
    absent = json.loads(out.read_text())["confidence"]
    assert absent["p_handle_within_2cm"] < 0.1 < confidence["p_handle_within_2cm"]
    line = refusal(absent)
    assert line.startswith("refused: P(handle within 2 cm) = ") and "this part" in line


def test_a_furniture_line_gives_one_row_per_true_part_and_its_calibration_round_trips(
        furniture_model_folder, capture_dir, tmp_path, monkeypatch):
    monkeypatch.setattr("nfr_drake.eval.confidence_data.FurnitureFitConfig", lambda: QUICK)
    fitted = FittedModel(furniture_model_folder)
    case = Case(str(furniture_model_folder), str(capture_dir), "clean", 0, "calibration")
    line = json.loads(json.dumps(run_case(case, fitted, None)))
    gt = read_capture_set(capture_dir).gt
    truth = {str(p["index"]): p["keypoints"]["handle"] for p in gt["parts"]}
    assert set(line["part_errors"]) == set(truth) and len(line["start_z"]) == QUICK.keep
    for k, error in line["part_errors"].items():
        handle = _slot_handle(fitted, torch.tensor(line["z"]), int(k))
        assert error == pytest.approx(np.linalg.norm(handle - truth[k]), abs=1e-5)
    rows = featurize([line])
    assert [r["part"] for r in rows] == [int(k) for k in line["part_errors"]]
    assert all(r["handle_error_m"] == line["part_errors"][str(r["part"])] for r in rows)
    assert all(name in r for r in rows for name, _ in FURNITURE_TERMS)
    # A calibration on rows like these is monotone in the existence logit and round-trips.
    rng = np.random.default_rng(0)
    synthetic = [{**rows[0], "part_exists_logit": float(v), "variant": "clean",
                  "handle_error_m": 0.01 if rng.uniform() < 1 / (1 + np.exp(-v)) else 0.3}
                 for v in rng.uniform(-6, 6, 200)]
    model = calibrate(synthetic, FURNITURE_TERMS, {"command": "test"})
    assert model.coef[[n for n, _ in FURNITURE_TERMS].index("part_exists_logit")] < 0
    model.write(tmp_path)
    again = ConfidenceModel.read(tmp_path)
    assert again.terms == model.terms and again.threshold == model.threshold
    for r in synthetic[:5]:
        assert again.probability(r) == pytest.approx(model.probability(r))
    p = [model.probability({**rows[0], "part_exists_logit": v}) for v in (-4.0, 0.0, 4.0)]
    assert p[0] < p[1] < p[2]
