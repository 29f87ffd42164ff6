"""Furniture data: generate (part images, per-part meta, textures, resuming after kill -9),
cameras that frame the whole piece at every q, captures with per-part ground truth, validate, sheet."""

import json
import math
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
from dataset_checks import (
    ARRAYS,
    assert_same_data,
    dead_pid,
    files_of,
    kill_after_first_object,
    kill_when,
    object_arrays,
)
from pydrake.multibody.plant import MultibodyPlant

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution, framing_distance, look_at
from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.data.contact_sheet import contact_sheet
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.generate import generate_dataset, part_articulations
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.data.shards import OBJECTS_DIR, DatasetSpec
from nfr_drake.data.validate import PART_KEYS
from nfr_drake.data.visualize import PART_PALETTE
from nfr_drake.errors import DatasetError
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.objects.articulated import _part_corners
from nfr_drake.objects.furniture import sample_furniture
from nfr_drake.objects.textures import texture_image
from nfr_drake.parsing import make_parser

SPEC = DatasetSpec("furniture", objects=2, articulations=2, views=2, size=32, seed=0,
                   cameras=CameraDistribution(framing="bounds"))
ARGS = ["--category", "furniture", "--objects", "2", "--articulations", "2", "--views", "2",
        "--size", "32", "--seed", "0"]
NAMES = (*ARRAYS, "part")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    root = tmp_path_factory.mktemp("furniture")
    generate_dataset(SPEC, root, workers=1, progress=False)
    return root


def _object(i):
    return sample_object("furniture", object_rng(SEED_DOMAIN_TRAIN, SPEC.seed, i), name=f"furniture_{i:06d}")


def _folder(root, i):
    return root / OBJECTS_DIR / f"obj_{i:06d}"


def _loads_in_drake(sdf_path):
    plant = MultibodyPlant(0.0)
    make_parser(plant).AddModels(str(sdf_path))
    plant.Finalize()
    return plant


def test_resume_after_kill_is_bit_identical_with_the_same_files(reference, tmp_path):
    cmd = [sys.executable, "-m", "nfr_drake.cli", "generate", *ARGS, "--out", str(tmp_path), "--workers", "1"]
    assert kill_after_first_object(cmd, tmp_path) < SPEC.objects, "run finished before the kill"
    partial = tmp_path / OBJECTS_DIR / f".obj_000001.tmp-{dead_pid()}"
    partial.mkdir(exist_ok=True)
    (partial / "part.npy").write_bytes(b"truncated")
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    spec_of = [json.loads((root / "dataset.json").read_text()) for root in (tmp_path, reference)]
    assert spec_of[0] == spec_of[1]  # the CLI frames furniture by its bounds, as SPEC does
    assert_same_data(reference, tmp_path, SPEC.objects, NAMES)
    for i in range(SPEC.objects):  # meta.json, object.sdf and textures too
        assert files_of(_folder(reference, i)) == files_of(_folder(tmp_path, i))


def test_part_image_marks_fronts_exactly_where_the_labels_do(reference):
    for i in range(SPEC.objects):
        arrays = object_arrays(reference, i, NAMES)
        part, label = arrays["part"], arrays["label"]
        assert part.dtype == np.int8 and part.shape == label.shape == (2, 2, 32, 32)
        np.testing.assert_array_equal(part >= 0, np.isin(label, (2, 3)))
        assert part.min() >= -1 and part.max() < _object(i).num_fronts
        assert (part >= 0).any()


