"""`nfr-drake poses`: a folder of photos -> a capture set with metric camera poses in frame O.

Steps: resize the photos to the working size; structure from motion (`sfm`); a similarity into
metres from a ChArUco board in the photos or from known camera centres (`alignment`); the world
frame W is the board's frame B, the floor frame under a board lying on the floor (z up, the floor
at z = 0; checked against the floor the sparse points show, `floor`), or the anchors' frame; the
object's pose X_WO takes W to O; undistorted images and poses X_OC are written as a capture set
(docs/DATASET_FORMAT.md) with `report.json` (`report`) and the sparse points in O
(`points3D.ply`, metres).
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import cv2
import numpy as np
import tyro

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import write_capture_set
from nfr_drake.errors import ConfigError
from nfr_drake.perception.alignment import (
    MAX_ANCHOR_RESIDUAL,
    AlignmentError,
    AlignmentResult,
    Similarity,
    align_to_camera_poses,
    align_to_centres,
    check_not_collinear,
    parse_object_pose,
    read_anchors,
)
from nfr_drake.perception.charuco import (
    BoardNotFoundError,
    CharucoBoardSpec,
    CharucoPoseEstimator,
    floor_frame_in_board,
)
from nfr_drake.perception.floor import FloorPlane, floor_plane
from nfr_drake.perception.photos import WorkingPhoto, prepare_photos
from nfr_drake.perception.report import PoseReport
from nfr_drake.perception.sfm import (
    ReconstructionError,
    SfmOptions,
    camera_poses,
    exif_focal_prior,
    image_cameras,
    run_sfm,
)

REPORT_FILE = "report.json"
POINTS_FILE = "points3D.ply"
_ASPECT_TOLERANCE = 0.01
DEFAULT_BOARD = CharucoBoardSpec()
DEFAULT_SFM = SfmOptions()
WorldFrame = Literal["board", "floor"]
"""W with a board: its own frame B, or the floor frame F under it (`charuco.floor_frame_in_board`)."""


class FloorError(AlignmentError):
    """The board does not lie on the floor that the photos show (`--world floor`)."""


@dataclass(frozen=True)
class Alignment:
    """How the reconstruction is made metric: exactly one of a board or anchors (or neither, with
    `allow_unaligned`)."""

    charuco: CharucoBoardSpec | None = None
    anchors: dict[str, np.ndarray] | None = None
    allow_unaligned: bool = False
    max_anchor_residual: float = MAX_ANCHOR_RESIDUAL
    """Refuse anchors whose RMS residual after alignment exceeds this fraction of their spread."""
    world: WorldFrame = "board"
    """With the board: W is the board frame B, or the floor frame under it ("floor", z up)."""
    floor_check: bool = True
    """With `world` "floor": refuse a board that does not lie on the floor the sparse points show."""


def _progress(message: str) -> None:
    print(f"[poses] {message}", file=sys.stderr, flush=True)


def _working_camera(camera: PinholeCamera, photos: list[WorkingPhoto]) -> PinholeCamera:
    """The known camera scaled to the working size; all photos must share its size (or aspect)."""
    sizes = sorted({p.original_size for p in photos})
    if len(sizes) > 1:
        raise ConfigError(f"known intrinsics need photos of one size; found {sizes}")
    (w, h), = sizes
    if abs(w / h - camera.width / camera.height) > _ASPECT_TOLERANCE * w / h:
        raise ConfigError(f"the intrinsics are for {camera.width}x{camera.height} images, the "
                          f"photos are {w}x{h} (another aspect ratio; rotated photos?)")
    return camera.scaled(*photos[0].size)


def _board_message(estimator: CharucoPoseEstimator, found: int, where: str) -> str:
    spec = estimator.spec
    return (f"the ChArUco board ({spec.squares[0]}x{spec.squares[1]} squares, {spec.dictionary}) "
            f"was found in {found} {where}; metric alignment needs it in at least 2. Check the "
            "board options (--board.squares, --board.dictionary, --board.legacy-pattern)")


def _photos_with_board(estimator: CharucoPoseEstimator, image_dir: Path,
                       photos: list[WorkingPhoto]) -> list[str]:
    """Names of the photos that show enough ChArUco corners for a pose; fails early with fewer
    than two (before the costly reconstruction)."""
    names = [p.name for p in photos
             if len(estimator.detect(cv2.imread(str(image_dir / p.work_name)))[0])
             >= estimator.min_corners]
    if len(names) < 2:
        raise BoardNotFoundError(_board_message(estimator, len(names), f"of {len(photos)} photos"))
    return names


def _board_poses(estimator: CharucoPoseEstimator, image_dir: Path, work_names: dict[str, str],
                 cameras: dict[str, PinholeCamera]) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
    """X_BC and detection details for each registered photo that shows the board."""
    X_BCs, details = {}, {}
    for name, work_name in work_names.items():
        pose = estimator.estimate(cv2.imread(str(image_dir / work_name)), cameras[name])
        if pose is not None:
            X_BCs[name] = pose.X_BC
            details[name] = {"corners": pose.corners,
                             "reprojection_error_px": pose.reprojection_error_px}
    return X_BCs, details


def _ply_text(points: np.ndarray, colors: np.ndarray) -> str:
    """ASCII PLY of points (N, 3) in metres with uint8 colours (N, 3)."""
    header = ["ply", "format ascii 1.0", f"element vertex {len(points)}",
              "property float x", "property float y", "property float z",
              "property uchar red", "property uchar green", "property uchar blue", "end_header"]
    rows = [f"{x:.6f} {y:.6f} {z:.6f} {r} {g} {b}"
            for (x, y, z), (r, g, b) in zip(points, colors, strict=True)]
    return "\n".join(header + rows) + "\n"


def _check_anchor_names(anchors: dict[str, np.ndarray], photos_dir: Path,
                        photos: list[WorkingPhoto]) -> None:
    """Every anchor must name a photo of the folder (a typo or another folder's anchors would
    otherwise silently leave the alignment fewer anchors than the file holds)."""
    missing = sorted(set(anchors) - {p.name for p in photos})
    if missing:
        raise AlignmentError(
            f"{len(missing)} of {len(anchors)} anchors name photos that are not in {photos_dir}: "
            f"{', '.join(missing[:10])}{' ...' if len(missing) > 10 else ''} (anchors are keyed by "
            f"photo file name, e.g. {photos[0].name!r}); remove them or fix the names")


def _focal_priors(photos_dir: Path, photos: list[WorkingPhoto]) -> dict[tuple[int, int], float]:
    """Working size -> EXIF focal length (px at that size) of the first photo of that size that
    has one."""
    priors = {}
    for photo in photos:
        if photo.size not in priors:
            focal = exif_focal_prior(photos_dir / photo.name, *photo.size)
            if focal is not None:
                priors[photo.size] = focal
    return priors


def _check_request(alignment: Alignment, out: Path, max_size: int) -> None:
    if alignment.charuco is not None and alignment.anchors is not None:
        raise ConfigError("align with either a ChArUco board or anchors, not both")
    if alignment.world == "floor" and alignment.charuco is None:
        raise ConfigError("--world floor needs --charuco: the floor frame lies under a ChArUco board "
                          "lying face up on the floor")
    if alignment.charuco is None and alignment.anchors is None and not alignment.allow_unaligned:
        raise ConfigError("no metric alignment: pass --charuco (board in the photos) or --anchors "
                          "centres.json (known camera centres), or --allow-unaligned for poses in "
                          "SfM's arbitrary frame and scale")
    if out.exists():
        raise ConfigError(f"{out} already exists; choose another --out")
    if max_size < 64:
        raise ConfigError(f"max_size {max_size} px is too small for feature matching")
    if not alignment.max_anchor_residual > 0:
        raise ConfigError(f"max_anchor_residual {alignment.max_anchor_residual} must be positive "
                          "(a fraction of the anchors' spread, e.g. 0.05)")


def _align(alignment: Alignment, estimator: CharucoPoseEstimator | None, image_dir: Path,
           work_names: dict[str, str], X_RCs: dict[str, np.ndarray],
           cameras: dict[str, PinholeCamera]) -> tuple[AlignmentResult | None, dict[str, dict]]:
    """The similarity R -> W from the board (photos in `work_names`) or the anchors, and the
    board detections per photo; (None, {}) when unaligned."""
    if estimator is not None:
        X_BCs, details = _board_poses(estimator, image_dir, work_names, cameras)
        if len(X_BCs) < 2:
            raise BoardNotFoundError(_board_message(estimator, len(X_BCs), "registered photo(s)"))
        return align_to_camera_poses(X_RCs, X_BCs, "charuco"), details
    if alignment.anchors is not None:
        return align_to_centres(X_RCs, alignment.anchors, alignment.max_anchor_residual), {}
    return None, {}


def _world_in_alignment_frame(alignment: Alignment) -> np.ndarray:
    """X_AW (4x4): the world frame W in the frame A that the similarity maps into (B, or the
    anchors' frame)."""
    if alignment.world == "floor":
        return floor_frame_in_board(alignment.charuco.thickness_m)
    return np.eye(4)


def _check_floor(p_W: np.ndarray, alignment: Alignment, progress) -> FloorPlane | None:
    """The floor plane of the sparse points p_W (N, 3) in the floor frame W; FloorError when it
    contradicts the board lying on it (unless the check is off). None unless `world` is floor."""
    if alignment.world != "floor":
        return None
    plane = floor_plane(p_W)
    if not plane.found:
        progress(f"floor check: no floor plane in the sparse points ({plane.support} of {plane.points} "
                 "points on the best nearly horizontal plane); the board is taken to lie on the floor")
    elif alignment.floor_check and plane.problem():
        raise FloorError(plane.problem())
    else:
        progress(f"floor check: {plane.support} sparse points on a floor tilted {plane.tilt_deg:.2f} deg, "
                 f"{100 * plane.height_m:+.1f} cm from the board's floor")
    return plane


def _undistorted_images(image_dir: Path, work_names: list[str], cameras: list[PinholeCamera]
                        ) -> tuple[list[np.ndarray], list[PinholeCamera] | PinholeCamera]:
    """Undistorted RGB images (H, W, 3) and their pinhole camera(s): one if all are equal."""
    images, pinholes = [], []
    for work_name, camera in zip(work_names, cameras, strict=True):
        undistorted, pinhole = camera.undistort(cv2.imread(str(image_dir / work_name)))
        images.append(cv2.cvtColor(undistorted, cv2.COLOR_BGR2RGB))
        pinholes.append(pinhole)
    return images, pinholes[0] if all(c == pinholes[0] for c in pinholes) else pinholes


def estimate_poses(photos_dir: Path, out: Path, alignment: Alignment,
                   camera: PinholeCamera | None = None, X_WO: np.ndarray | None = None,
                   max_size: int = 1024, min_registered: int = 3,
                   sfm_options: SfmOptions = DEFAULT_SFM, work_dir: Path | None = None,
                   progress=_progress) -> PoseReport:
    """Estimate metric camera poses of the photos in `photos_dir` and write the capture set `out`.

    Args:
        alignment: the board or the anchors (camera centres in W, metres, by photo name).
        camera: intrinsics of the photos at their original size, held fixed; None to
            self-calibrate (SIMPLE_RADIAL, started from the EXIF focal length when there is one).
        X_WO: pose of the object frame O in W (4x4; W per `alignment.world`); None means O = W.
        max_size: the photos' longer side for SfM and in the capture set, pixels.
        min_registered: fewer registered photos is an error.
        work_dir: keeps the resized photos, COLMAP database and models; default a temporary folder.
        progress: called with one line per step.
    Returns the report (also written to `out/report.json`). Raises NfrDrakeError subclasses.
    """
    _check_request(alignment, out, max_size)
    estimator = CharucoPoseEstimator(alignment.charuco) if alignment.charuco else None
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="nfr_poses_") as tmp:
        work = Path(work_dir) if work_dir is not None else Path(tmp)
        image_dir = work / "images"
        progress(f"resizing photos from {photos_dir} to at most {max_size} px")
        photos = prepare_photos(photos_dir, image_dir, max_size)
        work_name = {p.name: p.work_name for p in photos}
        # Cheap checks before the costly reconstruction.
        with_board = _photos_with_board(estimator, image_dir, photos) if estimator else []
        if alignment.anchors is not None:
            _check_anchor_names(alignment.anchors, photos_dir, photos)
            names = sorted(alignment.anchors)
            check_not_collinear(np.array([alignment.anchors[n] for n in names]), names)

        work_camera = _working_camera(camera, photos) if camera else None
        focal_priors = _focal_priors(photos_dir, photos) if camera is None else {}
        sfm = run_sfm(image_dir, {p.work_name: p.size for p in photos}, work, work_camera,
                      sfm_options, progress, focal_priors)
        rec = sfm.reconstruction
        photo_name = {p.work_name: p.name for p in photos}
        X_RCs = {photo_name[n]: X for n, X in camera_poses(rec).items()}
        cameras = {photo_name[n]: c for n, c in image_cameras(rec).items()}
        registered = sorted(X_RCs)
        unregistered = [p.name for p in photos if p.name not in X_RCs]
        if len(registered) < min_registered:
            raise ReconstructionError(
                f"only {len(registered)} of {len(photos)} photos registered (need {min_registered}); "
                f"not registered: {', '.join(unregistered)}")

        if estimator is not None:
            progress("estimating the ChArUco board's pose in the registered photos")
        aligned, board_details = _align(
            alignment, estimator, image_dir,
            {n: work_name[n] for n in registered if n in with_board}, X_RCs, cameras)
        S = aligned.similarity if aligned else Similarity.identity()
        X_WA = np.linalg.inv(_world_in_alignment_frame(alignment))
        points = list(rec.points3D.values())
        p_A = S.apply(np.array([p.xyz for p in points]).reshape(-1, 3))
        floor = _check_floor(p_A @ X_WA[:3, :3].T + X_WA[:3, 3], alignment, progress)
        X_OA = (np.linalg.inv(X_WO) if X_WO is not None else np.eye(4)) @ X_WA
        X_OCs = [X_OA @ S.apply_pose(X_RCs[n]) for n in registered]
        p_O = p_A @ X_OA[:3, :3].T + X_OA[:3, 3]
        colors = np.array([p.color for p in points], dtype=np.uint8).reshape(-1, 3)

        progress(f"writing the capture set {out}")
        images, pinholes = _undistorted_images(image_dir, [work_name[n] for n in registered],
                                               [cameras[n] for n in registered])
        world = "the floor under the board (z up)" if alignment.world == "floor" else None
        if aligned is None:
            frame = "R (unaligned: SfM's frame and arbitrary scale)"
        elif X_WO is not None:
            frame = "O" + (f" (W: {world})" if world else "")
        else:
            frame = f"O = W ({world or 'no object pose given'})"
        report = PoseReport(
            photos=len(photos), working_size_px=max(photos[0].size), registered=registered,
            unregistered=unregistered,
            mean_reprojection_error_px=float(rec.compute_mean_reprojection_error()),
            points3D=len(points), num_models=sfm.num_models,
            calibration="known" if camera else "self-calibrated" + (
                " from the EXIF focal length" if focal_priors else ""),
            alignment=aligned, frame=frame,
            frames={f"images/frame_{i:03d}.png": n for i, n in enumerate(registered)},
            cameras={n: cameras[n].to_json() for n in registered}, board_poses=board_details,
            floor=None if floor is None else floor.to_json(),
            seconds={**sfm.seconds, "total": time.perf_counter() - start})
        write_capture_set(out, images, X_OCs, pinholes,
                          extra_files={REPORT_FILE: report.dumps(), POINTS_FILE: _ply_text(p_O, colors)},
                          source_photos=registered)
    return report


