"""Tuning the keypoint head on fitted codes: fits resume, the head learns, only the head changes."""

import json
import shutil

import pytest
import torch
from safetensors.torch import load_file

from nfr_drake.data.captures import captures_command
from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.inference.head_tuning import (
    FITS_DIR,
    HeadTuningConfig,
    _pairs,
    fit_captures,
    tune_head,
    write_tuned_model,
)
from nfr_drake.inference.infer import FittedModel


@pytest.fixture(scope="module")
def fitted_run(model_folder, tmp_path_factory):
    """12 capture sets fitted once (the fit's default budget on the tiny model)."""
    root = tmp_path_factory.mktemp("tune")
    captures_command("closet", n=12, out=root / "caps", views=3, size=16, seed=7)
    dirs = fit_captures(model_folder, root / "caps", root / "run")
    return root, dirs


def test_fits_are_kept_and_not_redone(model_folder, fitted_run):
    root, dirs = fitted_run
    fits = sorted((root / "run" / FITS_DIR).glob("*.json"))
    assert [f.stem for f in fits] == [d.name for d in dirs]
    stamps = [f.stat().st_mtime_ns for f in fits]
    fit_captures(model_folder, root / "caps", root / "run")
    assert [f.stat().st_mtime_ns for f in fits] == stamps
    fit = json.loads(fits[0].read_text())
    assert len(fit["z"]) == 2 + FittedModel(model_folder).codes.shape[1]
    assert 0.0 <= fit["q"] <= 1.0


def test_the_head_learns_the_pairs_and_only_the_head_changes(model_folder, fitted_run, tmp_path):
    root, dirs = fitted_run
    fitted = FittedModel(model_folder)
    z, true, known, owner, observed = _pairs(fitted, dirs, root / "run")
    assert z.shape[0] == true.shape[0] == owner.shape[0] and true.shape[1:] == (4, 3) and known.all()
    assert len(observed) == 12
    record = tune_head(fitted, dirs, root / "run",
                       HeadTuningConfig(steps=300, lr=3e-3, distill_weight=0.0, holdout=0.2))
    assert record["held_out"] == 2 and record["captures"] == 12
    assert record["train_fit_m2"]["last"] < 0.5 * record["train_fit_m2"]["first"]
    rmse = record["held_out_keypoint_rmse_cm"]
    assert rmse["after"] <= rmse["before"]  # the best held-out step is kept (step 0 included)

    write_tuned_model(model_folder, fitted, tmp_path / "tuned", record)
    old = load_file(str(model_folder / "model.safetensors"))
    new = load_file(str(tmp_path / "tuned" / "model.safetensors"))
    assert old.keys() == new.keys()
    changed = {k for k in old if not torch.equal(old[k], new[k])}
    assert all(k.startswith("keypoint_head.") for k in changed)
    assert bool(changed) == (record["best_step"] > 0)
    tuned = FittedModel(tmp_path / "tuned")
    assert tuned.keypoint_names == fitted.keypoint_names
    assert json.loads((tmp_path / "tuned" / "config.json").read_text())[
        "keypoint_head_tuning"]["best_step"] == record["best_step"]


def test_bad_options_and_too_few_captures(model_folder, fitted_run, tmp_path):
    root, dirs = fitted_run
    shutil.copytree(dirs[0], tmp_path / "caps" / "closet_000")
    (tmp_path / "caps" / "closet_000" / "gt.json").unlink()
    with pytest.raises(NfrDrakeError, match="gt.json"):
        fit_captures(model_folder, tmp_path / "caps", tmp_path / "run")
    with pytest.raises(ConfigError):
        HeadTuningConfig(holdout=0.7)
    with pytest.raises(ConfigError):
        HeadTuningConfig(steps=0)
    with pytest.raises(NfrDrakeError, match="at least 10"):
        tune_head(FittedModel(model_folder), dirs[:5], root / "run", HeadTuningConfig())


@pytest.mark.slow
def test_a_slot_model_learns_every_parts_keypoints_where_gt_names_them(furniture_model_folder, tmp_path):
    captures_command("furniture", n=10, out=tmp_path / "caps", views=2, size=16, seed=7)
    dirs = fit_captures(furniture_model_folder, tmp_path / "caps", tmp_path / "run")
    fitted = FittedModel(furniture_model_folder)
    S = fitted.num_slots
    fit = json.loads((tmp_path / "run" / FITS_DIR / f"{dirs[0].name}.json").read_text())
    assert len(fit["z"]) == 2 * S + fitted.codes.shape[1]
    z, true, known, owner, observed = _pairs(fitted, dirs, tmp_path / "run")
    assert true.shape[1:] == (4 * S, 3) and known.shape == true.shape[:2] == (len(z), 4 * S)
    for i, d in enumerate(dirs):  # each part's handle and goal known, a door's hinge too, nothing else
        parts = json.loads((d / "gt.json").read_text())["parts"]
        expected = {4 * p["index"] + j for p in parts
                    for j in ((0, 1, 2, 3) if p["type"] == "door" else (0, 1))}
        rows = known[owner == i]
        assert {int(k) for k in torch.nonzero(rows.any(0)).ravel()} == expected
        assert bool(rows.all(0)[list(expected)].all())
        assert len(observed[i][1]) == len(parts)
    record = tune_head(fitted, dirs, tmp_path / "run",
                       HeadTuningConfig(steps=200, lr=3e-3, distill_weight=0.0, holdout=0.2))
    assert record["train_fit_m2"]["last"] < 0.5 * record["train_fit_m2"]["first"]
    assert record["held_out_keypoint_rmse_cm"]["after"] <= record["held_out_keypoint_rmse_cm"]["before"]
