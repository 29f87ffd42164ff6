"""The 2D handle detector: any image size, training that learns, resumes and round-trips; offset
targets for one handle (closets) and for several (furniture)."""

import json
import pickle
from dataclasses import replace

import numpy as np
import pytest
import torch

from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.errors import ConfigError
from nfr_drake.nfr.checkpoint import CheckpointError
from nfr_drake.perception.front_reading import FRONT_HEIGHT_PX
from nfr_drake.perception.handle_detector import training
from nfr_drake.perception.handle_detector.data import (
    project_points,
    projected_handles,
    sample_batch,
    sample_front_batch,
)
from nfr_drake.perception.handle_detector.model import HandleDetector, HandleDetectorConfig, load_detector
from nfr_drake.perception.handle_detector.training import DetectorTrainConfig, train_detector

SMALL = HandleDetectorConfig(channels=8, dilations=(1, 2, 1))


def test_any_image_size_gives_a_map_of_that_size():
    net = HandleDetector(SMALL)
    for h, w in ((32, 32), (48, 80)):
        (found,) = net.detect([np.zeros((h, w, 3), np.uint8)])
        prob = found.probability
        assert prob.shape == (h, w) and np.all((prob >= 0) & (prob <= 1))
        assert found.offset_px.shape == (h, w, 2)


def test_training_lowers_the_loss_resumes_and_round_trips(tiny_dataset, tmp_path):
    torch.manual_seed(0)
    config = DetectorTrainConfig(steps=40, images_per_batch=4, crop=24, checkpoint_every=20)
    out = tmp_path / "det"
    record = train_detector([tiny_dataset], out, config, SMALL)
    assert sorted(p.name for p in (out / "checkpoint").iterdir()) == [
        "model.safetensors", "optimizer.safetensors", "trainer.json"]
    losses = json.loads((out / "checkpoint" / "trainer.json").read_text())["losses"]
    assert len(losses) == 40 and np.mean(losses[-10:]) < np.mean(losses[:10])
    assert set(record["held_out_handle_iou"]) == {str(tiny_dataset)}
    saved = json.loads((out / "config.json").read_text())
    assert saved["model"]["channels"] == 8 and saved["train"]["steps"] == 40

    net, _ = load_detector(out)
    image = np.random.default_rng(0).integers(0, 255, (32, 32, 3), dtype=np.uint8)
    with pytest.raises(ConfigError, match="--resume"):
        train_detector([tiny_dataset], out, config, SMALL)
    # A finished run resumed is already done: the same weights come out.
    train_detector([tiny_dataset], out, config, SMALL, resume=True)
    again, _ = load_detector(out)
    (a,), (b,) = net.detect([image]), again.detect([image])
    np.testing.assert_allclose(a.probability, b.probability)
    np.testing.assert_allclose(a.offset_px, b.offset_px)
    with pytest.raises(ConfigError, match="other options"):
        train_detector([tiny_dataset], out, DetectorTrainConfig(steps=41, checkpoint_every=20), SMALL,
                       resume=True)


def test_bad_folder_and_bad_options(tmp_path):
    with pytest.raises(CheckpointError, match="config.json: handle detector config not found"):
        load_detector(tmp_path)
    with pytest.raises(ConfigError):
        HandleDetectorConfig(channels=0)
    with pytest.raises(ConfigError):
        DetectorTrainConfig(crop=4)
    with pytest.raises(ConfigError, match="at least one"):
        train_detector([], tmp_path / "x", DetectorTrainConfig())


def test_offset_targets_point_at_the_projected_grip_centre(tiny_dataset):
    """On handle pixels, pixel centre + target offset is one point: the handle keypoint's
    projection, inside the handle's pixel box (so the projection's conventions are right), and
    mirrored crops mirror the offsets."""
    data = RenderedDataset(tiny_dataset)
    rgb, mask, offset = sample_batch(data, 128, data.spec.size, np.random.default_rng(0))
    S = data.spec.size
    seen = 0
    for m, o in zip(mask.numpy() > 0.5, offset.numpy(), strict=True):
        rows, cols = np.nonzero(m)
        if rows.size < 3:
            continue
        votes = np.stack([cols + 0.5 + o[0, rows, cols], rows + 0.5 + o[1, rows, cols]], -1)
        np.testing.assert_allclose(votes, np.broadcast_to(votes[0], votes.shape), atol=1e-3)
        assert cols.min() - 1 <= votes[0, 0] <= cols.max() + 2
        assert rows.min() - 1 <= votes[0, 1] <= rows.max() + 2
        seen += 1
    assert seen >= 5 and rgb.shape[-1] == S


