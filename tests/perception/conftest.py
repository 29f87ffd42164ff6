"""Fixtures of the perception tests: the shared real-photo data, Herz-Jesu-P8, and a small folder of
Drake-rendered photos."""

import json
import os
from pathlib import Path

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.synthetic import SyntheticPhotoScene, orbit_poses, write_photo_folder

HERZ_JESU = "real_photos/herz_jesu_p8"


def shared_data_dir() -> Path:
    """`$NFR_DRAKE_SHARED_DATA`, else `../shared/data` beside the repository."""
    env = os.environ.get("NFR_DRAKE_SHARED_DATA")
    return Path(env) if env else (Path(__file__).parents[2] / ".." / "shared" / "data").resolve()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    root = shared_data_dir()
    if not root.is_dir():
        pytest.skip(f"shared test photos not found at {root} (set NFR_DRAKE_SHARED_DATA)")
    return root


@pytest.fixture(scope="session")
def herz_jesu(shared_data) -> tuple[Path, dict]:
    """(images folder, ground-truth cameras by image name) of Herz-Jesu-P8."""
    root = shared_data / HERZ_JESU
    if not (root / "cameras.json").is_file():
        pytest.skip(f"{root}/cameras.json not found")
    return root / "images", json.loads((root / "cameras.json").read_text())["cameras"]


@pytest.fixture(scope="session")
def small_photos(tmp_path_factory) -> tuple[Path, dict[str, np.ndarray]]:
    """Eight Drake photos (320 x 240, pinhole) of a closet in a textured room, and their true poses
    X_OC (4x4, OpenCV axes) by photo name. SfM on them takes a few seconds."""
    closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
    scene = SyntheticPhotoScene(closet, 0.5, PinholeCamera.from_fov(320, 240, np.deg2rad(50)))
    folder = write_photo_folder(tmp_path_factory.mktemp("small_photos") / "photos", scene,
                                orbit_poses(8, np.array([0.4, 0.0, 0.35])))
    truth = json.loads((folder / "truth.json").read_text())
    return folder, {name: np.array(X) for name, X in truth["X_OC"].items()}
