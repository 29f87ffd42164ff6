"""`demo` and scenarios refuse a model of another category before any work (exit 2, one line)."""

import pytest
import torch

from nfr_drake.cli import main
from nfr_drake.errors import NfrDrakeError
from nfr_drake.nfr.checkpoint import write_model_folder
from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.model import NFRAutoDecoder
from nfr_drake.systems import pipeline

TINY = NFRModelConfig(latent_obj_dim=4, hyper_hidden=8, field_width=8, feature_dim=8,
                      pe_frequencies=1, march_steps=2, lstm_hidden=4, pixel_hidden=8,
                      keypoint_hidden=8)


@pytest.fixture
def drawer_model(tmp_path, monkeypatch):
    """A tiny drawer model folder; perceiving anything with it fails the test."""
    torch.manual_seed(0)
    folder = tmp_path / "drawer"
    write_model_folder(folder, NFRAutoDecoder(TINY, num_objects=2),
                       {"category": "drawer", "keypoint_names": ["handle", "goal"]})

    def no_work(*args, **kwargs):
        raise AssertionError("the pipeline started before checking the model's category")

    monkeypatch.setattr(pipeline, "perceive", no_work)
    return folder


def test_a_scenario_refuses_a_model_of_another_category(drawer_model):
    with pytest.raises(NfrDrakeError, match=f"closet object, but {drawer_model} is a drawer model"):
        pipeline.run_scenario(pipeline.Scenario(category="closet", model=str(drawer_model)))


def test_demo_with_a_drawer_model_exits_2(drawer_model, tmp_path, capsys):
    status = main(["demo", "--model", str(drawer_model), "--replay", str(tmp_path / "r.html")])
    err = capsys.readouterr().err
    assert status == 2 and "drawer model; use a closet model" in err and err.count("\n") == 1
