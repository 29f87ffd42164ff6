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
from pydrake.geometry import Role
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, PrismaticJoint, RevoluteJoint
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.objects.articulated import ArticulatedObject, Front
from nfr_drake.objects.plant import add_articulated_object
from nfr_drake.parsing import make_parser
from nfr_drake.world.keypoints import DEFAULT_GRID_SIZE, KeypointTrajectory
from nfr_drake.world.obstacles import object_obstacles
from nfr_drake.world.plan import ObstacleBox

_Z = np.array([0.0, 0.0, 1.0])
_HINGE_HALF_SPAN = 0.25  # hinge keypoints of a loaded model: this far along the axis from the handle's foot


def object_pose(xyz, yaw_deg: float) -> RigidTransform:
    """X_WO of an object standing on the floor: origin at `xyz` (3,) in W, m, turned `yaw_deg`
    degrees about W's z. ConfigError unless these are three finite coordinates and a finite angle."""
    p_WO = np.asarray(xyz, float)
    if p_WO.shape != (3,) or not np.all(np.isfinite(p_WO)) or not np.isfinite(yaw_deg):
        raise ConfigError(f"object pose: need three finite coordinates (m) and a finite yaw (deg), "
                          f"got xyz {p_WO.tolist()} and yaw {yaw_deg}")
    return RigidTransform(RollPitchYaw(0.0, 0.0, np.radians(yaw_deg)), p_WO)


def set_joint_value(plant: MultibodyPlant, plant_context, joint, value: float) -> None:
    """Set a one-dof joint's position (rad or m) in `plant_context`."""
    q = plant.GetPositions(plant_context)
    q[joint.position_start()] = value
    plant.SetPositions(plant_context, q)


GRIP_END_MARGIN = 0.02
"""Free bar kept at each end of a grip (half a finger pad plus a drawer handle's post), m."""


def grip_half_length(front: Front) -> float:
    """Half the stretch of a front's grip where fingers fit, m (0 for a knob)."""
    return max(0.0, front.grip_half_length - GRIP_END_MARGIN)


def random_part(obj: ArticulatedObject, rng: np.random.Generator) -> int:
    """A front index of `obj` drawn uniformly from `rng` (the piece's own stream, after the piece)."""
    return int(rng.integers(obj.num_fronts))


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
            close on it, m; 0 for a point grip (a knob, or a loaded model).
        locked_joints: the object's other joints, held at 0 (shut) in simulation: locked in the
            context (`Joint.Lock`), so they stay bodies on joints, the same model as everywhere.
        obstacles: the object's collision geometry in W without the moving part, as boxes, for
            planning with the true model (`nfr_drake.world.obstacles`); None: the planner derives
            a carcass box from the keypoints (closets, drawers, loaded models).
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
                        q: float, grid_size: int = DEFAULT_GRID_SIZE) -> SceneObject:
        """A model file; the parent body of `joint_name` is welded at X_WO, the joint set to q.

        The handle point is the mean origin of the handle body's collision (else visual) geometries,
        or the body origin when it has none.
        """
        path = Path(path)
        if not path.is_file():
            raise NfrDrakeError(f"object model {path} does not exist")

        def add_to(plant: MultibodyPlant) -> ModelInstanceIndex:
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
            joint = plant.GetJointByName(joint_name, model)
            plant.WeldFrames(plant.world_frame(), joint.parent_body().body_frame(), X_WO)
            return model

        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        model = add_to(plant)
        plant.Finalize()
        joint = plant.GetJointByName(joint_name, model)
        if not isinstance(joint, (RevoluteJoint, PrismaticJoint)):
            raise NfrDrakeError(f"joint {joint_name!r} is a {joint.type_name()} joint; "
                                "need revolute or prismatic")
        lower, upper = joint.position_lower_limits()[0], joint.position_upper_limits()[0]
        if not (np.isfinite(lower) and np.isfinite(upper) and upper > lower):
            raise NfrDrakeError(f"joint {joint_name!r} needs finite limits (lower < upper) to map q "
                                "onto [0, 1]")
        body = plant.GetBodyByName(handle_body_name, model)
        inspector = scene_graph.model_inspector()
        frame_id = plant.GetBodyFrameIdOrThrow(body.index())
        geometries = (inspector.GetGeometries(frame_id, Role.kProximity)
                      or inspector.GetGeometries(frame_id, Role.kIllustration))
        p_BH = (np.mean([inspector.GetPoseInFrame(g).translation() for g in geometries], axis=0)
                if geometries else np.zeros(3))

        context = plant.CreateDefaultContext()
        revolute = isinstance(joint, RevoluteJoint)
        q_grid = np.linspace(0.0, 1.0, grid_size)
        names = ("handle", "hinge_top", "hinge_bottom") if revolute else ("handle",)
        p_WK = np.zeros((grid_size, len(names), 3))
        for i, qi in enumerate(q_grid):
            set_joint_value(plant, context, joint, lower + qi * (upper - lower))
            X_WB = plant.EvalBodyPoseInWorld(context, body)
            p_WK[i, 0] = X_WB @ p_BH
            X_WJ = joint.frame_on_parent().CalcPoseInWorld(context)
            axis_W = X_WJ.rotation() @ (joint.revolute_axis() if revolute else joint.translation_axis())
            if revolute:
                a = axis_W if axis_W @ _Z >= 0 else -axis_W
                foot = X_WJ.translation() + ((p_WK[i, 0] - X_WJ.translation()) @ a) * a
                p_WK[i, 1], p_WK[i, 2] = foot + _HINGE_HALF_SPAN * a, foot - _HINGE_HALF_SPAN * a
            if i == 0:
                R_BW = X_WB.rotation().inverse()
                bar_W = axis_W if revolute else np.cross(_Z, axis_W)
                if np.linalg.norm(bar_W) < 1e-6:
                    raise NfrDrakeError(f"prismatic joint {joint_name!r} is vertical; only horizontal "
                                        "slides (drawers) are supported")
                bar_B = R_BW @ (bar_W / np.linalg.norm(bar_W))
        category = "closet" if revolute else "drawer"
        kt = KeypointTrajectory(category, q_grid, names, p_WK, q)
        return SceneObject(category, add_to, joint_name, handle_body_name, p_BH, bar_B, kt)
