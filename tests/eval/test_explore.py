"""`nfr-drake explore`: paths between codes end on the two objects, sampled codes follow the
training codes' distribution, the command writes its figures and an offline Meshcat page; for a
model of several part slots (furniture) slot by slot: each slot's q along the path, one part swept
at a time, every part's keypoints and trajectories."""

import base64
import re
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import FURNITURE_PARTS
from headless_browser import CHROMIUM, JS_ERROR, screenshot
from PIL import Image
from pydrake.geometry import Meshcat

from nfr_drake.cli import main
from nfr_drake.data.captures import captures_command
from nfr_drake.errors import ConfigError
from nfr_drake.eval.explore import (
    ExploredObject,
    _keypoint_marks,
    articulation_strips,
    explore_command,
    explored_at,
    interpolation_path,
    model_view,
    object_html,
    object_parts,
    orbit_view,
    render,
    sampled_objects,
)
from nfr_drake.inference.forward import keypoint_trajectory
from nfr_drake.inference.infer import FittedModel
from nfr_drake.inference.latent_space import CodeGaussian, farthest_code, interpolate_codes
from nfr_drake.systems.replay import write_replay

FILES = ("interpolation.png", "articulations.png", "samples.png", "object.html")


@pytest.fixture(scope="module")
def fitted(model_folder):
    return FittedModel(model_folder)


def capture_sets(factory, category: str, n: int, **options) -> list[Path]:
    """n capture sets of `category` made by `nfr-drake captures` (options: its keywords)."""
    root = factory.mktemp(f"explore_{category}_caps")
    captures_command(category, n=n, out=root, **options)
    return [root / f"{category}_{i:03d}" for i in range(n)]


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    return capture_sets(tmp_path_factory, "closet", 1, views=3, size=32)[0]


def test_interpolate_codes_moves_z_obj_on_a_line_and_q_along_the_circle():
    a, b = torch.tensor([1.0, -2.0, 0.5]), torch.tensor([3.0, 2.0, -0.5])
    z_obj, q = interpolate_codes(a, 0.2, b, 0.9, np.array([0.0, 0.25, 1.0]))
    assert torch.equal(z_obj[0], a) and torch.equal(z_obj[-1], b)
    assert torch.allclose(z_obj[1], 0.75 * a + 0.25 * b)
    np.testing.assert_allclose(q, [0.2, 0.375, 0.9])
    with pytest.raises(ConfigError):
        interpolate_codes(a, 0.2, b, 0.9, np.array([0.0, 1.5]))


def test_farthest_code():
    codes = torch.tensor([[0.0, 0.0], [1.0, 0.0], [-3.0, 1.0], [0.5, 0.5]])
    assert farthest_code(codes, torch.tensor([0.5, 0.0])) == 2


def test_interpolation_ends_are_the_two_objects(fitted):
    generator = torch.Generator().manual_seed(1)
    k = fitted.codes.shape[1]
    a = ExploredObject("a", torch.randn(k, generator=generator), 0.1)
    b = ExploredObject("b", torch.randn(k, generator=generator), 0.8)
    path = interpolation_path(a, b, 5)
    view = model_view(fitted, 24)
    for end, obj in ((path[0], a), (path[-1], b)):
        ours, theirs = render(fitted, end, view), render(fitted, obj, view)
        assert np.array_equal(ours.rgb, theirs.rgb) and np.array_equal(ours.labels, theirs.labels)
        assert np.array_equal(ours.depth, theirs.depth)
        grid = np.linspace(0, 1, 5)
        np.testing.assert_array_equal(keypoint_trajectory(fitted.model, end.z, grid),
                                      keypoint_trajectory(fitted.model, obj.z, grid))
    middle = render(fitted, path[2], view)
    for obj in (a, b):
        assert np.abs(middle.depth - render(fitted, obj, view).depth).max() > 1e-4
    assert path[2].q == pytest.approx(0.45)


def test_sampled_codes_follow_the_training_codes():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(6, 6)) * 0.3
    codes = torch.as_tensor(rng.normal(size=(4000, 6)) @ A.T + np.arange(6), dtype=torch.float32)
    gaussian = CodeGaussian.fit(codes)
    assert not gaussian.is_diagonal
    drawn = gaussian.sample(40000, np.random.default_rng(1))
    x = codes.double().numpy()
    np.testing.assert_allclose(drawn.mean(0), x.mean(0), atol=0.02)
    np.testing.assert_allclose(np.cov(drawn, rowvar=False), np.cov(x, rowvar=False), atol=0.02)


def test_few_codes_give_a_diagonal_gaussian():
    codes = torch.as_tensor(np.random.default_rng(2).normal(size=(5, 8)) * np.arange(1, 9))
    gaussian = CodeGaussian.fit(codes)
    assert gaussian.is_diagonal
    np.testing.assert_allclose(np.diag(gaussian.cov), codes.numpy().var(0, ddof=1))
    drawn = gaussian.sample(50000, np.random.default_rng(3))
    np.testing.assert_allclose(drawn.std(0) / np.sqrt(np.diag(gaussian.cov)), 1.0, atol=0.03)


