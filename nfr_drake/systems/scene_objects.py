"""Articulated objects as the simulation sees them: how to load one, its joint, its handle.

Either one front of a sampled `ArticulatedObject` (the other fronts held shut, their geometry and the
carcass's an obstacle for the planner) or any SDFormat/URDF file with one revolute or prismatic
joint. The ground-truth keypoint trajectory is read from the model (handle point, hinge axis or
slide).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, PrismaticJoint, RevoluteJoint
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.objects.articulated import ArticulatedObject, Front
from nfr_drake.objects.plant import add_articulated_object
from nfr_drake.systems.model_files import (
    MASSLESS_DENSITY,
    AddedMass,
    add_model_file,
    body_box,
    check_handle_stands_out,
    check_opens_outward,
    check_placement,
    handle_grip,
    handle_notes,
    massless_parts,
    mesh_problems,
    shut_and_open,
    shut_by_geometry,
    slide_front_normal,
)
from nfr_drake.world.keypoints import (
    APPROACH_KEYPOINT,
    DEFAULT_GRID_SIZE,
    GRIP_AXIS_KEYPOINT,
    GRIP_AXIS_OFFSET,
    KeypointTrajectory,
)
from nfr_drake.world.obstacles import box_corners, geometry_obstacles, object_obstacles
from nfr_drake.world.plan import ObstacleBox

_Z = np.array([0.0, 0.0, 1.0])
_HINGE_HALF_SPAN = 0.25  # hinge keypoints of a loaded model: this far along the axis from the handle's foot


def object_pose(xyz, yaw_deg: float, rpy_deg=(0.0, 0.0, 0.0)) -> RigidTransform:
    """X_WO of an object: origin at `xyz` (3,) in W, m, rotated by roll, pitch, yaw `rpy_deg` (3,)
    (a model drawn lying on its side) and then turned `yaw_deg` degrees about W's z (so the yaws
    add). ConfigError unless these are finite."""
    p_WO, rpy = np.asarray(xyz, float), np.asarray(rpy_deg, float)
    if (p_WO.shape != (3,) or rpy.shape != (3,) or not np.all(np.isfinite(p_WO))
            or not np.all(np.isfinite(rpy)) or not np.isfinite(yaw_deg)):
        raise ConfigError(f"object pose: need three finite coordinates (m) and a finite yaw (deg), "
                          f"got xyz {p_WO.tolist()}, yaw {yaw_deg} and rpy {rpy.tolist()}")
    return RigidTransform(RollPitchYaw(np.radians(rpy + [0.0, 0.0, yaw_deg])), p_WO)


def set_joint_value(plant: MultibodyPlant, plant_context, joint, value: float) -> None:
    """Set a one-dof joint's position (rad or m) in `plant_context`."""
    q = plant.GetPositions(plant_context)
    q[joint.position_start()] = value
    plant.SetPositions(plant_context, q)


def _swept_keypoints(plant: MultibodyPlant, context, joint, body, p_BH: np.ndarray, moving_points: dict,
                     shut_and_open: tuple[float, float], q: float, grid_size: int) -> KeypointTrajectory:
    """Ground truth of a loaded model's joint over q in [0, 1] (joint values from shut to open): the
    handle p_BH and `moving_points` (name -> point in the handle body's frame B, m) as B moves, and
    for a revolute joint the hinge keypoints on its axis `_HINGE_HALF_SPAN` either side of the
    handle's foot. `context` is left at q = 1."""
    revolute = isinstance(joint, RevoluteJoint)
    X_WJ = joint.frame_on_parent().CalcPoseInWorld(context)
    axis_W = X_WJ.rotation() @ (joint.revolute_axis() if revolute else joint.translation_axis())
    a = axis_W if axis_W @ _Z >= 0 else -axis_W
    q_grid = np.linspace(0.0, 1.0, grid_size)
    names = (("handle", "hinge_top", "hinge_bottom") if revolute else ("handle",)) + tuple(moving_points)
    p_WK = np.zeros((grid_size, len(names), 3))
    shut, opened = shut_and_open
    for i, qi in enumerate(q_grid):
        set_joint_value(plant, context, joint, shut + qi * (opened - shut))
        X_WB = plant.EvalBodyPoseInWorld(context, body)
        p_WK[i, 0] = X_WB @ p_BH
        if revolute:
            foot = X_WJ.translation() + ((p_WK[i, 0] - X_WJ.translation()) @ a) * a
            p_WK[i, 1], p_WK[i, 2] = foot + _HINGE_HALF_SPAN * a, foot - _HINGE_HALF_SPAN * a
        p_WK[i, len(names) - len(moving_points):] = [X_WB @ p for p in moving_points.values()]
    kt = KeypointTrajectory("closet" if revolute else "drawer", q_grid, names, p_WK, q)
    return kt.told_turn(abs(opened - shut))


