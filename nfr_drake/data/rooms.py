"""Random rooms around an object: floor, walls, other furniture, clutter, the robot arm, lights.

A `Room` is drawn around the target object (frame O = W, as in `ObjectRenderer`) once its
cameras are known (`sample_room_cameras`), so that walls, clutter and the arm stay clear of them:
- a floor, a back wall behind the object (0-30 cm gap), side walls beyond every camera and a
  ceiling, textured from one family (`room_textures`: "train" or "heldout");
- neighbours along the back wall: closets, drawers and furniture from the object generators,
  each at its own articulation, placed left and right of the object's swept bounds (every
  state of its fronts) so that nothing intersects, sometimes right beside it (gap under 2 cm);
  optionally a twin (a copy of the object) right beside it;
- clutter: boxes, cylinders and spheres on the floor and on the tops of the furniture;
- in training rooms (style "train") also random textures of the room family on some clutter
  (`RETEXTURE_CLUTTER`) and on some neighbours (`RETEXTURE_NEIGHBOUR`: carcass and fronts in one
  texture, handles kept); held-out rooms keep the object generators' own looks;
- the Panda arm on the floor in front of the object in a random configuration;
- lights from one set (`room_lighting`: "train" or "heldout").
`Room.add_to` is the `add_scenery` hook of `ObjectRenderer`, which labels everything but the
target object as background, so the object's mask is its label image > 0.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal
from urllib.parse import unquote, urlparse

import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import framing_distance, look_at
from nfr_drake.data.room_lighting import RoomLighting, sample_room_lighting
from nfr_drake.data.room_textures import FAMILY_KINDS, FLOOR_KINDS, REPEAT_M, WALL_KINDS, room_texture_uri
from nfr_drake.errors import ConfigError
from nfr_drake.objects import CATEGORIES, ArticulatedObject, Part, SemanticClass, sample_object
from nfr_drake.objects.appearance import sample_rgba
from nfr_drake.objects.textures import TEXTURE_KINDS, texture_uri

ROOM_TEXTURE_POOL = 200
"""Seeds per room texture kind: rooms draw their floor and walls from this many images per kind."""
RETEXTURE_CLUTTER = 0.5
"""Training rooms: chance that a textured piece of clutter wears a room texture of the training family."""
RETEXTURE_NEIGHBOUR = 0.3
"""Training rooms: chance that a neighbour (not a twin) wears one room texture of the training family."""
_CAMERA_CLEARANCE_M = 0.4  # walls, clutter and the arm's base keep this far from every camera


@dataclass(frozen=True)
class RoomDistribution:
    """What the random rooms around an object hold (angles in degrees, lengths in m).

    style: texture family and lighting set, "train" or "heldout" (for evaluation).
    neighbours: range of the number of other pieces of furniture along the back wall.
    beside_probability: chance that a neighbour stands right beside the previous piece (gap
        under 2 cm), else 5-60 cm away.
    twin_probability: chance that a copy of the object stands right beside it.
    clutter: range of the number of boxes, cylinders and spheres.
    robot_probability: chance that the Panda arm stands in front of the object.
    cut_probability: chance that a camera stands closer than the framing distance and looks
        off-centre, so that the image edge cuts the object.
    azimuth_deg, elevation_deg: camera directions on the front hemisphere.
    margin: free border around the object's swept bounds, a fraction of the image's half-size.
    """

    style: Literal["train", "heldout"] = "train"
    neighbours: tuple[int, int] = (0, 3)
    beside_probability: float = 0.5
    twin_probability: float = 0.0
    clutter: tuple[int, int] = (3, 12)
    robot_probability: float = 0.8
    cut_probability: float = 0.2
    azimuth_deg: tuple[float, float] = (-70.0, 70.0)
    elevation_deg: tuple[float, float] = (0.0, 45.0)
    margin: tuple[float, float] = (0.05, 0.5)

    def __post_init__(self):
        if self.style not in ("train", "heldout"):
            raise ConfigError(f"room style must be 'train' or 'heldout', got {self.style!r}")
        for name in ("neighbours", "clutter", "azimuth_deg", "elevation_deg", "margin"):
            lo, hi = getattr(self, name)
            if not lo <= hi:
                raise ConfigError(f"room {name}: min {lo} exceeds max {hi}")
        if min(self.neighbours[0], self.clutter[0]) < 0:
            raise ConfigError("room: neighbour and clutter counts must be >= 0")
        for name in ("beside_probability", "twin_probability", "robot_probability", "cut_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ConfigError(f"room {name} must lie in [0, 1], got {getattr(self, name)}")
        if not -90.0 < self.elevation_deg[0] and self.elevation_deg[1] < 90.0:
            raise ConfigError("room elevation_deg must lie strictly between -90 and 90")
        if not 0.0 <= self.margin[0] and self.margin[1] < 1.0:
            raise ConfigError(f"room margin must lie in [0, 1), got {self.margin}")


@dataclass(frozen=True)
class Neighbour:
    """Another piece of furniture: the object, its pose X_WO (4, 4) and articulation q (F,)."""

    obj: ArticulatedObject
    X_WO: np.ndarray
    q: np.ndarray
    twin: bool = False
    texture: str | None = None
    """A room texture's URI that covers the neighbour's carcass and fronts, or None (its own looks)."""


@dataclass(frozen=True)
class RobotPose:
    """The arm's base pose X_WB (4, 4) on the floor and its joint positions q (7,), rad."""

    X_WB: np.ndarray
    q: np.ndarray


