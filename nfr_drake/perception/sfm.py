"""Structure from motion with pycolmap 4.x on the CPU: SIFT, exhaustive matching, incremental mapping.

`run_sfm` turns a folder of (resized) photos into a `pycolmap.Reconstruction` in its own
arbitrary frame R and scale. Camera poses come out as `cam_from_world` (COLMAP: X_CR, OpenCV
axes); `camera_poses` turns them into X_RC. Known intrinsics are held fixed. Without them the
photos of one size share one camera, self-calibrated with COLMAP's SIMPLE_RADIAL model
(f, cx, cy, k): its focal length and distortion during mapping, then its principal point in a
final bundle adjustment. (COLMAP on its own gives every photo without EXIF data a camera of its
own, and keeps principal points at the image centre: on Herz-Jesu-P8 that doubles the worst camera
centre error, docs/POSE_ESTIMATION.md.)
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pycolmap

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.errors import NfrDrakeError

SELF_CALIBRATION_MODEL = "SIMPLE_RADIAL"
MIN_IMAGES_FOR_PRINCIPAL_POINT = 4
"""A self-calibrated camera gets its principal point refined only when this many registered images
share it: one image cannot tell a principal-point shift from a rotation."""
MAX_PRINCIPAL_POINT_SHIFT = 0.05
"""A refined principal point farther than this fraction of the image size from the centre (real
lenses are within a few per cent) means the photos do not constrain it: the refinement is dropped."""


class ReconstructionError(NfrDrakeError):
    """Structure from motion found no model, or registered too few photos."""


@dataclass(frozen=True)
class SfmOptions:
    """Options of the structure-from-motion run."""

    max_num_features: int = 8192
    """SIFT features kept per image."""
    first_octave: int = -1
    """SIFT's first octave: -1 upsamples the image once (more features, slower), 0 does not."""
    max_ratio: float = 0.8
    """Lowe's ratio test threshold for matches."""
    min_num_matches: int = 15
    """Verified matches an image pair needs to be used by the mapper."""
    seed: int = 0
    """Random seed of RANSAC and the mapper (runs with several threads may still differ slightly)."""
    num_threads: int = -1
    """CPU threads; -1 uses all cores."""
    camera_per_image: bool = False
    """Self-calibration: a camera of its own for every photo (COLMAP's default for photos without
    EXIF data; less exact, since every photo then fits its own focal length and distortion)
    instead of one camera per image size."""
    refine_principal_point: bool = True
    """Self-calibration: refine the principal point of each shared camera in a final bundle
    adjustment (otherwise it stays at the image centre)."""
    verbose: bool = False
    """Show COLMAP's own log lines (otherwise only its warnings and errors)."""


@dataclass
class SfmResult:
    """A reconstruction and what it took.

    reconstruction: the largest model, frame R, arbitrary scale;
    num_models: models the mapper found (more than one means the photos fell into groups);
    seconds: wall time per stage ("extraction", "matching", "mapping").
    """

    reconstruction: pycolmap.Reconstruction
    num_models: int
    seconds: dict[str, float] = field(default_factory=dict)


def _reader_options(camera: PinholeCamera | None, size: tuple[int, int], focal_prior: float | None
                    ) -> pycolmap.ImageReaderOptions:
    if camera is None and focal_prior is not None:
        w, h = size
        return pycolmap.ImageReaderOptions(camera_model=SELF_CALIBRATION_MODEL,
                                           camera_params=f"{focal_prior:.17g},{w / 2},{h / 2},0")
    if camera is None:
        return pycolmap.ImageReaderOptions(camera_model=SELF_CALIBRATION_MODEL)
    model, params = camera.colmap_model()
    return pycolmap.ImageReaderOptions(camera_model=model,
                                       camera_params=",".join(f"{v:.17g}" for v in params))