def test_sampled_objects_report_their_nearest_training_code(fitted):
    z_objs, nearest = sampled_objects(fitted, 3, seed=4)
    assert len(z_objs) == 3 and nearest.shape == (3,)
    expected = [float((fitted.codes - z).norm(dim=-1).min()) for z in z_objs]
    np.testing.assert_allclose(nearest, expected, rtol=1e-5)


def _meshcat_commands(html: str) -> list[bytes]:
    """The scene commands a Meshcat static page embeds (base64 msgpack data URLs)."""
    return [base64.b64decode(m) for m in
            re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)]


def test_html_holds_the_point_cloud_and_the_trajectories_offline(fitted, tmp_path):
    obj = ExploredObject("a", fitted.codes[1], 0.3)
    html = tmp_path / "object.html"
    points = object_html(fitted, obj, model_view(fitted, 24), html, cloud_size=24)
    text = html.read_text()
    # Nothing fetched over the network at load time: no external scripts, styles or images.
    assert not re.search(r"<script[^>]+src=|<link|<img|src=[\"']https?:|url\(\s*[\"']?https?:", text)
    commands = _meshcat_commands(text)
    cloud = [c for c in commands if b"/drake/object/point_cloud" in c]
    assert len(cloud) == 1 and b"Points" in cloud[0] and len(cloud[0]) >= 12 * points > 0
    for name in fitted.keypoint_names:
        assert any(f"/drake/object/keypoints/{name}/path".encode() in c for c in commands), name
        assert any(f"/drake/object/keypoints/{name}/now".encode() in c for c in commands), name
    if CHROMIUM is None:
        pytest.skip("needs Chromium to render the page: apt-get install chromium")
    image, log = screenshot(html, tmp_path)
    assert not [line for line in log.splitlines() if JS_ERROR.search(line)]
    empty, _ = screenshot(write_replay(Meshcat(), tmp_path / "empty.html"), tmp_path)
    changed = np.any(np.abs(image.astype(int) - empty.astype(int)) > 12, axis=-1)
    assert changed.mean() > 0.002, f"only {changed.mean():.2%} of the pixels show the scene"


def test_command_writes_the_figures(model_folder, capture, tmp_path, capsys):
    out = tmp_path / "explore"
    explore_command(model_folder, out=out, capture=(capture,), steps=3, samples=2,
                    sample_q=(0.0, 1.0), size=24)
    for name in FILES:
        assert (out / name).stat().st_size > 1000, name
    for name in FILES[:3]:
        width, height = Image.open(out / name).size
        assert width > 3 * 24 and height > 2 * 24
    printed = capsys.readouterr().out
    assert "fitted closet_000" in printed and "training object" in printed


