"""Dataset generation: determinism, sharding, resuming after kill -9, the torch Dataset."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch
from dataset_checks import assert_same_data, kill_after_first_object, object_arrays

from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.generate import articulation_values, generate_dataset, stale_objects
from nfr_drake.data.shards import OBJECTS_DIR, DatasetSpec, completed_objects
from nfr_drake.errors import DatasetError

SPEC = DatasetSpec("closet", objects=5, articulations=3, views=2, size=32, seed=4)
ARGS = ["--category", "closet", "--objects", "5", "--articulations", "3", "--views", "2",
        "--size", "32", "--seed", "4"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    root = tmp_path_factory.mktemp("reference")
    generate_dataset(SPEC, root, workers=1, progress=False)
    return root


def test_shards_and_workers_give_the_same_data(reference, tmp_path):
    generate_dataset(SPEC, tmp_path, workers=2, shard="1/2", progress=False)
    assert completed_objects(tmp_path) == [1, 3]
    generate_dataset(SPEC, tmp_path, workers=2, shard="0/2", progress=False)
    assert_same_data(reference, tmp_path, SPEC.objects)


def test_resume_after_kill_completes_without_duplicates_or_corruption(reference, tmp_path):
    cmd = [sys.executable, "-m", "nfr_drake.cli", "generate", *ARGS, "--out", str(tmp_path),
           "--workers", "2"]
    assert kill_after_first_object(cmd, tmp_path) < SPEC.objects, "run finished before the kill"
    # A write interrupted halfway leaves a temporary folder; the next run must clean it up.
    partial = tmp_path / OBJECTS_DIR / ".obj_000004.tmp-99999"
    partial.mkdir(exist_ok=True)
    (partial / "rgb.npy").write_bytes(b"truncated")
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(tmp_path / OBJECTS_DIR)) == [f"obj_{i:06d}" for i in range(5)]
    assert_same_data(reference, tmp_path, SPEC.objects)


def test_other_options_on_an_existing_folder_are_refused(reference):
    other = DatasetSpec("closet", objects=5, articulations=4, views=2, size=32, seed=4)
    with pytest.raises(DatasetError, match="articulations: 3 vs 4"):
        generate_dataset(other, reference, progress=False)


def test_objects_drawn_by_another_generator_version_are_refused(reference, tmp_path):
    """A rerun on a dataset whose objects the generator now draws otherwise (here: one object's
    meta.json as an older sampler wrote it) names them instead of mixing two versions."""
    shutil.copytree(reference, tmp_path / "d")
    meta_path = tmp_path / "d" / OBJECTS_DIR / "obj_000002" / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta["params"]["width"] += 0.01
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match=r"1 objects on disk \(obj_000002\) were drawn by another"):
        generate_dataset(SPEC, tmp_path / "d", progress=False)
    assert stale_objects(SPEC, reference) == []


def test_bad_shard_is_a_clean_cli_error(tmp_path):
    result = subprocess.run([sys.executable, "-m", "nfr_drake.cli", "generate", *ARGS, "--out",
                             str(tmp_path), "--shard", "3/2"], capture_output=True, text=True)
    assert result.returncode == 2 and "need 0 <= i < n" in result.stderr
    assert "Traceback" not in result.stderr


def test_torch_dataset_reads_views_with_their_metadata(reference):
    ds = RenderedDataset(reference)
    assert len(ds) == 5 * 3 * 2 and ds.keypoint_names == ("handle", "hinge_top", "hinge_bottom", "goal")
    item = ds[7]  # object 1, articulation 0, view 1
    raw = object_arrays(reference, 1)
    np.testing.assert_allclose(item.rgb.numpy(), raw["rgb"][0, 1] / 255.0, atol=1e-6)
    assert item.label.dtype == torch.int64 and item.object_index.item() == 1
    assert item.q.item() == 0.0
    background = item.label == 0
    assert torch.isinf(item.depth[background]).all() and torch.isfinite(item.depth[~background]).all()
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=4)))
    assert batch.rgb.shape == (4, 32, 32, 3) and batch.X_OC.shape == (4, 4, 4)
    assert batch.keypoints.shape == (4, 4, 3)


def test_articulation_values_cover_the_range():
    rng = np.random.default_rng(0)
    q = articulation_values(rng, 10)
    assert q[0] == 0.0 and q[-1] == 1.0 and np.all(np.diff(q) > 0)
    assert 0.0 <= articulation_values(rng, 1)[0] <= 1.0
