"""Pose-estimation speed: seconds per image for SIFT extraction, exhaustive matching and incremental
mapping (pycolmap, CPU) at a working size of 1024 px.

Usage: python benchmarks/pose_estimation.py [--repeats 3] [--synthetic-photos 12]
Photo sets: Herz-Jesu-P8 from the shared data (`$NFR_DRAKE_SHARED_DATA` or ../shared/data beside
the repository; skipped when absent) with its known intrinsics, and Drake-rendered photos of a
closet in a textured room (1024 x 768, known intrinsics). SIFT runs with first octave -1 (COLMAP's
default: the image is upsampled once) and 0. Prints a markdown table for docs/BENCHMARKS.md; each
figure is the median over the repeats. Matching is exhaustive, so its cost per image grows with
the number of images (n - 1 pairs per image).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import tempfile
from datetime import date
from pathlib import Path

import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.perception.photos import prepare_photos
from nfr_drake.perception.sfm import SfmOptions, run_sfm
from nfr_drake.perception.synthetic import SyntheticPhotoScene, orbit_poses, write_photo_folder

WORKING_SIZE = 1024
STAGES = ("extraction", "matching", "mapping")


def shared_data_dir() -> Path:
    env = os.environ.get("NFR_DRAKE_SHARED_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"


def herz_jesu(root: Path) -> tuple[Path, PinholeCamera] | None:
    """Herz-Jesu-P8's image folder and camera, or None when the shared data is absent."""
    folder = root / "real_photos" / "herz_jesu_p8"
    if not (folder / "cameras.json").is_file():
        return None
    first = next(iter(json.loads((folder / "cameras.json").read_text())["cameras"].values()))
    K = np.array(first["K"])
    return folder / "images", PinholeCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], first["width"],
                                          first["height"])


def synthetic(out: Path, n: int) -> tuple[Path, PinholeCamera]:
    """n Drake-rendered photos (1024 x 768) and their camera."""
    camera = PinholeCamera.from_fov(1024, 768, np.deg2rad(50))
    closet = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 0, 0))
    scene = SyntheticPhotoScene(closet, 0.5, camera)
    write_photo_folder(out, scene, orbit_poses(n, np.array([0.4, 0.0, 0.35])))
    return out, PinholeCamera(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height)


def measure(photos: Path, camera: PinholeCamera, first_octave: int, work: Path) -> dict[str, float]:
    """Seconds per stage of one SfM run on the photos resized to the working size."""
    images = prepare_photos(photos, work / "images", WORKING_SIZE)
    result = run_sfm(work / "images", [p.work_name for p in images], work,
                     camera.scaled(*images[0].size), SfmOptions(first_octave=first_octave),
                     progress=None)
    result.seconds["registered"] = result.reconstruction.num_reg_images()
    return result.seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--synthetic-photos", type=int, default=12)
    args = parser.parse_args()
    print(f"{date.today()}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"load average before: {os.getloadavg()[0]:.2f}")
    with tempfile.TemporaryDirectory(prefix="nfr_bench_poses_") as tmp:
        tmp = Path(tmp)
        sets = []
        real = herz_jesu(shared_data_dir())
        if real is not None:
            sets.append(("Herz-Jesu-P8 (1024 x 683)", *real))
        else:
            print(f"(Herz-Jesu-P8 not found under {shared_data_dir()}: skipped)")
        sets.append(("synthetic closet room (1024 x 768)",
                     *synthetic(tmp / "synthetic", args.synthetic_photos)))
        print("| photos | images | SIFT first octave | extraction s/img | matching s/img "
              "| mapping s/img | total s | registered |")
        print("|---|---|---|---|---|---|---|---|")
        for label, photos, camera in sets:
            n = len([p for p in photos.iterdir() if p.suffix in (".jpg", ".png")])
            for octave in (-1, 0):
                runs = [measure(photos, camera, octave, tmp / f"work_{octave}_{i}")
                        for i in range(args.repeats)]
                median = {k: statistics.median(r[k] for r in runs) for k in (*STAGES, "registered")}
                per_image = " | ".join(f"{median[k] / n:.2f}" for k in STAGES)
                total = sum(median[k] for k in STAGES)
                print(f"| {label} | {n} | {octave} | {per_image} | {total:.1f} "
                      f"| {int(median['registered'])}/{n} |", flush=True)


if __name__ == "__main__":
    main()
