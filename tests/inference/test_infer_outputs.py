"""`infer` checks its outputs before fitting and flags a fit from too few views."""

import json

import pytest

from nfr_drake.cli import main
from nfr_drake.data.captures import captures_command
from nfr_drake.inference import infer as infer_module


def _capture(root, views):
    captures_command("closet", n=1, out=root, views=views, size=16, seed=7)
    return next(p for p in root.iterdir() if (p / "transforms.json").is_file())


@pytest.fixture(scope="module")
def one_view(tmp_path_factory):
    return _capture(tmp_path_factory.mktemp("one_view"), 1)


def _infer(capture, model, *args):
    return main(["infer", str(capture), "--model", str(model), "--restarts", "1", "--max-steps",
                 "2", "--fit.explore-steps", "0", "--focus-steps", "0", "--fit.preset", "thorough",
                 "--threads", "1", *map(str, args)])


def test_one_view_warns_on_stderr_and_in_the_result(one_view, model_folder, tmp_path, capsys):
    assert _infer(one_view, model_folder, "--out", tmp_path / "r.json") == 0
    err = capsys.readouterr().err
    assert "warning: " in err and "only 1 view(s)" in err
    warnings = json.loads((tmp_path / "r.json").read_text())["extra"]["warnings"]
    assert len(warnings) == 1 and "only 1 view(s)" in warnings[0]


@pytest.mark.parametrize("option", ["--out", "--report", "--point-cloud", "--handle-plot"])
def test_unwritable_outputs_fail_before_the_fit(one_view, model_folder, tmp_path, capsys,
                                                monkeypatch, option):
    def no_fit(*args, **kwargs):
        raise AssertionError("fitted before checking the outputs")

    monkeypatch.setattr(infer_module, "infer", no_fit)
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    outputs = {"--out": tmp_path / "r.json"}
    for bad in (tmp_path, a_file / "x.png"):  # an existing folder; a path under a file
        status = _infer(one_view, model_folder, *[x for k, v in {**outputs, option: bad}.items()
                                                  for x in (k, v)])
        err = capsys.readouterr().err
        assert status == 2 and f"{option} {bad}" in err and err.count("\n") == 1


@pytest.fixture(scope="module")
def three_views(tmp_path_factory):
    return _capture(tmp_path_factory.mktemp("three_views"), 3)


def test_report_point_cloud_and_handle_plot_are_written(three_views, model_folder, tmp_path, capsys):
    import cv2

    from nfr_drake.perception.pointcloud import read_semantic_ply

    out = {name: tmp_path / "sub" / name for name in ("r.json", "report.png", "cloud.ply", "handle.png")}
    assert _infer(three_views, model_folder, "--out", out["r.json"], "--report", out["report.png"],
                  "--point-cloud", out["cloud.ply"], "--handle-plot", out["handle.png"]) == 0
    stdout = capsys.readouterr().out
    points, classes = read_semantic_ply(out["cloud.ply"])
    assert f"point cloud: {out['cloud.ply']} ({len(points)} points)" in stdout
    assert len(points) == len(classes) and set(classes.tolist()) <= {1, 2, 3}
    report = cv2.imread(str(out["report.png"]))
    # three rows (photos, renders, segmentation) of 16 px views, 2 px gaps, pixels doubled
    assert report.shape[:2] == (2 * (3 * 18 + 2), 2 * (3 * 18 + 2))
    assert cv2.imread(str(out["handle.png"])) is not None
    assert f"report: {out['report.png']}" in stdout and f"handle plot: {out['handle.png']}" in stdout


def test_handle_path_on_interpolates_the_trajectory():
    import numpy as np

    from nfr_drake.inference.result import FitResult

    path = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 4.0]])
    result = FitResult("closet", 0.5, {}, np.array([0.0, 1.0]), {"handle": path}, 0.0, 0.0)
    np.testing.assert_allclose(infer_module.handle_path_on(np.array([0.0, 0.25, 1.0]), result),
                               [[0, 0, 0], [0.25, -0.5, 1.0], [1, -2, 4]])


def test_estimate_pose_finds_the_object_on_the_floor_and_reports_in_w(model_folder, tmp_path, capsys):
    import math

    import numpy as np

    root = tmp_path / "captures"
    captures_command("closet", n=1, out=root, views=8, size=96, seed=11, q=0.0)
    capture = next(p for p in root.iterdir() if (p / "transforms.json").is_file())
    yaw = 2.0
    X_WO = np.eye(4)
    X_WO[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    X_WO[:2, 3] = [0.8, -1.2]
    doc = json.loads((capture / "transforms.json").read_text())
    for frame in doc["frames"]:  # the camera poses in a floor frame W
        frame["transform_matrix"] = (X_WO @ np.array(frame["transform_matrix"])).tolist()
    (capture / "transforms.json").write_text(json.dumps(doc))
    out = tmp_path / "r.json"
    assert _infer(capture, model_folder, "--out", out, "--estimate-pose", "--masks", "background") == 0
    assert "object pose: x 0.8" in capsys.readouterr().out
    result = json.loads(out.read_text())
    X_WO_hat = np.array(result["extra"]["object_pose"]["X_WO"])
    error = np.linalg.inv(X_WO) @ X_WO_hat
    assert np.linalg.norm(error[:2, 3]) < 0.02
    assert abs(math.degrees(math.atan2(error[1, 0], error[0, 0]))) < 2.0
    # Positions come out in W: the trajectory's points lie near the object's place in W.
    handle = np.array(result["trajectory"]["keypoints"]["handle"])
    assert np.linalg.norm(handle[:, :2] - X_WO[:2, 3], axis=1).max() < 2.0


def test_estimate_pose_without_a_segmenter_is_one_line(one_view, model_folder, tmp_path, capsys):
    status = _infer(one_view, model_folder, "--out", tmp_path / "r.json", "--estimate-pose",
                    "--segmenter", tmp_path / "none")
    err = capsys.readouterr().err
    assert status == 2 and "no segmenter in" in err and err.count("\n") == 1


def test_masked_rays_keep_the_pixels_on_the_object(one_view):
    import numpy as np

    from nfr_drake.data.capture import read_capture_set
    from nfr_drake.inference.fit import observed_rays

    capture = read_capture_set(one_view)
    image = capture.load_images()[0]
    mask = np.zeros(image.shape[:2], np.float32)
    mask[4:9, 2:12] = 0.9
    rays = observed_rays(capture, [image], masks=[mask])
    assert rays.rgb.shape[0] == 50
    np.testing.assert_allclose(rays.rgb[0].numpy(), image[4, 2] / 255.0, atol=1e-6)
