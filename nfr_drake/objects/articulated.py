"""A one-joint articulated object built from primitive parts: geometry, kinematics, keypoints.

Every category (closet, drawer) samples its parameters and returns an `ArticulatedObject`; the
SDFormat writer, the keypoint function and the semantic labels are shared by all categories.

Frames (see DESIGN.md): O is the object frame (origin on the floor under the centre of the carcass
footprint, +x out of the front face, +z up). The carcass link's frame is O. The moving link's frame
M sits on the joint: at q = 0 it has O's orientation and origin `p_OJ`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Literal

import numpy as np


class SemanticClass(enum.IntEnum):
    """Label values of the semantic images (DESIGN.md)."""

    BACKGROUND = 0
    CARCASS = 1
    MOVING = 2
    HANDLE = 3


SEMANTIC_CLASS_NAMES = ("background", "carcass", "moving", "handle")

# Visual and collision names are "<class>__<part>", so a renderer can recover the class of a
# geometry from its name alone.
_NAME_SEPARATOR = "__"


def part_semantic_class(geometry_name: str) -> SemanticClass:
    """Class of a geometry named by `Part.geometry_name` (a Drake scoped name is accepted).

    Raises ValueError for names that this package did not write.
    """
    local_name = geometry_name.rsplit("::", 1)[-1]
    prefix = local_name.split(_NAME_SEPARATOR, 1)[0]
    try:
        return SemanticClass[prefix.upper()]
    except KeyError:
        raise ValueError(f"geometry {geometry_name!r} carries no semantic class prefix") from None


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
        rgba: colour, each channel in [0, 1].
    """

    name: str
    semantic: SemanticClass
    shape: Literal["box", "cylinder", "sphere"]
    size: tuple[float, ...]
    p_LP: tuple[float, float, float]
    rgba: tuple[float, float, float, float]
    rpy_LP: tuple[float, float, float] = (0.0, 0.0, 0.0)

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


@dataclass(frozen=True)
class ArticulatedObject:
    """One sampled instance of a category: a fixed carcass, one moving link, one joint.

    Attributes:
        category: "closet" or "drawer".
        name: model name in SDFormat.
        base_parts: parts of the carcass link, expressed in O.
        moving_parts: parts of the moving link, expressed in M.
        joint_type: "revolute" (q maps to an angle, rad) or "prismatic" (a distance, m).
        p_OJ: joint origin in O, m, shape (3,).
        axis_O: unit joint axis in O (and in M, which shares O's orientation at q = 0), shape (3,).
        joint_upper: joint value at q = 1 (rad or m); q = 0 is joint value 0.
        fixed_keypoints: keypoints on the carcass, in O.
        moving_keypoints: keypoints on the moving link, in M.
        keypoint_names: the order in which keypoints are stacked into arrays.
        params: the sampled parameters, for the record.
        moving_density: kg/m^3 of the moving link's parts, for its inertia.
        joint_damping: viscous damping of the joint, N m s/rad or N s/m.
    """

    category: str
    name: str
    base_parts: tuple[Part, ...]
    moving_parts: tuple[Part, ...]
    joint_type: Literal["revolute", "prismatic"]
    p_OJ: tuple[float, float, float]
    axis_O: tuple[float, float, float]
    joint_upper: float
    fixed_keypoints: dict[str, tuple[float, float, float]]
    moving_keypoints: dict[str, tuple[float, float, float]]
    keypoint_names: tuple[str, ...]
    params: dict = field(default_factory=dict)
    moving_density: float = 500.0
    joint_damping: float = 2.0

    # Names shared with the SDFormat and everything that loads it.
    base_link_name = "carcass"

    @property
    def moving_link_name(self) -> str:
        return "door" if self.joint_type == "revolute" else "drawer"

    @property
    def joint_name(self) -> str:
        return "door_hinge" if self.joint_type == "revolute" else "drawer_slide"

    @property
    def height(self) -> float:
        return float(self.params["height"])

    def joint_value(self, q: float | np.ndarray) -> float | np.ndarray:
        """Joint angle (rad) or travel (m) at articulation q in [0, 1]."""
        return q * self.joint_upper

    def X_OM(self, q: float) -> np.ndarray:
        """Pose of the moving link M in O at articulation q, homogeneous, shape (4, 4)."""
        X = np.eye(4)
        v = self.joint_value(q)
        axis = np.asarray(self.axis_O)
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

    def look_at_target(self) -> np.ndarray:
        """The point cameras look at: the carcass centre, in O, m."""
        return np.array([0.0, 0.0, self.height / 2.0])

    def moving_inertia(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass (kg), centre of mass in M (m, (3,)) and inertia about it in M (kg m^2, (3, 3))."""
        masses = np.array([self.moving_density * p.volume() for p in self.moving_parts])
        centres = np.array([p.p_LP for p in self.moving_parts])
        mass = float(masses.sum())
        p_Mcm = (masses[:, None] * centres).sum(0) / mass
        inertia = np.zeros((3, 3))
        for m, c, part in zip(masses, centres, self.moving_parts, strict=True):
            d = c - p_Mcm
            inertia += m * (part.unit_inertia_about_centre() + (d @ d) * np.eye(3) - np.outer(d, d))
        return mass, p_Mcm, inertia
