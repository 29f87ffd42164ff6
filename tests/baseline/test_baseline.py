"""Image-encoder baseline: shapes, the explicit geometric extrapolation, checkpoints, training."""

import numpy as np
import pytest
import torch

from nfr_drake.baseline.model import BaselineConfig, ImageEncoderBaseline, extrapolate_keypoints
from nfr_drake.baseline.train import (
    BaselineTrainConfig,
    load_baseline,
    save_baseline,
    train_baseline,
)
from nfr_drake.data.generate import generate_dataset
from nfr_drake.data.shards import DatasetSpec
from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object

CLOSET_KP = ("handle", "hinge_top", "hinge_bottom", "goal")


def test_forward_shapes_and_ranges():
    model = ImageEncoderBaseline(BaselineConfig("drawer", ("handle", "goal"), "prismatic",
                                                channels=(8, 16)))
    out = model(torch.rand(3, 5, 3, 32, 32), torch.eye(4).expand(3, 5, 4, 4))
    assert out.q.shape == (3,) and out.keypoints.shape == (3, 2, 3) and out.travel.shape == (3,)
    assert ((out.q > 0) & (out.q < 1)).all() and (out.travel > 0).all()


@pytest.mark.parametrize("category", ["closet", "drawer"])
def test_extrapolation_with_true_inputs_reproduces_the_true_trajectory(category):
    grid = np.linspace(0, 1, 11)
    for i in range(6):  # both hinge sides among these seeds
        obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, 1, i))
        q = 0.3
        pred = extrapolate_keypoints(obj.keypoint_names, obj.joint_type, obj.keypoint_array(q), q,
                                     obj.joint_upper, grid)
        np.testing.assert_allclose(pred, obj.keypoint_array(grid), atol=1e-9)


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