def _mapping_options(known_intrinsics: bool, options: SfmOptions) -> pycolmap.IncrementalPipelineOptions:
    mapping = pycolmap.IncrementalPipelineOptions(
        min_num_matches=options.min_num_matches, num_threads=options.num_threads,
        random_seed=options.seed, extract_colors=True)
    if known_intrinsics:
        mapping.ba_refine_focal_length = False
        mapping.ba_refine_principal_point = False
        mapping.ba_refine_extra_params = False
        mapping.mapper.abs_pose_refine_focal_length = False
        mapping.mapper.abs_pose_refine_extra_params = False
    return mapping


def run_sfm(image_dir: Path, image_sizes: dict[str, tuple[int, int]], work_dir: Path,
            camera: PinholeCamera | None, options: SfmOptions | None = None,
            progress: Callable[[str], None] | None = print,
            focal_priors: dict[tuple[int, int], float] | None = None) -> SfmResult:
    """Reconstruct cameras and sparse points from the images in `image_dir`.

    Args:
        image_sizes: image file name -> (width, height) in pixels, of the images to use.
        camera: intrinsics of every image (all must have its size), held fixed; None to
            self-calibrate one SIMPLE_RADIAL camera per image size (per image with
            `options.camera_per_image`).
        focal_priors: (width, height) -> focal length (px) to start self-calibrating the images
            of that size from (e.g. from the photos' EXIF); default COLMAP's 1.2 x the longer side.
        work_dir: receives `database.db` and the mapper's `sparse/` models.
        progress: called with one line per stage; None for silence.
    Raises ReconstructionError when no model is found.
    """
    options = options or SfmOptions()
    previous_level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 0 if options.verbose else 1
    try:
        return _run_sfm(image_dir, image_sizes, work_dir, camera, options,
                        progress or (lambda _: None), focal_priors or {})
    finally:
        pycolmap.logging.minloglevel = previous_level


def _extract(database: Path, image_dir: Path, image_sizes: dict[str, tuple[int, int]],
             camera: PinholeCamera | None, options: SfmOptions,
             focal_priors: dict[tuple[int, int], float]) -> None:
    """SIFT features of every image into `database`, with one camera per image size (a fresh
    camera for each call of COLMAP's extractor in its single-camera mode) or per image."""
    extraction = pycolmap.FeatureExtractionOptions(num_threads=options.num_threads)
    extraction.sift.max_num_features = options.max_num_features
    extraction.sift.first_octave = options.first_octave
    per_image = camera is None and options.camera_per_image
    for size in sorted(set(image_sizes.values())):
        pycolmap.extract_features(
            database, image_dir, image_names=[n for n, s in image_sizes.items() if s == size],
            camera_mode=pycolmap.CameraMode.PER_IMAGE if per_image else pycolmap.CameraMode.SINGLE,
            reader_options=_reader_options(camera, size, focal_priors.get(size)),
            extraction_options=extraction, device=pycolmap.Device.cpu)