@dataclass(frozen=True)
class Room:
    """One room around the target object (at W = O). surfaces: floor, walls, ceiling; clutter:
    boxes, cylinders, spheres; both as parts of the world body (frame W)."""

    surfaces: tuple[Part, ...]
    neighbours: tuple[Neighbour, ...]
    clutter: tuple[Part, ...]
    robot: RobotPose | None
    lighting: RoomLighting

    def add_to(self, plant, X_PW: np.ndarray | None = None) -> None:
        """Add everything to `plant` (before Finalize); the `ObjectRenderer` scenery hook. X_PW
        (4, 4): the room's frame W (the target object's frame) in the plant's world, default
        identity; the room's lights move with it by `RoomLighting.moved`."""
        from pydrake.math import RigidTransform

        from nfr_drake.objects.plant import add_articulated_object
        from nfr_drake.world.robot import ARM_JOINTS, FINGER_JOINTS, FINGER_OPEN, add_panda

        X_PW = RigidTransform() if X_PW is None else RigidTransform(X_PW)
        for part in (*self.surfaces, *self.clutter):
            _add_world_part(plant, part, X_PW)
        for i, nb in enumerate(self.neighbours):
            model = add_articulated_object(plant, nb.obj, X_PW @ RigidTransform(nb.X_WO),
                                           f"room_furniture_{i}")
            for front, value in zip(nb.obj.fronts, nb.obj.joint_values(nb.q), strict=True):
                plant.GetJointByName(front.joint_name, model).set_default_positions([value])
        if self.robot is not None:
            model = add_panda(plant, X_PW @ RigidTransform(self.robot.X_WB), "room_panda")
            for name, value in zip(ARM_JOINTS, self.robot.q, strict=True):
                plant.GetJointByName(name, model).set_default_positions([value])
            for name in FINGER_JOINTS:
                plant.GetJointByName(name, model).set_default_positions([FINGER_OPEN])

    def to_json(self) -> dict:
        """What meta.json records of the room: textures, neighbours, clutter, arm and lights."""
        return {
            "surfaces": {p.name: Path(unquote(urlparse(p.texture).path)).name for p in self.surfaces
                         if p.texture},
            "neighbours": [{"category": nb.obj.category, "twin": nb.twin, "X_WO": nb.X_WO.tolist(),
                            "q": np.asarray(nb.q).tolist(), "params": nb.obj.params,
                            "texture": nb.texture and Path(unquote(urlparse(nb.texture).path)).name}
                           for nb in self.neighbours],
            "clutter": len(self.clutter),
            "robot": None if self.robot is None else {"X_WB": self.robot.X_WB.tolist(),
                                                      "q": self.robot.q.tolist()},
            "lighting": self.lighting.to_json(),
        }


def _add_world_part(plant, part: Part, X_PW) -> None:
    """Register `part` (pose in the room's frame W) as visual geometry of the plant's world body,
    the room at X_PW (a RigidTransform)."""
    from pydrake.geometry import (
        Box,
        Cylinder,
        GeometryInstance,
        IllustrationProperties,
        PerceptionProperties,
        Rgba,
        Sphere,
    )
    from pydrake.math import RigidTransform, RollPitchYaw

    shape = {"box": lambda s: Box(*s), "cylinder": lambda s: Cylinder(*s),
             "sphere": lambda s: Sphere(s[0])}[part.shape](part.size)
    instance = GeometryInstance(X_PW @ RigidTransform(RollPitchYaw(part.rpy_LP), part.p_LP), shape,
                                part.geometry_name)
    for props in (IllustrationProperties(), PerceptionProperties()):
        props.AddProperty("phong", "diffuse", Rgba(*part.rgba))
        if part.texture:
            props.AddProperty("phong", "diffuse_map", unquote(urlparse(part.texture).path))
        if isinstance(props, IllustrationProperties):
            instance.set_illustration_properties(props)
        else:
            instance.set_perception_properties(props)
    plant.RegisterVisualGeometry(plant.world_body(), instance)


