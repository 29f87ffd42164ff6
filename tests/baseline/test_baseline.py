"""Image-encoder baseline: shapes, the explicit geometric extrapolation, checkpoints, training;
the furniture baseline's slots, training and parts."""

from pathlib import Path

import numpy as np
import pytest
import torch

from nfr_drake.baseline.model import (
    BaselineConfig,
    ImageEncoderBaseline,
    extrapolate_keypoints,
)
from nfr_drake.baseline.predict import predict_capture
from nfr_drake.baseline.train import (
    BaselineTrainConfig,
    load_baseline,
    save_baseline,
    train_baseline,
)
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.generate import generate_dataset
from nfr_drake.data.object_records import front_record
from nfr_drake.data.shards import DatasetSpec
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS, _part_keypoints, slot_trajectory
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.eval.command import eval_command
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object

CLOSET_KP = ("handle", "hinge_top", "hinge_bottom", "goal")
FURNITURE = BaselineConfig("furniture", SLOT_KEYPOINTS, "per_slot", channels=(8, 16), num_slots=8)


def test_forward_shapes_and_ranges():
    model = ImageEncoderBaseline(BaselineConfig("drawer", ("handle", "goal"), "prismatic",
                                                channels=(8, 16)))
    out = model(torch.rand(3, 5, 3, 32, 32), torch.eye(4).expand(3, 5, 4, 4))
    assert out.q.shape == (3, 1) and out.keypoints.shape == (3, 1, 2, 3) and out.travel.shape == (3, 1)
    assert ((out.q > 0) & (out.q < 1)).all() and (out.travel > 0).all()
    assert out.exists is None and out.types is None


def test_furniture_slots_have_q_keypoints_and_exists_and_type_logits():
    out = ImageEncoderBaseline(FURNITURE)(torch.rand(2, 3, 3, 32, 32), torch.eye(4).expand(2, 3, 4, 4))
    assert out.q.shape == (2, 8) and out.keypoints.shape == (2, 8, 4, 3)
    assert out.exists.shape == (2, 8) and out.types.shape == (2, 8, 2)
    assert ((out.q > 0) & (out.q < 1)).all() and (out.travel == 0).all()
    with pytest.raises(ConfigError, match="num_slots"):
        BaselineConfig("furniture", SLOT_KEYPOINTS, "per_slot", num_slots=1)
    with pytest.raises(ConfigError, match="num_slots"):
        BaselineConfig("closet", CLOSET_KP, "revolute", num_slots=2)
    with pytest.raises(ConfigError, match="slot keypoints"):
        BaselineConfig("furniture", CLOSET_KP, "per_slot", num_slots=8)


def test_the_shipped_closet_baseline_loads_as_one_slot():
    model, doc = load_baseline(Path("models/closet/baseline"))
    assert model.config.num_slots == 1 and doc["training"]["image_size"] == 64
    out = model(torch.rand(1, 2, 3, 64, 64), torch.eye(4).expand(1, 2, 4, 4))
    assert out.keypoints.shape == (1, 1, 4, 3) and (out.travel == 0).all()


@pytest.mark.parametrize("category", ["closet", "drawer"])
def test_extrapolation_with_true_inputs_reproduces_the_true_trajectory(category):
    grid = np.linspace(0, 1, 11)
    for i in range(6):  # both hinge sides among these seeds
        obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, 1, i))
        q = 0.3
        pred = extrapolate_keypoints(obj.keypoint_names, obj.joint_type, obj.keypoint_array(q), q,
                                     obj.joint_upper, grid)
        np.testing.assert_allclose(pred, obj.keypoint_array(grid), atol=1e-9)


def test_slot_extrapolation_with_true_inputs_reproduces_the_true_trajectories():
    grid, q = np.linspace(0, 1, 11), 0.3
    seen = set()
    for i in range(8):
        obj = sample_object("furniture", object_rng(SEED_DOMAIN_TRAIN, 1, i))
        for k, front in enumerate(obj.fronts):
            qs = np.r_[q, grid]
            record = {**front_record(obj, k), "q": qs.tolist(), "keypoints": {
                n: front.keypoint_array(qs)[:, j].tolist() for j, n in enumerate(front.keypoint_names)}}
            true = _part_keypoints(record)  # (1 + N, 4, 3)
            np.testing.assert_allclose(slot_trajectory(front.kind, true[0], q, grid), true[1:], atol=1e-9)
            seen.add((front.kind, front.axis_O))
    assert len(seen) == 3  # drawers and doors hinged on either side


