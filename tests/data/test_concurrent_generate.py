"""Two runs on one dataset folder: the second refuses, a live run's work is never deleted, and
dataset.json is created once, whole."""

import subprocess
import sys
import time
from pathlib import Path

import pytest

from nfr_drake.cli import main
from nfr_drake.data import shards
from nfr_drake.data.generate import generate_dataset
from nfr_drake.data.shards import OBJECTS_DIR, DatasetSpec, completed_objects, dataset_lock
from nfr_drake.errors import DatasetError

SPEC = DatasetSpec("closet", objects=2, articulations=1, views=1, size=16, seed=4)


def test_a_second_run_on_a_folder_being_written_refuses(tmp_path, capsys):
    with dataset_lock(tmp_path):  # a run writing the folder
        status = main(["generate", "--category", "closet", "--objects", "2", "--articulations",
                       "1", "--views", "1", "--size", "16", "--out", str(tmp_path)])
        err = capsys.readouterr().err
        assert status == 2 and err.count("\n") == 1
        assert "being written by another `nfr-drake generate`" in err
    assert not (tmp_path / OBJECTS_DIR).exists() and not (tmp_path / shards.SPEC_FILE).exists()
    generate_dataset(SPEC, tmp_path, workers=1, progress=False)  # the lock is free again
    assert completed_objects(tmp_path) == [0, 1]


def test_only_the_partial_folders_of_dead_runs_are_cleaned(tmp_path):
    """An orphaned worker of a killed run (alive) keeps its temporary folder; a dead run's goes,
    and so does a killed one's that its parent has not reaped yet (a zombie)."""
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    zombie = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    zombie.kill()
    while Path(f"/proc/{zombie.pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
        time.sleep(0.01)
    try:
        objects = tmp_path / OBJECTS_DIR
        for pid in (live.pid, dead.pid, zombie.pid):
            (objects / f".obj_000001.tmp-{pid}").mkdir(parents=True)
        generate_dataset(SPEC, tmp_path, workers=1, progress=False)
        assert (objects / f".obj_000001.tmp-{live.pid}").is_dir()
        assert not (objects / f".obj_000001.tmp-{dead.pid}").exists()
        assert not (objects / f".obj_000001.tmp-{zombie.pid}").exists()
        assert completed_objects(tmp_path) == [0, 1]
    finally:
        live.kill()
        live.wait()
        zombie.wait()


def test_dataset_json_written_meanwhile_by_another_run_is_not_overwritten(tmp_path, monkeypatch):
    """Another run creates dataset.json between this run's look and its write: this run must
    compare with it, not replace it."""
    other = DatasetSpec("closet", objects=3, articulations=1, views=1, size=16, seed=4)
    shards.open_dataset_dir(tmp_path, other)
    first = (tmp_path / shards.SPEC_FILE).read_text()
    exists = Path.exists
    monkeypatch.setattr(Path, "exists", lambda p: False if p.name == shards.SPEC_FILE else exists(p))
    with pytest.raises(DatasetError, match="objects: 3 vs 2"):
        shards.open_dataset_dir(tmp_path, SPEC)
    assert (tmp_path / shards.SPEC_FILE).read_text() == first
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".dataset")] == []