class _RunsCode:
    """Unpickling this touches a file: what a crafted checkpoint could do."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (type(self.marker).touch, (self.marker,))


def test_a_pickled_checkpoint_is_refused_and_never_unpickled(tiny_dataset, tmp_path):
    out = tmp_path / "det"
    out.mkdir()
    marker = tmp_path / "code_ran"
    (out / "checkpoint.pt").write_bytes(pickle.dumps({"model": _RunsCode(marker)}))
    config = DetectorTrainConfig(steps=2, images_per_batch=2, crop=16, checkpoint_every=1)
    for resume in (True, False):
        with pytest.raises(CheckpointError, match="checkpoint.pt: a pickled checkpoint"):
            train_detector([tiny_dataset], out, config, SMALL, resume=resume)
    assert not marker.exists()


def test_resume_continues_where_the_killed_run_left_off(tiny_dataset, tmp_path, monkeypatch):
    """A run killed at step 25 (checkpoint at 20) and resumed ends with the weights of a run that
    was never killed: weights, Adam moments, scheduler and both RNGs come back from the
    safetensors + JSON checkpoint."""
    config = DetectorTrainConfig(steps=40, images_per_batch=2, crop=16, checkpoint_every=10)
    image = np.random.default_rng(1).integers(0, 255, (32, 32, 3), dtype=np.uint8)
    torch.manual_seed(5)
    train_detector([tiny_dataset], tmp_path / "once", config, SMALL)
    calls = []

    def killed_at_step_25(*args):
        calls.append(1)
        if len(calls) == 25:
            raise KeyboardInterrupt
        return loss(*args)

    loss = training._loss
    monkeypatch.setattr(training, "_loss", killed_at_step_25)
    torch.manual_seed(5)
    with pytest.raises(KeyboardInterrupt):
        train_detector([tiny_dataset], tmp_path / "twice", config, SMALL)
    monkeypatch.setattr(training, "_loss", loss)
    torch.manual_seed(99)  # the resumed run restores the torch RNG itself
    train_detector([tiny_dataset], tmp_path / "twice", config, SMALL, resume=True)
    (a,), (b,) = (load_detector(tmp_path / run)[0].detect([image]) for run in ("once", "twice"))
    np.testing.assert_allclose(a.probability, b.probability, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(a.offset_px, b.offset_px, rtol=1e-5, atol=1e-5)


def test_furniture_pixels_vote_for_their_own_fronts_handle(furniture_dataset):
    """Furniture: each handle pixel's target is the projected handle of its own front (the part
    image), so a crop's votes are several points, each a front's projected handle (mirrored in a
    mirrored crop); the projections agree with the handles' label pixels."""
    data = RenderedDataset(furniture_dataset)
    S = data.spec.size
    A, V = data.spec.articulations, data.spec.views
    targets = []
    for j, rec in enumerate(data.records):
        for a in range(A):
            for v in range(V):
                uv = projected_handles(data, j, a, v)
                assert uv.shape == (len(rec.meta["parts"]), 2)
                targets += [uv, uv * [-1, 1] + [S, 0]]
                labels, part = np.asarray(rec.label[a, v]), np.asarray(rec.part[a, v])
                for k in range(len(uv)):
                    rows, cols = np.nonzero((labels == 3) & (part == k))
                    if rows.size >= 2:
                        assert np.linalg.norm([cols.mean() + 0.5, rows.mean() + 0.5] - uv[k]) < 3.0
    targets = np.concatenate(targets)
    rgb, mask, offset = sample_batch(data, 64, S, np.random.default_rng(0))
    several = 0
    for m, o in zip(mask.numpy() > 0.5, offset.numpy(), strict=True):
        rows, cols = np.nonzero(m)
        votes = np.stack([cols + 0.5 + o[0, rows, cols], rows + 0.5 + o[1, rows, cols]], -1)
        if not len(votes):
            continue
        assert np.abs(votes[:, None] - targets[None]).max(-1).min(-1).max() < 1e-3
        several += len(np.unique(np.round(votes, 3), axis=0)) >= 2
    assert several >= 3


def test_front_targets_vote_for_each_fronts_face_corners(furniture_dataset):
    """Front outputs' targets: every front pixel of the scaled image votes (pixel + offset) for its
    own front's projected face corners, door pixels are front pixels of door fronts; mirrored
    images vote for the mirrored corners with left and right swapped."""
    data = RenderedDataset(furniture_dataset)
    scale = data.spec.size / FRONT_HEIGHT_PX
    targets = []
    for j, rec in enumerate(data.records):
        for a in range(data.spec.articulations):
            for v in range(data.spec.views):
                faces = np.array([p["face_corners"][a] for p in rec.meta["parts"]])
                corners = project_points(data, j, a, v, faces)
                uv = corners / scale
                mirrored = (uv * [-1, 1] + [FRONT_HEIGHT_PX, 0])[:, [1, 0, 3, 2]]
                targets += [uv, mirrored]
    targets = np.concatenate(targets)  # (n, 4, 2)
    rgb, front, door, offset = sample_front_batch(data, 24, np.random.default_rng(1))
    assert rgb.shape[2:] == front.shape[1:] == (FRONT_HEIGHT_PX, FRONT_HEIGHT_PX)
    assert offset.shape == (24, 4, 2, FRONT_HEIGHT_PX, FRONT_HEIGHT_PX)
    assert torch.all(door <= front) and 0 < door.sum() < front.sum()
    for f, o in zip(front.numpy() > 0.5, offset.numpy(), strict=True):
        rows, cols = np.nonzero(f)
        votes = np.stack([cols + 0.5 + o[:, 0, rows, cols], rows + 0.5 + o[:, 1, rows, cols]], -1)
        nearest = np.abs(votes.transpose(1, 0, 2)[:, None] - targets[None]).max((-1, -2)).min(-1)
        assert nearest.max() < 1e-3