def test_checkpoint_round_trip_and_errors(tmp_path):
    model = ImageEncoderBaseline(BaselineConfig("closet", CLOSET_KP, "revolute", channels=(8, 16)))
    save_baseline(tmp_path / "m", model, {"note": "test"})
    loaded, doc = load_baseline(tmp_path / "m")
    x, poses = torch.rand(1, 2, 3, 32, 32), torch.eye(4).expand(1, 2, 4, 4)
    torch.testing.assert_close(loaded(x, poses).keypoints, model.eval()(x, poses).keypoints)
    (tmp_path / "m" / "model.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(NfrDrakeError, match="model.safetensors: not a readable safetensors"):
        load_baseline(tmp_path / "m")
    with pytest.raises(NfrDrakeError, match="config.json: baseline config not found"):
        load_baseline(tmp_path / "missing")


def test_short_training_reduces_the_loss_and_resumes(tmp_path):
    spec = DatasetSpec("closet", objects=4, articulations=3, views=3, size=32, seed=2)
    generate_dataset(spec, tmp_path / "data", workers=1, progress=False)
    config = BaselineTrainConfig(steps=60, batch=4, views=2, checkpoint_every=30, log_every=10, threads=1)
    train_baseline(tmp_path / "data", tmp_path / "run", config, progress=False)
    rows = (tmp_path / "run" / "metrics.csv").read_text().splitlines()[1:]
    first, last = float(rows[0].split(",")[1]), float(rows[-1].split(",")[1])
    assert last < first
    longer = BaselineTrainConfig(steps=90, batch=4, views=2, checkpoint_every=30, log_every=10, threads=1)
    train_baseline(tmp_path / "data", tmp_path / "run", longer, resume=True, progress=False)
    assert (tmp_path / "run" / "train_state.json").read_text() == '{"step": 90}'
    with pytest.raises(NfrDrakeError, match="not empty"):
        train_baseline(tmp_path / "data", tmp_path / "run", config, progress=False)


def test_furniture_training_resumes_and_its_prediction_is_the_fits_parts_scored_by_eval(
        furniture_dataset, tmp_path):
    config = BaselineTrainConfig(steps=4, batch=2, views=2, checkpoint_every=2, log_every=2, threads=1)
    train_baseline(furniture_dataset, tmp_path / "run", config, progress=False)
    longer = BaselineTrainConfig(steps=6, batch=2, views=2, checkpoint_every=2, log_every=2, threads=1)
    train_baseline(furniture_dataset, tmp_path / "run", longer, resume=True, progress=False)
    assert (tmp_path / "run" / "train_state.json").read_text() == '{"step": 6}'
    assert len((tmp_path / "run" / "metrics.csv").read_text().splitlines()) == 1 + 3
    model, doc = load_baseline(tmp_path / "run")
    assert model.config.num_slots == 8 and model.config.joint_type == "per_slot"

    captures_command("furniture", n=1, out=tmp_path / "caps", views=2, size=24, seed=3)
    capture = read_capture_set(tmp_path / "caps" / "furniture_000")
    grid = np.linspace(0, 1, 5)
    pred = predict_capture(model, capture, doc["training"]["image_size"], grid)
    assert pred.trajectory.shape == (8, 5, 4, 3)
    pred.exists[:] = np.arange(8) < 2
    parts = pred.parts()
    assert [p["index"] for p in parts] == [0, 1]
    for p in parts:
        assert set(p) == {"index", "type", "q", "keypoints", "trajectory"}
        assert p["type"] in ("door", "drawer") and list(p["keypoints"]) == list(SLOT_KEYPOINTS)
        assert p["trajectory"]["q"] == grid.tolist() and len(p["trajectory"]["keypoints"]["handle"]) == 5
        np.testing.assert_allclose(p["keypoints"]["handle"], pred.keypoints[p["index"], 0])

    eval_command([tmp_path / "caps"], tmp_path / "eval", baseline=tmp_path / "run", category="furniture",
                 example_plots=0, threads=1)
    summary = (tmp_path / "eval" / "summary.md").read_text()
    assert "| caps | baseline | 1 | " in summary
    with pytest.raises(NfrDrakeError, match="a closet baseline, but the sets hold furniture"):
        eval_command([tmp_path / "caps"], tmp_path / "eval2", baseline=Path("models/closet/baseline"))