def test_meta_has_a_q_and_named_keypoints_per_part_in_canonical_order(reference):
    for i in range(SPEC.objects):
        obj, meta = _object(i), json.loads((_folder(reference, i) / "meta.json").read_text())
        q = np.asarray(meta["q"])
        assert q.shape == (SPEC.articulations, obj.num_fronts) and ((0 <= q) & (q <= 1)).all()
        assert "canonical" in meta["part_order"] and len(meta["parts"]) == obj.num_fronts
        for k, (front, part) in enumerate(zip(obj.fronts, meta["parts"], strict=True)):
            assert (part["index"], part["type"], part["joint_name"]) == (k, front.kind, front.joint_name)
            np.testing.assert_array_equal(part["q"], q[:, k])
            assert list(part["keypoints"]) == list(front.keypoint_names)
            for a in range(SPEC.articulations):
                for name, p_O in front.keypoints(q[a, k]).items():
                    np.testing.assert_allclose(part["keypoints"][name][a], p_O, atol=1e-12)
            if front.kind == "door":
                np.testing.assert_allclose(part["hinge_axis"]["point"], front.p_OJ)
            else:
                assert part["travel"] == front.joint_upper and part["pull_axis"] == [1.0, 0.0, 0.0]


def test_objects_ship_their_textures_and_load_from_their_folder(reference):
    textured = 0
    for i in range(SPEC.objects):
        sdf = _folder(reference, i) / "object.sdf"
        assert "file://" not in sdf.read_text()
        textured += len(list((_folder(reference, i) / "textures").glob("*.png")))
        plant = _loads_in_drake(sdf)
        assert all(plant.HasJointNamed(f.joint_name) for f in _object(i).fronts)
    assert textured > 0, "the test dataset should hold a textured piece"


def test_part_articulations_mix_shut_single_and_independent_states():
    q = part_articulations(np.random.default_rng(0), 400, 5)
    opened = (q > 0).sum(1)
    assert q.shape == (400, 5) and ((0 <= q) & (q <= 1)).all()
    for count, share in ((0, 0.15 + 0.5 / 32), (1, 0.35 + 0.5 * 5 / 32)):
        assert abs(np.mean(opened == count) - share) < 0.07, count
    assert np.mean(opened >= 3) > 0.2


def _pieces():
    """The tallest and the widest of 20 tall cabinets and 20 kitchen runs and sideboards each."""
    objs = [sample_furniture(np.random.default_rng([3, j, i]), kind=kind)
            for j, kind in enumerate(("tall_cabinet", "kitchen_run", "sideboard")) for i in range(20)]
    return [max(objs, key=lambda o: o.swept_bounds()[1][2]),
            max(objs, key=lambda o: np.ptp(np.array(o.swept_bounds())[:, 1]))]


def _corners_at(obj, q):
    """Corners of the bounding box of every part at articulations q, in O, shape (8, 3)."""
    pts = [np.concatenate([_part_corners(p) for p in obj.base_parts])]
    for front, qk in zip(obj.fronts, obj.articulation(q), strict=True):
        X = front.X_OM(qk)
        pts.append(np.concatenate([_part_corners(p) for p in front.parts]) @ X[:3, :3].T + X[:3, 3])
    pts = np.concatenate(pts)
    lo, hi = pts.min(0), pts.max(0)
    return np.array([[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]] for a in (0, 1) for b in (0, 1)
                     for c in (0, 1)])


def _project(camera, X_OC, p_O):
    p_C = (p_O - X_OC[:3, 3]) @ X_OC[:3, :3]
    return np.column_stack([camera.fx * p_C[:, 0] / p_C[:, 2] + camera.cx,
                            camera.fy * p_C[:, 1] / p_C[:, 2] + camera.cy]), p_C[:, 2]


def test_cameras_see_the_tallest_and_widest_pieces_whole_at_every_q():
    camera = PinholeCamera.from_fov(64, 64, math.radians(50.0))
    cameras = CameraDistribution(framing="bounds")
    tallest, widest = _pieces()
    assert tallest.swept_bounds()[1][2] > 1.9 and np.ptp(np.array(widest.swept_bounds())[:, 1]) > 1.6
    for obj in (tallest, widest):
        rng = np.random.default_rng(1)
        X_OCs = cameras.sample(rng, 12, *cameras.target_of(obj), camera)
        for q in (1.0, 0.5, 0.0):
            for X_OC in X_OCs:
                uv, z = _project(camera, X_OC, _corners_at(obj, q))
                assert (z > 0.1).all() and (uv >= 0).all() and (uv <= 64).all(), (obj.params["kind"], q, uv)
        renderer = ObjectRenderer(obj, camera)
        for X_OC in X_OCs[:3]:  # nothing of the piece touches the image border, doors open
            label = renderer.render(1.0, X_OC).label
            assert label.any() and not np.concatenate([label[0], label[-1], label[:, 0], label[:, -1]]).any()


