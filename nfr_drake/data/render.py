"""Rendering articulated objects with Drake: an RgbdSensor on RenderEngineVtk.

`ObjectRenderer` builds one diagram per object (plant + scene graph + VTK renderer + sensor) and
then renders RGB, semantic labels and depth at any articulation q and any camera pose X_OC. The
sensor rides on a free "camera rig" body whose pose is set per view, so views cost one render each
and no diagram is rebuilt. The object's carcass is welded at the world origin, so W = O here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    LightParameter,
    MakeRenderEngineVtk,
    PerceptionProperties,
    RenderCameraCore,
    RenderEngineVtkParams,
    RenderLabel,
    Role,
    RoleAssign,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import ModelInstanceIndex, SpatialInertia
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.objects import ArticulatedObject
from nfr_drake.objects.articulated import LABELS_PER_PART, MAX_FRONTS
from nfr_drake.objects.plant import add_articulated_object, apply_semantic_labels, set_articulation

RENDERER_NAME = "nfr_vtk"
DEFAULT_BACKGROUND_RGB = (0.92, 0.92, 0.92)
_CLIP_NEAR_M, _CLIP_FAR_M = 0.05, 20.0


class LightSet(Protocol):
    """Lights a renderer takes."""

    def drake_lights(self) -> list[LightParameter]: ...


@dataclass(frozen=True)
class Lighting:
    """A camera headlight plus one directional key light fixed in the world.

    Intensities are VTK light intensities; `key_direction_W` is the direction the light travels.
    """

    headlight_intensity: float = 0.55
    key_intensity: float = 0.6
    key_direction_W: tuple[float, float, float] = (-0.5, 0.3, -1.0)
    key_rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def drake_lights(self) -> list[LightParameter]:
        from pydrake.geometry import Rgba

        direction = np.asarray(self.key_direction_W, float)
        return [
            LightParameter(type="directional", frame="camera", intensity=self.headlight_intensity,
                           direction=[0.0, 0.0, 1.0]),
            LightParameter(type="directional", frame="world", intensity=self.key_intensity,
                           direction=direction / np.linalg.norm(direction),
                           color=Rgba(*self.key_rgb, 1.0)),
        ]


def sample_lighting(rng: np.random.Generator) -> Lighting:
    """Random lighting: headlight and key intensities, a key light from above, a warm or cool tint."""
    azimuth = rng.uniform(-np.pi, np.pi)
    elevation = rng.uniform(np.deg2rad(30), np.deg2rad(80))
    towards_light = np.array([np.cos(elevation) * np.cos(azimuth),
                              np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    warm = rng.uniform(-0.08, 0.08)  # > 0: warmer (less blue), < 0: cooler (less red)
    return Lighting(
        headlight_intensity=float(rng.uniform(0.4, 0.75)),
        key_intensity=float(rng.uniform(0.3, 0.8)),
        key_direction_W=tuple(-towards_light),
        key_rgb=(1.0 - max(-warm, 0.0), 1.0 - abs(warm) / 2, 1.0 - max(warm, 0.0)),
    )


@dataclass(frozen=True)
class RenderedView:
    """One view. rgb: uint8 (H, W, 3); label: uint8 (H, W) semantic class (docs/CONVENTIONS.md);
    depth: float32 (H, W), metres along the optical axis, inf where no surface is hit;
    part: int8 (H, W) index of the front seen in each pixel (docs/FURNITURE.md), -1 where none."""

    rgb: np.ndarray
    label: np.ndarray
    depth: np.ndarray
    part: np.ndarray


# Render labels this package assigns: 1 (carcass) to class + 4 (k + 1) of the last front.
_MAX_LABEL = LABELS_PER_PART * (MAX_FRONTS + 1) + LABELS_PER_PART - 1
SCENERY_LABEL = 1000
"""RenderLabel of everything a renderer shows besides its object (class 0, part -1)."""


def split_render_label(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Semantic class (uint8) and front index (int8, -1 where none) of raw RenderLabel values.

    Labels outside this package's range (background, Drake's reserved values) are class 0, part -1.
    """
    raw = np.asarray(raw, dtype=np.int64)
    ours = (raw >= 1) & (raw <= _MAX_LABEL)
    label = np.where(ours, raw % LABELS_PER_PART, 0).astype(np.uint8)
    part = np.where(ours, raw // LABELS_PER_PART - 1, -1).astype(np.int8)
    return label, part


def drake_camera_info(camera: PinholeCamera) -> CameraInfo:
    """Drake's CameraInfo of a pinhole camera whose renders match the camera's intrinsics.

    CameraInfo's documentation puts pixel centres at integer coordinates, but RenderEngineVtk
    (drake 1.51) draws a point at (fx x / z + center_x, fy y / z + center_y) in our convention,
    top-left pixel centre at (0.5, 0.5): the principal point passes through unchanged.
    Subtracting half a pixel, as the documentation suggests, shifts every render by -0.5 px in u
    and v against the stated intrinsics (measured by
    tests/data/test_render.py::test_spheres_render_where_the_intrinsics_project_them)."""
    if camera.distortion:
        raise ValueError("Drake renders undistorted pinhole images only")
    return CameraInfo(camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy)


def _label_scenery(plant: MultibodyPlant, scene_graph, model: ModelInstanceIndex) -> None:
    """Give every perception geometry outside `model` the RenderLabel `SCENERY_LABEL` (Drake's
    parser labels geometry by body index, which would collide with the object's labels)."""
    inspector = scene_graph.model_inspector()
    for i in range(plant.num_model_instances()):
        if ModelInstanceIndex(i) == model:
            continue
        for body_index in plant.GetBodyIndices(ModelInstanceIndex(i)):
            frame_id = plant.GetBodyFrameIdOrThrow(body_index)
            for geometry_id in inspector.GetGeometries(frame_id, Role.kPerception):
                props = PerceptionProperties(inspector.GetPerceptionProperties(geometry_id))
                props.UpdateProperty("label", "id", RenderLabel(SCENERY_LABEL))
                scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)
                scene_graph.AssignRole(plant.get_source_id(), geometry_id, props, RoleAssign.kNew)