@pytest.mark.parametrize("problem", ["model", "capture", "out", "captures", "steps", "part"])
def test_bad_inputs_exit_2_with_one_line(model_folder, capture, tmp_path, capsys, problem):
    out = tmp_path / "out"
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    model = str(model_folder)
    args = {"model": [str(tmp_path / "no_model"), "--out", str(out)],
            "capture": [model, "--capture", str(tmp_path / "no_capture"), "--out", str(out)],
            "out": [model, "--out", str(blocker / "explore")],
            "captures": [model, *["--capture", str(capture)] * 3, "--out", str(out)],
            "steps": [model, "--steps", "1", "--out", str(out)],
            "part": [model, "--part", "0", "--out", str(out)]}[problem]
    assert main(["explore", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("nfr-drake explore: error:") and "\n" not in err, err
    assert not out.exists()  # checked before any work


@pytest.fixture(scope="module")
def furniture(furniture_model_folder):
    return FittedModel(furniture_model_folder)


@pytest.fixture(scope="module")
def furniture_captures(tmp_path_factory):
    return tuple(capture_sets(tmp_path_factory, "furniture", 2, views=2, size=24, seed=3))


def test_interpolate_codes_moves_each_slot_on_its_own_circle():
    a, b = torch.zeros(3), torch.ones(3)
    z_obj, q = interpolate_codes(a, np.array([0.0, 0.8, 0.2]), b, np.array([1.0, 0.0, 0.2]),
                                 np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(q, [[0.0, 0.8, 0.2], [0.5, 0.4, 0.2], [1.0, 0.0, 0.2]])
    with pytest.raises(ConfigError):
        interpolate_codes(a, np.zeros(2), b, np.zeros(3), np.array([0.0, 1.0]))


def test_object_parts_are_the_slots_the_keypoint_head_finds(furniture, fitted):
    obj = explored_at(furniture, "a", furniture.codes[0], 0.6)
    parts = object_parts(furniture, obj.z)
    assert [(p.slot, p.kind) for p in parts] == list(enumerate(FURNITURE_PARTS))
    np.testing.assert_allclose(obj.qs, [0.6] * len(FURNITURE_PARTS) + [0.0] * 5)
    door, drawer = parts[0], parts[1]
    assert door.category == "closet" and door.names == ("handle", "goal", "hinge_top", "hinge_bottom")
    assert drawer.category == "drawer" and drawer.names == ("handle", "goal") and drawer.indices == (4, 5)
    assert obj.z.shape == (2 * 8 + furniture.codes.shape[1],)
    one = object_parts(fitted, fitted.codes[0])
    assert len(one) == 1 and one[0].names == fitted.keypoint_names


def test_furniture_interpolation_ends_are_the_two_objects(furniture):
    k = furniture.codes.shape[1]
    a = ExploredObject("a", furniture.codes[0], np.array([0.1, 0.9, 0.0, 0, 0, 0, 0, 0]))
    b = ExploredObject("b", furniture.codes[1] + torch.ones(k), np.array([0.7, 0.1, 0.5, 0, 0, 0, 0, 0]))
    path = interpolation_path(a, b, 3)
    np.testing.assert_allclose(path[1].qs[:3], [0.4, 0.5, 0.25])
    view = model_view(furniture, 16)
    for end, obj in ((path[0], a), (path[-1], b)):
        assert torch.equal(end.z, obj.z)
        assert np.array_equal(render(furniture, end, view).depth, render(furniture, obj, view).depth)
    assert "q 0.10 0.90 0.00" in a.describe()


def test_a_part_sweep_moves_only_that_part(furniture):
    """One strip per part the head finds, each changing only its slot's z_art from shut to open;
    keypoint paths are drawn for that part alone, and its dots lie on its path."""
    obj = explored_at(furniture, "a", furniture.codes[2], 0.3)
    strips = articulation_strips(furniture, obj, 4)
    assert [set(s.swept) for s in strips] == [{0}, {1}, {2}]
    assert [s.name for s in strips] == ["part 0, door", "part 1, drawer", "part 2, door"]
    view = orbit_view(np.array([0.35, 0.0, 1.0]), 4.0, 30.0, 64)
    for k, strip in enumerate(strips):
        np.testing.assert_allclose([o.qs[k] for o in strip.objects], np.linspace(0, 1, 4))
        for o in strip.objects:
            changed = torch.nonzero(o.z != obj.z).flatten().tolist()
            assert set(changed) <= {2 * k, 2 * k + 1}
            marks = _keypoint_marks(furniture, o, view, strip.swept)
            assert marks, "no keypoint in view"
            for name, m in marks.items():
                assert (len(m["path"]) > 0) == name.startswith(f"{k}/"), name
            handle = marks[f"{k}/handle"]
            assert np.linalg.norm(handle["path"] - handle["now"], axis=1).min() < 1.0  # px
    assert [s.name for s in articulation_strips(furniture, obj, 4, part=5)] == ["part 5, not found"]


def test_furniture_html_holds_every_part_trajectory(furniture, tmp_path):
    obj = explored_at(furniture, "a", furniture.codes[0], 0.5)
    html = tmp_path / "object.html"
    points = object_html(furniture, obj, model_view(furniture, 24), html, cloud_size=24)
    commands = _meshcat_commands(html.read_text())
    assert any(b"/drake/object/point_cloud" in c for c in commands) and points > 0
    for slot, kind in enumerate(FURNITURE_PARTS):
        names = ("handle", "goal", "hinge_top", "hinge_bottom") if kind == "door" else ("handle", "goal")
        for name in names:
            assert any(f"/drake/object/keypoints/part{slot}/{name}/path".encode() in c for c in commands)
    assert not any(b"/drake/object/keypoints/part3/" in c for c in commands)


def test_furniture_command_writes_the_figures(furniture_model_folder, furniture_captures, tmp_path, capsys):
    """Two fitted pieces (the fit `nfr-drake infer` runs): figures with every part found, one
    articulation strip per part, or one with --part."""
    out, one = tmp_path / "explore", tmp_path / "explore_part"
    explore_command(furniture_model_folder, out=out, capture=furniture_captures, steps=3, samples=2,
                    sample_q=(0.0, 1.0), size=24)
    printed = capsys.readouterr().out
    for name in FILES:
        assert (out / name).stat().st_size > 1000, name
    assert "fitted furniture_000" in printed and "fitted furniture_001" in printed
    assert "the keypoint head finds parts 0 door, 1 drawer, 2 door (its fit lists" in printed
    assert "part 0, door; part 1, drawer; part 2, door: swept one at a time" in printed
    explore_command(furniture_model_folder, out=one, steps=3, samples=1, sample_q=(0.0,), size=24, part=1)
    assert "part 1, drawer: swept" in capsys.readouterr().out
    all_parts, part_1 = (Image.open(d / "articulations.png").size[1] for d in (out, one))
    assert all_parts / part_1 == pytest.approx((6 * 1.45 + 1.1) / (3 * 1.45 + 1.1), rel=0.01)  # 6 rows, 3


@pytest.mark.parametrize("part", ["8", "-1"])
def test_a_part_beyond_the_slots_exits_2_with_one_line(furniture_model_folder, tmp_path, capsys, part):
    out = tmp_path / "out"
    assert main(["explore", str(furniture_model_folder), "--part", part, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "8 part slots, 0 to 7" in err and "\n" not in err, err
    assert not out.exists()
