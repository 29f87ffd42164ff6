"""`eval-pipeline --objects`: only the chosen indices run, each drawn as in a run of all."""

import csv

import pytest

from nfr_drake.cli import main
from nfr_drake.eval import pipeline_eval
from nfr_drake.eval.pipeline_eval import PipelineRow


@pytest.fixture
def recorded(monkeypatch):
    """Replaces the run of one object by a row of its scenario; returns the scenarios run."""
    scenarios = []

    def fake_row(scenario):
        scenarios.append(scenario)
        return PipelineRow(category=scenario.category, index=scenario.index, q_true=0.0, q_estimate=0.0,
                           keypoint_rmse_cm=1.0, handle_path_rmse_cm=1.0, handle_error_cm=1.0,
                           hinge_side_correct=None, p_handle_within_2cm=float("nan"), refused=False,
                           planned=True, grasped=True, success=scenario.index % 2 == 0, final_error=0.5,
                           unit="cm", max_drift_cm=0.1, fit_seconds=1.0, planning_seconds=1.0, failure="",
                           pose_error_cm=float("nan"), pose_error_deg=float("nan"), grasp_tries=1,
                           q_pulled=0.0, hinge_gap_cm=float("nan"),
                           pulled_on="panda_joint5 at its lower limit" if scenario.index % 4 == 0 else "")

    monkeypatch.setattr(pipeline_eval, "_row", fake_row)
    return scenarios


def test_objects_runs_the_chosen_indices_drawn_as_in_a_run_of_all(recorded, tmp_path, capsys):
    args = ["eval-pipeline", "--category", "drawer", "--model", "models/drawer", "--seed", "201",
            "--threads", "1"]
    assert main([*args, "--csv-path", str(tmp_path / "some.csv"), "--objects", "3", "8", "10"]) == 0
    with open(tmp_path / "some.csv") as f:
        assert [int(r["index"]) for r in csv.DictReader(f)] == [3, 8, 10]
    out = capsys.readouterr().out
    assert "2/3 succeeded" in out
    assert "pulled on from a second base: 1 (1 of them succeeded)" in out  # object 8
    chosen = {s.index: s for s in recorded}
    recorded.clear()
    assert main([*args, "--csv-path", str(tmp_path / "all.csv"), "--n", "11"]) == 0
    assert [s.index for s in recorded] == list(range(11))
    for i in (3, 8, 10):
        assert chosen[i] == recorded[i]
        assert chosen[i].sample_object().params == recorded[i].sample_object().params
        assert chosen[i].sample_item() == recorded[i].sample_item()


def test_objects_already_in_the_csv_are_skipped_and_negative_ones_refused(recorded, tmp_path):
    args = ["eval-pipeline", "--category", "drawer", "--model", "models/drawer", "--threads", "1",
            "--csv-path", str(tmp_path / "rows.csv")]
    assert main([*args, "--objects", "5", "2"]) == 0
    assert main([*args, "--objects", "2", "7"]) == 0
    assert [s.index for s in recorded] == [5, 2, 7]
    assert main([*args, "--objects", "-1"]) == 2


def test_pull_on_is_an_option_of_the_simulation(recorded, tmp_path):
    args = ["eval-pipeline", "--category", "drawer", "--model", "models/drawer", "--threads", "1",
            "--csv-path", str(tmp_path / "rows.csv"), "--objects", "1"]
    assert main(args) == 0 and recorded[-1].simulation.pull_on
    assert main([*args[:-2], "--objects", "2", "--no-pull-on"]) == 0 and not recorded[-1].simulation.pull_on
