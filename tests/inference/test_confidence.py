"""Fit confidence: features of a fit, the calibration (monotone, read from confidence.json), the
refusal line, and the capture variants it is checked on."""

import json
import shutil

import numpy as np
import pytest

from nfr_drake.cli import main
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.capture_variants import FEW_VIEWS, apply_variant, load_labels
from nfr_drake.eval.confidence_calibration import FURNITURE_TERMS, ROOM_TERMS, TERMS
from nfr_drake.inference.confidence import (
    ADVICE,
    CONFIDENCE_FILE,
    ConfidenceModel,
    edge_band,
    fit_features,
    fit_logistic,
    refusal,
    uniform_background_mask,
)

FEATURES = ("image_loss", "image_loss_worst_view", "silhouette_iou", "silhouette_iou_worst_view",
            "edge_contact", "sighting_missing", "sighting_gap_m", "start_loss_ratio",
            "code_distance", "views", "room")


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("captures")
    captures_command("closet", n=1, out=root, views=4, size=24, seed=7)
    return next(p for p in root.iterdir() if (p / "transforms.json").is_file())


def _calibration(threshold=0.5) -> ConfidenceModel:
    return ConfidenceModel([("image_loss", "log10"), ("silhouette_iou_worst_view", "one_minus")],
                           [-2.5, 0.1], [0.5, 0.1], [-2.0, -1.0], 1.0, threshold,
                           {"command": "test"})


def _infer(capture, model, out):
    return main(["infer", str(capture), "--model", str(model), "--out", str(out), "--restarts",
                 "1", "--max-steps", "2", "--fit.explore-steps", "0", "--focus-steps", "0",
                 "--fit.preset", "thorough", "--threads", "1"])


def test_infer_reports_the_features_and_with_a_calibration_the_probability(
        capture, model_folder, tmp_path, capsys):
    assert _infer(capture, model_folder, tmp_path / "plain.json") == 0
    plain = json.loads((tmp_path / "plain.json").read_text())["confidence"]
    assert plain["p_handle_within_2cm"] is None and "no calibration" in capsys.readouterr().out
    assert set(plain["features"]) == set(FEATURES) and len(plain["per_view"]) == 4
    f = plain["features"]
    assert f["views"] == 4 and 0.0 <= f["silhouette_iou_worst_view"] <= f["silhouette_iou"] <= 1.0
    assert 0.0 < f["image_loss"] <= f["image_loss_worst_view"] and f["code_distance"] > 0.0
    assert f["image_loss"] == pytest.approx(np.mean([v["image_loss"] for v in plain["per_view"]]))

    calibrated = tmp_path / "closet"
    shutil.copytree(model_folder, calibrated)
    _calibration().write(calibrated)
    assert _infer(capture, calibrated, tmp_path / "calibrated.json") == 0
    doc = json.loads((tmp_path / "calibrated.json").read_text())["confidence"]
    assert doc["p_handle_within_2cm"] == pytest.approx(_calibration().probability(doc["features"]))
    assert doc["threshold"] == 0.5
    assert f"P(handle within 2 cm) = {doc['p_handle_within_2cm']:.2f}" in capsys.readouterr().out


def test_logistic_calibration_recovers_a_monotone_law_and_round_trips(tmp_path):
    rng = np.random.default_rng(0)
    loss = 10 ** rng.uniform(-3.5, -1.0, 400)
    p_true = 1 / (1 + np.exp(-(-3.0 * (np.log10(loss) + 2.0))))
    y = (rng.uniform(size=400) < p_true).astype(float)
    x = np.log10(loss)
    coef, intercept = fit_logistic(((x - x.mean()) / x.std())[:, None], y, l2=0.1)
    assert coef[0] < 0  # more image loss, less confidence
    model = ConfidenceModel([("image_loss", "log10")], [x.mean()], [x.std()], coef.tolist(),
                            intercept, 0.3, {})
    p = [model.probability({"image_loss": v}) for v in np.logspace(-4, 0, 20)]
    assert np.all(np.diff(p) < 0) and p[0] > 0.9 and p[-1] < 0.1
    assert model.probability({"image_loss": 1e-2}) == pytest.approx(0.5, abs=0.12)
    model.write(tmp_path)
    again = ConfidenceModel.read(tmp_path)
    assert again == model and ConfidenceModel.read(tmp_path / "none") is None


def test_an_unreadable_calibration_is_a_one_line_error(tmp_path):
    (tmp_path / CONFIDENCE_FILE).write_text(json.dumps({"terms": [["image_loss", "cube"]]}))
    with pytest.raises(NfrDrakeError, match="not a readable confidence calibration"):
        ConfidenceModel.read(tmp_path)


