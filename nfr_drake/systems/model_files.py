"""A user's model file (SDFormat or URDF) made fit to plan on, or refused with one line that says
what to change (`SceneObject.from_model_file` composes these).

- Loading (`add_model_file`): one model; the root of the articulated joint's tree welded at X_WO
  (not the joint's parent, which may sit deeper); bodies without a joint to that tree fixed to it
  as drawn; a model attached to Drake's world (a root link named `world`) refused.
- The joint (`shut_and_open`, `shut_by_geometry`): which limit is shut. Rule: the limit nearer the
  joint's zero, the position the model is drawn in; refused as unclear when both are about as near
  (`--closed-at`); overruled when the handle is clearly nearer the rest of the model at the other.
- Massless moving parts (`massless_parts`): a door or drawer whose bodies have no mass gets
  `MASSLESS_DENSITY` over its geometry's boxes (Drake's solver needs a positive mass matrix).
- The handle (`handle_grip`, `handle_notes`, `check_handle_stands_out`): the centre of its grip
  (its geometry's bounding box's middle across, half its thickness in from its outermost face:
  a bar's axis, not the middle of the bar and its posts), and its bar axis when the geometry is
  elongated; a flush pull refused.
- Sliding doors (`slide_front_normal`): a prismatic joint whose handle stands out of its part
  across the slide axis slides sideways: the hand comes from the front.
- Placement (`check_placement`): height, up axis (the joint's axis), floor; a refusal suggests the
  `--object-xyz` / `--object-rpy-deg` that fix it.
- Meshes (`mesh_problems`): Drake collides with a mesh's convex hull; a concave one is reported and
  one whose hull covers the handle refused. Drake's VTK renderer draws an .obj only with vertex
  normals and PNG textures: `drawable_obj` writes a copy it draws for the cameras.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from pydrake.geometry import (
    GeometryInstance,
    IllustrationProperties,
    Mesh,
    PerceptionProperties,
    ReadObjToTriangleSurfaceMesh,
    Rgba,
    Role,
    SceneGraph,
    SceneGraphInspector,
)
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, SpatialInertia

from nfr_drake.errors import NfrDrakeError
from nfr_drake.parsing import make_parser
from nfr_drake.world.obstacles import box_corners, geometry_box

MASSLESS_DENSITY = 500.0
"""Density given to a massless moving part's bounding box, kg/m^3 (chipboard is 600-700)."""
MAX_HEIGHT, MIN_HEIGHT = 3.0, 0.05
"""Heights of a piece of furniture in metres that are plausible, m."""
SINK_TOLERANCE = 0.005
"""How far below the floor a model's lowest point may lie (a mesh exported 1-2 mm low), m."""
FLOAT_NOTICE = 0.05
"""A model whose lowest point is higher above the floor than this is noted (a wall cabinet?), m."""
MAX_AXIS_TILT_DEG = 30.0
"""A hinge more than this from vertical, or a slide less than 90 minus this from it, is refused."""
INWARD_COS = 0.2
"""A handle whose first move points this much (cosine) towards the rest of the model is refused."""
SHUT_EVIDENCE = 0.05
"""How much nearer the rest of the model the handle must be at the open limit than at the shut one
the rule picks for the geometry to overrule it, m."""
CONCAVE_FILL = 0.9
"""A closed .obj mesh filling less than this fraction of its convex hull is reported as concave."""
MIN_HANDLE_REACH = 0.01
"""How far a handle's geometry must reach out of its part's for the fingers to close on it, m."""
MAX_HANDLE_WIDTH = 0.2
"""A handle body whose geometry is wider than this both ways across its length (a door, not a bar)
is noted, m."""
_Z = np.array([0.0, 0.0, 1.0])
_UPRIGHTS = [RotationMatrix.MakeXRotation(np.pi / 2), RotationMatrix.MakeYRotation(-np.pi / 2),
             RotationMatrix.MakeXRotation(-np.pi / 2), RotationMatrix.MakeYRotation(np.pi / 2),
             RotationMatrix.MakeXRotation(np.pi)]
"""Rotations tried to stand a model up, Y-up exports first (y -> z)."""


@dataclass(frozen=True)
class AddedMass:
    """Mass given to a massless body: a solid box of full `size` (3,), m, centred at p_BC in the
    body's frame B, of `mass` kg."""

    body_name: str
    mass: float
    size: tuple[float, float, float]
    p_BC: tuple[float, float, float]


