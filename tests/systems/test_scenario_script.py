"""systems/ground_truth_plan.py loads its scenario YAML with yaml_load_typed and runs."""

import importlib.util
from pathlib import Path

from pydrake.common.yaml import yaml_load_typed

ROOT = Path(__file__).resolve().parents[2]
SYSTEMS = ROOT / "systems"


def _script():
    spec = importlib.util.spec_from_file_location("ground_truth_plan",
                                                  SYSTEMS / "ground_truth_plan.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_scenarios_load():
    script = _script()
    drawer = yaml_load_typed(schema=script.Scenario, filename=SYSTEMS / "ground_truth_open_drawer.yaml")
    assert drawer.object_yaw_deg == 20.0 and drawer.planner.num_waypoints == 10
    closet = yaml_load_typed(schema=script.Scenario, filename=SYSTEMS / "ground_truth_close_closet.yaml")
    assert (closet.category, closet.start_q, closet.target_q) == ("closet", 0.6, 0.0)


def test_close_closet_runs(tmp_path):
    script = _script()
    scenario = yaml_load_typed(schema=script.Scenario, filename=SYSTEMS / "ground_truth_close_closet.yaml")
    scenario.replay = str(tmp_path / "close.html")
    assert script.run(scenario)
    assert (tmp_path / "close.html").is_file()