def _refine_principal_points(reconstruction: pycolmap.Reconstruction, options: SfmOptions,
                             say: Callable[[str], None]) -> pycolmap.Reconstruction:
    """A global bundle adjustment that also refines the principal point of every camera that at
    least MIN_IMAGES_FOR_PRINCIPAL_POINT registered images share; the input when no camera
    qualifies or a principal point leaves MAX_PRINCIPAL_POINT_SHIFT of the image centre."""
    users: dict[int, int] = {}
    for image in reconstruction.images.values():
        if image.has_pose:
            users[image.camera_id] = users.get(image.camera_id, 0) + 1
    shared = {c for c, n in users.items() if n >= MIN_IMAGES_FOR_PRINCIPAL_POINT}
    if not shared:
        say(f"principal point kept at the image centre: no camera is shared by "
            f"{MIN_IMAGES_FOR_PRINCIPAL_POINT} registered photos")
        return reconstruction
    say("refining the principal point in a final bundle adjustment")
    refined = pycolmap.Reconstruction(reconstruction)
    ba = pycolmap.BundleAdjustmentOptions(refine_principal_point=True, print_summary=False)
    ba.ceres.solver_options.num_threads = options.num_threads
    config = pycolmap.BundleAdjustmentConfig()
    for image in refined.images.values():
        if image.has_pose:
            config.add_image(image.image_id)
    for camera_id in users.keys() - shared:
        config.set_constant_cam_intrinsics(camera_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
    pycolmap.create_default_bundle_adjuster(ba, config, refined).solve()
    for camera_id in shared:
        camera = refined.cameras[camera_id]
        shift = np.abs([camera.principal_point_x - camera.width / 2,
                        camera.principal_point_y - camera.height / 2])
        if np.any(shift > MAX_PRINCIPAL_POINT_SHIFT * np.array([camera.width, camera.height])):
            say(f"principal point kept at the image centre: refined it moved ({shift[0]:.0f}, "
                f"{shift[1]:.0f}) px, more than {MAX_PRINCIPAL_POINT_SHIFT:.0%} of the image size")
            return reconstruction
    return refined


def _run_sfm(image_dir: Path, image_sizes: dict[str, tuple[int, int]], work_dir: Path,
             camera: PinholeCamera | None, options: SfmOptions, say: Callable[[str], None],
             focal_priors: dict[tuple[int, int], float]) -> SfmResult:
    work_dir.mkdir(parents=True, exist_ok=True)
    database = work_dir / "database.db"
    database.unlink(missing_ok=True)
    pycolmap.set_random_seed(options.seed)
    seconds = {}

    n = len(image_sizes)
    say(f"extracting SIFT features from {n} images (CPU)")
    start = time.perf_counter()
    _extract(database, image_dir, image_sizes, camera, options, focal_priors)
    seconds["extraction"] = time.perf_counter() - start

    say(f"matching all {n * (n - 1) // 2} image pairs (exhaustive, CPU)")
    start = time.perf_counter()
    matching = pycolmap.FeatureMatchingOptions(num_threads=options.num_threads)
    matching.sift.max_ratio = options.max_ratio
    pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
    seconds["matching"] = time.perf_counter() - start

    say("incremental mapping")
    start = time.perf_counter()
    sparse = work_dir / "sparse"
    sparse.mkdir(exist_ok=True)
    models = pycolmap.incremental_mapping(database, image_dir, sparse,
                                          _mapping_options(camera is not None, options))
    if not models:
        raise ReconstructionError(
            f"no model found from {n} photos: too few matching features between them (photos need "
            "overlap, texture and a camera that moves between shots)")
    best = max(models.values(), key=lambda r: r.num_reg_images())
    if camera is None and options.refine_principal_point:
        best = _refine_principal_points(best, options, say)
    seconds["mapping"] = time.perf_counter() - start
    say(f"registered {best.num_reg_images()} of {n} images, {best.num_points3D()} points, "
        f"mean reprojection error {best.compute_mean_reprojection_error():.3f} px")
    return SfmResult(best, len(models), seconds)


def exif_focal_prior(photo: Path, width: int, height: int) -> float | None:
    """The focal length (px) of a photo's EXIF data (focal length with the sensor size, or the
    35 mm equivalent), scaled to width x height, for `run_sfm`'s focal_priors; None without EXIF."""
    exif = pycolmap.infer_camera_from_image(photo)
    if not exif.has_prior_focal_length:
        return None
    return exif.mean_focal_length() * max(width, height) / max(exif.width, exif.height)


def camera_poses(reconstruction: pycolmap.Reconstruction) -> dict[str, np.ndarray]:
    """Image name -> X_RC (4x4, OpenCV axes) of each registered image, frame R of the model."""
    poses = {}
    for image in reconstruction.images.values():
        if not image.has_pose:
            continue
        X_CR = np.eye(4)
        X_CR[:3] = image.cam_from_world().matrix()
        poses[image.name] = np.linalg.inv(X_CR)
    return poses


def image_cameras(reconstruction: pycolmap.Reconstruction) -> dict[str, PinholeCamera]:
    """Image name -> the (possibly self-calibrated) camera of each registered image."""
    return {image.name: PinholeCamera.from_colmap(reconstruction.cameras[image.camera_id])
            for image in reconstruction.images.values() if image.has_pose}
