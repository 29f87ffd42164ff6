"""Evaluation of furniture, part by part: a perfect prediction scores zero, a shift scores the shift,
the part count and the table; `nfr-drake eval` with a furniture model."""

from pathlib import Path

import numpy as np
import pytest

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.slot_dataset import PART_TYPES, SLOT_KEYPOINTS
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.command import eval_command
from nfr_drake.eval.evaluate import evaluate
from nfr_drake.eval.parts import PartMetrics, PartsPrediction, parts_summary_table, score_parts
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.result import PART_KEYPOINTS

S = 8


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    root = tmp_path_factory.mktemp("furniture_caps")
    captures_command("furniture", n=2, out=root, views=3, size=16, seed=3)
    return root


def _oracle(shift=(0.0, 0.0, 0.0), extra_slot: bool = False):
    """The truth of gt.json as a prediction (axis points of drawers left at zero)."""
    def method(capture, grid):
        parts = capture.gt["parts"]
        q, exists, types = np.zeros(S), np.zeros(S, bool), np.zeros(S, int)
        keypoints, paths = np.zeros((S, 4, 3)), np.zeros((S, len(grid), 4, 3))
        for part in parts:
            k = part["index"]
            q[k], exists[k], types[k] = part["q"], True, PART_TYPES.index(part["type"])
            for name, gt_name in PART_KEYPOINTS[part["type"]].items():
                i = SLOT_KEYPOINTS.index(name)
                keypoints[k, i] = np.add(part["keypoints"][gt_name], shift)
                paths[k, :, i] = np.add(part["trajectory"]["keypoints"][gt_name], shift)
        if extra_slot:
            exists[len(parts)] = True
        return PartsPrediction(q, exists, types, keypoints, paths, 2.0)
    return method


def test_perfect_prediction_scores_zero_and_a_shift_scores_the_shift(captures):
    capture = read_capture_set(captures / "furniture_000")
    grid = np.asarray(capture.gt["parts"][0]["trajectory"]["q"])
    rows = score_parts(capture, _oracle()(capture, grid), "s", "oracle")
    assert [r.part for r in rows] == [p["index"] for p in capture.gt["parts"]]
    for r in rows:
        assert r.articulation_error == 0 and r.keypoint_rmse_cm == 0 and r.handle_trajectory_rmse_cm == 0
        assert r.goal_error_cm == 0
        assert r.found and r.type_right and r.count_right
    shifted = score_parts(capture, _oracle((0.03, 0.0, 0.04), extra_slot=True)(capture, grid), "s", "x")
    for r in shifted:
        assert r.keypoint_rmse_cm == pytest.approx(5.0) and r.handle_error_cm == pytest.approx(5.0)
        assert r.handle_trajectory_rmse_cm == pytest.approx(5.0) and r.goal_error_cm == pytest.approx(5.0)
        if r.part_type == "door":
            assert r.hinge_error_cm == pytest.approx(5.0)
        else:
            assert np.isnan(r.hinge_error_cm)
        assert not r.count_right and r.parts_found == len(capture.gt["parts"]) + 1


def test_evaluation_resumes_and_tables_each_method(captures, tmp_path):
    csv_path = tmp_path / "r.csv"
    kwargs = dict(scorer=score_parts, row_type=PartMetrics)
    results = evaluate({"oracle": _oracle()}, {"pieces": captures}, csv_path, **kwargs)
    parts = sum(len(read_capture_set(d).gt["parts"]) for d in sorted(captures.iterdir()))
    assert len(results) == parts
    again = evaluate({"oracle": _oracle()}, {"pieces": captures}, csv_path, **kwargs)
    assert len(again) == parts and len(csv_path.read_text().splitlines()) == parts + 1
    assert isinstance(again[0].found, bool) and isinstance(again[0].part, int)
    table = parts_summary_table(again)
    assert "| pieces | oracle | 2 | " in table and "| 100 % | 100 % | 100 % |" in table
    assert len(table.splitlines()) == 3
    assert all(line.count("|") == table.splitlines()[0].count("|") for line in table.splitlines())


def test_eval_of_a_furniture_model_writes_its_tables_and_plots(furniture_model_folder, captures,
                                                               tmp_path, capsys):
    quick = FurnitureFitConfig(starts=2, keep=1, steps=2, rays_per_step=32, lookup_rays=32)
    out = tmp_path / "eval"
    eval_command([captures], out, model=furniture_model_folder, category="furniture", limit=1,
                 furniture_fit=quick, example_plots=1, threads=1)
    assert "| furniture_caps0 | neural field | 1 |" in capsys.readouterr().out.replace(
        captures.name, "furniture_caps0")
    first = read_capture_set(captures / "furniture_000").gt["parts"][0]["index"]
    for name in ("results.csv", "summary.md", "errors.png",
                 f"handle_{captures.name}_furniture_000_part{first}.png"):
        assert (out / name).is_file(), name


def test_eval_of_a_calibrated_furniture_model_writes_each_parts_confidence(
        furniture_model_folder, captures, tmp_path):
    import csv
    import shutil

    from nfr_drake.inference.confidence import ConfidenceModel

    model = tmp_path / "furniture"
    shutil.copytree(furniture_model_folder, model)
    # P = sigmoid(-1.5 * (-logit) / 5 - 0.5): a part the head finds (logit 5) 0.73, else 0.12.
    ConfidenceModel([("part_exists_logit", "negative")], [0.0], [5.0], [-1.5], -0.5, 0.5, {}).write(model)
    quick = FurnitureFitConfig(starts=2, keep=1, steps=2, rays_per_step=32, lookup_rays=32)
    out = tmp_path / "eval"
    eval_command([captures], out, model=model, category="furniture", limit=1, furniture_fit=quick,
                 example_plots=0, threads=1)
    rows = list(csv.DictReader(open(out / "results.csv")))
    for r in rows:
        found = int(r["part"]) < 3  # the tiny model finds slots 0-2 whatever the code
        assert float(r["confidence"]) == pytest.approx(0.73 if found else 0.12, abs=0.01)
        assert r["refused"] == ("0.0" if found else "1.0")
    summary = (out / "summary.md").read_text()
    refused = sum(int(r["part"]) >= 3 for r in rows)
    assert "good fits refused" in summary and f"| {refused} of {len(rows)} |" in summary


def test_a_closet_baseline_or_another_category_is_refused_for_furniture(furniture_model_folder, captures,
                                                                        tmp_path):
    with pytest.raises(NfrDrakeError, match="a closet baseline, but the sets hold furniture"):
        eval_command([captures], tmp_path, baseline=Path("models/closet/baseline"))
    with pytest.raises(NfrDrakeError, match="--category closet, but the sets hold furniture"):
        eval_command([captures], tmp_path, model=furniture_model_folder, category="closet")