def _corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                     for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def sample_room_cameras(rng: np.random.Generator, n: int, obj: ArticulatedObject, camera: PinholeCamera,
                        dist: RoomDistribution) -> np.ndarray:
    """n camera poses X_WC (OpenCV axes), shape (n, 4, 4), on the object's front hemisphere.

    Each frames the object's swept bounds with a free border drawn from `dist.margin`
    (`framing_distance`); with `dist.cut_probability` the camera moves to 45-80% of that distance
    and looks at a random point of the bounds instead, so that the image edge cuts the object.
    Cameras stay at least 0.3 m outside the swept bounds.
    """
    lo, hi = obj.swept_bounds()
    corners, centre = _corners(lo, hi), (lo + hi) / 2.0
    poses = []
    while len(poses) < n:
        az = np.deg2rad(rng.uniform(*dist.azimuth_deg))
        el = np.deg2rad(rng.uniform(*dist.elevation_deg))
        direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        target = centre + rng.normal(0.0, 0.03, 3) * (hi - lo)
        d = framing_distance(corners, target, direction, camera, rng.uniform(*dist.margin))
        if rng.uniform() < dist.cut_probability:
            d *= rng.uniform(0.45, 0.8)
            target = lo + rng.uniform(0.15, 0.85, 3) * (hi - lo)
        p_WC = target + d * direction
        if np.all((p_WC > lo - 0.3) & (p_WC < hi + 0.3)) or p_WC[2] < 0.1:
            continue
        poses.append(look_at(p_WC, target))
    return np.stack(poses)


def _box(name: str, centre, size, rgba, texture: str | None = None) -> Part:
    return Part(name, SemanticClass.BACKGROUND, "box", tuple(float(s) for s in size),
                tuple(float(c) for c in centre), tuple(rgba), texture=texture)


def _surfaces(rng: np.random.Generator, style: str, back_x: float, half_width: float, front_x: float,
              ceiling: float) -> tuple[Part, ...]:
    """Floor, back wall, side walls (y = +-half_width) and ceiling, 10 cm thick, inner faces at
    the given coordinates (m)."""
    floor_kind = FLOOR_KINDS[style][rng.integers(len(FLOOR_KINDS[style]))]
    wall_kind = WALL_KINDS[style][rng.integers(len(WALL_KINDS[style]))]
    floor = room_texture_uri(floor_kind, int(rng.integers(ROOM_TEXTURE_POOL)))
    wall = room_texture_uri(wall_kind, int(rng.integers(ROOM_TEXTURE_POOL)))
    depth, width, t = front_x - back_x, 2 * half_width, 0.1
    cx = (front_x + back_x) / 2
    white = (1.0, 1.0, 1.0, 1.0)
    ceiling_rgba = tuple(float(x) for x in (*np.full(3, rng.uniform(0.75, 0.95)), 1.0))
    # A face shows the whole texture once: split long surfaces into tiles of about REPEAT_M.
    parts = []
    for name, centre, size, rgba, tex in (
            ("floor", (cx, 0.0, -t / 2), (depth, width, t), white, floor),
            ("back_wall", (back_x - t / 2, 0.0, ceiling / 2), (t, width, ceiling), white, wall),
            ("left_wall", (cx, -half_width - t / 2, ceiling / 2), (depth, t, ceiling), white, wall),
            ("right_wall", (cx, half_width + t / 2, ceiling / 2), (depth, t, ceiling), white, wall),
            ("ceiling", (cx, 0.0, ceiling + t / 2), (depth, width, t), ceiling_rgba, None)):
        tiles = [max(1, int(round(s / REPEAT_M))) if s > t else 1 for s in size]
        tile = np.asarray(size) / tiles
        for idx in np.ndindex(*tiles):
            offset = (np.asarray(idx) + 0.5) * tile - np.asarray(size) / 2
            parts.append(_box(f"{name}_{'_'.join(map(str, idx))}", np.asarray(centre) + offset, tile,
                              rgba, tex))
    return tuple(parts)


