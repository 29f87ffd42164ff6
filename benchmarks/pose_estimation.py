"""Pose estimation: accuracy against plain pycolmap on real photos, and speed per stage.

Usage: python benchmarks/pose_estimation.py [--threads 2]
       python benchmarks/pose_estimation.py --speed [--repeats 3] [--synthetic-photos 12]

Accuracy (default): Herz-Jesu-P8 from the shared data (`$NFR_DRAKE_SHARED_DATA` or ../shared/data
beside the repository), self-calibrated, anchors = the true camera centres. Side by side in one
run: plain pycolmap (`extract_features`, `match_exhaustive`, `incremental_mapping` with their
default options, one SIMPLE_RADIAL camera for all photos, then `align_reconstruction_to_locations`
to the anchors) and `estimate_poses` (what `nfr-drake poses --anchors` runs) with its defaults and
with one option changed at a time (the first of those is the old default: a camera per photo, the
principal point at the image centre); then plain pycolmap with one option changed (camera per
photo, principal point refined during mapping, camera model); then the principal-point refinement
on the Drake-rendered room of the tests (principal point exactly at the centre) and on four-photo
subsets of Herz-Jesu-P8. Camera centre errors (mm) and rotation errors (deg) against the ground
truth, mean reprojection error, wall time. Prints markdown tables for docs/POSE_ESTIMATION.md.

Speed (--speed): seconds per image for SIFT extraction, exhaustive matching and incremental mapping
at a working size of 1024 px with known intrinsics, on Herz-Jesu-P8 and on Drake-rendered photos of
a closet in a textured room (1024 x 768); SIFT first octave -1 (COLMAP's default: the image is
upsampled once) and 0; each figure the median over the repeats (docs/BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import tempfile
import time
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pycolmap

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import read_capture_set
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.alignment import align_to_centres, rotation_angle
from nfr_drake.perception.charuco import CharucoBoardSpec
from nfr_drake.perception.photos import prepare_photos
from nfr_drake.perception.poses import Alignment, estimate_poses
from nfr_drake.perception.sfm import SfmOptions, camera_poses, run_sfm
from nfr_drake.perception.synthetic import SyntheticPhotoScene, orbit_poses, write_photo_folder

WORKING_SIZE = 1024
STAGES = ("extraction", "matching", "mapping")


def shared_data_dir() -> Path:
    env = os.environ.get("NFR_DRAKE_SHARED_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"


def herz_jesu(root: Path) -> tuple[Path, dict] | None:
    """Herz-Jesu-P8's image folder and ground-truth cameras by photo name, or None when absent."""
    folder = root / "real_photos" / "herz_jesu_p8"
    if not (folder / "cameras.json").is_file():
        return None
    return folder / "images", json.loads((folder / "cameras.json").read_text())["cameras"]


def truth_camera(truth: dict) -> PinholeCamera:
    """The true camera of Herz-Jesu-P8 (all photos share it)."""
    first = next(iter(truth.values()))
    K = np.array(first["K"])
    return PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], first["width"], first["height"])


# Accuracy -------------------------------------------------------------------------------------
def true_poses(truth: dict) -> dict[str, np.ndarray]:
    """Herz-Jesu-P8's camera poses X_WC (4x4, OpenCV axes, metres) by photo name."""
    poses = {}
    for name, camera in truth.items():
        X = np.eye(4)
        X[:3, :3], X[:3, 3] = camera["R_world_from_cam"], camera["center_world"]
        poses[name] = X
    return poses


def pose_errors(X_est: dict[str, np.ndarray], X_true: dict[str, np.ndarray]) -> dict[str, float]:
    """Mean and max camera-centre error (mm) and mean rotation error (deg) of the estimated poses
    (4x4, OpenCV axes, metres, by photo name) against the true ones, in the same frame."""
    centre_mm = [1000 * np.linalg.norm(X[:3, 3] - X_true[n][:3, 3]) for n, X in X_est.items()]
    rotation_deg = [np.degrees(rotation_angle(X_true[n][:3, :3].T @ X[:3, :3])) for n, X in X_est.items()]
    return {"registered": f"{len(X_est)}/{len(X_true)}", "mean_mm": float(np.mean(centre_mm)),
            "max_mm": float(np.max(centre_mm)), "rotation_deg": float(np.mean(rotation_deg))}