def test_framing_distance_is_the_tight_one():
    camera = PinholeCamera.from_fov(48, 32, math.radians(40.0))
    rng = np.random.default_rng(2)
    corners = rng.uniform(-0.5, 0.8, (8, 3))
    target, direction = np.array([0.1, 0.0, 0.4]), np.array([0.8, 0.3, 0.5])
    direction /= np.linalg.norm(direction)
    d = framing_distance(corners, target, direction, camera, margin=0.2)
    uv, _ = _project(camera, look_at(target + d * direction, target), corners)
    low, high = 0.1 * np.array([48, 32]), 0.9 * np.array([48, 32])
    assert (uv >= low - 1e-9).all() and (uv <= high + 1e-9).all()
    assert np.isclose(np.minimum(uv - low, high - uv).min(), 0.0, atol=1e-9)  # one corner on the border


def test_closet_cameras_keep_their_fixed_distances():
    closet = sample_object("closet", np.random.default_rng(0))
    cameras = CameraDistribution()
    target, bounds = cameras.target_of(closet)
    assert bounds is None and np.array_equal(target, closet.look_at_target())
    X_OCs = cameras.sample(np.random.default_rng(0), 50, target)
    distances = np.linalg.norm(X_OCs[:, :3, 3] - target, axis=1)
    assert (distances >= 1.4).all() and (distances <= 1.9).all()