def add_model_file(plant: MultibodyPlant, path: Path, joint_name: str, handle_body_name: str,
                   X_WO: RigidTransform, added_masses: tuple[AddedMass, ...] = ()) -> ModelInstanceIndex:
    """Parse the model into `plant` (before Finalize) as the module docstring says; returns its instance."""
    try:
        models = make_parser(plant, "object").AddModels(str(path))
    except RuntimeError as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise NfrDrakeError(
            f"Drake could not load {path}: {first}\n  Drake reads SDFormat (.sdf) and URDF "
            "(.urdf) whose meshes are .obj, .gltf/.glb or .vtk; convert other meshes (e.g. "
            ".stl, .dae) to .obj or .gltf (meshlab, blender or trimesh do this), or replace "
            "collision meshes with primitives, and check package:// paths resolve.") from None
    if len(models) != 1:
        raise NfrDrakeError(f"{path} holds {len(models)} models; give a file with one")
    model = models[0]
    if not plant.HasJointNamed(joint_name, model):
        names = [plant.get_joint(j).name() for j in plant.GetJointIndices(model)]
        raise NfrDrakeError(f"{path} has no joint {joint_name!r}; its joints: {names}")
    if not plant.HasBodyNamed(handle_body_name, model):
        names = [plant.get_body(b).name() for b in plant.GetBodyIndices(model)]
        raise NfrDrakeError(f"{path} has no body {handle_body_name!r}; its bodies: {names}")
    world = plant.world_body().index()
    joints = [plant.get_joint(j) for j in plant.GetJointIndices(model)]
    for joint in joints:
        if world in (joint.parent_body().index(), joint.child_body().index()):
            raise NfrDrakeError(
                f"{path}: joint {joint.name()!r} attaches the model to 'world', which Drake takes for "
                "its own world (a link named 'world' is not a body), so the model cannot be placed: "
                "rename that link (e.g. to 'base') or remove the joint, then place it with --object-xyz")
    root = tree_root(plant, model, plant.GetJointByName(joint_name, model).parent_body())
    X_WR0 = plant.GetDefaultFloatingBaseBodyPose(root)
    for other in free_roots(plant, model, root):  # fixed to the root as drawn
        plant.WeldFrames(root.body_frame(), other.body_frame(),
                         X_WR0.inverse() @ plant.GetDefaultFloatingBaseBodyPose(other))
    plant.WeldFrames(plant.world_frame(), root.body_frame(), X_WO)
    for added in added_masses:
        body = plant.GetBodyByName(added.body_name, model)
        extra = plant.AddRigidBody(f"{added.body_name}_added_mass", model,
                                   SpatialInertia.SolidBoxWithMass(added.mass, *added.size))
        plant.WeldFrames(body.body_frame(), extra.body_frame(), RigidTransform(np.asarray(added.p_BC)))
    return model


def _parents(plant: MultibodyPlant, model: ModelInstanceIndex) -> dict:
    """Body index -> parent body index over the model's joints."""
    return {plant.get_joint(j).child_body().index(): plant.get_joint(j).parent_body().index()
            for j in plant.GetJointIndices(model)}


def tree_root(plant: MultibodyPlant, model: ModelInstanceIndex, body):
    """The body at the root of `body`'s tree of joints (before Finalize)."""
    parents = _parents(plant, model)
    index = body.index()
    while index in parents:
        index = parents[index]
    return plant.get_body(index)


def free_roots(plant: MultibodyPlant, model: ModelInstanceIndex, root) -> list:
    """The model's bodies other than `root` with no parent joint: Drake would let them fall."""
    parents = _parents(plant, model)
    return [plant.get_body(b) for b in plant.GetBodyIndices(model)
            if b not in parents and b != root.index()]


def shut_and_open(joint, closed_at: str | None) -> tuple[float, float]:
    """Joint values (rad or m) at q = 0 (shut) and q = 1 (fully open): `closed_at` "lower" or
    "upper", or None for the rule of the module docstring."""
    lower, upper = float(joint.position_lower_limits()[0]), float(joint.position_upper_limits()[0])
    if closed_at is None:
        if abs(abs(lower) - abs(upper)) <= 0.1 * (upper - lower):
            raise NfrDrakeError(
                f"joint {joint.name()!r}: which limit is shut is unclear (lower {lower:.3g} and upper "
                f"{upper:.3g} are about as far from the position the model is drawn in, 0); give "
                "--closed-at lower or --closed-at upper")
        closed_at = "lower" if abs(lower) < abs(upper) else "upper"
    return (lower, upper) if closed_at == "lower" else (upper, lower)


