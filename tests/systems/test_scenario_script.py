"""Scenario YAML files (systems/*.yaml) load with yaml_load_typed; systems/run_scenario.py runs them."""

import subprocess
import sys
from pathlib import Path

import pytest

from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario

ROOT = Path(__file__).resolve().parents[2]
SYSTEMS = ROOT / "systems"


@pytest.mark.parametrize("path", sorted(SYSTEMS.glob("*.yaml")), ids=lambda p: p.name)
def test_every_scenario_file_loads(path):
    scenario = Scenario.load(path)
    assert isinstance(scenario.fit, FitConfig)


def test_ground_truth_scenarios_load():
    drawer = Scenario.load(SYSTEMS / "ground_truth_open_drawer.yaml")
    assert drawer.object_yaw_deg == 20.0 and drawer.planner.num_waypoints == 10
    assert (drawer.objects, drawer.keypoints, drawer.perceives) == ("train", "ground_truth", False)
    closet = Scenario.load(SYSTEMS / "ground_truth_close_closet.yaml")
    assert (closet.category, closet.q_start, closet.q_target) == ("closet", 0.6, 0.0)


def test_fit_options_load_into_the_shared_frozen_config(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("category: drawer\nfit:\n  max_steps: 300\n  handle_detector: false\n")
    scenario = Scenario.load(path)
    assert scenario.fit == FitConfig(max_steps=300, handle_detector=False)
    path.write_text("fit:\n  explore_steps: 100\n  max_steps: 50\n")
    with pytest.raises(ConfigError, match="explore_steps"):
        Scenario.load(path)
    path.write_text("fit:\n  preset: fast\n  focus_steps: 150\n  start: spread\n")  # thorough's
    fit = Scenario.load(path).fit.resolved()
    assert (fit.focus_steps, fit.start) == (150, "spread")
    assert fit.max_steps == FitConfig.PRESETS["fast"]["max_steps"]
    path.write_text("fit:\n  max_stepz: 300\n")
    with pytest.raises(RuntimeError, match="max_stepz"):
        Scenario.load(path)


def test_close_closet_runs(tmp_path):
    scenario = Scenario.load(SYSTEMS / "ground_truth_close_closet.yaml")
    scenario.replay = str(tmp_path / "close.html")
    outcome = run_scenario(scenario)
    assert outcome.task.success and not outcome.perceived
    assert (tmp_path / "close.html").is_file()
    assert "estimated q" not in outcome.report() and "replay:" in outcome.report()


def test_script_refuses_a_bad_scenario_with_status_2(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("category: sofa\n")
    result = subprocess.run([sys.executable, str(SYSTEMS / "run_scenario.py"), str(path)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and "sofa" in result.stderr


def test_frozen_configs_with_literal_fields_load(tmp_path):
    """Drake's YAML reader knows no Literal: the mutable twin reads such a field as a str."""
    from dataclasses import dataclass
    from typing import Literal

    from pydrake.common.yaml import yaml_load_typed

    from nfr_drake.systems.scenario import _thawed

    @dataclass(frozen=True)
    class Options:
        mode: Literal["fast", "thorough"] = "fast"
        steps: int = 3

    loaded = yaml_load_typed(schema=_thawed(Options), data="mode: thorough\nsteps: 5\n")
    assert Options(**vars(loaded)) == Options("thorough", 5)
