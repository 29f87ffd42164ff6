"""Articulated objects built from primitive parts: geometry, kinematics, keypoints.

Every category (closet, drawer, furniture) samples its parameters and returns an
`ArticulatedObject`: a fixed carcass link and one or more movable fronts (`Front`), each a link on
its own revolute or prismatic joint. The SDFormat writer, the keypoint functions and the semantic
labels are shared by all categories.

Frames (see docs/CONVENTIONS.md): O is the object frame (origin on the floor under the centre of the carcass
footprint, +x out of the front face, +z up). The carcass link's frame is O. The link frame M_k of
front k sits on its joint: at q = 0 it has O's orientation and origin `Front.p_OJ`.

Fronts are in canonical order (docs/FURNITURE.md): columns left to right as seen from the front
(increasing O-frame y, since +x points at the viewer and +z up, the viewer's left is -y), then top
to bottom within a column. "Part k" is `fronts[k]` in the data, the labels and the planner alike.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass, field
from typing import Literal

import numpy as np


class SemanticClass(enum.IntEnum):
    """Label values of the semantic images (docs/CONVENTIONS.md)."""

    BACKGROUND = 0
    CARCASS = 1
    MOVING = 2
    HANDLE = 3


SEMANTIC_CLASS_NAMES = ("background", "carcass", "moving", "handle")

LABELS_PER_PART = 4
"""Render labels of front k are class + LABELS_PER_PART * (k + 1): class = label % 4,
part index = label // 4 - 1 (-1 for the carcass and the background)."""

MAX_FRONTS = 8
"""At most this many fronts per object (labels stay far below Drake's reserved RenderLabels)."""

# Visual and collision names are "<class>__<part>" or "<class>__f<k>__<part>", so a renderer can
# recover the class and the front index of a geometry from its name alone.
_NAME_SEPARATOR = "__"
_FRONT_PREFIX = re.compile(r"^f(\d+)$")


def _local_name(geometry_name: str) -> str:
    return geometry_name.rsplit("::", 1)[-1]


def part_semantic_class(geometry_name: str) -> SemanticClass:
    """Class of a geometry named by `Part.geometry_name` (a Drake scoped name is accepted).

    Raises ValueError for names that this package did not write.
    """
    prefix = _local_name(geometry_name).split(_NAME_SEPARATOR, 1)[0]
    try:
        return SemanticClass[prefix.upper()]
    except KeyError:
        raise ValueError(f"geometry {geometry_name!r} carries no semantic class prefix") from None


def part_index_of(geometry_name: str) -> int:
    """Front index of a geometry: k for "<class>__f<k>__...", -1 for the carcass.

    Moving and handle geometry without an "f<k>" segment (closets, drawers: one front) is front 0.
    """
    if part_semantic_class(geometry_name) == SemanticClass.CARCASS:
        return -1
    segments = _local_name(geometry_name).split(_NAME_SEPARATOR)
    match = _FRONT_PREFIX.match(segments[1]) if len(segments) > 2 else None
    return int(match.group(1)) if match else 0


def render_label_value(geometry_name: str) -> int:
    """RenderLabel value of a geometry: 1 for the carcass, class + 4 (k + 1) for front k's parts."""
    cls = part_semantic_class(geometry_name)
    if cls == SemanticClass.CARCASS:
        return int(cls)
    return int(cls) + LABELS_PER_PART * (part_index_of(geometry_name) + 1)


def front_part_name(index: int, name: str) -> str:
    """Name of a part of front `index` whose geometry name will carry the index ("f2__bar")."""
    return f"f{index}{_NAME_SEPARATOR}{name}"


@dataclass(frozen=True)
class Part:
    """A primitive solid of one link.

    Attributes:
        name: unique within the object.
        semantic: its label class.
        shape: "box" (size = x, y, z extents, m), "cylinder" (size = radius, length along the
            part's z, m) or "sphere" (size = radius,).
        p_LP: position of the part's centre in its link frame L, m.
        rpy_LP: roll-pitch-yaw of the part in L, rad.
        rgba: colour, each channel in [0, 1] (multiplies the texture, if any).
        texture: path of a PNG diffuse map for the visual, or None for a plain colour.
    """

    name: str
    semantic: SemanticClass
    shape: Literal["box", "cylinder", "sphere"]
    size: tuple[float, ...]
    p_LP: tuple[float, float, float]
    rgba: tuple[float, float, float, float]
    rpy_LP: tuple[float, float, float] = (0.0, 0.0, 0.0)
    texture: str | None = None

    @property
    def geometry_name(self) -> str:
        return f"{self.semantic.name.lower()}{_NAME_SEPARATOR}{self.name}"

    def volume(self) -> float:
        if self.shape == "box":
            return float(np.prod(self.size))
        if self.shape == "cylinder":
            r, length = self.size
            return float(np.pi * r**2 * length)
        return float(4.0 / 3.0 * np.pi * self.size[0] ** 3)

    def unit_inertia_about_centre(self) -> np.ndarray:
        """Rotational inertia per unit mass about the part's centre, in L, m^2, shape (3, 3)."""
        if self.shape == "box":
            x, y, z = self.size
            I_P = np.diag([y * y + z * z, x * x + z * z, x * x + y * y]) / 12.0
        elif self.shape == "cylinder":
            r, h = self.size
            I_P = np.diag([(3 * r * r + h * h) / 12.0, (3 * r * r + h * h) / 12.0, r * r / 2.0])
        else:
            I_P = np.eye(3) * 0.4 * self.size[0] ** 2
        R_LP = rotation_from_rpy(self.rpy_LP)
        return R_LP @ I_P @ R_LP.T


