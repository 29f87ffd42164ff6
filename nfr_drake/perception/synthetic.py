"""Synthetic photo folders: a closet in a textured or furnished room with a ChArUco board, rendered
by Drake.

The objects of `nfr_drake.objects` are plain-coloured and give SIFT little to hold on to, so this
scene adds what real rooms have: a floor and walls with random texture (or a furnished room of
`nfr_drake.data.rooms`: textured surfaces, other furniture, clutter, room lights), and a ChArUco
board lying on the floor in front of the object (for `nfr-drake poses --charuco`). Photos are
rendered with Drake's RgbdSensor (RenderEngineVtk) at known poses X_OC; `write_photo_folder`
stores them with `truth.json` so that the pose pipeline can be checked end to end.

Frames: the object frame O is the world frame of this scene. The board frame B is OpenCV's (see
`charuco`); the board lies face up, so z_B points down: X_OB = [Rz(yaw) Rx(pi), p_OB]. The floor
frame F under the board (`charuco.floor_frame_in_board`) is what `nfr-drake poses --world floor`
writes poses in: X_OF = X_OB X_BF, O and F differ by a translation on the floor and a yaw.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
from pydrake.geometry import (
    GeometryInstance,
    IllustrationProperties,
    Mesh,
    PerceptionProperties,
    RenderLabel,
    Rgba,
)
from pydrake.math import RigidTransform

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.capture import write_image
from nfr_drake.data.render import Lighting, ObjectRenderer, RenderedView
from nfr_drake.data.rooms import Room, RoomDistribution, sample_room
from nfr_drake.objects import ArticulatedObject
from nfr_drake.perception.charuco import CharucoBoardSpec, floor_frame_in_board

TRUTH_FILE = "truth.json"
_PX_PER_SQUARE = 200


@dataclass(frozen=True)
class RoomSpec:
    """The textured room around the object (metres, in O)."""

    floor_half_size_m: float = 3.0
    """The floor is a square of this half side centred under the object."""
    wall_distance_m: float = 1.5
    """The back wall is the plane x = -wall_distance_m."""
    wall_height_m: float = 2.5
    texture_px: int = 2048
    """Side of each wall and floor texture, pixels."""
    board: CharucoBoardSpec = field(default_factory=lambda: CharucoBoardSpec(square_m=0.08,
                                                                             marker_m=0.06))
    """The ChArUco board on the floor (larger than the test print, to be seen from 2 m)."""
    p_OB: tuple[float, float, float] = (0.6, 0.28, 0.001)
    """Position of the board's origin corner, on the floor; its z is the board's thickness."""
    board_yaw_deg: float = 0.0
    """The board's turn about the vertical: the angle from x_O to x_B, degrees."""


def board_pose(room: RoomSpec) -> np.ndarray:
    """X_OB (4x4): the board lies face up on the floor turned by `board_yaw_deg`; at yaw 0,
    x_B = x_O, y_B = -y_O, z_B = -z_O."""
    yaw = np.deg2rad(room.board_yaw_deg)
    R_OB = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0, 0, 1.0]])
    X_OB = np.eye(4)
    X_OB[:3, :3] = R_OB @ np.diag([1.0, -1.0, -1.0])
    X_OB[:3, 3] = room.p_OB
    return X_OB


def floor_pose(room: RoomSpec) -> np.ndarray:
    """X_OF (4x4): the floor frame F that `nfr-drake poses --world floor` puts under the board
    (the board's thickness p_OB[2])."""
    return board_pose(room) @ floor_frame_in_board(room.p_OB[2])


