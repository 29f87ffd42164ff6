"""`nfr-drake infer` with a furniture model: the furniture fit, `parts` and one part's single-part
fields, and what the result gives the planner."""

import json
import re

import numpy as np
import pytest
from PIL import Image
from pydrake.math import RigidTransform

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS
from nfr_drake.errors import NfrDrakeError
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import FittedModel, infer_command, infer_parts
from nfr_drake.inference.result import FitResult
from nfr_drake.world.keypoints import KeypointTrajectory
from tests.conftest import FURNITURE_PARTS

QUICK = FurnitureFitConfig(starts=2, keep=1, steps=3, rays_per_step=32, lookup_rays=32)


@pytest.fixture(scope="module")
def capture_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("furniture_captures")
    captures_command(category="furniture", n=1, out=out, views=3, size=24, seed=3)
    return out / "furniture_000"


def test_infer_writes_every_part_found_and_one_part_in_the_single_part_fields(
        furniture_model_folder, capture_dir, tmp_path, capsys):
    # Before the furniture fit joined `infer`, a furniture model failed inside the one-slot fit with
    # a matrix shape error.
    out = tmp_path / "result.json"
    infer_command(capture_dir, model=furniture_model_folder, out=out, furniture_fit=QUICK,
                  trajectory_points=5, part=1, threads=1)
    doc = json.loads(out.read_text())
    assert [(p["index"], p["type"]) for p in doc["parts"]] == list(enumerate(FURNITURE_PARTS))
    assert all(list(p["keypoints"]) == list(SLOT_KEYPOINTS) for p in doc["parts"])
    assert doc["category"] == "furniture"
    assert doc["part"] == {"index": 1, "type": "drawer", "found": True}
    drawer = doc["parts"][1]
    assert doc["q"] == drawer["q"] and list(doc["keypoints"]) == ["handle", "goal"]
    assert doc["keypoints"]["handle"] == drawer["keypoints"]["handle"]
    assert np.asarray(doc["trajectory"]["keypoints"]["goal"]).shape == (5, 3)
    assert "parts found: 0 door" in capsys.readouterr().out
    result = FitResult.read(out)
    assert result.part_of(0).part == {"index": 0, "type": "door", "found": True}
    assert list(result.part_of(0).keypoints) == ["handle", "goal", "hinge_top", "hinge_bottom"]
    door = result.part_of(0)
    np.testing.assert_allclose(door.keypoints["hinge_top"], doc["parts"][0]["keypoints"]["axis_0"])


def test_a_furniture_result_gives_the_planner_its_part(furniture_model_folder, capture_dir):
    fitted = FittedModel(furniture_model_folder)
    grid = np.linspace(0, 1, 4)
    result, fit, slots = infer_parts(fitted, read_capture_set(capture_dir), QUICK, grid)
    assert result.part["index"] == 0
    assert len(slots) == fitted.num_slots  # every slot's confidence, those not found included
    assert [slots[p["index"]] for p in result.parts] == [p["confidence"] for p in result.parts]
    # The tiny model has no calibration: the features of each part, no probability.
    assert result.confidence["p_handle_within_2cm"] is None
    assert len(result.confidence["per_view"]) == 3
    assert result.confidence["features"] == result.parts[0]["confidence"]["features"]
    assert result.part_of(1).confidence["features"] == result.parts[1]["confidence"]["features"]
    assert result.confidence["features"]["part_exists_logit"] == pytest.approx(5.0, abs=1e-4)
    X_WO = RigidTransform([1.0, 0.0, 0.0])
    door = KeypointTrajectory.from_fit_result(result.to_json(), X_WO)
    drawer = KeypointTrajectory.from_fit_result(result.part_of(1).to_json(), X_WO)
    assert door.category == "closet" and drawer.category == "drawer"
    assert door.q_current == pytest.approx(fit.q[0], abs=1e-9)
    # The drawer's handle path is slot 1 swept with the other slots held, moved into W.
    np.testing.assert_allclose(drawer.point("handle", grid)[:, 0] - 1.0,
                               np.asarray(result.parts[1]["trajectory"]["keypoints"]["handle"])[:, 0])
    with pytest.raises(NfrDrakeError, match="finds no part 5"):
        result.part_of(5)


def test_a_part_the_field_does_not_find_is_given_with_a_warning(furniture_model_folder, capture_dir):
    fitted = FittedModel(furniture_model_folder)
    result, _, _ = infer_parts(fitted, read_capture_set(capture_dir), QUICK, np.linspace(0, 1, 3), part=6)
    assert result.part == {"index": 6, "type": "door", "found": False}
    assert any("finds no part 6" in w for w in result.extra["warnings"])
    with pytest.raises(NfrDrakeError, match="out of range"):
        infer_parts(fitted, read_capture_set(capture_dir), QUICK, np.linspace(0, 1, 3), part=8)


def test_the_point_cloud_and_report_of_a_furniture_fit_are_written(furniture_model_folder, capture_dir,
                                                                   tmp_path, capsys):
    """`--point-cloud` and `--report` with a furniture model: the fitted code rendered as it is
    (every part slot at its own articulation) from the capture's cameras, labelled points in a
    PLY, and the photos over the renders and their segmentation (three rows of the three views,
    pixels doubled); before, both options were refused."""
    from nfr_drake.inference.forward import semantic_point_cloud

    cloud, report = tmp_path / "cloud.ply", tmp_path / "report.png"
    infer_command(capture_dir, model=furniture_model_folder, out=tmp_path / "r.json", point_cloud=cloud,
                  report=report, furniture_fit=QUICK, trajectory_points=3, threads=1)
    figure = np.asarray(Image.open(report))
    assert figure.shape[0] >= 3 * 2 * 24 and figure.shape[1] >= 3 * 2 * 24
    count = int(re.search(r"point cloud: .* \((\d+) points", capsys.readouterr().out).group(1))
    header = cloud.read_bytes()[:400].decode("ascii", "ignore")
    assert f"element vertex {count}" in header
    fitted = FittedModel(furniture_model_folder)
    cap = read_capture_set(capture_dir)
    _, fit, _ = infer_parts(fitted, cap, QUICK, np.linspace(0, 1, 3))
    views = [(f.camera, f.X_OC) for f in cap.frames]
    points, classes = semantic_point_cloud(fitted.model, fit.z, None, views)
    assert len(points) == count and set(np.unique(classes)) <= {1, 2, 3}


def test_options_a_furniture_fit_does_not_have_are_refused(furniture_model_folder, model_folder,
                                                           capture_dir, tmp_path):
    with pytest.raises(NfrDrakeError, match="--handle-plot: not available for a model with several parts"):
        infer_command(capture_dir, model=furniture_model_folder, out=tmp_path / "r.json",
                      handle_plot=tmp_path / "h.png", furniture_fit=QUICK, threads=1)
    closets = tmp_path / "closets"
    captures_command(category="closet", n=1, out=closets, views=3, size=16)
    with pytest.raises(NfrDrakeError, match="--part is for models with several parts"):
        infer_command(closets / "closet_000", model=model_folder, out=tmp_path / "r.json", part=0,
                      threads=1)
