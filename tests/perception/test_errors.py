"""`nfr-drake poses` fails with exit status 2 and a clear message on bad input."""

import json

import cv2
import numpy as np
import pytest

from nfr_drake.cli import main


def _poses(capsys, *args):
    status = main(["poses", *map(str, args)])
    return status, capsys.readouterr().err


@pytest.fixture
def noise_photos(tmp_path):
    """Three unrelated noise images: nothing matches between them."""
    folder = tmp_path / "noise"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        image = cv2.resize(rng.integers(0, 256, (60, 80, 3), dtype=np.uint8), (320, 240),
                           interpolation=cv2.INTER_NEAREST)
        cv2.imwrite(str(folder / f"noise_{i}.png"), image)
    return folder


def test_no_alignment_requested(capsys, noise_photos, tmp_path):
    status, err = _poses(capsys, noise_photos, "--out", tmp_path / "out")
    assert status == 2 and "no metric alignment" in err


def test_no_model_found(capsys, noise_photos, tmp_path):
    status, err = _poses(capsys, noise_photos, "--out", tmp_path / "out", "--allow-unaligned")
    assert status == 2 and ("no model found" in err or "registered" in err)
    assert not (tmp_path / "out").exists()


def test_collinear_anchors(capsys, noise_photos, tmp_path):
    anchors = tmp_path / "anchors.json"
    anchors.write_text(json.dumps({f"noise_{i}.png": [0.1 * i, 0.0, 1.0] for i in range(3)}))
    status, err = _poses(capsys, noise_photos, "--out", tmp_path / "out", "--anchors", anchors)
    assert status == 2 and "collinear" in err


def test_board_not_found(capsys, noise_photos, tmp_path):
    status, err = _poses(capsys, noise_photos, "--out", tmp_path / "out", "--charuco")
    assert status == 2 and "ChArUco board" in err and "found in 0" in err


def test_missing_folder_and_existing_output(capsys, noise_photos, tmp_path):
    status, err = _poses(capsys, tmp_path / "nothing", "--out", tmp_path / "out",
                         "--allow-unaligned")
    assert status == 2 and "not found" in err
    status, err = _poses(capsys, noise_photos, "--out", noise_photos, "--allow-unaligned")
    assert status == 2 and "already exists" in err


def test_anchor_residual_limit_must_be_positive(capsys, noise_photos, tmp_path):
    anchors = tmp_path / "anchors.json"
    anchors.write_text(json.dumps({f"noise_{i}.png": [0.1 * i, 0.1 * (i % 2), 1.0] for i in range(3)}))
    status, err = _poses(capsys, noise_photos, "--out", tmp_path / "out", "--anchors", anchors,
                         "--max-anchor-residual", "0")
    assert status == 2 and "must be positive" in err