def shut_by_geometry(handle_at: Callable[[float], np.ndarray], static_box: tuple[np.ndarray, np.ndarray],
                     shut: float, opened: float, joint_name: str) -> tuple[float, float, list[str]]:
    """The rule's (shut, open) joint values, swapped when the handle is more than `SHUT_EVIDENCE`
    nearer the box bounding the parts that do not move (lo, hi in W, m) at the open one (a model
    drawn open), with a note saying so. `handle_at(value)`: the handle in W, m, at a joint value."""
    lo, hi = static_box
    distances = [float(np.linalg.norm(np.maximum(lo - p, 0.0) + np.maximum(p - hi, 0.0)))
                 for p in (handle_at(shut), handle_at(opened))]
    if distances[0] <= distances[1] + SHUT_EVIDENCE:
        return shut, opened, []
    return opened, shut, [
        f"joint {joint_name!r} is taken as shut at {opened:.3g}, where its handle is "
        f"{(distances[0] - distances[1]) * 100:.0f} cm nearer the rest of the model than at {shut:.3g} "
        "(the model is drawn open?); --closed-at says otherwise"]


def check_opens_outward(handle_at: Callable[[float], np.ndarray], p_WS: np.ndarray, shut: float,
                        opened: float, joint_name: str) -> None:
    """Refuse a door or drawer whose handle first moves towards the centre p_WS (W, m) of the parts
    that do not move, horizontally (more than `INWARD_COS` of its way): its axis or limits point
    the wrong way. `handle_at(value)`: the handle in W, m, at a joint value."""
    p0 = handle_at(shut)
    step, out = (handle_at(shut + 0.1 * (opened - shut)) - p0) * [1, 1, 0], (p0 - p_WS) * [1, 1, 0]
    if np.linalg.norm(step) > 1e-9 and np.linalg.norm(out) > 1e-9 and \
            step @ out < -INWARD_COS * np.linalg.norm(step) * np.linalg.norm(out):
        raise NfrDrakeError(
            f"joint {joint_name!r} moves its handle into the model as it opens (from {shut:.3g} towards "
            f"{opened:.3g}): its axis or its limits point the wrong way; negate the axis (or the limits "
            "and their order) in the model")


def body_box(plant: MultibodyPlant, inspector: SceneGraphInspector, body,
             required: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """Corners lo, hi (3,) in the body's frame of the box bounding its geometries (collision ones,
    else visual ones), m; None when it has none. Meshes Drake cannot measure (formats other than
    .obj, .gltf, .vtk, which it accepts for visuals) are left out, or, when `required` and they
    are all the body has, refused."""
    frame_id = plant.GetBodyFrameIdOrThrow(body.index())
    unreadable = []
    for role in (Role.kProximity, Role.kIllustration):
        corners = []
        for g in inspector.GetGeometries(frame_id, role):
            try:
                box = geometry_box(inspector, g)
            except RuntimeError:
                unreadable.append(Path(inspector.GetShape(g).source().path()).name)
                continue
            if box is not None:
                corners.append(box_corners(*box))
        if corners:
            corners = np.concatenate(corners)
            return corners.min(axis=0), corners.max(axis=0)
    if required and unreadable:
        raise NfrDrakeError(f"the mesh {unreadable[0]} of body {body.name()!r} cannot be measured (Drake "
                            "reads .obj, .gltf and .vtk meshes): convert it to .obj or .gltf")
    return None


def _bodies_box(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context, bodies,
                frame) -> tuple[np.ndarray, np.ndarray] | None:
    """lo, hi (3,) in `frame` of the box bounding the geometries of `bodies`, m; None if none."""
    X_FW = frame.CalcPoseInWorld(plant_context).inverse()
    corners = []
    for body in bodies:
        box = body_box(plant, inspector, body)
        if box is not None:
            X_FB = X_FW @ plant.EvalBodyPoseInWorld(plant_context, body)
            corners.append(box_corners(X_FB @ RigidTransform((box[0] + box[1]) / 2), box[1] - box[0]))
    if not corners:
        return None
    corners = np.concatenate(corners)
    return corners.min(axis=0), corners.max(axis=0)


def massless_parts(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context,
                   model: ModelInstanceIndex) -> list[AddedMass]:
    """For each joint of the model that moves bodies of no mass in all (its child and what is
    welded to it), the mass its child gets: the volume of their geometries' bounding boxes at
    `MASSLESS_DENSITY` (at least that of a 2 cm cube), as a solid box the size of their bounding
    box (at least 2 cm a side)."""
    added = []
    for index in plant.GetJointIndices(model):
        joint = plant.get_joint(index)
        if joint.num_velocities() == 0:
            continue
        child = joint.child_body()
        group = plant.GetBodiesWeldedTo(child)
        if sum(b.default_mass() for b in group) > 1e-6:
            continue
        box = _bodies_box(plant, inspector, plant_context, group, child.body_frame())
        lo, hi = box if box is not None else (np.full(3, -0.01), np.full(3, 0.01))
        size = np.maximum(hi - lo, 0.02)
        volume = sum(float(np.prod(box[1])) for b in group
                     for g in inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(b.index()), Role.kProximity)
                     for box in [geometry_box(inspector, g)] if box is not None)
        added.append(AddedMass(child.name(), MASSLESS_DENSITY * max(volume, 0.02 ** 3), tuple(size),
                               tuple((lo + hi) / 2)))
    return added