def test_captures_carry_every_part_their_images_and_textures(tmp_path):
    out = tmp_path / "caps"
    out.mkdir()
    partial = f".furniture_000.tmp-{dead_pid()}"
    (out / partial).mkdir()  # left by a killed run
    captures_command("furniture", n=2, out=out, views=2, size=32, seed=0, shard="1/2")
    assert sorted(p.name for p in out.iterdir()) == [partial, "furniture_001"]
    captures_command("furniture", n=2, out=out, views=2, size=32, seed=0, shard="0/2")
    assert sorted(p.name for p in out.iterdir()) == ["furniture_000", "furniture_001"]
    # One run, killed with -9 after its first capture set and run again: the same files.
    killed = tmp_path / "killed"
    cmd = [sys.executable, "-m", "nfr_drake.cli", "captures", "--category", "furniture", "--n", "2",
           "--views", "2", "--size", "32", "--seed", "0", "--out", str(killed)]
    kill_when(cmd, lambda: (killed / "furniture_000").is_dir())
    assert not (killed / "furniture_001").exists(), "run finished before the kill"
    assert subprocess.run(cmd, capture_output=True).returncode == 0
    assert files_of(killed) == files_of(out)
    for i in range(2):
        root = out / f"furniture_{i:03d}"
        cap = read_capture_set(root)
        obj = sample_object("furniture", object_rng(SEED_DOMAIN_CAPTURE, 0, i))
        gt = cap.gt
        assert gt["category"] == "furniture" and len(gt["q"]) == obj.num_fronts == len(gt["parts"])
        for k, (front, part) in enumerate(zip(obj.fronts, gt["parts"], strict=True)):
            assert all(key in part for key in PART_KEYS) and part["index"] == k and part["q"] == gt["q"][k]
            assert ("hinge_axis" in part) == (front.kind == "door") != ("travel" in part)
            for name, p_O in front.keypoints(part["q"]).items():
                np.testing.assert_allclose(part["keypoints"][name], p_O, atol=1e-12)
            traj = part["trajectory"]
            for name in front.keypoint_names:
                np.testing.assert_allclose(traj["keypoints"][name], front.keypoint_array(traj["q"])
                                           [:, front.keypoint_names.index(name)], atol=1e-12)
        for label_path, part_path in zip(gt["label_paths"], gt["part_paths"], strict=True):
            label = cv2.imread(str(root / label_path), cv2.IMREAD_UNCHANGED)
            part = cv2.imread(str(root / part_path), cv2.IMREAD_UNCHANGED).view(np.int8)
            np.testing.assert_array_equal(part >= 0, np.isin(label, (2, 3)))
        assert "file://" not in (root / "object.sdf").read_text()
        plant = _loads_in_drake(root / "object.sdf")
        assert all(plant.HasJointNamed(f.joint_name) for f in obj.fronts)
    assert list((out / "furniture_000" / "textures").glob("*.png")), "capture 0 is a textured desk"
    result = subprocess.run([sys.executable, "-m", "nfr_drake.cli", "validate", str(out / "furniture_000")],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "ground truth: furniture, 2 parts (drawer, door)" in result.stdout


def test_validate_catches_a_missing_texture_and_a_wrong_part_image(tmp_path):
    captures_command("furniture", n=1, out=tmp_path, views=2, size=32, seed=0)
    root = tmp_path / "furniture_000"

    def validate():
        return subprocess.run([sys.executable, "-m", "nfr_drake.cli", "validate", str(root)],
                              capture_output=True, text=True)

    part_png = root / "parts" / "frame_001.png"
    good = part_png.read_bytes()
    cv2.imwrite(str(part_png), np.full((32, 32), 255, np.uint8))
    result = validate()
    assert result.returncode == 2 and "disagree" in result.stderr and "Traceback" not in result.stderr
    part_png.write_bytes(good)
    next((root / "textures").glob("*.png")).unlink()
    result = validate()
    assert result.returncode == 2 and "not found" in result.stderr


def test_validate_and_sheet_read_a_furniture_dataset(reference):
    result = subprocess.run([sys.executable, "-m", "nfr_drake.cli", "validate", str(reference)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "furniture dataset, 2 of 2 objects complete" in result.stdout
    ds = RenderedDataset(reference)
    for use in (lambda: ds[0], lambda: ds.keypoint_names):  # what training reads first
        with pytest.raises(DatasetError, match="a q and keypoints per front"):
            use()
    block = 3 * 34 + 2  # RGB, label and part rows of one object, 2 px apart
    sheet = contact_sheet(ds, objects=2, articulations=2)
    assert sheet.shape == (2 * block, 2 * 34 + 2, 3)
    part = object_arrays(reference, 1, ("part",))["part"][0, 0]
    tile = sheet[block + 2 + 2 * 34:block + 2 + 2 * 34 + 32, 2:34]
    np.testing.assert_array_equal(tile[part >= 0], PART_PALETTE[part[part >= 0]])
    side_by_side = contact_sheet(ds, objects=2, articulations=2, per_row=2)
    assert side_by_side.shape == (block + 12, 2 * (2 * 34 + 2) + 18, 3)
    np.testing.assert_array_equal(side_by_side[6:6 + block, 6 + 2 * 34 + 2 + 6:-6], sheet[block:])


def test_textures_written_at_once_by_several_processes_are_whole(tmp_path):
    names = [(kind, seed) for kind in ("wood", "metal") for seed in range(4)]
    code = ("from nfr_drake.objects.textures import texture_uri\n"
            f"for kind, seed in {names!r}: texture_uri(kind, seed)")
    env = {**os.environ, "NFR_DRAKE_TEXTURE_DIR": str(tmp_path)}
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env) for _ in range(4)]
    assert [p.wait() for p in procs] == [0] * 4
    # Every file whole, and no temporary file left behind.
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{k}_{s:08d}.png" for k, s in names)
    for kind, seed in names:
        image = cv2.cvtColor(cv2.imread(str(tmp_path / f"{kind}_{seed:08d}.png")), cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(image, texture_image(kind, seed))
