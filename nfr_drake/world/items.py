"""Items the arm picks and places: a box, a can or a mug, built from primitives.

Frame I of an item: origin at the centre of its bottom face, +z up, +x the mug's handle direction
(a box's depth axis), +y the axis the fingers close along (the grasp width). Shapes, poses and
masses are what planning (the held item's collision geometry) and simulation (a free body) share.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import (
    AddCompliantHydroelasticProperties,
    AddContactMaterial,
    Box,
    Cylinder,
    ProximityProperties,
    Shape,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import RigidBody, SpatialInertia, UnitInertia

from nfr_drake.errors import NfrDrakeError

ITEM_KINDS = ("box", "can", "mug")
ITEM_MODULUS = 1e7
"""Hydroelastic modulus of an item's collision shapes, Pa (hard plastic, as Drake's hydroelastic
guidance has it for stiff objects). With point contact a can or a mug standing on a closet's
floor rocked on its rim for ever (1-5 cm/s at the end of the run: never 'resting')."""
_MUG_HANDLE = (0.012, 0.025)  # the mug handle's thickness (along y) and reach beyond its wall (along x), m
MAX_GRASP_WIDTH = 0.07
"""Widest item the open gripper (2 x `FINGER_OPEN` = 8 cm) takes with 5 mm to spare each side, m."""


@dataclass(frozen=True)
class Item:
    """One item. Attributes: kind ("box", "can", "mug"); width: extent along y (the grasp width;
    a can's or mug's diameter), m; depth: extent along x (a box's; cans and mugs: the diameter), m;
    height, m; mass, kg; friction: Coulomb coefficient (static = dynamic)."""

    kind: str
    width: float
    depth: float
    height: float
    mass: float
    friction: float = 0.8

    def __post_init__(self) -> None:
        if self.kind not in ITEM_KINDS:
            raise NfrDrakeError(f"item kind must be one of {', '.join(ITEM_KINDS)}, got {self.kind!r}")
        if not 0.0 < self.width <= MAX_GRASP_WIDTH:
            raise NfrDrakeError(f"item width {self.width:.3f} m is outside (0, {MAX_GRASP_WIDTH}] "
                                "(the open gripper's span)")
        if min(self.depth, self.height, self.mass, self.friction) <= 0.0:
            raise NfrDrakeError("item depth, height, mass and friction must be positive")

    def __str__(self) -> str:
        return (f"{self.kind} {100 * self.depth:.1f} x {100 * self.width:.1f} x {100 * self.height:.1f} cm, "
                f"{1000 * self.mass:.0f} g")

    def shapes(self) -> list[tuple[str, Shape, RigidTransform]]:
        """(name, shape, X_IS) of the item's primitives, in frame I."""
        if self.kind == "box":
            return [("body", Box(self.depth, self.width, self.height),
                     RigidTransform([0.0, 0.0, self.height / 2]))]
        r = self.width / 2
        body = ("body", Cylinder(r, self.height), RigidTransform([0.0, 0.0, self.height / 2]))
        if self.kind == "can":
            return [body]
        thick, reach = _MUG_HANDLE
        handle = Box(reach, thick, 0.6 * self.height)
        return [body, ("handle", handle, RigidTransform([r + reach / 2 - 0.002, 0.0, 0.5 * self.height]))]

    @property
    def half_extents(self) -> np.ndarray:
        """Half the bounding box of the item in I about (0, 0, height / 2), m, shape (3,)."""
        reach = _MUG_HANDLE[1] if self.kind == "mug" else 0.0
        return np.array([self.depth / 2 + reach, self.width / 2, self.height / 2])

    def add_to(self, plant: MultibodyPlant, name: str = "item",
               rgba: tuple[float, float, float, float] = (0.85, 0.55, 0.15, 1.0)) -> RigidBody:
        """A free body with the item's collision and visual shapes and a solid-box inertia of its
        bounding box; before Finalize(). The collision shapes are compliant hydroelastic
        (`ITEM_MODULUS`), so the item rests on rigid hydroelastic surfaces on a contact patch."""
        p_Icm = np.array([0.0, 0.0, self.height / 2])
        G_Icm = UnitInertia.SolidBox(*(2 * self.half_extents))
        body = plant.AddRigidBody(name, plant.AddModelInstance(name),
                                  SpatialInertia(self.mass, p_Icm, G_Icm.ShiftFromCenterOfMass(-p_Icm)))
        props = ProximityProperties()
        AddContactMaterial(dissipation=1.0, friction=CoulombFriction(self.friction, self.friction),
                           properties=props)
        AddCompliantHydroelasticProperties(0.005, ITEM_MODULUS, props)
        for part, shape, X_IS in self.shapes():
            plant.RegisterCollisionGeometry(body, X_IS, shape, f"{name}_{part}", props)
            plant.RegisterVisualGeometry(body, X_IS, shape, f"{name}_{part}", np.asarray(rgba))
        return body


def sample_item(rng: np.random.Generator, kind: str | None = None) -> Item:
    """An item of `kind` (default: drawn uniformly) with sizes drawn from `rng`: grasp widths
    4-6.5 cm, heights 8-11 cm, masses 0.1-0.3 kg."""
    kind = kind or ITEM_KINDS[int(rng.integers(len(ITEM_KINDS)))]
    width = float(rng.uniform(0.04, 0.065))
    depth = float(rng.uniform(0.04, 0.07)) if kind == "box" else width
    return Item(kind, width, depth, float(rng.uniform(0.08, 0.11)), float(rng.uniform(0.1, 0.3)))