def poses_command(
    photos_dir: Annotated[Path, tyro.conf.Positional],
    out: Path,
    intrinsics: Path | None = None,
    max_size: int = 1024,
    charuco: bool = False,
    board: CharucoBoardSpec = DEFAULT_BOARD,
    world: WorldFrame = "board",
    floor_check: bool = True,
    anchors: Path | None = None,
    max_anchor_residual: float = MAX_ANCHOR_RESIDUAL,
    object_pose: str | None = None,
    min_registered: int = 3,
    allow_unaligned: bool = False,
    work_dir: Path | None = None,
    sfm: SfmOptions = DEFAULT_SFM,
) -> int:
    """Estimate metric camera poses of a folder of photos and write a capture set in frame O.

    Args:
        photos_dir: folder of photos (jpg, png, ...) of one static scene, taken with one camera.
        out: capture-set folder to create (transforms.json, images/, report.json, points3D.ply).
        intrinsics: JSON with fl_x, fl_y, cx, cy, w, h and optional k1, k2, p1, p2, k3..k6 (pixel
            centres at +0.5); the photos' camera, held fixed. Default: self-calibration.
        max_size: longer side of the images used and written, pixels.
        charuco: make the poses metric with the ChArUco board (--board.*) seen in the photos;
            W is then the board frame, or the floor frame with --world floor.
        board: the board's geometry (--board.thickness-m: its face's height above the floor).
        world: with --charuco, W is the board's own frame ("board": z into the board) or, for a
            board lying face up on the floor, the floor frame under it ("floor": x along the
            board's rows, z up, the floor at z = 0, the origin under the board's origin corner):
            what `nfr-drake infer --estimate-pose` fits directly.
        floor_check: with --world floor, refuse a board that does not lie on the floor that the
            sparse points show (tilted over 3 deg or over 3 cm above or below it).
        anchors: JSON {"photo.jpg": [x, y, z], ...}: known camera centres in W, metres (3 or
            more, not on a line), keyed by the photos' file names.
        max_anchor_residual: refuse the anchors (they probably belong to other photos) when their
            RMS residual after alignment exceeds this fraction of their spread (RMS distance from
            their centroid).
        object_pose: X_WO, the object frame in W: "x y z roll pitch yaw" (metres, radians; write
            --object-pose="-0.1 ..." for a leading minus) or a JSON file with a 4x4 matrix.
            Default: O = W.
        min_registered: fail when fewer photos register.
        allow_unaligned: with neither --charuco nor --anchors, write poses in SfM's own frame and
            arbitrary scale instead of failing.
        work_dir: keep the resized photos, COLMAP database and models here.
        sfm: feature and mapping options.
    """
    X_WO = parse_object_pose(object_pose) if object_pose is not None else None
    camera = PinholeCamera.from_json_file(intrinsics) if intrinsics else None
    alignment = Alignment(charuco=board if charuco else None,
                          anchors=read_anchors(anchors) if anchors else None,
                          allow_unaligned=allow_unaligned, max_anchor_residual=max_anchor_residual,
                          world=world, floor_check=floor_check)
    report = estimate_poses(photos_dir, out, alignment, camera, X_WO, max_size, min_registered,
                            sfm, work_dir)
    print(report.summary())
    print(f"capture set: {out}")
    if report.unregistered:
        print(f"warning: {len(report.unregistered)} photo(s) not registered", file=sys.stderr)
    return 0

