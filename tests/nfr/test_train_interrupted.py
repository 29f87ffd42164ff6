"""Training never passes an interrupted run or an incomplete dataset off as a complete one."""

import os
import shutil
import signal

import pytest

from nfr_drake.baseline.train import BaselineTrainConfig, train_baseline
from nfr_drake.cli import main
from nfr_drake.errors import DatasetError
from nfr_drake.nfr import train as train_module

SMALL = ["--model.field-width", "8", "--model.feature-dim", "8", "--model.hyper-hidden", "8",
         "--model.march-steps", "3", "--sampler.images-per-batch", "2",
         "--sampler.rays-per-image", "16", "--log-every", "5", "--val-every", "100",
         "--ckpt-every", "100", "--val-images", "2", "--threads", "1"]


@pytest.fixture
def half_dataset(tiny_dataset, tmp_path):
    """The tiny dataset as a killed `generate` leaves it: object 1 of 2 never written."""
    copy = tmp_path / "half"
    shutil.copytree(tiny_dataset, copy)
    shutil.rmtree(copy / "objects" / "obj_000001")
    return copy


def test_an_incomplete_dataset_is_refused_unless_allowed(half_dataset, tmp_path, capsys):
    args = ["train", "--data", str(half_dataset), "--out", str(tmp_path / "run"),
            "--optim.steps", "2", *SMALL]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "1 of the 2 objects are on disk (missing obj 1)" in err and "--allow-incomplete" in err
    assert not (tmp_path / "run").exists()
    assert main([*args, "--allow-incomplete"]) == 0
    assert "warning: " in capsys.readouterr().err
    with pytest.raises(DatasetError, match="missing obj 1"):
        train_baseline(half_dataset, tmp_path / "baseline",
                       BaselineTrainConfig(steps=1, batch=1, views=1, threads=1), progress=False)


def test_sigterm_checkpoints_and_exits_143(tiny_dataset, tmp_path, monkeypatch, capsys):
    """SIGTERM at step 3 of 20: a checkpoint of step 3, exit status 143 and a line that says
    so; --resume then completes the run (exit 0)."""
    loss, calls = train_module.nfr_loss, []

    def terminated_at_step_3(*args):
        calls.append(1)
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return loss(*args)

    monkeypatch.setattr(train_module, "nfr_loss", terminated_at_step_3)
    args = ["train", "--data", str(tiny_dataset), "--out", str(tmp_path / "run"),
            "--optim.steps", "20", *SMALL]
    assert main(args) == 143
    err = capsys.readouterr().err
    assert "interrupted at step 3 of 20" in err and "rerun with --resume" in err
    assert (tmp_path / "run" / "checkpoints" / "step_0000003").is_dir()
    monkeypatch.setattr(train_module, "nfr_loss", loss)
    assert main([*args, "--resume"]) == 0
    assert (tmp_path / "run" / "checkpoints" / "step_0000020").is_dir()