GRIP_END_MARGIN = 0.02
"""Free bar kept at each end of a grip (half a finger pad plus a drawer handle's post), m."""


def grip_half_length(front: Front) -> float:
    """Half the stretch of a front's grip where fingers fit, m (0 for a knob)."""
    return max(0.0, front.grip_half_length - GRIP_END_MARGIN)


def random_part(obj: ArticulatedObject, rng: np.random.Generator) -> int:
    """A front index of `obj` drawn uniformly from `rng` (the piece's own stream, after the piece)."""
    return int(rng.integers(obj.num_fronts))


def sampled_part(category: str, seed: int, index: int, X_WO: RigidTransform, part: int | None = None
                 ) -> tuple[ArticulatedObject, int, SceneObject]:
    """Object `index` of `category` drawn from object_rng(SEED_DOMAIN_TRAIN, seed, index), the part
    to open (`part`, else `random_part` from the object's stream) and that part shut at pose X_WO."""
    rng = object_rng(SEED_DOMAIN_TRAIN, seed, index)
    obj = sample_object(category, rng)
    drawn = random_part(obj, rng)
    part = drawn if part is None else part
    return obj, part, SceneObject.from_articulated_object(obj, X_WO, 0.0, part=part)


@dataclass(frozen=True)
class SceneObject:
    """An articulated object placed in the world.

    Attributes:
        category: "closet" (revolute joint) or "drawer" (prismatic joint).
        add_to: adds the object to a plant with its base welded at its pose; returns its instance.
        joint_name, handle_body_name: names within the object's model instance.
        p_BH: handle grip centre in the handle body's frame B, m, shape (3,).
        bar_B: unit axis of the grip in B, shape (3,).
        ground_truth: the true keypoint trajectory, in W.
        grip_half_length: half the stretch of the grip, along bar_B about p_BH, where a hand can
            close on it, m; 0 for a point grip (a knob).
        locked_joints: the object's other joints, held at 0 (shut) in simulation: locked in the
            context (`Joint.Lock`), so they stay bodies on joints, the same model as everywhere.
        obstacles: the object's collision geometry in W without the moving part, as boxes, for
            planning with the true model (`nfr_drake.world.obstacles`); None: the planner derives
            a carcass box from the keypoints (closets, drawers).
        joint_range: the joint's values (rad or m) at q = 0 (shut) and q = 1 (open); None: its
            lower and upper limits (a loaded model may be shut at its upper limit).
        notes: what loading a model file found unusual but plannable, one line each.
        handle_middle_W: a model file's handle geometry's box middle in W, shut, m, (3,): what the
            cameras frame (`category_frame`); None: the grip centre (a sampled object's handle).
    """

    category: str
    add_to: Callable[[MultibodyPlant], ModelInstanceIndex]
    joint_name: str
    handle_body_name: str
    p_BH: np.ndarray
    bar_B: np.ndarray
    ground_truth: KeypointTrajectory
    grip_half_length: float = 0.0
    locked_joints: tuple[str, ...] = ()
    obstacles: tuple[ObstacleBox, ...] | None = None
    joint_range: tuple[float, float] | None = None
    notes: tuple[str, ...] = ()
    handle_middle_W: np.ndarray | None = None

    def shut_and_open(self, joint) -> tuple[float, float]:
        """The joint's values at q = 0 and q = 1 (rad or m): `joint_range`, else its limits."""
        if self.joint_range is not None:
            return self.joint_range
        return float(joint.position_lower_limits()[0]), float(joint.position_upper_limits()[0])

    def in_joint_units(self, keypoints: KeypointTrajectory) -> KeypointTrajectory:
        """Fitted or given door keypoints, whose q is 90 degrees per unit (the fields' convention,
        docs/CONVENTIONS.md), told in this object's q, its joint's fraction from shut to open
        (`joint_range`): a model file's door that opens 100 degrees is at 54 degrees at its q 0.54,
        the keypoints' 0.6. Drawers (their travel is fitted, not known) and objects without a
        `joint_range` (generated ones, 90 degrees) are returned as they are."""
        if keypoints.category != "closet" or self.category != "closet" or self.joint_range is None:
            return keypoints
        span = abs(self.joint_range[1] - self.joint_range[0])
        return keypoints.rescaled(np.pi / 2 / span)

    def category_frame(self) -> tuple[RigidTransform, tuple[np.ndarray, np.ndarray]]:
        """Frame O of the neural field's objects (docs/CONVENTIONS.md) for this object, shut, and
        its bounds in O (min and max corners (3,), m): O's origin lies under the centre of the
        footprint of what the joint does not move (the smallest rectangle about its collision
        boxes, the carcass), at their lowest point; +x points out of the rectangle's side the shut
        handle (`handle_middle_W`, else its grip centre) stands furthest out of; +z is W's. The
        bounds hold those boxes and that handle point. NfrDrakeError when nothing but the moving
        part has collision geometry."""
        if not self.obstacles:
            raise NfrDrakeError("the model has no collision geometry besides its moving part: the "
                                "cameras and the neural field's frame need the carcass's")
        corners = np.concatenate([box_corners(b.X_WB, b.size) for b in self.obstacles])
        handle = (self.handle_middle_W if self.handle_middle_W is not None
                  else self.ground_truth.point("handle", 0.0))
        turns = np.radians(np.arange(0.0, 90.0, 0.25))
        axes = np.stack([np.cos(turns), np.sin(turns)], -1)  # (T, 2): the rectangle's first axis
        along = corners[:, :2] @ axes.T, corners[:, :2] @ np.stack([-axes[:, 1], axes[:, 0]], -1).T
        areas = np.ptp(along[0], axis=0) * np.ptp(along[1], axis=0)
        u = axes[int(np.argmin(areas))]
        normals = np.array([u, -u, [-u[1], u[0]], [u[1], -u[0]]])
        spans = corners[:, :2] @ normals.T  # (N, 4): each side's outward coordinate
        mid = np.array([(spans[:, 0].max() - spans[:, 1].max()) / 2.0,
                        (spans[:, 2].max() - spans[:, 3].max()) / 2.0])
        centre_xy = mid[0] * u + mid[1] * normals[2]
        beyond = handle[:2] @ normals.T - spans.max(0)  # how far the handle stands out of each side
        x = normals[int(np.argmax(beyond))]
        X_WO = RigidTransform(RotationMatrix.MakeZRotation(float(np.arctan2(x[1], x[0]))),
                              [*centre_xy, float(corners[:, 2].min())])
        in_O = X_WO.inverse().multiply(np.vstack([corners, handle]).T).T
        return X_WO, (in_O.min(0), in_O.max(0))

    @staticmethod
    def from_articulated_object(obj: ArticulatedObject, X_WO: RigidTransform, q: float,
                                part: int = 0) -> SceneObject:
        """Front `part` of a sampled object at articulation q, the other fronts shut.

        A piece of furniture also gives the planner its geometry as obstacles; a closet or a
        drawer (one front) leaves it the keypoint-derived box, as its fitted keypoints do."""
        if not 0 <= part < obj.num_fronts:
            kinds = ", ".join(f"{k}: {f.kind}" for k, f in enumerate(obj.fronts))
            raise NfrDrakeError(f"part {part} is out of range: {obj.name} has {obj.num_fronts} "
                                f"parts ({kinds})")
        front = obj.front(part)
        obstacles = (tuple(object_obstacles(obj, X_WO, 0.0, moving=part))
                     if obj.category == "furniture" else None)
        return SceneObject(
            category="closet" if front.joint_type == "revolute" else "drawer",
            add_to=lambda plant: add_articulated_object(plant, obj, X_WO),
            joint_name=front.joint_name,
            handle_body_name=front.link_name,
            p_BH=np.asarray(front.moving_keypoints["handle"], dtype=float),
            bar_B=np.asarray(front.grip_axis_M, dtype=float),
            ground_truth=KeypointTrajectory.from_articulated_object(obj, X_WO, q, part=part),
            grip_half_length=grip_half_length(front),
            locked_joints=tuple(f.joint_name for k, f in enumerate(obj.fronts) if k != part),
            obstacles=obstacles)

    @staticmethod
    def from_model_file(path: Path, joint_name: str, handle_body_name: str, X_WO: RigidTransform,
                        q: float, closed_at: str | None = None,
                        grid_size: int = DEFAULT_GRID_SIZE) -> SceneObject:
        """A model file made fit to plan on (`nfr_drake.systems.model_files`): the root of the
        joint's tree welded at X_WO, the joint set to q (0 at its shut limit, `closed_at` "lower",
        "upper" or None for the rule there), the other joints held shut, massless parts given a
        mass; or a one-line NfrDrakeError saying what to change.

        The handle point is the centre of the handle body's grip (`model_files.grip_centre`); an
        elongated handle gives the bar axis (`GRIP_AXIS_KEYPOINT`), a sliding door the approach
        from its front (`APPROACH_KEYPOINT`). The obstacles are the boxes of every collision
        geometry the joint does not move, at the shut pose (none: the keypoint-derived box).
        """
        path = Path(path)
        if not path.is_file():
            raise NfrDrakeError(f"object model {path} does not exist")

        def build(added: tuple[AddedMass, ...]):
            builder = DiagramBuilder()
            plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
            model = add_model_file(plant, path, joint_name, handle_body_name, X_WO, added)
            plant.Finalize()
            return plant, scene_graph.model_inspector(), model

        plant, inspector, model = build(())
        joint = plant.GetJointByName(joint_name, model)
        if not isinstance(joint, (RevoluteJoint, PrismaticJoint)):
            raise NfrDrakeError(f"joint {joint_name!r} is a {joint.type_name()} joint; "
                                "need revolute or prismatic")
        lower, upper = joint.position_lower_limits()[0], joint.position_upper_limits()[0]
        if not (np.isfinite(lower) and np.isfinite(upper) and upper > lower):
            raise NfrDrakeError(f"joint {joint_name!r} needs finite limits (lower < upper) to map q "
                                f"onto [0, 1], has [{lower:.3g}, {upper:.3g}]: give it a <limit> with lower "
                                "and upper (a URDF 'continuous' joint becomes 'revolute')")
        others = [plant.get_joint(j) for j in plant.GetJointIndices(model)
                  if j != joint.index() and plant.get_joint(j).num_positions() > 0]
        for other in others:
            if other.num_positions() != 1:
                raise NfrDrakeError(f"joint {other.name()!r} is a {other.type_name()} joint: only one-dof "
                                    "joints can be held shut; make it fixed")
        shut, opened = shut_and_open(joint, closed_at)
        added = tuple(massless_parts(plant, inspector, plant.CreateDefaultContext(), model))
        notes = [f"body {a.body_name!r} and what is welded to it have no mass: given {a.mass:.2g} kg "
                 f"({MASSLESS_DENSITY:.0f} kg/m^3 over its geometry's boxes); give it an inertial "
                 "element" for a in added]
        if added:
            plant, inspector, model = build(added)
            joint = plant.GetJointByName(joint_name, model)
        context = plant.CreateDefaultContext()
        for other in others:
            set_joint_value(plant, context, plant.GetJointByName(other.name(), model), 0.0)
        body = plant.GetBodyByName(handle_body_name, model)
        moving = set(plant.GetBodiesKinematicallyAffectedBy([joint.index()]))
        if body.index() not in moving:
            raise NfrDrakeError(f"the handle body {handle_body_name!r} does not move with joint "
                                f"{joint_name!r}; give --handle-body a body on the moving part")
        p_BH, grip_B, grip_half = handle_grip(plant, inspector, context, joint, body)
        notes += handle_notes(plant, inspector, body)
        bodies = [plant.get_body(b) for b in plant.GetBodyIndices(model)]

        def corners_W(of) -> list[np.ndarray]:  # the corners (8, 3) in W of each geometry box of `of`
            return [box_corners(plant.EvalBodyPoseInWorld(context, b) @ RigidTransform((box[0] + box[1]) / 2),
                                box[1] - box[0])
                    for b in of for box in [body_box(plant, inspector, b)] if box is not None]

        def handle_at(value: float) -> np.ndarray:
            set_joint_value(plant, context, joint, value)
            return plant.EvalBodyPoseInWorld(context, body) @ p_BH

        static = corners_W([b for b in bodies if b.index() not in moving])
        static_box = (np.concatenate(static).min(0), np.concatenate(static).max(0)) if static else None
        if closed_at is None and static_box is not None:
            shut, opened, drawn_open = shut_by_geometry(handle_at, static_box, shut, opened, joint_name)
            notes += drawn_open
        set_joint_value(plant, context, joint, shut)
        corners = corners_W(bodies)
        if not corners:
            raise NfrDrakeError(f"{path} has no geometry")
        revolute = isinstance(joint, RevoluteJoint)
        X_WJ = joint.frame_on_parent().CalcPoseInWorld(context)
        axis_W = X_WJ.rotation() @ (joint.revolute_axis() if revolute else joint.translation_axis())
        notes += check_placement(np.concatenate(corners), X_WO, axis_W, revolute)
        X_WB = plant.EvalBodyPoseInWorld(context, body)
        handle_box = body_box(plant, inspector, body)
        handle_middle_W = X_WB @ (p_BH if handle_box is None else (handle_box[0] + handle_box[1]) / 2)
        notes += mesh_problems(plant, inspector, context, model, moving, X_WB @ p_BH)
        check_handle_stands_out(plant, inspector, context, joint, body)
        front_W = None if revolute else slide_front_normal(plant, inspector, context, joint, body, axis_W)
        if front_W is None and static_box is not None:
            check_opens_outward(handle_at, (static_box[0] + static_box[1]) / 2, shut, opened, joint_name)
            set_joint_value(plant, context, joint, shut)
        R_BW = X_WB.rotation().inverse()
        if grip_B is None:
            bar_W = _Z if front_W is not None else axis_W if revolute else np.cross(_Z, axis_W)
            grip_B = R_BW @ (bar_W / np.linalg.norm(bar_W))
            grip_half = GRIP_END_MARGIN
        moving_points = {GRIP_AXIS_KEYPOINT: p_BH + GRIP_AXIS_OFFSET * grip_B}
        if front_W is not None:
            moving_points[APPROACH_KEYPOINT] = p_BH + GRIP_AXIS_OFFSET * (R_BW @ front_W)
        obstacles = geometry_obstacles(plant, inspector, context,
                                       [b for b in bodies if b.index() not in moving])
        kt = _swept_keypoints(plant, context, joint, body, p_BH, moving_points, (shut, opened), q, grid_size)
        return SceneObject(
            kt.category, lambda plant: add_model_file(plant, path, joint_name, handle_body_name, X_WO, added),
            joint_name, handle_body_name, p_BH, grip_B, kt,
            grip_half_length=max(0.0, grip_half - GRIP_END_MARGIN),
            locked_joints=tuple(j.name() for j in others), obstacles=tuple(obstacles) or None,
            joint_range=(shut, opened), notes=tuple(notes), handle_middle_W=handle_middle_W)
