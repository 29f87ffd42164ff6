"""Photo folders (listing, resizing), the EXIF focal-length prior of self-calibration, and the
cameras that self-calibration shares between photos."""

import cv2
import numpy as np
import pytest
from PIL import Image

from nfr_drake.perception import sfm
from nfr_drake.perception.photos import PhotoFolderError, prepare_photos, working_size
from nfr_drake.perception.sfm import SfmOptions, exif_focal_prior, run_sfm


def test_working_size():
    assert working_size((3072, 2048), 1024) == (1024, 683)
    assert working_size((480, 640), 1024) == (480, 640)  # never enlarged


def test_prepare_photos(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    Image.fromarray(np.zeros((400, 600, 3), np.uint8)).save(photos / "b.jpg")
    Image.fromarray(np.zeros((100, 150, 3), np.uint8)).save(photos / "a.png")
    (photos / "notes.txt").write_text("not a photo")
    prepared = prepare_photos(photos, tmp_path / "work", 300)
    assert [(p.name, p.work_name, p.original_size, p.size) for p in prepared] == [
        ("a.png", "a.png", (150, 100), (150, 100)), ("b.jpg", "b.png", (600, 400), (300, 200))]
    assert Image.open(tmp_path / "work" / "b.png").size == (300, 200)
    Image.fromarray(np.zeros((10, 10, 3), np.uint8)).save(photos / "a.jpg")
    with pytest.raises(PhotoFolderError, match="share a name"):
        prepare_photos(photos, tmp_path / "work", 300)
    (tmp_path / "empty").mkdir()
    with pytest.raises(PhotoFolderError, match="no photos"):
        prepare_photos(tmp_path / "empty", tmp_path / "w2", 300)


def test_exif_focal_prior(tmp_path):
    path = tmp_path / "phone.jpg"
    Image.fromarray(np.zeros((300, 400, 3), np.uint8)).save(path)
    assert exif_focal_prior(path, 200, 150) is None
    exif = Image.Exif()
    exif.get_ifd(0x8769)[0xA405] = 28  # FocalLengthIn35mmFilm
    Image.fromarray(np.zeros((300, 400, 3), np.uint8)).save(path, exif=exif)
    f = exif_focal_prior(path, 200, 150)
    # 28 mm on a 36 x 24 mm frame: about 0.78 to 0.81 of the longer side (COLMAP uses the diagonal).
    assert 0.7 * 200 < f < 0.9 * 200


def test_one_camera_per_image_size(small_photos, tmp_path):
    """Self-calibration gives the photos of one size one camera (COLMAP on its own gives every
    photo without EXIF data a camera, i.e. a focal length and distortion, of its own)."""
    images = prepare_photos(small_photos[0], tmp_path / "images", 320)
    sizes = {p.work_name: p.size for p in images}
    for name in list(sizes)[:2]:  # two photos taken at a lower resolution
        path = tmp_path / "images" / name
        cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), (288, 216), interpolation=cv2.INTER_AREA))
        sizes[name] = (288, 216)
    options = SfmOptions(num_threads=2)
    rec = run_sfm(tmp_path / "images", sizes, tmp_path / "shared", None, options,
                  progress=None).reconstruction
    camera_of = {image.name: image.camera_id for image in rec.images.values() if image.has_pose}
    assert len(camera_of) == 8
    by_size = {size: {camera_of[n] for n, s in sizes.items() if s == size} for size in set(sizes.values())}
    assert all(len(ids) == 1 for ids in by_size.values()) and len(rec.cameras) == 2
    rec = run_sfm(tmp_path / "images", sizes, tmp_path / "per_image", None,
                  SfmOptions(num_threads=2, camera_per_image=True),
                  progress=None).reconstruction
    assert len(rec.cameras) == 8


def test_principal_point_refined_only_when_plausible(small_photos, tmp_path, monkeypatch):
    """The shared camera's principal point leaves the image centre in the final bundle adjustment,
    unless it would move further than MAX_PRINCIPAL_POINT_SHIFT (here set to 0: any move)."""
    images = prepare_photos(small_photos[0], tmp_path / "images", 320)
    sizes = {p.work_name: p.size for p in images}

    def principal_point(work: str) -> tuple[list[str], np.ndarray]:
        said = []
        rec = run_sfm(tmp_path / "images", sizes, tmp_path / work, None, SfmOptions(num_threads=2),
                      progress=said.append).reconstruction
        (camera,) = rec.cameras.values()
        return said, np.array([camera.principal_point_x, camera.principal_point_y])

    said, refined = principal_point("refined")
    assert "refining the principal point in a final bundle adjustment" in said
    assert np.any(refined != [160, 120]) and np.all(np.abs(refined - [160, 120]) < 0.05 * 320)
    monkeypatch.setattr(sfm, "MAX_PRINCIPAL_POINT_SHIFT", 0.0)
    said, kept = principal_point("kept")
    assert np.all(kept == [160, 120]) and any("kept at the image centre" in line for line in said)