def plain_pycolmap(images: Path, X_true: dict[str, np.ndarray], work: Path, threads: int,
                   camera_mode=pycolmap.CameraMode.SINGLE, camera_model: str = "SIMPLE_RADIAL",
                   refine_principal_point: bool = False) -> dict[str, float]:
    """pycolmap with its default options (but the ones given) on the photos as they are, aligned by
    `align_reconstruction_to_locations` to the true camera centres; also the errors of the same
    reconstruction aligned by the project's Umeyama fit (`align_to_centres`)."""
    start = time.perf_counter()
    work.mkdir(parents=True)
    database = work / "database.db"
    pycolmap.extract_features(database, images, camera_mode=camera_mode,
                              reader_options=pycolmap.ImageReaderOptions(camera_model=camera_model),
                              extraction_options=pycolmap.FeatureExtractionOptions(num_threads=threads),
                              device=pycolmap.Device.cpu)
    pycolmap.match_exhaustive(database, matching_options=pycolmap.FeatureMatchingOptions(
        num_threads=threads), device=pycolmap.Device.cpu)
    models = pycolmap.incremental_mapping(database, images, work, pycolmap.IncrementalPipelineOptions(
        num_threads=threads, ba_refine_principal_point=refine_principal_point))
    rec = max(models.values(), key=lambda r: r.num_reg_images())
    seconds = time.perf_counter() - start
    X_RCs = camera_poses(rec)
    umeyama = align_to_centres(X_RCs, {n: X[:3, 3] for n, X in X_true.items()}, max_residual=np.inf)
    names = sorted(X_RCs)
    sim = pycolmap.align_reconstruction_to_locations(
        rec, names, np.array([X_true[n][:3, 3] for n in names]), 3, pycolmap.RANSACOptions())
    rec.transform(sim)
    umeyama_errors = pose_errors({n: umeyama.similarity.apply_pose(X) for n, X in X_RCs.items()}, X_true)
    return {**pose_errors(camera_poses(rec), X_true), "umeyama_mean_mm": umeyama_errors["mean_mm"],
            "umeyama_max_mm": umeyama_errors["max_mm"],
            "reprojection_px": rec.compute_mean_reprojection_error(), "seconds": seconds}


def project(images: Path, X_true: dict[str, np.ndarray], out: Path, options: dict,
            alignment: Alignment | None = None) -> dict[str, float]:
    """`estimate_poses` with `options` as keyword arguments; aligned by the true camera centres as
    anchors unless `alignment` is given."""
    alignment = alignment or Alignment(anchors={n: X[:3, 3] for n, X in X_true.items()})
    report = estimate_poses(images, out, alignment, progress=lambda _: None, **options)
    X_est = {frame.source_photo: frame.X_OC for frame in read_capture_set(out).frames}
    return {**pose_errors(X_est, X_true), "reprojection_px": report.mean_reprojection_error_px,
            "seconds": report.seconds["total"]}


TABLE_HEAD = ("| method | registered | centre error mean / max (mm) | rotation error mean (deg) "
              "| reprojection (px) | time (s) |\n|---|---|---|---|---|---|")


def row(label: str, r: dict[str, float]) -> None:
    print(f"| {label} | {r['registered']} | {r['mean_mm']:.1f} / {r['max_mm']:.1f} "
          f"| {r['rotation_deg']:.2f} | {r['reprojection_px']:.3f} | {r['seconds']:.0f} |", flush=True)


def subset(images: Path, names: list[str], out: Path) -> Path:
    """A folder with copies of the photos `names` of `images`."""
    out.mkdir(parents=True)
    for name in names:
        shutil.copy(images / name, out / name)
    return out