def handle_grip(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context, joint,
                body) -> tuple[np.ndarray, np.ndarray | None, float]:
    """The handle in its body's frame B: its grip centre p_BH, m, (3,) (`grip_centre`; the body's
    origin when it has no geometry); the unit bar axis (3,) when its geometry's box in B has a
    longest side at least twice the next (else None); half that side, m."""
    box = body_box(plant, inspector, body, required=True)
    if box is None:
        return np.zeros(3), None, 0.0
    lo, hi = box
    p_BH = grip_centre(plant, inspector, plant_context, joint, body, (lo + hi) / 2)
    extent = hi - lo
    order = np.argsort(extent)[::-1]
    if extent[order[0]] < 2.0 * extent[order[1]]:
        return p_BH, None, 0.0
    return p_BH, np.eye(3)[order[0]], float(extent[order[0]] / 2)


def grip_centre(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context, joint, body,
                p_BH: np.ndarray) -> np.ndarray:
    """Where a hand closes on the handle, in its body's frame B, m, (3,): in the joint's child
    frame C, the middle of the handle's box across the direction it stands out of its part most,
    and along that direction its outermost face less half its thickness (the smaller of the box's
    two other sides: a bar's or a knob's diameter), no deeper than the box's middle. A bar on
    posts has its box's middle between the bar and the door, where the fingers would close on the
    posts' ends; this is the bar's axis. p_BH (the box's middle) is kept where the part has no
    geometry but the handle."""
    boxes = _part_frame_boxes(plant, inspector, plant_context, joint, body)
    if boxes is None:
        return p_BH
    part, (h_lo, h_hi), X_WC = boxes
    face = int(np.argmax(_reach_per_face(part, (h_lo, h_hi))))
    axis, sign = face % 3, (1.0 if face < 3 else -1.0)
    across = [a for a in range(3) if a != axis]
    half = min(h_hi[a] - h_lo[a] for a in across) / 2
    p_CH = (h_lo + h_hi) / 2
    outer = h_hi[axis] if sign > 0 else h_lo[axis]
    p_CH[axis] = outer - sign * min(half, abs(outer - p_CH[axis]))
    X_BC = plant.EvalBodyPoseInWorld(plant_context, body).inverse() @ X_WC
    return X_BC @ p_CH


def handle_notes(plant: MultibodyPlant, inspector: SceneGraphInspector, body) -> list[str]:
    """Notes on a handle body that is no handle: one with no geometry, or one whose geometry's
    box is wider than `MAX_HANDLE_WIDTH` both ways across its longest side (the door itself?)."""
    box = body_box(plant, inspector, body)
    if box is None:
        return [f"the handle body {body.name()!r} has no geometry: its origin is taken as the handle"]
    extent = np.sort(box[1] - box[0])[::-1]
    if extent[1] > MAX_HANDLE_WIDTH:
        return [f"the handle body {body.name()!r} is {extent[0]:.2f} m by {extent[1]:.2f} m: the hand grips "
                "the centre of its geometry; give --handle-body a body that holds only the handle"]
    return []