def board_footprint(room: RoomSpec, margin_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The board's axis-aligned bounds on the floor in O, widened by `margin_m`: (lo, hi), (2,) each."""
    nx, ny = room.board.squares
    corners_B = np.array([[0, 0, 0], [nx, 0, 0], [0, ny, 0], [nx, ny, 0]]) * room.board.square_m
    X_OB = board_pose(room)
    corners_O = corners_B @ X_OB[:3, :3].T + X_OB[:3, 3]
    return corners_O[:, :2].min(axis=0) - margin_m, corners_O[:, :2].max(axis=0) + margin_m


def furnished_room(rng: np.random.Generator, obj: ArticulatedObject, cameras_O: np.ndarray,
                   room: RoomSpec, distribution: RoomDistribution) -> Room:
    """A random room of `nfr_drake.data.rooms` around `obj` that leaves the cameras at cameras_O
    (N, 3) clear, without the clutter that would stand on the board."""
    furnished = sample_room(rng, obj, cameras_O, distribution)
    lo, hi = board_footprint(room, margin_m=0.05)

    def off_board(part) -> bool:
        xy, reach = np.asarray(part.p_LP[:2]), max(part.size[:2]) if part.shape != "sphere" else part.size[0]
        return part.p_LP[2] > 0.5 or not np.all((xy > lo - reach) & (xy < hi + reach))

    return replace(furnished, clutter=tuple(p for p in furnished.clutter if off_board(p)))


def random_texture(rng: np.random.Generator, size: int) -> np.ndarray:
    """A feature-rich texture: uint8 RGB (size, size, 3) of random shapes at many scales."""
    image = np.full((size, size, 3), rng.integers(90, 200, size=3), np.uint8)
    for radius in (size // 16, size // 40, size // 100, size // 250):
        for _ in range(int(6 * (size / max(radius, 1)) ** 1.2)):
            centre = tuple(int(v) for v in rng.integers(0, size, 2))
            colour = tuple(int(v) for v in rng.integers(0, 256, 3))
            r = max(1, int(radius * rng.uniform(0.4, 1.0)))
            if rng.random() < 0.5:
                cv2.circle(image, centre, r, colour, -1, cv2.LINE_AA)
            else:
                corner = (centre[0] + r, centre[1] + int(r * rng.uniform(0.3, 1.5)))
                cv2.rectangle(image, centre, corner, colour, -1, cv2.LINE_AA)
    return cv2.GaussianBlur(image, (0, 0), 0.7)


def board_texture(spec: CharucoBoardSpec) -> np.ndarray:
    """The board image, uint8 RGB, exactly `_PX_PER_SQUARE` pixels per square, no margin."""
    nx, ny = spec.squares
    grey = spec.board().generateImage((nx * _PX_PER_SQUARE, ny * _PX_PER_SQUARE), marginSize=0,
                                      borderBits=1)
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2RGB)


def _write_quad_obj(path: Path, size_x: float, size_y: float) -> None:
    """An OBJ rectangle [0, size_x] x [0, size_y] in its z = 0 plane, seen from -z.

    Texture coordinates put image pixel (u, v) (u right, v down, normalised) at
    (u size_x, v size_y, 0), as OpenCV's board coordinates do.
    """
    path.write_text(
        f"v 0 0 0\nv {size_x} 0 0\nv {size_x} {size_y} 0\nv 0 {size_y} 0\n"
        "vt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\n"
        "vn 0 0 -1\n"
        "f 1/1/1 3/3/1 2/2/1\nf 1/1/1 4/4/1 3/3/1\n")


class SyntheticPhotoScene:
    """A closet at articulation q in a textured room, photographed by a Drake RgbdSensor.

    Args:
        obj: the object, welded with its frame O at the world origin.
        q: articulation in [0, 1].
        camera: intrinsics of every photo (no distortion).
        room: the room and board; seed: the textures' random seed.
        furnishing: a furnished room (`furnished_room`) in place of the random textured floor and
            back wall: its surfaces, furniture, clutter, arm and lights; the board stays.
    """

    def __init__(self, obj: ArticulatedObject, q: float, camera: PinholeCamera,
                 room: RoomSpec | None = None, seed: int = 0, furnishing: Room | None = None):
        self.obj, self.q, self.camera = obj, q, camera
        self.room = room or RoomSpec()
        self.furnishing = furnishing
        self._assets = tempfile.TemporaryDirectory(prefix="nfr_synthetic_")
        assets = Path(self._assets.name)
        rng = np.random.default_rng(seed)

        surfaces = []
        for name, X_OQ, size, texture in self._surfaces(rng, board_only=furnishing is not None):
            write_image(assets / f"{name}.png", texture)
            _write_quad_obj(assets / f"{name}.obj", *size)
            surfaces.append((assets / f"{name}.obj", assets / f"{name}.png", X_OQ, name))

        def add_room(plant):
            for surface in surfaces:
                self._add_textured_quad(plant, *surface)
            if furnishing is not None:
                furnishing.add_to(plant)

        lighting = Lighting() if furnishing is None else furnishing.lighting
        self._renderer = ObjectRenderer(obj, camera, lighting, background_rgb=(0.8, 0.8, 0.8),
                                        add_scenery=add_room)

    def _surfaces(self, rng: np.random.Generator, board_only: bool = False):
        """(name, X_OQ, (size_x, size_y), texture) of each textured rectangle Q, seen from -z_Q:
        the floor, the back wall and the board, or the board alone."""
        r = self.room
        h, d, t = r.floor_half_size_m, r.wall_distance_m, r.texture_px
        floor = np.diag([1.0, -1.0, -1.0, 1.0])  # faces up
        floor[:3, 3] = (-h, h, 0.0)
        back = np.eye(4)  # the plane x = -d, facing +x: x_Q = y_O, y_Q = -z_O, z_Q = -x_O
        back[:3, :3] = np.column_stack([[0, 1, 0], [0, 0, -1], [-1, 0, 0]])
        back[:3, 3] = (-d, -h, r.wall_height_m)
        if not board_only:
            yield "floor", floor, (2 * h, 2 * h), random_texture(rng, t)
            yield "back_wall", back, (2 * h, r.wall_height_m), random_texture(rng, t)
        nx, ny = r.board.squares
        yield ("board", board_pose(r), (nx * r.board.square_m, ny * r.board.square_m),
               board_texture(r.board))

    @staticmethod
    def _add_textured_quad(plant, obj_path: Path, png_path: Path, X_OQ: np.ndarray, name: str):
        instance = GeometryInstance(RigidTransform(X_OQ), Mesh(str(obj_path)), name)
        illustration = IllustrationProperties()  # Meshcat: untextured grey
        illustration.AddProperty("phong", "diffuse", Rgba(0.7, 0.7, 0.7, 1.0))
        instance.set_illustration_properties(illustration)
        perception = PerceptionProperties()
        perception.AddProperty("phong", "diffuse", Rgba(1.0, 1.0, 1.0, 1.0))
        perception.AddProperty("phong", "diffuse_map", str(png_path))
        perception.AddProperty("label", "id", RenderLabel(0))
        instance.set_perception_properties(perception)
        plant.RegisterVisualGeometry(plant.world_body(), instance)

    def render(self, X_OC: np.ndarray) -> np.ndarray:
        """The photo from camera pose X_OC (4x4, OpenCV axes): uint8 RGB (H, W, 3)."""
        return self._renderer.render_rgb(self.q, X_OC)

    def render_view(self, X_OC: np.ndarray) -> RenderedView:
        """The pinhole view from X_OC with the object's labels (0 on everything else) and depth."""
        return self._renderer.render(self.q, X_OC)


def orbit_poses(n: int, target_O: np.ndarray, distance_m: float = 2.0,
                azimuth_deg: tuple[float, float] = (-50.0, 50.0),
                elevation_deg: tuple[float, float] = (22.0, 38.0)) -> np.ndarray:
    """n camera poses X_OC (n, 4, 4) on an arc in front of the object (+x), looking at target_O.

    Azimuths are spread evenly; elevations alternate between the bounds so the centres do not
    lie on one line or one horizontal circle.
    """
    az = np.deg2rad(np.linspace(*azimuth_deg, n))
    el = np.deg2rad(np.where(np.arange(n) % 2 == 0, elevation_deg[0], elevation_deg[1]))
    poses = []
    for a, e in zip(az, el, strict=True):
        direction = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
        poses.append(look_at(target_O + distance_m * direction, target_O))
    return np.stack(poses)


def apply_distortion(rgb: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    """The photo a lens with `camera`'s distortion would take, from a pinhole image (H, W, 3)
    with the same K. Each distorted pixel samples the pinhole image where its undistorted ray
    lands (bilinear); pixels whose ray leaves the pinhole image are black."""
    h, w = rgb.shape[:2]
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    grid = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    K = camera.K_opencv
    pinhole = cv2.undistortPoints(grid, K, camera.dist_opencv, P=K).reshape(h, w, 2)
    return cv2.remap(rgb, pinhole[..., 0], pinhole[..., 1], cv2.INTER_LINEAR)


def write_photo_folder(out: Path, scene: SyntheticPhotoScene, X_OCs: np.ndarray,
                       distortion: tuple[float, ...] = ()) -> Path:
    """Render one photo per pose into `out` (photo_XXX.png) with `truth.json`.

    distortion: OpenCV coefficients (k1, k2, p1, p2[, k3]) applied to the renders, as a real
    lens would. truth.json: `camera` (the photos' intrinsics, a valid `--intrinsics` file),
    `X_OC` per photo name (4x4, OpenCV axes), `X_OB` (the board), `X_OF` (the floor frame under
    it, `floor_pose`), the board's geometry and thickness, the category, q and the object's
    keypoints at q (metres, in O).
    """
    c = scene.camera
    camera = PinholeCamera(c.fx, c.fy, c.cx, c.cy, c.width, c.height, tuple(distortion))
    out.mkdir(parents=True, exist_ok=True)
    poses = {}
    for i, X_OC in enumerate(X_OCs):
        name = f"photo_{i:03d}.png"
        rgb = scene.render(X_OC)
        write_image(out / name, apply_distortion(rgb, camera) if camera.has_distortion else rgb)
        poses[name] = np.asarray(X_OC).tolist()
    b = scene.room.board
    truth = {"camera": camera.to_json(), "X_OC": poses,
             "X_OB": board_pose(scene.room).tolist(), "X_OF": floor_pose(scene.room).tolist(),
             "board": {"squares": list(b.squares), "square_m": b.square_m, "marker_m": b.marker_m,
                       "dictionary": b.dictionary, "thickness_m": scene.room.p_OB[2]},
             "category": scene.obj.category, "q": scene.q,
             "keypoints": {k: v.tolist() for k, v in scene.obj.keypoints(scene.q).items()}}
    (out / TRUTH_FILE).write_text(json.dumps(truth, indent=2))
    return out