def rotation_from_rpy(rpy: tuple[float, float, float]) -> np.ndarray:
    """Rotation matrix of SDFormat/Drake roll-pitch-yaw angles (extrinsic x, then y, then z)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def axis_angle_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by `angle` (rad) about the unit vector `axis` (Rodrigues), shape (3, 3)."""
    a = np.asarray(axis, dtype=float)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


FACE_CORNERS = ("top_left", "top_right", "bottom_left", "bottom_right")
"""Order of `Front.face_corners`."""


@dataclass(frozen=True)
class Front:
    """One movable front (a door or a drawer): a link on one joint, with its keypoints.

    Attributes:
        kind: "door" (revolute) or "drawer" (prismatic).
        link_name, joint_name: names in the SDFormat ("front2", "front2_joint"; closets and
            drawers keep "door"/"door_hinge" and "drawer"/"drawer_slide").
        parts: parts of the link, expressed in its frame M.
        joint_type: "revolute" (q maps to an angle, rad) or "prismatic" (a distance, m).
        p_OJ: joint origin in O (= origin of M at q = 0), m, shape (3,).
        axis_O: unit joint axis in O (and in M, which shares O's orientation at q = 0), shape (3,).
            A drawer's axis is its pull direction.
        joint_upper: joint value at q = 1 (rad or m; a drawer's travel); q = 0 is joint value 0.
        fixed_keypoints: keypoints on the carcass, in O.
        moving_keypoints: keypoints on this link, in M.
        keypoint_names: the order in which keypoints are stacked into arrays.
        grip_axis_M: unit axis of the handle's grip in M (along a bar; any for a knob), shape (3,).
        grip_half_length: half the length of the grip along `grip_axis_M`, m; 0 for a point grip.
        density: kg/m^3 of the link's parts, for its mass and inertia.
        damping: viscous damping of the joint, N m s/rad or N s/m.
        face_M: the front's outer face, a rectangle in M's plane of constant x: (x, y0, y1, z0,
            z1), m (furniture fronts; None for the closet and drawer categories).
    """

    kind: Literal["door", "drawer"]
    link_name: str
    joint_name: str
    parts: tuple[Part, ...]
    joint_type: Literal["revolute", "prismatic"]
    p_OJ: tuple[float, float, float]
    axis_O: tuple[float, float, float]
    joint_upper: float
    fixed_keypoints: dict[str, tuple[float, float, float]]
    moving_keypoints: dict[str, tuple[float, float, float]]
    keypoint_names: tuple[str, ...]
    grip_axis_M: tuple[float, float, float] = (0.0, 0.0, 1.0)
    grip_half_length: float = 0.0
    density: float = 500.0
    damping: float = 2.0
    face_M: tuple[float, float, float, float, float] | None = None

    def joint_value(self, q: float | np.ndarray) -> float | np.ndarray:
        """Joint angle (rad) or travel (m) at articulation q in [0, 1]."""
        return q * self.joint_upper

    def face_corners(self, q: float | np.ndarray) -> np.ndarray:
        """Corners of the outer face in O at articulation q, `FACE_CORNERS` order: shape (4, 3),
        or (N, 4, 3) for N values of q, m. Left and top as seen from the front (smaller y, larger z
        in M, which shares O's orientation at q = 0)."""
        if self.face_M is None:
            raise ValueError(f"{self.link_name}: no face rectangle (not a furniture front)")
        x, y0, y1, z0, z1 = self.face_M
        c_M = np.array([[x, y0, z1], [x, y1, z1], [x, y0, z0], [x, y1, z0]])
        qs = np.atleast_1d(np.asarray(q, dtype=float))
        out = np.stack([c_M @ X[:3, :3].T + X[:3, 3] for X in map(self.X_OM, qs)])
        return out if np.ndim(q) else out[0]

    def X_OM(self, q: float) -> np.ndarray:
        """Pose of this front's link M in O at articulation q, homogeneous, shape (4, 4)."""
        X = np.eye(4)
        v = self.joint_value(q)
        axis = np.asarray(self.axis_O, dtype=float)
        X[:3, 3] = self.p_OJ
        if self.joint_type == "revolute":
            X[:3, :3] = axis_angle_rotation(axis, v)
        else:
            X[:3, 3] = np.asarray(self.p_OJ) + v * axis
        return X

    def keypoints(self, q: float) -> dict[str, np.ndarray]:
        """Keypoint positions in O at articulation q, each shape (3,), m."""
        X_OM = self.X_OM(q)
        out = {}
        for name in self.keypoint_names:
            if name in self.fixed_keypoints:
                out[name] = np.asarray(self.fixed_keypoints[name], dtype=float)
            else:
                p_M = np.asarray(self.moving_keypoints[name], dtype=float)
                out[name] = X_OM[:3, :3] @ p_M + X_OM[:3, 3]
        return out

    def keypoint_array(self, q: float | np.ndarray) -> np.ndarray:
        """Keypoints stacked in `keypoint_names` order: shape (K, 3), or (N, K, 3) for N values of q."""
        qs = np.atleast_1d(np.asarray(q, dtype=float))
        arr = np.stack([np.stack([self.keypoints(qi)[n] for n in self.keypoint_names]) for qi in qs])
        return arr if np.ndim(q) else arr[0]

    def inertia(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass (kg), centre of mass in M (m, (3,)) and inertia about it in M (kg m^2, (3, 3))."""
        masses = np.array([self.density * p.volume() for p in self.parts])
        centres = np.array([p.p_LP for p in self.parts])
        mass = float(masses.sum())
        p_Mcm = (masses[:, None] * centres).sum(0) / mass
        inertia = np.zeros((3, 3))
        for m, c, part in zip(masses, centres, self.parts, strict=True):
            d = c - p_Mcm
            inertia += m * (part.unit_inertia_about_centre() + (d @ d) * np.eye(3) - np.outer(d, d))
        return mass, p_Mcm, inertia


@dataclass(frozen=True)
class ArticulatedObject:
    """One sampled instance of a category: a fixed carcass and its movable fronts.

    Attributes:
        category: "closet", "drawer" or "furniture".
        name: model name in SDFormat.
        base_parts: parts of the carcass link, expressed in O.
        fronts: the movable fronts in canonical order (module docstring); at most MAX_FRONTS.
        params: the sampled parameters, for the record (JSON-serialisable).

    The single-joint attributes (`joint_type`, `p_OJ`, `X_OM`, `keypoints`, ...) are those of the
    only front; they raise ValueError on an object with several fronts (use `front(k)`).
    """

    category: str
    name: str
    base_parts: tuple[Part, ...]
    fronts: tuple[Front, ...]
    params: dict = field(default_factory=dict)

    # Names shared with the SDFormat and everything that loads it.
    base_link_name = "carcass"

    def __post_init__(self):
        if not 1 <= len(self.fronts) <= MAX_FRONTS:
            raise ValueError(f"an object has 1 to {MAX_FRONTS} fronts, got {len(self.fronts)}")
        names = [f.link_name for f in self.fronts] + [f.joint_name for f in self.fronts]
        if len(set(names)) != len(names) or self.base_link_name in names:
            raise ValueError(f"link and joint names of the fronts must be unique: {names}")

    @property
    def num_fronts(self) -> int:
        return len(self.fronts)

    def front(self, k: int) -> Front:
        """Front k in canonical order."""
        return self.fronts[k]

    @property
    def only_front(self) -> Front:
        """The front of a one-front object (closets, drawers); ValueError if there are several."""
        if len(self.fronts) != 1:
            raise ValueError(f"{self.name} has {len(self.fronts)} fronts; the single-joint API "
                             "needs exactly one (use front(k))")
        return self.fronts[0]

    # The single-joint API of one-front objects.
    @property
    def moving_parts(self) -> tuple[Part, ...]:
        return self.only_front.parts

    @property
    def joint_type(self) -> str:
        return self.only_front.joint_type

    @property
    def p_OJ(self) -> tuple[float, float, float]:
        return self.only_front.p_OJ

    @property
    def axis_O(self) -> tuple[float, float, float]:
        return self.only_front.axis_O

    @property
    def joint_upper(self) -> float:
        return self.only_front.joint_upper

    @property
    def fixed_keypoints(self) -> dict[str, tuple[float, float, float]]:
        return self.only_front.fixed_keypoints

    @property
    def moving_keypoints(self) -> dict[str, tuple[float, float, float]]:
        return self.only_front.moving_keypoints

    @property
    def keypoint_names(self) -> tuple[str, ...]:
        return self.only_front.keypoint_names

    @property
    def moving_density(self) -> float:
        return self.only_front.density

    @property
    def joint_damping(self) -> float:
        return self.only_front.damping

    @property
    def moving_link_name(self) -> str:
        return self.only_front.link_name

    @property
    def joint_name(self) -> str:
        return self.only_front.joint_name

    def joint_value(self, q: float | np.ndarray) -> float | np.ndarray:
        """Joint angle (rad) or travel (m) of the only front at articulation q in [0, 1]."""
        return self.only_front.joint_value(q)

    def X_OM(self, q: float) -> np.ndarray:
        """Pose of the only front's link M in O at articulation q, shape (4, 4)."""
        return self.only_front.X_OM(q)

    def keypoints(self, q: float) -> dict[str, np.ndarray]:
        """Keypoint positions of the only front in O at articulation q, each shape (3,), m."""
        return self.only_front.keypoints(q)

    def keypoint_array(self, q: float | np.ndarray) -> np.ndarray:
        """The only front's keypoints: shape (K, 3), or (N, K, 3) for N values of q."""
        return self.only_front.keypoint_array(q)

    def moving_inertia(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass, centre of mass in M and inertia of the only front (`Front.inertia`)."""
        return self.only_front.inertia()

    # The multi-front API.
    def articulation(self, q: float | np.ndarray) -> np.ndarray:
        """q of every front, shape (F,): a scalar applies to all fronts, a vector is checked."""
        if np.ndim(q) and np.shape(q) != (len(self.fronts),):
            raise ValueError(f"expected {len(self.fronts)} articulations, got shape {np.shape(q)}")
        return np.broadcast_to(np.asarray(q, dtype=float), (len(self.fronts),)).copy()

    def joint_values(self, q: float | np.ndarray) -> np.ndarray:
        """Joint value of every front (rad or m), shape (F,), for q of shape () or (F,)."""
        return np.array([f.joint_value(qk) for f, qk in zip(self.fronts, self.articulation(q),
                                                            strict=True)])

    def X_OM_k(self, k: int, q: float) -> np.ndarray:
        """Pose of front k's link in O at its articulation q, shape (4, 4)."""
        return self.fronts[k].X_OM(q)

    def front_keypoints(self, q: float | np.ndarray) -> tuple[dict[str, np.ndarray], ...]:
        """Keypoints in O of every front at articulations q (shape () or (F,)), one dict per front."""
        return tuple(f.keypoints(qk) for f, qk in zip(self.fronts, self.articulation(q), strict=True))

    @property
    def height(self) -> float:
        return float(self.params["height"])

    def look_at_target(self) -> np.ndarray:
        """The point cameras look at: the centre of the carcass's bounding box, in O, m."""
        lo, hi = self.base_bounds()
        return (lo + hi) / 2.0

    def base_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (min, max) of the carcass parts in O, m, each shape (3,)."""
        corners = np.concatenate([_part_corners(p) for p in self.base_parts])
        return corners.min(0), corners.max(0)

    def swept_bounds(self, steps: int = 17) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (min, max) in O of all parts over every articulation, m, each (3,).

        A front's parts depend on its own q only, so the union of each front's sweep (q at `steps`
        points of [0, 1]) bounds every state of the object, doors open included (a door's arc is
        sampled every 90 / (steps - 1) degrees: at 17 steps within 0.12 % of its width)."""
        corners = [np.concatenate([_part_corners(p) for p in self.base_parts])]
        for front in self.fronts:
            local = np.concatenate([_part_corners(p) for p in front.parts])
            for q in np.linspace(0.0, 1.0, steps):
                X_OM = front.X_OM(q)
                corners.append(local @ X_OM[:3, :3].T + X_OM[:3, 3])
        corners = np.concatenate(corners)
        return corners.min(0), corners.max(0)


def _part_corners(part: Part) -> np.ndarray:
    """Corners of the part's bounding box in its link frame, shape (8, 3)."""
    if part.shape == "box":
        half = np.asarray(part.size, dtype=float) / 2
    elif part.shape == "cylinder":
        half = np.array([part.size[0], part.size[0], part.size[1] / 2])
    else:
        half = np.full(3, part.size[0])
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
    return (rotation_from_rpy(part.rpy_LP) @ (signs * half).T).T + np.asarray(part.p_LP)