def synthetic_charuco(out: Path) -> tuple[Path, dict[str, np.ndarray], Alignment, np.ndarray]:
    """The Drake-rendered room of tests/perception/test_synthetic_end_to_end.py: 8 photos
    (1024 x 768, principal point at the centre, distorting lens), true X_OC by photo name, the
    ChArUco alignment and X_WO."""
    camera = PinholeCamera.from_fov(1024, 768, np.deg2rad(50))
    closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
    folder = write_photo_folder(out, SyntheticPhotoScene(closet, 0.5, camera),
                                orbit_poses(8, np.array([0.4, 0.0, 0.35])), (-0.12, 0.03, 5e-4, -3e-4))
    truth = json.loads((folder / "truth.json").read_text())
    b = truth["board"]
    board = CharucoBoardSpec(tuple(b["squares"]), b["square_m"], b["marker_m"], b["dictionary"])
    return (folder, {n: np.array(X) for n, X in truth["X_OC"].items()}, Alignment(charuco=board),
            np.linalg.inv(np.array(truth["X_OB"])))


def accuracy(threads: int, tmp: Path) -> None:
    found = herz_jesu(shared_data_dir())
    if found is None:
        print(f"Herz-Jesu-P8 not found under {shared_data_dir()} (set NFR_DRAKE_SHARED_DATA)")
        return
    images, truth = found
    X_true = true_poses(truth)
    sfm = SfmOptions(num_threads=threads)
    fixed_pp = replace(sfm, refine_principal_point=False)
    variants = [
        ("`nfr-drake poses` (defaults)", {}),
        ("old default: a camera per photo, principal point fixed (`--sfm.camera-per-image "
         "--sfm.no-refine-principal-point`)",
         {"sfm_options": replace(fixed_pp, camera_per_image=True)}),
        ("one camera, principal point fixed (`--sfm.no-refine-principal-point`)", {"sfm_options": fixed_pp}),
        ("a camera per photo, principal point refined (`--sfm.camera-per-image`)",
         {"sfm_options": replace(sfm, camera_per_image=True)}),
        ("SIFT first octave 0 (`--sfm.first-octave 0`)", {"sfm_options": replace(sfm, first_octave=0)}),
        ("photos at 768 px (`--max-size 768`)", {"max_size": 768}),
        ("known intrinsics (`--intrinsics`, reference)", {"camera": truth_camera(truth)}),
    ]
    pycolmap.logging.minloglevel = 1  # COLMAP's warnings and errors only, as in `run_sfm`
    print("Herz-Jesu-P8, 8 photos (1024 x 683), self-calibrated unless said, anchors = true camera "
          "centres; errors against the ground truth after each method's alignment\n")
    print(TABLE_HEAD)
    plain = plain_pycolmap(images, X_true, tmp / "plain", threads)
    row("plain pycolmap: default options, SIMPLE_RADIAL, one camera, "
        "`align_reconstruction_to_locations`", plain)
    for i, (label, options) in enumerate(variants):
        row(label, project(images, X_true, tmp / f"project_{i}", {"sfm_options": sfm, **options}))
    print(f"\nThe plain pycolmap reconstruction aligned by the project's Umeyama fit instead: "
          f"{plain['umeyama_mean_mm']:.1f} / {plain['umeyama_max_mm']:.1f} mm.\n")

    print("Plain pycolmap with one option changed (Herz-Jesu-P8 as above)\n")
    print(TABLE_HEAD)
    for i, (label, options) in enumerate([
            ("a camera per photo (`CameraMode.PER_IMAGE`, COLMAP's choice for photos without EXIF)",
             {"camera_mode": pycolmap.CameraMode.PER_IMAGE}),
            ("principal point refined during mapping", {"refine_principal_point": True}),
            ("a camera per photo, principal point refined during mapping",
             {"camera_mode": pycolmap.CameraMode.PER_IMAGE, "refine_principal_point": True}),
            ("camera model RADIAL", {"camera_model": "RADIAL"}),
            ("camera model OPENCV", {"camera_model": "OPENCV"}),
            ("camera model SIMPLE_PINHOLE", {"camera_model": "SIMPLE_PINHOLE"})]):
        row(label, plain_pycolmap(images, X_true, tmp / f"plain_{i}", threads, **options))

    print("\nThe principal point refined (default) or fixed (`--sfm.no-refine-principal-point`), "
          "elsewhere\n")
    print(TABLE_HEAD)
    folder, X_synthetic, board, X_WO = synthetic_charuco(tmp / "synthetic")
    for label, options in (("refined", {"sfm_options": sfm}), ("fixed", {"sfm_options": fixed_pp})):
        row(f"Drake-rendered room, 8 photos, principal point at the centre, `--charuco`: {label}",
            project(folder, X_synthetic, tmp / f"synthetic_{label}", {**options, "X_WO": X_WO}, board))
    for names in (["0000.jpg", "0001.jpg", "0002.jpg", "0003.jpg"],
                  ["0002.jpg", "0003.jpg", "0004.jpg", "0005.jpg"]):
        photos = subset(images, names, tmp / f"herz_jesu_{names[0]}")
        for label, options in (("refined", {"sfm_options": sfm}), ("fixed", {"sfm_options": fixed_pp})):
            row(f"Herz-Jesu-P8 photos {names[0]} to {names[-1]}: {label}",
                project(photos, {n: X_true[n] for n in names}, tmp / f"{photos.name}_{label}", options))