def test_refusal_says_why_and_what_to_do():
    features = dict.fromkeys(FEATURES, 0.0) | {"views": 10.0, "silhouette_iou_worst_view": 0.6,
                                               "image_loss": 0.05, "image_loss_worst_view": 0.08,
                                               "edge_contact": 0.3}
    model = ConfidenceModel([("silhouette_iou_worst_view", "one_minus"), ("edge_contact", "identity")],
                            [0.1, 0.05], [0.1, 0.1], [-1.0, -0.5], 0.0, 0.4, {})
    confidence = {"p_handle_within_2cm": 0.2, "threshold": 0.4, "features": features,
                  "weakest": model.weakest(features)}
    line = refusal(confidence)
    assert line.startswith("refused: P(handle within 2 cm) = 0.20 < 0.40") and "\n" not in line
    assert confidence["weakest"] == "silhouette_iou_worst_view" and "silhouette IoU 0.60" in line
    assert refusal(confidence, threshold=0.1) is None
    cut = features | {"silhouette_iou_worst_view": 0.95}
    assert "cut by the image edge" in refusal({**confidence, "weakest": model.weakest(cut)})
    assert "more views" in refusal({**confidence, "weakest": None})
    two_views = {**confidence, "features": features | {"views": 2.0}, "weakest": "sighting_missing"}
    assert "more sides" in refusal(two_views)  # no sighting is possible below 3 views
    assert refusal({**confidence, "p_handle_within_2cm": None}) is None  # no calibration
    room = refusal({**confidence, "features": features | {"room": 1.0}})
    assert "not calibrated" in room and "--min-confidence 0" in room and "\n" not in room
    # A furniture part without a sighting of its own: that is what the line says, whichever
    # sighting term weighed most.
    unsighted = {**confidence, "features": features | {"part_unsighted": 1.0},
                 "weakest": "part_sighting_rms_px"}
    assert "sighted no handle of this part" in refusal(unsighted)
    assert "only loosely" in refusal({**unsighted, "features": features | {"part_unsighted": 0.0}})


def test_every_calibration_term_has_its_own_advice():
    """A refusal names what to do after its weakest term: each term a calibration can keep has a
    line of its own, not the generic one."""
    for name, _ in {*TERMS, *ROOM_TERMS, *FURNITURE_TERMS}:
        assert name in ADVICE and ADVICE[name] != ADVICE[None], name


def test_background_mask_finds_an_object_on_a_uniform_background():
    image = np.full((20, 30, 3), 235, np.uint8)
    image[5:12, 8:20] = (40, 90, 40)
    mask = uniform_background_mask(image)
    assert mask.sum() == 7 * 12 and mask[5:12, 8:20].all()


def test_capture_variants(capture):
    cap = read_capture_set(capture)
    images = cap.load_images()
    few, few_images = apply_variant("few_views", cap, images, 0)
    assert len(few.frames) == len(few_images) == FEW_VIEWS
    cut, cut_images = apply_variant("edge_cut", cap, images, 0)
    for frame, new, image in zip(cut.frames, cut_images, images, strict=True):
        assert new.shape[1] == frame.camera.width < image.shape[1]
        assert frame.camera.cx in (cap.frames[0].camera.cx,
                                   cap.frames[0].camera.cx - (image.shape[1] - new.shape[1]))
    for variant in ("occluded", "background", "recoloured"):
        same, changed = apply_variant(variant, cap, images, 0)
        assert same is cap and any((a != b).any() for a, b in zip(images, changed, strict=True))
    assert apply_variant("background", cap, images, 3)[1][0].tolist() == \
        apply_variant("background", cap, images, 3)[1][0].tolist()
    with pytest.raises(NfrDrakeError, match="unknown capture variant"):
        apply_variant("fog", cap, images, 0)


def test_the_edge_band_covers_the_sides_the_mask_touches():
    mask = np.zeros((16, 24), bool)
    assert not edge_band(mask).any()
    mask[5:9, 0:6] = True  # touches the left side only
    band = edge_band(mask)
    assert band[:, :3].all() and not band[:, 3:].any()
    mask[0, 12] = True  # and the top
    band = edge_band(mask)
    assert band[:2].all() and band[:, :3].all() and not band[2:, 3:].any()


