"""Fixtures of the perception tests: the shared real-photo data and the Herz-Jesu-P8 run."""

import json
import os
from pathlib import Path

import pytest

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