def test_front_outputs_start_from_a_handle_detector_and_train(furniture_dataset, tiny_dataset, tmp_path):
    torch.manual_seed(0)
    config = DetectorTrainConfig(steps=40, images_per_batch=2, crop=16, checkpoint_every=40)
    handles_only = tmp_path / "handles"
    train_detector([furniture_dataset], handles_only, config, SMALL)
    fronts = HandleDetectorConfig(channels=8, dilations=(1, 2, 1), fronts=True)
    started = HandleDetector(fronts)
    started.start_from(load_detector(handles_only)[0])
    image = np.random.default_rng(0).integers(0, 255, (48, 40, 3), dtype=np.uint8)
    (a,), (b,) = load_detector(handles_only)[0].detect([image]), started.detect([image])
    np.testing.assert_allclose(a.probability, b.probability, atol=1e-6)
    (front_map,) = started.read_fronts([image])
    assert front_map.door_probability.shape == (FRONT_HEIGHT_PX, round(40 * FRONT_HEIGHT_PX / 48))
    assert front_map.corner_offset_px.shape == (*front_map.door_probability.shape, 4, 2)
    assert front_map.scale == pytest.approx([40 / front_map.door_probability.shape[1], 48 / FRONT_HEIGHT_PX])
    with pytest.raises(ConfigError, match="no front outputs"):
        load_detector(handles_only)[0].read_fronts([image])
    with pytest.raises(ConfigError, match="another architecture"):
        HandleDetector(HandleDetectorConfig(channels=4, dilations=(1, 2, 1), fronts=True)).start_from(started)
    with pytest.raises(ConfigError, match="give --fronts"):
        train_detector([furniture_dataset], tmp_path / "no_fronts", config, SMALL, init=handles_only)

    out = tmp_path / "fronts"
    record = train_detector([furniture_dataset], out, config, fronts, init=handles_only)
    losses = json.loads((out / "checkpoint" / "trainer.json").read_text())["losses"]
    assert np.mean(losses[-10:]) < np.mean(losses[:10])
    assert 0.0 <= record["held_out_door_accuracy"][str(furniture_dataset)] <= 1.0
    trained = load_detector(out)[0]
    assert record["init"] == str(handles_only) and trained.config.fronts
    # Started from a detector with front outputs, the front network goes on from its weights.
    more = HandleDetector(fronts)
    more.start_from(trained)
    (x,), (y,) = trained.read_fronts([image]), more.read_fronts([image])
    np.testing.assert_allclose(x.door_probability, y.door_probability, atol=1e-6)
    with pytest.raises(ConfigError, match="another width"):
        HandleDetector(HandleDetectorConfig(channels=8, dilations=(1, 2, 1), fronts=True,
                                            front_channels=16)).start_from(trained)
    (c,) = trained.detect([image])  # the handle network was kept as it was
    np.testing.assert_allclose(c.probability, a.probability, atol=1e-6)
    # Tuning the handles instead: the handle network trains on, the front network stays.
    tuned = train_detector([furniture_dataset], tmp_path / "tuned", config, fronts, init=out, tune="handles")
    assert tuned["tune"] == "handles"
    tuned_net = load_detector(tmp_path / "tuned")[0]
    (f,), (h,) = tuned_net.read_fronts([image]), tuned_net.detect([image])
    np.testing.assert_allclose(f.door_probability, x.door_probability, atol=1e-6)
    assert np.abs(h.probability - c.probability).max() > 1e-4
    with pytest.raises(ConfigError, match="no front outputs to keep"):
        train_detector([furniture_dataset], tmp_path / "no_front_net", config, fronts, init=handles_only,
                       tune="handles")
    with pytest.raises(ConfigError, match="tune is one of"):
        HandleDetector(fronts).start_from(trained, tune="both")
    with pytest.raises(ConfigError, match="give --init"):
        train_detector([furniture_dataset], tmp_path / "no_init", config, fronts, tune="handles")
    with pytest.raises(ConfigError, match="--tune is one of"):
        train_detector([furniture_dataset], tmp_path / "bad_tune", config, fronts, init=out, tune="both")
    both = train_detector([furniture_dataset], tmp_path / "both", replace(config, steps=4), fronts)
    assert set(both["held_out_handle_iou"]) == set(both["held_out_door_accuracy"]) == {str(furniture_dataset)}
    with pytest.raises(ConfigError, match="front outputs need furniture"):
        train_detector([tiny_dataset], tmp_path / "closets", config, fronts)