def _part_frame_boxes(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context, joint,
                      handle_body) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray],
                                            RigidTransform] | None:
    """In the joint's child frame C: the box (lo, hi) bounding the moving part's geometry without
    the handle body, the handle body's box, and X_WC; None when either has no geometry."""
    child = joint.child_body()
    bodies = [plant.get_body(b) for b in plant.GetBodiesKinematicallyAffectedBy([joint.index()])
              if b != handle_body.index()]
    part = _bodies_box(plant, inspector, plant_context, bodies, child.body_frame())
    handle = _bodies_box(plant, inspector, plant_context, [handle_body], child.body_frame())
    if part is None or handle is None:
        return None
    return part, handle, plant.EvalBodyPoseInWorld(plant_context, child)


def _reach_per_face(part: tuple[np.ndarray, np.ndarray], handle: tuple[np.ndarray, np.ndarray]
                    ) -> np.ndarray:
    """How far the handle's box (lo, hi) stands out past each face of the part's box (lo, hi), one
    frame, m, (6,): the +x, +y, +z faces, then -x, -y, -z (negative: inside)."""
    return np.concatenate([handle[1] - part[1], part[0] - handle[0]])


def check_handle_stands_out(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context, joint,
                            handle_body) -> None:
    """Refuse a handle whose geometry reaches less than `MIN_HANDLE_REACH` out of the box of the
    part's other geometry: a flush or recessed pull, which a parallel gripper cannot close on."""
    boxes = _part_frame_boxes(plant, inspector, plant_context, joint, handle_body)
    if boxes is None:
        return
    part, handle, _ = boxes
    reach = float(np.max(_reach_per_face(part, handle)))
    if reach < MIN_HANDLE_REACH:
        raise NfrDrakeError(
            f"the handle body {handle_body.name()!r} reaches {max(reach, 0.0) * 100:.1f} cm out of its part "
            f"(a flush or recessed pull): the gripper closes on handles standing at least "
            f"{MIN_HANDLE_REACH * 100:.0f} cm out; give --handle-body such a handle")


def slide_front_normal(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context, joint,
                       handle_body, axis_W: np.ndarray) -> np.ndarray | None:
    """The outward normal (3,) in W of a sliding door's front, or None for a drawer.

    The centre of the handle's box stands out of the box bounding the part's other geometry (in
    the joint's child frame) along one of its axes: across the slide and horizontally for a sliding
    door, along the slide for a drawer. No such side (or no geometry): a drawer."""
    boxes = _part_frame_boxes(plant, inspector, plant_context, joint, handle_body)
    if boxes is None:
        return None
    (lo, hi), (h_lo, h_hi), X_WC = boxes
    p_CH = (h_lo + h_hi) / 2
    excess = np.maximum(np.maximum(p_CH - hi, lo - p_CH), 0.0)
    side = int(np.argmax(excess))
    if excess[side] < 0.005:
        return None
    n_W = X_WC.rotation() @ (np.eye(3)[side] * np.sign(p_CH[side] - (lo[side] + hi[side]) / 2))
    return n_W if abs(n_W @ axis_W) < 0.5 and abs(n_W @ _Z) < 0.5 else None


def _axis_upright(axis_W: np.ndarray, revolute: bool) -> bool:
    tilt = np.degrees(np.arccos(np.clip(abs(axis_W @ _Z), 0.0, 1.0)))
    return tilt <= MAX_AXIS_TILT_DEG if revolute else tilt >= 90.0 - MAX_AXIS_TILT_DEG


