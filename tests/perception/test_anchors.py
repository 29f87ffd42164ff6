"""`nfr-drake poses --anchors`: one-line errors for a bad anchors file, for anchors of photos that
are not in the folder, and for anchors of other photos (refused after alignment, nothing written);
the capture set names the photo of each frame."""

import json

import numpy as np
import pytest

from nfr_drake.cli import main
from nfr_drake.data.capture import read_capture_set


def _poses(capsys, photos_dir, out, anchors: dict | str, tmp_path):
    path = tmp_path / "anchors.json"
    path.write_text(anchors if isinstance(anchors, str) else json.dumps(anchors, indent=1))
    status = main(["poses", str(photos_dir), "--out", str(out), "--anchors", str(path),
                   "--sfm.num-threads", "2"])
    errors = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    return status, "\n".join(errors)


def _centres(X_OCs: dict[str, np.ndarray], names: list[str]) -> dict[str, list[float]]:
    return {a: X_OCs[b][:3, 3].tolist() for a, b in zip(sorted(X_OCs), names, strict=True)}


def test_true_anchors_give_the_true_poses_and_keep_photo_names(capsys, small_photos, tmp_path):
    folder, X_OCs = small_photos
    status, err = _poses(capsys, folder, tmp_path / "out", _centres(X_OCs, sorted(X_OCs)), tmp_path)
    assert status == 0, err
    frames = read_capture_set(tmp_path / "out").frames
    assert sorted(f.source_photo for f in frames) == sorted(X_OCs)
    doc = json.loads((tmp_path / "out" / "transforms.json").read_text())
    assert [f["source_photo"] for f in doc["frames"]] == [f.source_photo for f in frames]
    for frame in frames:  # the frame is the photo it names: its pose is that photo's
        error = np.linalg.norm(frame.X_OC[:3, 3] - X_OCs[frame.source_photo][:3, 3])
        assert error < 0.03, f"{frame.source_photo}: centre off by {1000 * error:.0f} mm"


def test_anchors_of_other_photos_are_refused(capsys, small_photos, tmp_path):
    """Anchors shuffled between the photos (a similarity fits them with an RMS residual of 59 % of
    their spread): exit 2, one line, no capture set."""
    folder, X_OCs = small_photos
    names = sorted(X_OCs)
    shuffled = [names[i] for i in (2, 3, 0, 1, 4, 5, 6, 7)]
    status, err = _poses(capsys, folder, tmp_path / "out", _centres(X_OCs, shuffled), tmp_path)
    assert status == 2
    assert "anchors probably belong to other photos" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_anchors_of_photos_not_in_the_folder(capsys, small_photos, tmp_path):
    folder, X_OCs = small_photos
    anchors = _centres(X_OCs, sorted(X_OCs))
    anchors["IMG_0001.jpg"] = [0.0, 0.0, 1.0]
    anchors["photo_000.jpg"] = anchors.pop("photo_000.png")
    status, err = _poses(capsys, folder, tmp_path / "out", anchors, tmp_path)
    assert status == 2
    assert "2 of 9 anchors name photos that are not in" in err
    assert "IMG_0001.jpg, photo_000.jpg" in err and not (tmp_path / "out").exists()


@pytest.mark.parametrize(("text", "message"), [
    ('{\n "photo_000.png": [0, 0, 1],\n "photo_001.png": [0, "1.5", 1]\n}',
     'line 3: the anchor of \'photo_001.png\' is [0, "1.5", 1]; expected [x, y, z]'),
    ('{\n "photo_000.png": [0, 0, 1],\n "photo_001.png": [0, 1]\n}', "line 3: the anchor of"),
    ('{\n "photo_000.png": [0, 0, true]\n}', "line 2: the anchor of"),
    ('{\n "photo_000.png": [0, 0, 1],\n "photo_000.png": [0, 1, 1]\n}',
     "photo 'photo_000.png' has 2 anchors (lines 2, 3)"),
    ('{\n "photo_000.png": [0, 0, 1],\n}', "malformed JSON"),
    ('[[0, 0, 1]]', "expected an object"),
])
def test_bad_anchors_file(capsys, small_photos, tmp_path, text, message):
    """Each problem gives one line naming the file and, for an entry, its line; before SfM."""
    status, err = _poses(capsys, small_photos[0], tmp_path / "out", text, tmp_path)
    assert status == 2 and message in err and str(tmp_path / "anchors.json") in err
    assert len(err.splitlines()) == 1