class ObjectRenderer:
    """Renders one `ArticulatedObject` with a Drake RgbdSensor at any q and camera pose.

    Args:
        obj: the object; its carcass is welded at the world origin (frame O = W).
        camera: intrinsics of every view (no distortion).
        lighting: lights of this renderer (anything with `drake_lights()`: `Lighting`,
            `nfr_drake.data.room_lighting.RoomLighting`); default `Lighting()`.
        background_rgb: clear colour, each channel in [0, 1].
        add_scenery: called with the plant before it is finalised, to add more geometry (a
            room: `nfr_drake.data.rooms.Room.add_to`); joints it adds keep their default
            positions. Its geometry is labelled `SCENERY_LABEL`: class 0 in the label images.
    """

    def __init__(self, obj: ArticulatedObject, camera: PinholeCamera,
                 lighting: LightSet | None = None,
                 background_rgb: tuple[float, float, float] = DEFAULT_BACKGROUND_RGB,
                 add_scenery: Callable[[MultibodyPlant], None] | None = None):
        self.obj = obj
        self.camera = camera
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
        params = RenderEngineVtkParams(default_clear_color=list(background_rgb),
                                       lights=(lighting or Lighting()).drake_lights())
        scene_graph.AddRenderer(RENDERER_NAME, MakeRenderEngineVtk(params))
        self._model = add_articulated_object(plant, obj)
        if add_scenery is not None:
            add_scenery(plant)
        rig_model = plant.AddModelInstance("camera_rig")
        rig = plant.AddRigidBody("camera_rig", rig_model, SpatialInertia.SolidSphereWithMass(0.1, 0.05))
        plant.Finalize()
        apply_semantic_labels(plant, scene_graph, self._model)
        if add_scenery is not None:
            _label_scenery(plant, scene_graph, self._model)

        core = RenderCameraCore(RENDERER_NAME, drake_camera_info(camera),
                                ClippingRange(_CLIP_NEAR_M, _CLIP_FAR_M), RigidTransform())
        sensor = builder.AddSystem(RgbdSensor(
            parent_id=plant.GetBodyFrameIdOrThrow(rig.index()), X_PB=RigidTransform(),
            color_camera=ColorRenderCamera(core, show_window=False),
            depth_camera=DepthRenderCamera(core, DepthRange(_CLIP_NEAR_M, _CLIP_FAR_M))))
        builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
        self._diagram = builder.Build()
        self._context = self._diagram.CreateDefaultContext()
        self._plant, self._rig, self._sensor = plant, rig, sensor
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        self._sensor_context = sensor.GetMyContextFromRoot(self._context)

    def set_state(self, q: float | np.ndarray, X_OC: np.ndarray) -> None:
        """Set articulation q in [0, 1] (one value for all fronts, or shape (F,)) and camera pose
        X_OC (4x4, OpenCV axes)."""
        set_articulation(self._plant, self._plant_context, self.obj, self._model, q)
        self._plant.SetFreeBodyPose(self._plant_context, self._rig, RigidTransform(X_OC))

    def render_rgb(self, q: float | np.ndarray, X_OC: np.ndarray) -> np.ndarray:
        """uint8 RGB image (H, W, 3)."""
        self.set_state(q, X_OC)
        return self._sensor.color_image_output_port().Eval(self._sensor_context).data[..., :3].copy()

    def render(self, q: float | np.ndarray, X_OC: np.ndarray) -> RenderedView:
        """RGB, semantic labels, depth and front indices of one view."""
        self.set_state(q, X_OC)
        ctx = self._sensor_context
        rgb = self._sensor.color_image_output_port().Eval(ctx).data[..., :3].copy()
        label, part = split_render_label(self._sensor.label_image_output_port().Eval(ctx).data[..., 0])
        depth = self._sensor.depth_image_32F_output_port().Eval(ctx).data[..., 0].copy()
        return RenderedView(rgb, label, depth, part)