def check_placement(corners_W: np.ndarray, X_WO: RigidTransform, axis_W: np.ndarray,
                    revolute: bool) -> list[str]:
    """Refuse a model not in metres, lying on its side or sunk into the floor, suggesting the pose
    options that fix it; returns notes (one line each) for what is only unusual.

    corners_W: corners (N, 3) in W of the model's geometry boxes, shut, m; axis_W: the joint's unit
    axis in W."""
    lo, hi = corners_W.min(axis=0), corners_W.max(axis=0)
    height = float(hi[2] - lo[2])
    if not MIN_HEIGHT <= height <= MAX_HEIGHT:
        unit = "centimetres or millimetres" if height > MAX_HEIGHT else "a unit larger than metres"
        raise NfrDrakeError(
            f"the model is {height:.3g} m tall at this pose: is it in {unit}? Furniture is "
            f"{MIN_HEIGHT}-{MAX_HEIGHT} m tall; scale the model's lengths (geometry, poses, prismatic "
            "limits, mesh scale) to metres")
    p_WO = X_WO.translation()
    R = RotationMatrix.Identity()
    if not _axis_upright(axis_W, revolute):
        upright = [Rc for Rc in _UPRIGHTS if _axis_upright(Rc @ axis_W, revolute)]
        R = upright[0] if upright else R
    z_low = float(((R.matrix() @ (corners_W - p_WO).T).T + p_WO)[:, 2].min())
    xyz = np.round(p_WO - [0.0, 0.0, z_low], 3)
    pose = "--object-xyz " + " ".join(f"{v:.3g}" for v in xyz + 0.0)
    if not R.IsExactlyIdentity():
        rpy = np.degrees(RollPitchYaw(R @ X_WO.rotation()).vector())
        kind = "hinge" if revolute else "slide"
        raise NfrDrakeError(
            f"the joint's {kind} axis {np.round(axis_W, 3).tolist()} is "
            f"{'not vertical' if revolute else 'vertical'}: the model lies on its side (exported "
            f"Y-up?); stand it up with --object-rpy-deg {' '.join(f'{v:.0f}' for v in rpy + 0.0)} "
            f"{pose} (the planner opens doors on vertical hinges and drawers on horizontal slides)")
    if lo[2] < -SINK_TOLERANCE:
        raise NfrDrakeError(f"the model's lowest point is {-lo[2] * 100:.1f} cm below the floor "
                            f"(z = 0): lift it onto the floor with {pose}")
    if lo[2] > FLOAT_NOTICE:
        return [f"the model's lowest point is {lo[2] * 100:.0f} cm above the floor (a wall cabinet? "
                f"{pose} stands it on the floor)"]
    return []


def _volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Volume enclosed by outward triangles (M, 3) of vertices (V, 3), m^3."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return float(abs(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)


