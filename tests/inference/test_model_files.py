"""Damaged model files: one line naming the file (exit 2 from the CLI), never a traceback."""

import shutil

import pytest
import torch

from nfr_drake.baseline.model import BaselineConfig, ImageEncoderBaseline
from nfr_drake.baseline.train import load_baseline, save_baseline
from nfr_drake.cli import main
from nfr_drake.data.captures import captures_command
from nfr_drake.inference.infer import FittedModel
from nfr_drake.nfr.checkpoint import CheckpointError
from nfr_drake.perception.handle_detector.model import (
    DETECTOR_DIR,
    HandleDetector,
    HandleDetectorConfig,
    save_detector,
)

DETECTOR = HandleDetectorConfig(channels=4, dilations=(1, 2))
DAMAGED = ["model.safetensors", "config.json", f"{DETECTOR_DIR}/model.safetensors",
           f"{DETECTOR_DIR}/config.json"]


@pytest.fixture(scope="module")
def with_detector(model_folder, tmp_path_factory):
    """The tiny closet model with a (random) handle detector."""
    folder = tmp_path_factory.mktemp("det") / "closet"
    shutil.copytree(model_folder, folder)
    save_detector(folder / DETECTOR_DIR, HandleDetector(DETECTOR), {"model": {
        "channels": DETECTOR.channels, "dilations": list(DETECTOR.dilations)}})
    return folder


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps")
    captures_command("closet", n=1, out=root, views=3, size=16, seed=7)
    return next(p for p in root.iterdir() if (p / "transforms.json").is_file())


def _damage(folder, name, tmp_path):
    """A copy of `folder` whose file `name` is cut to a third of its length."""
    copy = tmp_path / "damaged"
    shutil.copytree(folder, copy)
    path = copy / name
    path.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 3])
    return copy, path


def test_the_model_loads_whole(with_detector):
    assert FittedModel(with_detector).handle_detector is not None


@pytest.mark.parametrize("name", DAMAGED)
def test_a_truncated_file_is_named_in_one_line(with_detector, name, tmp_path):
    folder, path = _damage(with_detector, name, tmp_path)
    with pytest.raises(CheckpointError, match=str(path)) as err:
        FittedModel(folder)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", [f"{DETECTOR_DIR}/model.safetensors", "config.json"])
def test_infer_exits_2_with_one_line(with_detector, capture, name, tmp_path, capsys):
    folder, path = _damage(with_detector, name, tmp_path)
    status = main(["infer", str(capture), "--model", str(folder), "--out", str(tmp_path / "r.json"),
                   "--threads", "1"])
    err = capsys.readouterr().err
    assert status == 2 and str(path) in err and err.count("\n") == 1
    assert not (tmp_path / "r.json").exists()


def test_a_truncated_baseline_is_named_in_one_line(tmp_path):
    torch.manual_seed(0)
    config = BaselineConfig("closet", ("handle", "goal"), "revolute", channels=(4,), embed_dim=8)
    save_baseline(tmp_path / "b", ImageEncoderBaseline(config), {})
    load_baseline(tmp_path / "b")
    for name in ("model.safetensors", "config.json"):
        folder, path = _damage(tmp_path / "b", name, tmp_path / name)
        with pytest.raises(CheckpointError, match=str(path)):
            load_baseline(folder)
