"""Acting on the fit confidence: the perception system's "confidence" port, the demo's refusal
(exit status 2, one line) and eval-pipeline's count of refusals apart from failures."""

import csv

import pytest

from nfr_drake.cli import main
from nfr_drake.eval.pipeline_eval import eval_pipeline_command
from nfr_drake.inference.confidence import ConfidenceModel
from nfr_drake.inference.fit import FitConfig
from nfr_drake.systems.pipeline import perceive_with_confidence
from nfr_drake.systems.scenario import Scenario
from tests.systems.conftest import write_tiny_closet_model

FAST = FitConfig(preset="thorough", restarts=1, explore_steps=0, max_steps=2, explore_rays=32,
                 rays_per_step=32, eval_rays=64, lookup_rays=64, focus_steps=0)
FIT_FLAGS = ["--fit.preset", "thorough", "--restarts", "1", "--fit.explore-steps", "0", "--max-steps", "2",
             "--focus-steps", "0", "--fit.eval-rays", "64", "--fit.lookup-rays", "64"]


@pytest.fixture(scope="module")
def calibrated_model(tmp_path_factory):
    """A tiny closet model folder (random weights) with a calibration whose threshold is 0.5."""
    folder = write_tiny_closet_model(tmp_path_factory, 3)
    ConfidenceModel([("image_loss", "log10")], [-2.5], [0.5], [-2.0], 0.0, 0.5, {}).write(folder)
    return folder


def test_the_perception_system_outputs_the_fit_confidence(calibrated_model):
    scenario = Scenario(category="closet", model=str(calibrated_model), views=3, image_size=24,
                        fit=FAST)
    _, _, confidence = perceive_with_confidence(scenario, scenario.sample_object())
    assert 0.0 < confidence["p_handle_within_2cm"] < 1.0 and confidence["threshold"] == 0.5
    assert len(confidence["per_view"]) == 3 and confidence["features"]["views"] == 3


def test_the_demo_refuses_below_the_threshold_in_one_line(calibrated_model, tmp_path, capsys):
    status = main(["demo", "--model", str(calibrated_model), "--views", "3", "--image-size", "24",
                   "--min-confidence", "1.0", "--threads", "1", "--replay",
                   str(tmp_path / "demo.html"), *FIT_FLAGS])
    out = capsys.readouterr().out
    refused = [line for line in out.splitlines() if line.startswith("refused:")]
    assert status == 2 and len(refused) == 1, out
    assert "< 1.00" in refused[0] and "planning" not in out and not (tmp_path / "demo.html").exists()


def test_eval_pipeline_counts_refusals_apart_from_failures(calibrated_model, tmp_path, capsys):
    csv_path = tmp_path / "pipeline.csv"
    eval_pipeline_command("closet", calibrated_model, csv_path, n=2, seed=100, fit=FAST,
                          image_size=24, min_confidence=1.0, threads=1)
    rows = list(csv.DictReader(open(csv_path)))
    assert [r["refused"] for r in rows] == ["True", "True"]
    assert all(r["planned"] == "False" and r["failure"].startswith("refused:") for r in rows)
    assert 0.0 < float(rows[0]["p_handle_within_2cm"]) < 1.0
    out = capsys.readouterr().out
    assert "| closet | 2 | 2 | 0 | 0 | **0%** | 0 |" in out
    assert out.strip().endswith("2 refused for low fit confidence, 0 failed")


def test_the_scenario_script_exits_2_on_a_refused_fit(calibrated_model, tmp_path):
    # Before, a refused fit (no task) stopped the script on outcome.task.success.
    import subprocess
    import sys
    from pathlib import Path

    path = tmp_path / "refuse.yaml"
    path.write_text(f"category: closet\nmodel: {calibrated_model}\nviews: 3\nimage_size: 24\n"
                    "min_confidence: 1.0\nfit:\n  restarts: 1\n  explore_steps: 0\n  max_steps: 2\n"
                    "  focus_steps: 0\n  eval_rays: 64\n  lookup_rays: 64\n")
    script = Path(__file__).resolve().parents[2] / "systems" / "run_scenario.py"
    result = subprocess.run([sys.executable, str(script), str(path), "--replay",
                             str(tmp_path / "r.html")], capture_output=True, text=True, timeout=600)
    refused = [line for line in result.stdout.splitlines() if line.startswith("refused:")]
    assert result.returncode == 2 and len(refused) == 1, result.stdout + result.stderr
    assert not (tmp_path / "r.html").exists()