def _neighbours(rng: np.random.Generator, obj: ArticulatedObject, dist: RoomDistribution,
                back_x: float) -> tuple[Neighbour, ...]:
    """Furniture along the back wall, alternating right and left of the object's swept bounds."""
    lo, hi = obj.swept_bounds()
    cursor = {+1: hi[1], -1: lo[1]}  # free edge on each side, W's y, m
    twin = rng.uniform() < dist.twin_probability
    count = int(rng.integers(dist.neighbours[0], dist.neighbours[1] + 1)) + int(twin)
    side = int(rng.choice([-1, 1]))
    out = []
    for i in range(count):
        if i == 0 and twin:
            other, gap = obj, rng.uniform(0.005, 0.03)
        else:
            category = str(rng.choice(sorted(CATEGORIES)))
            other = sample_object(category, rng, name=f"neighbour_{i}")
            gap = rng.uniform(0.005, 0.02) if rng.uniform() < dist.beside_probability else rng.uniform(
                0.05, 0.6)
        o_lo, o_hi = other.swept_bounds()
        b_lo, _ = other.base_bounds()
        y = cursor[side] + side * gap - (o_lo[1] if side > 0 else o_hi[1])
        cursor[side] = y + (o_hi[1] if side > 0 else o_lo[1])
        X_WO = np.eye(4)
        X_WO[:3, 3] = (back_x + rng.uniform(0.0, 0.05) - b_lo[0], y, 0.0)
        q = np.zeros(other.num_fronts) if twin and i == 0 and rng.uniform() < 0.5 else rng.uniform(
            0.0, 1.0, other.num_fronts) * (rng.uniform(size=other.num_fronts) < 0.4)
        texture = None
        if dist.style == "train" and not (twin and i == 0) and rng.uniform() < RETEXTURE_NEIGHBOUR:
            texture = _train_texture(rng)
            other = _retextured(other, texture)
        out.append(Neighbour(other, X_WO, q, twin=twin and i == 0, texture=texture))
        side = -side
    return tuple(out)


def _train_texture(rng: np.random.Generator) -> str:
    """The URI of a random room texture of the training family."""
    kinds = FAMILY_KINDS["train"]
    return room_texture_uri(kinds[rng.integers(len(kinds))], int(rng.integers(ROOM_TEXTURE_POOL)))


def _retextured(obj: ArticulatedObject, texture: str) -> ArticulatedObject:
    """`obj` with every part but the handles wearing `texture` (white rgba)."""
    def part(p: Part) -> Part:
        if p.semantic == SemanticClass.HANDLE:
            return p
        return replace(p, texture=texture, rgba=(1.0, 1.0, 1.0, 1.0))

    return replace(obj, base_parts=tuple(map(part, obj.base_parts)),
                   fronts=tuple(replace(f, parts=tuple(map(part, f.parts))) for f in obj.fronts))


def _clutter(rng: np.random.Generator, count: int, tops: list[tuple[np.ndarray, np.ndarray]],
             keep_out: list[tuple[np.ndarray, np.ndarray]], floor_lo: np.ndarray, floor_hi: np.ndarray,
             cameras_W: np.ndarray, style: str = "heldout") -> tuple[Part, ...]:
    """`count` primitives: on one of the `tops` (xy box lo, hi and height z in lo[2]) or on the
    floor within [floor_lo, floor_hi] (xy), outside the `keep_out` boxes and away from cameras;
    in "train" style a textured one wears a room texture with probability `RETEXTURE_CLUTTER`."""
    parts = []
    for i in range(count * 4):
        if len(parts) == count:
            break
        shape = ("box", "cylinder", "sphere")[rng.integers(3)]
        if shape == "box":
            size = (rng.uniform(0.06, 0.3), rng.uniform(0.06, 0.3), rng.uniform(0.04, 0.35))
            height, reach = size[2], 0.5 * float(np.hypot(size[0], size[1]))
        elif shape == "cylinder":
            size = (rng.uniform(0.02, 0.12), rng.uniform(0.06, 0.35))
            height, reach = size[1], size[0]
        else:
            size = (rng.uniform(0.03, 0.15),)
            height, reach = 2 * size[0], size[0]
        if tops and rng.uniform() < 0.4:
            lo, hi = tops[rng.integers(len(tops))]
            if np.any(hi[:2] - lo[:2] < 2 * reach):
                continue
            xy, z0 = rng.uniform(lo[:2] + reach, hi[:2] - reach), lo[2]
        else:
            xy, z0 = rng.uniform(floor_lo[:2], floor_hi[:2]), 0.0
            if any(np.all((xy > k_lo[:2] - reach - 0.03) & (xy < k_hi[:2] + reach + 0.03))
                   for k_lo, k_hi in keep_out):
                continue
        p = np.array([*xy, z0 + height / 2])
        if np.min(np.linalg.norm(cameras_W - p, axis=1)) < _CAMERA_CLEARANCE_M + reach:
            continue
        kind = TEXTURE_KINDS[rng.integers(len(TEXTURE_KINDS))]
        textured = rng.uniform() < 0.3
        texture = texture_uri(kind, int(rng.integers(ROOM_TEXTURE_POOL))) if textured else None
        if style == "train" and textured and rng.uniform() < RETEXTURE_CLUTTER:
            texture = _train_texture(rng)
        rgba = (1.0, 1.0, 1.0, 1.0) if textured else sample_rgba(rng, (0.0, 0.9), (0.15, 0.95))
        parts.append(Part(f"clutter_{i}", SemanticClass.BACKGROUND, shape, tuple(float(s) for s in size),
                          tuple(float(c) for c in p), rgba, (0.0, 0.0, float(rng.uniform(0, np.pi))),
                          texture))
    return tuple(parts)