# Speed ----------------------------------------------------------------------------------------
def synthetic(out: Path, n: int) -> tuple[Path, PinholeCamera]:
    """n Drake-rendered photos (1024 x 768) and their camera."""
    camera = PinholeCamera.from_fov(1024, 768, np.deg2rad(50))
    closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
    scene = SyntheticPhotoScene(closet, 0.5, camera)
    write_photo_folder(out, scene, orbit_poses(n, np.array([0.4, 0.0, 0.35])))
    return out, camera


def measure(photos: Path, camera: PinholeCamera, first_octave: int, work: Path,
            threads: int) -> dict[str, float]:
    """Seconds per stage of one SfM run on the photos resized to the working size."""
    images = prepare_photos(photos, work / "images", WORKING_SIZE)
    result = run_sfm(work / "images", {p.work_name: p.size for p in images}, work,
                     camera.scaled(*images[0].size),
                     SfmOptions(first_octave=first_octave, num_threads=threads), progress=None)
    result.seconds["registered"] = result.reconstruction.num_reg_images()
    return result.seconds


def speed(repeats: int, synthetic_photos: int, threads: int, tmp: Path) -> None:
    sets = []
    real = herz_jesu(shared_data_dir())
    if real is not None:
        sets.append(("Herz-Jesu-P8 (1024 x 683)", real[0], truth_camera(real[1])))
    else:
        print(f"(Herz-Jesu-P8 not found under {shared_data_dir()}: skipped)")
    sets.append(("synthetic closet room (1024 x 768)", *synthetic(tmp / "synthetic", synthetic_photos)))
    print("| photos | images | SIFT first octave | extraction s/img | matching s/img "
          "| mapping s/img | total s | registered |")
    print("|---|---|---|---|---|---|---|---|")
    for label, photos, camera in sets:
        n = len([p for p in photos.iterdir() if p.suffix in (".jpg", ".png")])
        for octave in (-1, 0):
            runs = [measure(photos, camera, octave, tmp / f"work_{label[:5]}_{octave}_{i}", threads)
                    for i in range(repeats)]
            median = {k: statistics.median(r[k] for r in runs) for k in (*STAGES, "registered")}
            per_image = " | ".join(f"{median[k] / n:.2f}" for k in STAGES)
            total = sum(median[k] for k in STAGES)
            print(f"| {label} | {n} | {octave} | {per_image} | {total:.1f} "
                  f"| {int(median['registered'])}/{n} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", action="store_true", help="time the SfM stages instead")
    parser.add_argument("--repeats", type=int, default=3, help="--speed: runs per configuration")
    parser.add_argument("--synthetic-photos", type=int, default=12, help="--speed: rendered photos")
    parser.add_argument("--threads", type=int, default=2, help="CPU threads of COLMAP")
    args = parser.parse_args()
    print(f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC, {platform.machine()}, "
          f"{os.cpu_count()} CPUs, no GPU used, pycolmap {pycolmap.__version__}, "
          f"{args.threads} COLMAP threads, load average before: {os.getloadavg()[0]:.2f}\n")
    with tempfile.TemporaryDirectory(prefix="nfr_bench_poses_") as tmp:
        if args.speed:
            speed(args.repeats, args.synthetic_photos, args.threads, Path(tmp))
        else:
            accuracy(args.threads, Path(tmp))


if __name__ == "__main__":
    main()
