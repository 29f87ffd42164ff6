"""Evaluation driver: a perfect prediction scores zero error; a shifted one scores the shift."""

import math

import cv2
import numpy as np
import pytest

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.evaluate import Prediction, evaluate, score, summary_table


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    root = tmp_path_factory.mktemp("caps")
    captures_command("closet", n=2, out=root, views=3, size=32)
    return root


def _oracle(shift=(0.0, 0.0, 0.0)):
    def method(capture, grid):
        gt = capture.gt
        offset = np.asarray(shift)
        traj = {k: np.asarray(v) + offset for k, v in gt["trajectory"]["keypoints"].items()}
        labels = [cv2.imread(str(capture.root / p), cv2.IMREAD_UNCHANGED)
                  for p in gt["label_paths"]]
        return Prediction(gt["q"], {k: np.asarray(v) + offset for k, v in gt["keypoints"].items()},
                          traj, 0.5, renders=capture.load_images(), labels=labels)
    return method


def test_perfect_prediction_scores_zero(captures):
    capture = read_capture_set(captures / "closet_000")
    m = score(capture, _oracle()(capture, None), "s", "oracle")
    assert m.articulation_error == 0 and m.keypoint_rmse_cm == 0 and m.handle_error_cm == 0
    assert m.handle_trajectory_rmse_cm == 0 and m.miou == 1.0 and m.psnr_db == math.inf


def test_shift_shows_in_keypoint_errors_and_evaluation_resumes(captures, tmp_path):
    csv_path = tmp_path / "r.csv"
    shift = np.array([0.03, 0.0, 0.04])
    results = evaluate({"shifted": _oracle(shift)}, {"closets": captures}, csv_path)
    assert len(results) == 2
    for r in results:
        assert r.keypoint_rmse_cm == pytest.approx(5.0)
        assert r.handle_trajectory_rmse_cm == pytest.approx(5.0)
        assert r.handle_error_cm == pytest.approx(5.0)
    again = evaluate({"shifted": _oracle(shift)}, {"closets": captures}, csv_path)
    assert len(again) == 2 and len(csv_path.read_text().splitlines()) == 3
    table = summary_table(again, "deg")
    assert "| closets | shifted | 2 |" in table and "5.00" in table


def test_results_of_another_version_are_refused(captures, tmp_path):
    csv_path = tmp_path / "r.csv"
    csv_path.write_text("capture,set_name,method,keypoint_rmse_cm\nx,closets,shifted,1.0\n")
    with pytest.raises(NfrDrakeError, match="another version"):
        evaluate({"shifted": _oracle()}, {"closets": captures}, csv_path)


def test_run_writes_the_tables_and_plots_and_returns_the_summary(captures, tmp_path):
    from nfr_drake.eval.report import run_evaluation

    out = tmp_path / "run"
    out.mkdir()
    methods = {"oracle": _oracle(), "shifted": _oracle((0.0, 0.02, 0.0))}
    table = run_evaluation(methods, [captures], out, example_plots=1)
    assert (out / "summary.md").read_text() == table + "\n"
    assert f"| {captures.name} | shifted | 2 |" in table and "2.00" in table
    assert (out / "errors.png").stat().st_size > 0
    assert len(list(out.glob(f"handle_{captures.name}_closet_000.png"))) == 1
    assert len((out / "results.csv").read_text().splitlines()) == 5
    run_evaluation(methods, [captures], out, example_plots=1)  # resumes: no row twice
    assert len((out / "results.csv").read_text().splitlines()) == 5


def test_the_summary_counts_refusals_next_to_the_errors(captures, tmp_path):
    def confident(shift, p, refused):
        oracle = _oracle(shift)

        def method(capture, grid):
            prediction = oracle(capture, grid)
            prediction.confidence, prediction.refused = p, refused
            return prediction
        return method

    methods = {"good refused": confident((0.0, 0.0, 0.0), 0.1, True),
               "far kept": confident((0.06, 0.0, 0.0), 0.9, False),
               "no confidence": _oracle()}
    results = evaluate(methods, {"closets": captures}, tmp_path / "r.csv")
    again = evaluate(methods, {"closets": captures}, tmp_path / "r.csv")  # read back from the CSV
    for rows in (results, again):
        by_method = {r.method: r for r in rows}
        assert by_method["good refused"].refused == 1.0 and by_method["far kept"].confidence == 0.9
        assert math.isnan(by_method["no confidence"].refused)
    table = summary_table(again, "deg")
    assert table.splitlines()[0].endswith("| refused | good fits refused | fits > 5 cm off kept |")
    assert "| 2 of 2 | 2 of 2 | 0 of 0 |" in table.split("good refused |")[1].splitlines()[0]
    assert "| 0 of 2 | 0 of 0 | 2 of 2 |" in table.split("far kept |")[1].splitlines()[0]
    assert table.split("no confidence |")[1].splitlines()[0].endswith("| n/a | n/a | n/a |")