def _room_features(capture, model_folder, images, masks):
    import torch

    from nfr_drake.inference.infer import FittedModel
    from nfr_drake.nfr.latent import q_to_z_art

    fitted = FittedModel(model_folder)
    cap = read_capture_set(capture)
    z = torch.cat([q_to_z_art(torch.tensor(0.3)), fitted.z_obj_mean])
    return fit_features(fitted.model, z, cap.frames, images, np.array([1.0, 2.0]),
                        fitted.codes, fitted.code_scale, 0, None, masks)


def test_in_a_room_the_silhouette_is_the_mask_and_not_compared_along_the_sides_it_touches(
        capture, model_folder):
    cap = read_capture_set(capture)
    images = cap.load_images()
    masks = [(label > 0).astype(np.float32) for label in load_labels(cap)]
    _, room_images = apply_variant("background", cap, images, 0)  # another background: a "room"
    alone, alone_views = _room_features(capture, model_folder, images, None)
    room, room_views = _room_features(capture, model_folder, room_images, masks)
    assert room["room"] == 1.0 and alone["room"] == 0.0
    # Only the background changed: the object's pixels, their image loss and the silhouettes
    # are the same as before the uniform background.
    same, _ = _room_features(capture, model_folder, images, masks)
    for name in ("image_loss", "silhouette_iou", "silhouette_iou_worst_view", "edge_contact"):
        assert room[name] == pytest.approx(same[name])
    border, _ = _room_features(capture, model_folder, room_images, None)
    assert border["edge_contact"] > alone["edge_contact"]  # the room is no background

    spilled, blob = [m.copy() for m in masks], [m.copy() for m in masks]
    for a, b in zip(spilled, blob, strict=True):
        a[:, :3] = 1.0  # the mask spills along the left side, within its band
        b[:, 0] = 1.0
    left = [v["silhouette_iou"] for v in _room_features(capture, model_folder, room_images, spilled)[1]]
    thin = [v["silhouette_iou"] for v in _room_features(capture, model_folder, room_images, blob)[1]]
    assert left == pytest.approx(thin)
    for a in spilled:
        a[8:16, 8:16] = 1.0  # a spill away from the sides counts
    inner = [v["silhouette_iou"] for v in _room_features(capture, model_folder, room_images, spilled)[1]]
    assert inner != pytest.approx(left)
    assert len(room_views) == len(alone_views) == 4


def test_a_fit_in_a_room_is_calibrated_by_the_room_file_when_the_model_has_one(
        capture, model_folder, tmp_path):
    from types import SimpleNamespace

    import torch

    from nfr_drake.inference.confidence import ROOM_CONFIDENCE_FILE
    from nfr_drake.inference.infer import FittedModel, fit_confidence
    from nfr_drake.nfr.latent import q_to_z_art

    folder = tmp_path / "closet"
    shutil.copytree(model_folder, folder)
    alone = _calibration(threshold=0.5)
    room = ConfidenceModel([("silhouette_iou_worst_view", "one_minus")], [0.3], [0.2], [-0.5], 4.0,
                           0.97, {"command": "test"})
    alone.write(folder)
    room.write(folder, ROOM_CONFIDENCE_FILE)
    cap = read_capture_set(capture)
    images = cap.load_images()
    masks = [(label > 0).astype(np.float32) for label in load_labels(cap)]
    fitted = FittedModel(folder)
    outcome = SimpleNamespace(z=torch.cat([q_to_z_art(torch.tensor(0.3)), fitted.z_obj_mean]),
                              start_losses=np.array([1.0, 2.0]))

    in_room = fit_confidence(fitted, outcome, cap, images, None, masks)
    assert in_room["calibration"] == ROOM_CONFIDENCE_FILE and in_room["threshold"] == 0.97
    assert in_room["p_handle_within_2cm"] == pytest.approx(room.probability(in_room["features"]))
    assert in_room["weakest"] == "silhouette_iou_worst_view"
    line = refusal(in_room, threshold=1.0)  # refused by the room calibration: its weakest feature
    assert "covers the object poorly" in line and "not calibrated" not in line
    plain = fit_confidence(fitted, outcome, cap, images, None)  # the object alone: confidence.json
    assert plain["calibration"] == CONFIDENCE_FILE and plain["threshold"] == 0.5
    assert plain["p_handle_within_2cm"] == pytest.approx(alone.probability(plain["features"]))

    (folder / ROOM_CONFIDENCE_FILE).unlink()  # an older model: rooms as before, by confidence.json
    old = fit_confidence(FittedModel(folder), outcome, cap, images, None, masks)
    assert old["calibration"] == CONFIDENCE_FILE and old["features"] == in_room["features"]
    assert old["p_handle_within_2cm"] == pytest.approx(alone.probability(old["features"]))
    assert "not calibrated" in refusal(old, threshold=1.0)
