"""The neural field in a Drake diagram: cameras photograph the object, the fit runs, keypoints out.

`NfrPerceptionSystem` reads the colour images of N cameras, fits the model's latent code when
triggered (at initialisation, or by `refit`), never per simulation step, and outputs the
forward-simulated `KeypointTrajectory` in the world frame, the estimated articulation q, the
fit's confidence (P(handle within 2 cm) and what it rests on, `inference.confidence`) and the
object's pose X_WO. With a model of furniture (several parts) it outputs the part asked for.

`AddNfrPerception` wires it up in Drake's style: it adds a render engine for the perception
cameras, one RgbdSensor per camera pose, and the system. Perceiving "alone" (the paper's setting),
the perception render engine sees the object alone (the robot, the floor and any other geometry
lose their perception role), against the background colour and lighting of the training renders:
a stand-in for segmenting the object out of a real photo. Perceiving the "room", it sees every
geometry of the plant (floor, walls, other furniture, clutter, the robot) under the lights given,
a segmenter (`perception.segmentation`, `models/segmenter`) finds the object in each photo (with
`mask_crop`, a second look at the crop around the object's box estimated from the first masks,
`segmentation.crop.posed_close_look`, and at the crop around its carcass's box for the carcass's
amodal masks, `posed_carcass_look`; where that pose is not of the piece the cameras aim at, at the
crop around the aim, `aimed_looks`), and the fit sees the photos with everything off the
object's mask painted in the training background (`paint_background`; off the region where the
estimated carcass can lie, only the pixels the segmenter is sure of kept, `paint_thresholds`; or,
`room_loss` "masked", only the pixels on the mask count in its loss).
Frame O of the model is the object's frame. Its pose X_WO in the world is estimated from the views
(W's floor at z = 0, z up): the object's masks give a visual hull and a floor box
(`perception.object_pose`), and the fit runs in that O. The paper's setting passes a known X_WO
instead.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
import torch
from pydrake.common.value import Value
from pydrake.geometry import (
    ClippingRange,
    ColorRenderCamera,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
    Role,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex, ModelInstanceIndex
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem, NumericParameterIndex
from pydrake.systems.sensors import ImageRgba8U, RgbdSensor

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.capture import CaptureFrame, CaptureSet
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB, Lighting, LightSet, drake_camera_info
from nfr_drake.inference.confidence import refusal
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.forward import semantic_point_cloud
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import (
    PAINTINGS,
    FittedModel,
    KeypointSource,
    Painting,
    RoomLoss,
    checked_paintings,
    infer,
    infer_painted,
    infer_parts,
    more_confident_look,
    paint_off_object,
    refined_object_pose,
)
from nfr_drake.inference.result import FitResult
from nfr_drake.perception.object_pose import (
    HullConfig,
    ObjectPoseEstimate,
    background_mask,
    estimate_object_pose_carcass_first,
)
from nfr_drake.perception.segmentation.crop import (
    AimedLook,
    RoomLooks,
    other_look,
    posed_close_look,
    room_looks,
)
from nfr_drake.perception.segmentation.model import Segmenter, load_segmenter
from nfr_drake.perception.segmentation.refine import refine_masks as refined_by_colour
from nfr_drake.world.cloud import SemanticCloud
from nfr_drake.world.keypoints import KeypointTrajectory

PERCEPTION_RENDERER = "nfr_perception"
SEGMENTER_DIR = Path("models/segmenter")
"""The shipped segmenter (`nfr-drake train-segmenter`), which finds the object in photos of a room."""
PerceptionScene = Literal["alone", "room"]
"""What the perception cameras see: the object "alone" before the training background (the
paper's setting), or the whole "room" (every geometry of the plant), the object found by a
segmenter."""


class NfrPerceptionSystem(LeafSystem):
    """Fits the neural field to N camera images and outputs the object's keypoint trajectory.

    .. pydrake_system::

        name: NfrPerceptionSystem
        input_ports:
        - camera_0_rgb
        - ...
        - camera_{N-1}_rgb
        output_ports:
        - keypoint_trajectory
        - q_estimate
        - fit_result
        - confidence
        - X_WO
        - semantic_cloud

    camera_i_rgb: ImageRgba8U of camera i (intrinsics `cameras[i]`, pose `X_WCs[i]`).
    keypoint_trajectory: abstract `KeypointTrajectory` in W over [0, 1], q_current = the estimate.
    q_estimate: BasicVector of size 1, the fitted articulation in [0, 1].
    fit_result: abstract `FitResult` (positions in O).
    confidence: abstract dict, the result's `confidence` ({p_handle_within_2cm, threshold,
    features, per_view}; p None when the model folder has no calibration; furniture: of the part
    asked for), or None.
    X_WO: abstract `RigidTransform`, the object's pose in W: the given one, or the estimate.
    semantic_cloud: abstract `SemanticCloud`, the fitted field's labelled surface points in W at
    the fitted q, rendered from the cameras at `cloud_size` pixels high (computed when first
    asked for; None for a model with several parts).

    Object masks: with a `segmenter` (a `Segmenter`, photos of a room), its probabilities (with
    `mask_crop`, those of its second look at the crop around the object's box from whole photos
    in each view, `posed_close_look`; when those masks give no pose, the first look's; the amodal
    carcass masks that give the pose likewise, `posed_carcass_look`; with an estimated pose whose
    floor box does not hold the cameras' aim point, or none, the aimed look's, `aimed_looks`,
    where it gives one: the extra's `aimed`, and a warning; `aimed_look`, `crop.AimedLook`), and
    the fit sees the photos painted in `background_rgb` off them (`room_loss` "background", as
    each of `paintings` says: one fit per painting, the one with the highest P(handle within 2 cm)
    kept, `infer_painted`; a model with several parts takes the first painting; with
    `refine_masks`, after the pixels the photo's colours call background are taken off the masks,
    `perception.segmentation.refine`) or only the pixels on them (`room_loss` "masked");
    without, the pixels off `background_rgb` (the object alone), every pixel counting in the loss.
    X_WO None: the pose is estimated at each fit from the masks and refined with the fitted field
    (`FitConfig.refine_pose`), the result's `extra["object_pose"]` says how (X_WO, the estimate
    before the refinement X_WO_estimated, its floor box, the refinement's report; `extra["warnings"]` names a
    size outside the model's category). With the crop stage and `look_again`, a fit that its
    confidence refuses (P(handle within 2 cm) below the calibration's threshold) is followed by a fit
    at the other look's pose and masks (`crop.other_look`: the aimed look after whole photos, whole
    photos after the aimed look), and the more confident of the two is kept (the extra's
    `looked_again`: which, both P and both looks' `aimed`; a warning when the second is kept).
    The fit runs in an initialisation event and whenever
    `refit` is called; outputs read the stored result. `fit_count` counts those (one each,
    however many fits the paintings and looking again run).
    `keypoint_source` picks the keypoint head or the fitted geometry (see
    `nfr_drake.inference.infer.KeypointSource`).

    A model with several parts (furniture) is fitted with `furniture_config` (`infer_parts`, the
    keypoint head's keypoints) and has a numeric parameter `part` (one value; the constructor's
    `part`, -1 for the first part the field finds): keypoint_trajectory, q_estimate and fit_result
    give that part (its trajectory with the other parts held at their fitted q). Another value
    (`set_part`) needs no new fit; a part the fit did not find then raises NfrDrakeError.
    """

    def __init__(self, model: FittedModel, cameras: list[PinholeCamera],
                 X_WCs: list[RigidTransform], X_WO: RigidTransform | None = None,
                 fit_config: FitConfig = FitConfig(), trajectory_points: int = 21,
                 keypoint_source: KeypointSource = "head", hull_config: HullConfig | None = None,
                 background_rgb: tuple[float, float, float] = DEFAULT_BACKGROUND_RGB,
                 segmenter: Segmenter | None = None, part: int | None = None,
                 furniture_config: FurnitureFitConfig = FurnitureFitConfig(),
                 room_loss: RoomLoss = "background", mask_crop: bool = True, cloud_size: int = 48,
                 aimed_look: AimedLook = "off-aim",
                 paintings: tuple[Painting, ...] = PAINTINGS, look_again: bool = True,
                 refine_masks: bool = False):
        super().__init__()
        self._keypoint_source = keypoint_source
        if len(cameras) != len(X_WCs) or not cameras:
            raise ValueError("need one camera per pose, and at least one")
        if model.num_slots == 1 and part is not None:
            raise ValueError(f"part: {model.folder} has one part; `part` selects one of a model with several")
        if model.num_slots > 1 and keypoint_source != "head":
            raise ValueError("a model with several parts gives the keypoint head's keypoints only")
        self._model, self._fit_config, self._furniture_config = model, fit_config, furniture_config
        self._cameras = list(cameras)
        self._X_WCs = list(X_WCs)
        self._X_WO = X_WO
        self._hull_config, self._background_rgb = hull_config or HullConfig(), background_rgb
        self._segmenter, self._room_loss, self._mask_crop = segmenter, room_loss, mask_crop
        self._aimed_look, self._look_again, self._refine_masks = aimed_look, look_again, refine_masks
        self._paintings = checked_paintings(paintings)
        self._q_grid = np.linspace(0.0, 1.0, trajectory_points)
        self._cloud_size = cloud_size
        self.fit_count = 0
        self._image_ports = [
            self.DeclareAbstractInputPort(f"camera_{i}_rgb", Value(ImageRgba8U()))
            for i in range(len(cameras))]
        self._result_index = self.DeclareAbstractState(Value[object](None))
        ticket = {self.abstract_state_ticket(self._result_index)}
        self._part_index = None
        if model.num_slots > 1:
            self._part_index = self.DeclareNumericParameter(BasicVector([-1.0 if part is None else part]))
            ticket.add(self.numeric_parameter_ticket(NumericParameterIndex(self._part_index)))
        self._trajectory_port = self.DeclareAbstractOutputPort(
            "keypoint_trajectory", lambda: Value[object](None), self._CalcKeypointTrajectory,
            prerequisites_of_calc=ticket)
        self._q_port = self.DeclareVectorOutputPort("q_estimate", 1, self._CalcQ,
                                                    prerequisites_of_calc=ticket)
        self._result_port = self.DeclareAbstractOutputPort(
            "fit_result", lambda: Value[object](None), self._CalcFitResult,
            prerequisites_of_calc=ticket)
        self._confidence_port = self.DeclareAbstractOutputPort(
            "confidence", lambda: Value[object](None), self._CalcConfidence,
            prerequisites_of_calc=ticket)
        self._X_WO_port = self.DeclareAbstractOutputPort(
            "X_WO", lambda: Value[object](None), self._CalcX_WO, prerequisites_of_calc=ticket)
        self._cloud_port = self.DeclareAbstractOutputPort(
            "semantic_cloud", lambda: Value[object](None), self._CalcSemanticCloud,
            prerequisites_of_calc=ticket)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._Fit)

    def get_camera_rgb_input_port(self, i: int):
        return self._image_ports[i]

    def get_keypoint_trajectory_output_port(self):
        return self._trajectory_port

    def get_q_estimate_output_port(self):
        return self._q_port

    def get_fit_result_output_port(self):
        return self._result_port

    def get_confidence_output_port(self):
        return self._confidence_port

    def get_semantic_cloud_output_port(self):
        return self._cloud_port

    def get_X_WO_output_port(self):
        return self._X_WO_port

    def set_part(self, context, part: int) -> None:
        """Ask for part `part` of a model with several parts (this system's context)."""
        if self._part_index is None:
            raise ValueError(f"{self._model.folder} has one part")
        context.get_mutable_numeric_parameter(self._part_index).SetAtIndex(0, part)

    def _part(self, context) -> int | None:
        """The part asked for, None for the first found (or a model with one part)."""
        if self._part_index is None:
            return None
        part = int(context.get_numeric_parameter(self._part_index).GetAtIndex(0))
        return None if part < 0 else part

    @property
    def camera_poses(self) -> list[RigidTransform]:
        """The cameras' poses X_WC in W (OpenCV axes), in port order."""
        return list(self._X_WCs)

    @property
    def cameras(self) -> list[PinholeCamera]:
        """The cameras' intrinsics, in port order."""
        return list(self._cameras)

    def refit(self, context) -> FitResult:
        """Fit again to the current camera images (this system's context); returns the result."""
        fitted = self._run_fit(context)
        context.get_mutable_abstract_state(self._result_index).set_value(fitted)
        return fitted[0]

    def _masks(self, images: list[np.ndarray]) -> list[np.ndarray]:
        """The object's mask (H, W) in [0, 1] per image: the segmenter's, or off the background."""
        if self._segmenter is not None and self._mask_crop:
            return posed_close_look(self._segmenter, images, [X.GetAsMatrix4() for X in self._X_WCs],
                                    self._cameras, self._model.category, self._hull_config)
        if self._segmenter is not None:
            return [self._segmenter.object_mask(image) for image in images]
        return [background_mask(image, self._background_rgb) for image in images]

    def _room_looks(self, images: list[np.ndarray]) -> RoomLooks | None:
        """`segmentation.crop.room_looks` (whole photos, or the aimed look as `aimed_look` says)
        where the pose is estimated with a segmenter and the crop stage, else None."""
        if self._X_WO is None and self._segmenter is not None and self._mask_crop:
            return room_looks(self._segmenter, images, [X.GetAsMatrix4() for X in self._X_WCs],
                              self._cameras, self._model.category, self._hull_config, self._aimed_look)
        return None

    def _looked(self, images: list[np.ndarray], looks: RoomLooks | None
                ) -> tuple[list[np.ndarray] | None, RigidTransform, dict, list[str]]:
        """The object's masks (None without a segmenter when the pose is given), X_WO (given or
        estimated), what the result's extra says of it, and warnings: those of `looks` when given
        (`_room_looks`); else the masks of `_masks` and the pose from them (the segmenter's amodal
        carcass first when it has that output, `estimate_object_pose_carcass_first`)."""
        if looks is not None:
            return looks.masks, *self._estimated(looks.estimate, looks.amodal, looks.aimed, looks.warnings)
        X_WCs = [X.GetAsMatrix4() for X in self._X_WCs]
        masks = self._masks(images) if self._X_WO is None or self._segmenter is not None else None
        if self._X_WO is not None:
            return masks, self._X_WO, {"estimated": False}, []
        carcass = ([self._segmenter.carcass_amodal(image) for image in images]
                   if self._segmenter is not None and self._segmenter.config.amodal else None)
        estimate, amodal, warnings = estimate_object_pose_carcass_first(
            masks, carcass, X_WCs, self._cameras, self._hull_config, self._model.category)
        return masks, *self._estimated(estimate, amodal, False, warnings)

    def _estimated(self, estimate: ObjectPoseEstimate, amodal: bool, aimed: bool, warnings: list[str]
                   ) -> tuple[RigidTransform, dict, list[str]]:
        """X_WO of an estimate, what the result's extra says of it, and warnings (a size outside
        the model's category added)."""
        problem = estimate.size_problem(self._model.category)
        return (RigidTransform(estimate.X_WO),
                {"estimated": True, "X_WO": estimate.X_WO.tolist(), "size": estimate.size.tolist(),
                 "box": estimate.box.tolist(), "amodal": amodal, "aimed": aimed},
                warnings + ([problem] if problem else []))

    def _run_fit(self, context) -> tuple[FitResult, RigidTransform]:
        images = [port.Eval(context).data[..., :3].copy() for port in self._image_ports]
        looks = self._room_looks(images)
        result, X_WO = self._fit(context, images, *self._looked(images, looks))
        if (looks is not None and self._look_again and self._model.num_slots == 1
                and refusal(result.confidence) is not None):
            other = other_look(self._segmenter, images, [X.GetAsMatrix4() for X in self._X_WCs],
                               self._cameras, self._model.category, looks, self._hull_config)
            if other is not None:
                again, X_WO_again = self._fit(context, images, *self._looked(images, other))
                result = more_confident_look(result, again, (looks.aimed, other.aimed))
                X_WO = X_WO_again if result is again else X_WO
        self.fit_count += 1
        return result, X_WO

    def _fit(self, context, images: list[np.ndarray], masks: list[np.ndarray] | None, X_WO: RigidTransform,
             pose: dict, warnings: list[str]) -> tuple[FitResult, RigidTransform]:
        """The fit at one look (`_looked`'s masks, pose and warnings): the result and X_WO (the
        estimate refined by the fitted field where the pose is estimated)."""
        X_OW = X_WO.inverse()
        frames = [CaptureFrame(Path(f"camera_{i}"), (X_OW @ X_WC).GetAsMatrix4(), camera)
                  for i, (X_WC, camera) in enumerate(zip(self._X_WCs, self._cameras, strict=True))]
        capture = CaptureSet(Path("drake_cameras"), frames)
        masked = self._segmenter is not None and self._room_loss == "masked"
        painting = self._segmenter is not None and not masked  # a given pose comes without a size
        X_WCs = [X.GetAsMatrix4() for X in self._X_WCs]
        if self._model.num_slots > 1:
            kept = None
            if painting:
                masks = refined_by_colour(images, masks) if self._refine_masks else masks
                images, kept = paint_off_object(images, masks, X_WCs, self._cameras, X_WO.GetAsMatrix4(),
                                                pose.get("size"), self._background_rgb, self._paintings[0])
            result, _, _ = infer_parts(self._model, capture, self._furniture_config, self._q_grid, images,
                                    self._part(context), masks if masked else None, kept)
        else:
            if painting:
                result, outcome = infer_painted(self._model, capture, self._fit_config, self._q_grid, images,
                                                masks, X_WCs, X_WO.GetAsMatrix4(), pose.get("size"),
                                                self._paintings, self._keypoint_source,
                                                refine_pose=self._X_WO is None,
                                                background_rgb=self._background_rgb,
                                                refine_masks=self._refine_masks)
            else:
                result, outcome = infer(self._model, capture, self._fit_config, self._q_grid, images,
                                        self._keypoint_source, masks=masks if self._segmenter else None,
                                        masked_loss=masked, refine_pose=self._X_WO is None)
            if self._X_WO is None:  # the estimate, and the field's refinement of it
                X_WO_refined, refined = refined_object_pose(X_WO.GetAsMatrix4(), result, outcome)
                X_WO = RigidTransform(X_WO_refined)
                pose.update(refined)
        result.extra["object_pose"] = pose
        result.extra["warnings"] = result.extra.get("warnings", []) + warnings
        return result, X_WO

    def _Fit(self, context, state) -> None:
        state.get_mutable_abstract_state(self._result_index).set_value(self._run_fit(context))

    def _stored(self, context) -> tuple[FitResult, RigidTransform]:
        fitted = context.get_abstract_state(self._result_index).get_value()
        if fitted is None:
            raise RuntimeError("NfrPerceptionSystem: no fit yet; initialise the simulator first")
        return fitted

    def _selected(self, context) -> tuple[FitResult, RigidTransform]:
        """`_stored`, its single-part fields those of the part asked for (furniture)."""
        result, X_WO = self._stored(context)
        part = self._part(context)
        if part is not None and part != result.part["index"]:
            result = result.part_of(part)
        return result, X_WO

    def _CalcKeypointTrajectory(self, context, output) -> None:
        result, X_WO = self._selected(context)
        output.set_value(KeypointTrajectory.from_fit_result(result.to_json(), X_WO))

    def _CalcQ(self, context, output) -> None:
        output.SetAtIndex(0, self._selected(context)[0].q)

    def _CalcFitResult(self, context, output) -> None:
        output.set_value(self._selected(context)[0])

    def _CalcConfidence(self, context, output) -> None:
        output.set_value(self._selected(context)[0].confidence)

    def _CalcX_WO(self, context, output) -> None:
        output.set_value(self._stored(context)[1])

    def _CalcSemanticCloud(self, context, output) -> None:
        result, X_WO = self._stored(context)
        if self._model.num_slots > 1 or result.z is None:
            output.set_value(None)
            return
        X_OW = X_WO.inverse()
        size = self._cloud_size
        views = [(camera.scaled(max(1, round(camera.width * size / camera.height)), size),
                  (X_OW @ X_WC).GetAsMatrix4())
                 for camera, X_WC in zip(self._cameras, self._X_WCs, strict=True)]
        z = torch.as_tensor(np.asarray(result.z))
        points_O, classes = semantic_point_cloud(self._model.model, z, result.q, views)
        output.set_value(SemanticCloud(X_WO.multiply(points_O.T.astype(float)).T, classes, result.q))


def render_only(plant: MultibodyPlant, scene_graph: SceneGraph, keep: ModelInstanceIndex) -> None:
    """Remove the perception role of every geometry of `plant` outside model instance `keep`, so
    render engines (RgbdSensors) see that model alone; Meshcat (illustration role) and contact
    (proximity role) are unaffected. pydrake cannot restrict a geometry to some renderers
    (its ("renderer", "accepting") property needs a C++ std::set), hence all of them.
    Call before creating a context."""
    inspector = scene_graph.model_inspector()
    keep_bodies = {int(i) for i in plant.GetBodyIndices(keep)}
    for i in range(plant.num_bodies()):
        frame_id = plant.GetBodyFrameIdIfExists(BodyIndex(i))
        if i in keep_bodies or frame_id is None:
            continue
        for geometry_id in inspector.GetGeometries(frame_id, Role.kPerception):
            scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kPerception)


def AddNfrPerception(builder: DiagramBuilder, plant: MultibodyPlant, scene_graph: SceneGraph,
                     model_dir: Path, object_model: ModelInstanceIndex, X_WO: RigidTransform | None,
                     X_WCs: list[RigidTransform], camera: PinholeCamera,
                     fit_config: FitConfig = FitConfig(), lighting: LightSet | None = None,
                     keypoint_source: KeypointSource = "head", scene: PerceptionScene = "alone",
                     segmenter: Path = SEGMENTER_DIR, part: int | None = None,
                     furniture_config: FurnitureFitConfig = FurnitureFitConfig(),
                     room_loss: RoomLoss = "background", mask_crop: bool = True,
                     aimed_look: AimedLook = "off-aim",
                     paintings: tuple[Painting, ...] = PAINTINGS, look_again: bool = True,
                     refine_masks: bool = False) -> NfrPerceptionSystem:
    """Add perception cameras at X_WCs and an `NfrPerceptionSystem` fed by them.

    `plant` must be finalised and hold every geometry of the scene. `scene` "alone": render engines
    then see the object alone (`render_only`) under `lighting` (default the training renders'
    `Lighting()`); "room": they see every geometry under `lighting` (a room's lights in W,
    `RoomLighting.moved`), the `segmenter` model folder finds the object (`mask_crop`: with a second,
    close look; `aimed_look`: when at the crop around where the cameras aim; `look_again`: at the
    other look when the first fit is refused; `refine_masks`: the masks' edges by the photos'
    colours) and `room_loss` says
    how the fit treats the pixels off its mask
    (`NfrPerceptionSystem`). X_WO: the object's
    known pose, or None to estimate it from the views (`NfrPerceptionSystem`). A model with several
    parts (furniture): `part` and `furniture_config` as in `NfrPerceptionSystem`. Returns the
    system; its RgbdSensors are named `nfr_camera_{i}`.
    """
    params = RenderEngineVtkParams(default_clear_color=list(DEFAULT_BACKGROUND_RGB),
                                   lights=(lighting or Lighting()).drake_lights())
    scene_graph.AddRenderer(PERCEPTION_RENDERER, MakeRenderEngineVtk(params))
    net = None
    if scene == "room":
        net = load_segmenter(segmenter)[0]
    else:
        render_only(plant, scene_graph, object_model)
    core = RenderCameraCore(PERCEPTION_RENDERER, drake_camera_info(camera),
                            ClippingRange(0.05, 20.0), RigidTransform())
    system = builder.AddNamedSystem("nfr_perception", NfrPerceptionSystem(
        FittedModel(model_dir), [camera] * len(X_WCs), X_WCs, X_WO, fit_config,
        keypoint_source=keypoint_source, segmenter=net, part=part, furniture_config=furniture_config,
        room_loss=room_loss, mask_crop=mask_crop, paintings=paintings, aimed_look=aimed_look,
        look_again=look_again, refine_masks=refine_masks))
    for i, X_WC in enumerate(X_WCs):
        sensor = builder.AddNamedSystem(f"nfr_camera_{i}", RgbdSensor(
            parent_id=scene_graph.world_frame_id(), X_PB=X_WC,
            color_camera=ColorRenderCamera(core, show_window=False),
            depth_camera=DepthRenderCamera(core, DepthRange(0.05, 20.0))))
        builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
        builder.Connect(sensor.color_image_output_port(), system.get_camera_rgb_input_port(i))
    return system
