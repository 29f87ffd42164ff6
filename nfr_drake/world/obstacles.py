"""Obstacle boxes from a sampled object's collision geometry (true models only).

The planner gets few boxes (each robot geometry is checked against each box at every collision
sample), so parts are merged where the arm cannot go between them:
- each carcass body (furniture parts named `b<n>_...`: its bottom, top, sides, back, partitions,
  dividers and shelves) is one solid box, its bounding box: behind shut fronts the arm never
  reaches into it;
- every other carcass part (a top, a plinth, each leg or foot) is its own box;
- each front other than the moving one gives its slab (panel and frame strips), its handle, and,
  when it is out of its compartment (q > 0), its drawer box: one bounding box each in its link
  frame, posed at its q.
Cylinders and spheres become their bounding boxes. The moving front is left out: the planner
treats it from its keypoints (docs/PLANNING.md).

A loaded model (any SDFormat/URDF file) gives one box per collision geometry instead
(`geometry_obstacles`): its oriented bounding box (`geometry_box`; a mesh's is that of its vertices,
so of the convex hull Drake collides with).
"""

from __future__ import annotations

import re
from collections import defaultdict

import numpy as np
from pydrake.geometry import CalcObb, GeometryId, SceneGraphInspector
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant

from nfr_drake.objects.articulated import ArticulatedObject, Part, SemanticClass, _part_corners
from nfr_drake.world.plan import ObstacleBox

_BODY_PANEL = re.compile(r"^b(\d+)_")


def _bounding_box(name: str, parts: list[Part], X_WL: RigidTransform) -> ObstacleBox:
    """The box bounding `parts` in their link frame L (axis-aligned in L), posed in W."""
    corners = np.concatenate([_part_corners(p) for p in parts])
    lo, hi = corners.min(0), corners.max(0)
    return ObstacleBox(name, hi - lo, RigidTransform(X_WL.rotation(), X_WL @ ((lo + hi) / 2)))


def object_obstacles(obj: ArticulatedObject, X_WO: RigidTransform, q: float | np.ndarray,
                     moving: int, merge: bool = True) -> list[ObstacleBox]:
    """Obstacle boxes in W of `obj` at pose X_WO and articulations q (shape () or (F,)), without
    front `moving`: merged as the module docstring says, or (`merge` False, for comparison) one
    box per part."""
    groups: dict[str, list[Part]] = defaultdict(list)
    for part in obj.base_parts:
        body = _BODY_PANEL.match(part.name) if merge else None
        groups[f"carcass_body{body.group(1)}" if body else f"carcass_{part.name}"].append(part)
    boxes = [_bounding_box(name, parts, X_WO) for name, parts in groups.items()]
    for k, (front, q_k) in enumerate(zip(obj.fronts, obj.articulation(q), strict=True)):
        if k == moving:
            continue
        X_WM = X_WO @ RigidTransform(front.X_OM(q_k))
        if not merge:
            boxes += [_bounding_box(f"front{k}_{p.name}", [p], X_WM) for p in front.parts]
            continue
        slab = [p for p in front.parts if p.semantic == SemanticClass.MOVING and "box_" not in p.name]
        box = [p for p in front.parts if p.semantic == SemanticClass.MOVING and "box_" in p.name]
        handle = [p for p in front.parts if p.semantic == SemanticClass.HANDLE]
        for what, parts in (("slab", slab), ("handle", handle), ("box", box if q_k > 0.0 else [])):
            if parts:
                boxes.append(_bounding_box(f"front{k}_{what}", parts, X_WM))
    return boxes


def distance_to_box(box: ObstacleBox, p_W: np.ndarray) -> np.ndarray:
    """Distances from points p_W (m, shape (N, 3)) to the solid box, m, shape (N,); 0 inside."""
    X_BW = box.X_WB.inverse()
    p_B = (X_BW.rotation().matrix() @ np.asarray(p_W, dtype=float).T).T + X_BW.translation()
    return np.linalg.norm(np.maximum(np.abs(p_B) - np.asarray(box.size) / 2, 0.0), axis=1)



def geometry_box(inspector: SceneGraphInspector,
                 geometry_id: GeometryId) -> tuple[RigidTransform, np.ndarray] | None:
    """The oriented bounding box of a geometry in the frame F it is attached to (its body's): pose
    X_FB of the box's centre and full size (3,), m; None for a half space."""
    obb = CalcObb(inspector.GetShape(geometry_id))
    if obb is None:
        return None
    return inspector.GetPoseInFrame(geometry_id) @ obb.pose(), 2.0 * np.asarray(obb.half_width())


def box_corners(X_FB: RigidTransform, size: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) in F of a box of full `size` (3,) centred at X_FB, m."""
    signs = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    return (X_FB.rotation().matrix() @ (signs * size).T).T + X_FB.translation()


def geometry_obstacles(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context,
                       bodies) -> list[ObstacleBox]:
    """One box in W per collision geometry of `bodies` at the configuration in `plant_context`: its
    oriented bounding box (`geometry_box`), named after the body and the geometry."""
    boxes = []
    for body in bodies:
        X_WBo = plant.EvalBodyPoseInWorld(plant_context, body)
        for geometry_id in plant.GetCollisionGeometriesForBody(body):
            box = geometry_box(inspector, geometry_id)
            if box is not None:
                boxes.append(ObstacleBox(f"{body.name()}_{inspector.GetName(geometry_id)}", box[1],
                                         X_WBo @ box[0]))
    return boxes