def _hull(inspector: SceneGraphInspector, geometry_id) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Vertices (V, 3) in the geometry's frame, faces (lists of vertex indices) and their outward
    unit normals (F, 3) of its convex hull."""
    hull = inspector.GetConvexHull(geometry_id)
    vertices = np.array([hull.vertex(v) for v in range(hull.num_vertices())])
    faces = [np.array([hull.element(f).vertex(k) for k in range(hull.element(f).num_vertices())])
             for f in range(hull.num_elements())]
    return vertices, faces, np.array([hull.face_normal(f) for f in range(hull.num_elements())])


def mesh_problems(plant: MultibodyPlant, inspector: SceneGraphInspector, plant_context,
                  model: ModelInstanceIndex, moving: set, p_WH: np.ndarray) -> list[str]:
    """Notes on concave collision meshes (Drake collides with their convex hulls); refuses a mesh
    on a part that does not move (`moving`: body indices) whose hull covers the handle point p_WH."""
    notes = []
    for index in plant.GetBodyIndices(model):
        body = plant.get_body(index)
        for g in plant.GetCollisionGeometriesForBody(body):
            shape = inspector.GetShape(g)
            if not isinstance(shape, Mesh) or not shape.source().is_path():
                continue
            name = Path(shape.source().path()).name
            vertices, faces, normals = _hull(inspector, g)
            X_GW = (plant.EvalBodyPoseInWorld(plant_context, body) @ inspector.GetPoseInFrame(g)).inverse()
            p_GH = X_GW @ p_WH
            inside = all(n @ (p_GH - vertices[f[0]]) <= 0.0 for f, n in zip(faces, normals, strict=True))
            if inside and index not in moving:
                raise NfrDrakeError(
                    f"the collision mesh {name} of body {body.name()!r} covers the handle: Drake "
                    "collides with a mesh's convex hull, not the mesh, so the hand cannot reach the "
                    "handle; split it into convex pieces (one mesh or box per panel) in the model's "
                    "collision elements")
            if Path(name).suffix.lower() != ".obj":
                continue
            try:
                mesh = ReadObjToTriangleSurfaceMesh(shape.source().path(), shape.scale3())
            except RuntimeError:  # e.g. several objects in one file: its concavity stays unmeasured
                continue
            tris = np.array([[mesh.element(t).vertex(k) for k in range(3)]
                             for t in range(mesh.num_elements())])
            mesh_vertices = np.array([mesh.vertex(v) for v in range(mesh.num_vertices())])
            hull_tris = np.array([[f[0], f[k], f[k + 1]] for f in faces for k in range(1, len(f) - 1)])
            fill = _volume(mesh_vertices, tris) / max(_volume(vertices, hull_tris), 1e-12)
            if fill < CONCAVE_FILL:
                notes.append(f"the collision mesh {name} of body {body.name()!r} is concave (fills "
                             f"{fill:.0%} of its convex hull): Drake collides with the hull")
    return notes


def _tagged(path: Path, folder: Path, suffix: str) -> Path:
    """A file in `folder` (made if missing) named after `path` and a hash of its absolute path
    (one copy per file)."""
    Path(folder).mkdir(parents=True, exist_ok=True)
    tag = hashlib.sha1(str(Path(path).resolve()).encode()).hexdigest()[:10]
    return Path(folder) / f"{Path(path).stem}_{tag}{suffix}"


def _write_whole(path: Path, data: str | bytes) -> None:
    """Write `data` (text or bytes) to `path` at once (a file beside it, then renamed): another
    process drawing the same model never reads a half-written copy."""
    part = path.with_name(f"{path.name}.{os.getpid()}.part")
    part.write_bytes(data.encode() if isinstance(data, str) else data)
    os.replace(part, path)


def _png_materials(mtl: Path, folder: Path) -> tuple[Path, list[str]]:
    """The material library `mtl` with every texture map in PNG (Drake's VTK renderer draws only
    PNG maps; a JPEG one leaves the face white and misdrawn), and the names of the maps that were
    not: where one was not, a copy of the library in `folder` naming PNG copies of all its maps,
    beside it in `folder` (the renderer reads a map beside its library); else (`mtl`, [])."""
    lines = mtl.read_text().splitlines()
    maps = [(mtl.parent / line.split()[-1]).resolve() for line in lines
            if line.split()[:1] and line.split()[0].startswith("map_") and len(line.split()) > 1]
    copied = [m.name for m in maps if m.suffix.lower() != ".png" and m.is_file()]
    if not copied:
        return mtl, []
    out = []
    for line in lines:
        tokens = line.split()
        if tokens and tokens[0].startswith("map_") and len(tokens) > 1:
            texture = (mtl.parent / tokens[-1]).resolve()
            image = cv2.imread(str(texture), cv2.IMREAD_UNCHANGED)
            if image is not None:
                png = _tagged(texture, folder, ".png")
                _write_whole(png, cv2.imencode(".png", image)[1].tobytes())
                line = " ".join([*tokens[:-1], png.name])
        out.append(line)
    copy = _tagged(mtl, folder, "_png.mtl")
    _write_whole(copy, "\n".join(out) + "\n")
    return copy, copied


def drawable_obj(path: Path, folder: Path) -> tuple[Path, list[str]] | None:
    """A copy in `folder` of the Wavefront .obj at `path` that Drake's VTK renderer draws, and what
    it changed; None when the file needs none. The renderer refuses an .obj without vertex normals:
    the copy gives each face its normal (flat shading: the normal of its first triangle, 'vn' lines
    first, faces as v/vt/vn). It draws only PNG texture maps: the copy's material library names PNG
    copies of the others (`_png_materials`). Its material library is referred to where it lies."""
    path = Path(path)
    lines = path.read_text().splitlines()
    normals_missing = not any(line.startswith("vn ") for line in lines)
    vertices = [np.array(line.split()[1:4], float) for line in lines if line.startswith("v ")]
    out, normals, changed = [], [], []
    for line in lines:
        tokens = line.split()
        if tokens[:1] == ["mtllib"]:
            mtl, copied = _png_materials((path.parent / " ".join(tokens[1:])).resolve(), folder)
            changed += [f"a texture that is not a PNG ({name})" for name in copied]
            out.append(f"mtllib {mtl.name if copied else mtl}")  # a copy lies beside the obj's copy
        elif tokens[:1] == ["f"] and normals_missing:
            corners = [t.split("/") for t in tokens[1:]]
            index = [int(c[0]) - 1 if int(c[0]) > 0 else len(vertices) + int(c[0]) for c in corners]
            p0, p1, p2 = (vertices[i] for i in index[:3])
            n = np.cross(p1 - p0, p2 - p0)
            normals.append(n / max(float(np.linalg.norm(n)), 1e-12))
            uv = [c[1] if len(c) > 1 else "" for c in corners]
            k = len(normals)
            out.append("f " + " ".join(f"{c[0]}/{t}/{k}" for c, t in zip(corners, uv, strict=True)))
        else:
            out.append(line)
    if normals_missing:
        changed.insert(0, "no vertex normals")
    if not changed:
        return None
    copy = _tagged(path, folder, "_drawable.obj")
    _write_whole(copy, "\n".join([f"vn {n[0]:.6f} {n[1]:.6f} {n[2]:.6f}" for n in normals] + out) + "\n")
    return copy, changed


def stl_as_obj(path: Path, folder: Path) -> Path:
    """A Wavefront .obj copy in `folder` of the STL mesh (binary or ASCII) at `path`, with each
    triangle's normal from its winding: Drake's VTK renderer ignores an STL visual (a model exported
    for ROS would be photographed without it)."""
    data = Path(path).read_bytes()
    count = int(np.frombuffer(data[80:84], "<u4")[0]) if len(data) >= 84 else -1
    if count >= 0 and len(data) == 84 + 50 * count:  # binary: 80-byte header, count, 50 bytes each
        records = np.frombuffer(data[84:], np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
        triangles = records["v"].astype(float)
    else:
        vertices = [line.split()[1:4] for line in data.decode(errors="replace").splitlines()
                    if line.strip().startswith("vertex")]
        triangles = np.array(vertices, float).reshape(-1, 3, 3)
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    lines = [f"v {x:.6g} {y:.6g} {z:.6g}" for x, y, z in triangles.reshape(-1, 3)]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
    lines += [f"f {3 * t + 1}//{t + 1} {3 * t + 2}//{t + 1} {3 * t + 3}//{t + 1}"
              for t in range(len(triangles))]
    copy = _tagged(path, folder, "_stl.obj")
    _write_whole(copy, "\n".join(lines) + "\n")
    return copy


def drawable_meshes(plant: MultibodyPlant, scene_graph: SceneGraph, model: ModelInstanceIndex,
                    folder: Path) -> list[str]:
    """For the cameras, each mesh of `model` that the renderer sees and cannot draw as it is
    swapped for a copy it can, in `folder` (an .obj without normals or with textures that are not
    PNG: `drawable_obj`; an STL, which the renderer ignores: `stl_as_obj`): the copy is registered
    as a visual geometry of the same body, at the same pose and scale, in the same diffuse colour,
    and the original loses its perception role (it keeps the others). Call before `Finalize`. One
    note per mesh swapped, and one per mesh the renderer ignores that is not swapped (formats
    other than .obj, .gltf, .stl: the cameras do not see it)."""
    inspector = scene_graph.model_inspector()
    swaps, notes = [], []
    for index in plant.GetBodyIndices(model):
        for g in inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(index), Role.kPerception):
            shape = inspector.GetShape(g)
            if not (isinstance(shape, Mesh) and shape.source().is_path()):
                continue
            path, body = Path(shape.source().path()), plant.get_body(index)
            if shape.extension() == ".obj":
                drawable = drawable_obj(path, folder)
                if drawable is not None:
                    swaps.append((body, g, shape, *drawable))
            elif shape.extension() == ".stl":
                swaps.append((body, g, shape, stl_as_obj(path, folder), ["an STL file"]))
            elif shape.extension() != ".gltf":
                notes.append(f"the visual mesh {path.name} of body {body.name()!r} is a {shape.extension()} "
                             "file, which Drake's renderer ignores: the cameras do not see it (convert it to "
                             ".obj or .gltf)")
    for body, g, shape, copy, changed in swaps:
        name, mesh = f"{inspector.GetName(g).split('::')[-1]}_drawable", Mesh(str(copy), shape.scale3())
        if any(line.startswith("mtllib") for line in copy.read_text().splitlines()):  # its own materials
            instance = GeometryInstance(inspector.GetPoseInFrame(g), mesh, name)
            instance.set_illustration_properties(IllustrationProperties())
            instance.set_perception_properties(PerceptionProperties())
            plant.RegisterVisualGeometry(body, instance)
        else:
            colour = inspector.GetPerceptionProperties(g).GetPropertyOrDefault("phong", "diffuse",
                                                                               Rgba(0.9, 0.9, 0.9, 1.0))
            plant.RegisterVisualGeometry(body, inspector.GetPoseInFrame(g), mesh, name, colour.rgba)
        scene_graph.RemoveRole(plant.get_source_id(), g, Role.kPerception)
        notes.append(f"the visual mesh {Path(shape.source().path()).name} of body {body.name()!r}: "
                     f"{'; '.join(changed)}; Drake's renderer cannot draw that, so the cameras see a copy "
                     "that it can")
    return notes