def _robot(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, cameras_W: np.ndarray
           ) -> RobotPose | None:
    """The arm's base 15-90 cm in front of the swept bounds (lo, hi), facing the object within 60
    degrees, 0.8 m from every camera; joints near Franka's ready pose (sigma 0.6 rad, within
    limits). None when no such base is found in 20 tries."""
    from nfr_drake.world.robot import Q_HOME, arm_joint_limits

    lower, upper = arm_joint_limits()

    for _ in range(20):
        p = np.array([hi[0] + rng.uniform(0.15, 0.9), rng.uniform(lo[1] - 0.8, hi[1] + 0.8), 0.0])
        if np.min(np.linalg.norm(cameras_W[:, :2] - p[:2], axis=1)) < 0.8:
            continue
        towards = (lo + hi) / 2 - p
        yaw = np.arctan2(towards[1], towards[0]) + rng.uniform(-1.0, 1.0) * np.pi / 3
        X_WB = np.eye(4)
        X_WB[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
        X_WB[:3, 3] = p
        q = np.clip(Q_HOME + rng.normal(0.0, 0.6, 7), lower + 0.05, upper - 0.05)
        return RobotPose(X_WB, q)
    return None


def sample_room(rng: np.random.Generator, obj: ArticulatedObject, cameras_W: np.ndarray,
                dist: RoomDistribution) -> Room:
    """A random room around `obj` (at W = O) that leaves the cameras at positions cameras_W (N, 3)
    clear; see the module docstring for what it holds."""
    lo, hi = obj.swept_bounds()
    back_x = float(lo[0] - rng.uniform(0.0, 0.3))
    neighbours = _neighbours(rng, obj, dist, back_x)
    boxes = [(lo, hi)]
    for nb in neighbours:
        n_lo, n_hi = nb.obj.swept_bounds()
        boxes.append((n_lo + nb.X_WO[:3, 3], n_hi + nb.X_WO[:3, 3]))
    extent_y = max(max(abs(b[0][1]), abs(b[1][1])) for b in boxes)
    half_width = max(extent_y + rng.uniform(0.1, 1.0), np.abs(cameras_W[:, 1]).max() + _CAMERA_CLEARANCE_M)
    front_x = max(float(cameras_W[:, 0].max()) + 1.0, hi[0] + 2.0)
    ceiling = max(rng.uniform(2.4, 3.0), float(cameras_W[:, 2].max()) + _CAMERA_CLEARANCE_M,
                  max(float(b[1][2]) for b in boxes) + 0.4)
    surfaces = _surfaces(rng, dist.style, back_x, half_width, front_x, ceiling)
    robot = _robot(rng, lo, hi, cameras_W) if rng.uniform() < dist.robot_probability else None
    keep_out = [(b_lo, b_hi) for b_lo, b_hi in boxes]
    if robot is not None:
        keep_out.append((robot.X_WB[:3, 3] - 0.3, robot.X_WB[:3, 3] + 0.3))
    tops = []
    for nb_obj, X in [(obj, np.eye(4))] + [(nb.obj, nb.X_WO) for nb in neighbours]:
        b_lo, b_hi = nb_obj.base_bounds()
        tops.append((np.array([*(b_lo[:2] + X[:2, 3]), b_hi[2]]), b_hi + X[:3, 3]))
    count = int(rng.integers(dist.clutter[0], dist.clutter[1] + 1))
    clutter = _clutter(rng, count, tops, keep_out, np.array([back_x, -half_width]),
                       np.array([front_x - 0.5, half_width]), cameras_W, dist.style)
    centre = (lo + hi) / 2
    lighting = sample_room_lighting(rng, dist.style, centre, ceiling)
    return Room(surfaces, neighbours, clutter, robot, lighting)
