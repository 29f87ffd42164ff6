"""Perception in a room: a room placed at the object's pose, cameras that see it, the segmenter's
masks in the fit, and a pose the masks do not give."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.rooms import RoomDistribution, sample_room
from nfr_drake.errors import ConfigError
from nfr_drake.inference import infer as infer_module
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.objects.plant import add_articulated_object
from nfr_drake.perception import object_pose as object_pose_module
from nfr_drake.perception.object_pose import ObjectPoseError, ObjectPoseEstimate
from nfr_drake.perception.segmentation import crop as crop_module
from nfr_drake.perception.segmentation.model import Segmenter, SegmenterConfig
from nfr_drake.systems import perception as perception_module
from nfr_drake.systems.perception import SEGMENTER_DIR, AddNfrPerception
from nfr_drake.systems.pipeline import perception_room, run_scenario, visible_silhouettes
from nfr_drake.systems.scenario import Scenario
from tests.systems.conftest import TINY_FIT

SEGMENTER = Path(__file__).parents[2] / SEGMENTER_DIR


def _needs_segmenter():
    if not (SEGMENTER / "model.safetensors").is_file():
        pytest.skip(f"no shipped segmenter at {SEGMENTER}")


def _room_plant(room, X_PW=None):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    room.add_to(plant, X_PW)
    plant.Finalize()
    diagram = builder.Build()
    inspector = scene_graph.model_inspector()
    world = {inspector.GetName(g): inspector.GetPoseInFrame(g)
             for g in inspector.GetGeometries(plant.GetBodyFrameIdOrThrow(plant.world_body().index()))}
    return plant, plant.GetMyContextFromRoot(diagram.CreateDefaultContext()), world


def test_a_room_placed_at_X_PW_is_the_same_room_moved():
    obj = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 9, 0))
    cameras = np.array([[2.0, 0.3, 1.0], [1.8, -0.6, 1.4]])
    room = sample_room(np.random.default_rng(3), obj, cameras,
                       RoomDistribution(style="heldout", neighbours=(2, 2), robot_probability=1.0))
    assert room.robot is not None and len(room.neighbours) == 2
    X_PW = RigidTransform(RollPitchYaw(0.0, 0.0, 2.1), [0.7, -1.2, 0.0])
    (plant_0, context_0, world_0), (plant_1, context_1, world_1) = (
        _room_plant(room), _room_plant(room, X_PW.GetAsMatrix4()))
    for name in ("room_panda::panda", "room_furniture_0", "room_furniture_1"):
        model_0, model_1 = plant_0.GetModelInstanceByName(name), plant_1.GetModelInstanceByName(name)
        for i_0, i_1 in zip(plant_0.GetBodyIndices(model_0), plant_1.GetBodyIndices(model_1), strict=True):
            X_0 = plant_0.EvalBodyPoseInWorld(context_0, plant_0.get_body(i_0))
            X_1 = plant_1.EvalBodyPoseInWorld(context_1, plant_1.get_body(i_1))
            np.testing.assert_allclose((X_PW @ X_0).GetAsMatrix4(), X_1.GetAsMatrix4(), atol=1e-9)
    # Floor, walls and clutter are the world body's geometry, at X_PW times their pose in W.
    assert len(world_0) == len(room.surfaces) + len(room.clutter) and world_0.keys() == world_1.keys()
    for name, X_0 in world_0.items():
        np.testing.assert_allclose((X_PW @ X_0).GetAsMatrix4(), world_1[name].GetAsMatrix4(), atol=1e-9)
    lights = room.lighting.moved(X_PW.GetAsMatrix4()).lights
    for before, after in zip(room.lighting.lights, lights, strict=True):
        if before.frame == "camera":
            assert after == before
        else:
            np.testing.assert_allclose(after.position, X_PW.multiply(np.array(before.position)), atol=1e-12)
            np.testing.assert_allclose(after.direction, X_PW.rotation().multiply(np.array(before.direction)),
                                       atol=1e-12)


def _perception_scene(model_dir, scene, X_WO, known=True, fit=TINY_FIT, paintings=("region",),
                      aimed_look="off-aim", look_again=True, refine_masks=False):
    obj = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 5, 1))
    scenario = Scenario(seed=5, index=1, object_xyz=list(X_WO.translation()),
                        object_yaw_deg=math.degrees(RollPitchYaw(X_WO.rotation()).yaw_angle()))
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    model = add_articulated_object(plant, obj, X_WO)
    X_OCs = CameraDistribution().sample(np.random.default_rng(1), 3, obj.look_at_target())
    X_WCs = [X_WO @ RigidTransform(X) for X in X_OCs]
    lighting = None
    if scene == "room":
        room = perception_room(scenario, obj, X_WCs)
        room.add_to(plant, X_WO.GetAsMatrix4())
        lighting = room.lighting.moved(X_WO.GetAsMatrix4())
    plant.Finalize()
    camera = PinholeCamera.from_fov(32, 32, math.radians(50))
    system = AddNfrPerception(builder, plant, scene_graph, model_dir, model, X_WO if known else None,
                              X_WCs, camera, fit, lighting, scene=scene, segmenter=SEGMENTER,
                              paintings=paintings, aimed_look=aimed_look, look_again=look_again,
                              refine_masks=refine_masks)
    return builder.Build(), system


def test_room_perception_sees_the_room_and_fits_on_the_segmenters_masks(model_dir, monkeypatch):
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    seen = {}
    for scene in ("alone", "room"):
        diagram, _ = _perception_scene(model_dir, scene, X_WO)
        context = diagram.CreateDefaultContext()
        sensor = diagram.GetSubsystemByName("nfr_camera_0")
        image = sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(context))
        seen[scene] = image.data[..., :3]
    background = np.round(255 * np.array(DEFAULT_BACKGROUND_RGB))
    off_background = lambda image: np.mean(np.abs(image.astype(float) - background).max(-1) > 8)  # noqa: E731
    assert off_background(seen["alone"]) < 0.7  # the object alone before the training background
    assert off_background(seen["room"]) > 0.99  # floor, walls: no background left
    # The fit gets the segmenter's masks, one per view, of the image's size, and the photos painted
    # in the training background off them (the whole image in the loss).
    calls = []
    real_infer = infer_module.infer

    def spy(*args, **kwargs):
        calls.append((args[4], kwargs))
        return real_infer(*args, **kwargs)

    monkeypatch.setattr(infer_module, "infer", spy)
    looks = []
    real_look = perception_module.posed_close_look

    def look_spy(net, images, X_WCs, cameras, category, hull):
        looks.append((len(images), len(X_WCs), category))
        return real_look(net, images, X_WCs, cameras, category, hull)

    monkeypatch.setattr(perception_module, "posed_close_look", look_spy)
    diagram, system = _perception_scene(model_dir, "room", X_WO)
    Simulator(diagram).Initialize()
    assert system.fit_count == 1 and len(calls) == 1
    assert looks == [(3, 3, "closet")]  # the crop stage over the three posed views (mask_crop)
    images, kwargs = calls[0]
    masks = kwargs["masks"]
    assert kwargs["masked_loss"] is False
    assert kwargs["refine_pose"] is False  # a given pose is never moved
    assert masks is not None and len(masks) == 3 and all(m.shape == (32, 32) for m in masks)
    assert all(0.0 <= m.min() and m.max() <= 1.0 for m in masks)
    for image, mask in zip(images, masks, strict=True):
        off = mask < 0.01
        assert off.any() and np.abs(image[off].astype(float) - background).max() <= 3


def test_one_fit_per_painting_and_the_most_confident_kept(model_dir, monkeypatch):
    """Two paintings ("region", then "sure"): two fits on differently painted photos (the sure one
    paints more), each told which pixels its photos keep (where the handle detector counts), the
    one whose P(handle within 2 cm) is higher kept, and the result says which."""
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    calls, kept, given_p = [], [], iter([0.3, 0.8])
    real_infer = infer_module.infer

    def spy(*args, **kwargs):
        result, outcome = real_infer(*args, **kwargs)
        result.confidence = {**(result.confidence or {}), "p_handle_within_2cm": next(given_p)}
        calls.append((args[4], result))
        kept.append(kwargs["kept"])
        return result, outcome

    monkeypatch.setattr(infer_module, "infer", spy)
    diagram, system = _perception_scene(model_dir, "room", X_WO, paintings=("region", "sure"))
    context = diagram.CreateDefaultContext()
    Simulator(diagram, context).Initialize()
    assert system.fit_count == 1 and len(calls) == 2
    background = np.round(255 * np.array(DEFAULT_BACKGROUND_RGB))
    painted = [sum(int((np.abs(i.astype(float) - background).max(-1) <= 3).sum()) for i in images)
               for images, _ in calls]
    assert painted[1] >= painted[0]
    for (images, _), kept_pixels in zip(calls, kept, strict=True):
        assert [k.sum() for k in kept_pixels] != [0] * len(images)
        for image, k in zip(images, kept_pixels, strict=True):  # every pixel not kept is painted
            assert (image[~k] == background).all()
    result = system.get_fit_result_output_port().Eval(system.GetMyContextFromRoot(context))
    assert result.confidence["p_handle_within_2cm"] == 0.8 and result.q == calls[1][1].q
    assert result.extra["paintings"] == {"chosen": "sure",
                                         "p_handle_within_2cm": {"region": 0.3, "sure": 0.8}}
    with pytest.raises(ValueError, match="paintings"):
        _perception_scene(model_dir, "room", X_WO, paintings=("brush",))
    # A given pose comes without a carcass size: "fronts" paints as "region", one fit for both.
    calls.clear()
    given_p = iter([0.5])
    diagram, system = _perception_scene(model_dir, "room", X_WO, paintings=("region", "fronts"))
    Simulator(diagram).Initialize()
    assert len(calls) == 1


@pytest.mark.parametrize("refine_masks", [True, False])
def test_the_fit_gets_the_masks_refined_by_the_photos_colours(model_dir, monkeypatch, refine_masks):
    """With `refine_masks` the segmenter's masks are refined once per fit (`segmentation.refine`)
    before the painting, and the fit gets the refined masks, never above the segmenter's; without,
    the segmenter's as they are."""
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    refined, fitted_on = [], []
    real_refine, real_infer = infer_module.refined_by_colour, infer_module.infer

    def refine_spy(images, masks):
        out = real_refine(images, masks)
        refined.append((masks, out))
        return out

    def infer_spy(*args, **kwargs):
        fitted_on.append(kwargs["masks"])
        return real_infer(*args, **kwargs)

    monkeypatch.setattr(infer_module, "refined_by_colour", refine_spy)
    monkeypatch.setattr(infer_module, "infer", infer_spy)
    diagram, system = _perception_scene(model_dir, "room", X_WO, refine_masks=refine_masks)
    Simulator(diagram).Initialize()
    assert len(fitted_on) == 1 and len(refined) == (1 if refine_masks else 0)
    if refine_masks:
        (raw, out), = refined
        assert all(a is b for a, b in zip(fitted_on[0], out, strict=True))
        for before, after in zip(raw, out, strict=True):
            assert after.shape == before.shape and np.all(after <= before)
            assert np.all((after == before) | (after == 0.0))


def test_crop_masks_that_give_no_pose_fall_back_to_the_first_look(model_dir, monkeypatch):
    """The crop stage's masks agree on no object (here: empty): the pose and the fit's masks come
    from the segmenter's first look, and the result says so."""
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    real_load = perception_module.load_segmenter

    def visible_only(folder):
        net, record = real_load(folder)
        net.config = replace(net.config, amodal=False)  # the pose from the visible masks
        return net, record

    monkeypatch.setattr(perception_module, "load_segmenter", visible_only)
    monkeypatch.setattr(crop_module, "posed_close_look",
                        lambda net, images, *args: [np.zeros(i.shape[:2], np.float32) for i in images])
    real_estimate = object_pose_module.estimate_object_pose
    poses_from = []

    def estimate(masks, *args, **kwargs):
        poses_from.append(max(float(m.max()) for m in masks))
        if poses_from[-1] == 0.0:
            return real_estimate(masks, *args, **kwargs)  # raises ObjectPoseError: nothing on the masks
        return ObjectPoseEstimate.from_box(np.array([1.0, 0.4, 0.6, 0.5, 0.6, 0.9]), 0.02, 1, np.zeros(6))

    monkeypatch.setattr(object_pose_module, "estimate_object_pose", estimate)
    fit = replace(TINY_FIT, pose_max_shift_m=0.5)  # the tiny model's move is kept, not refused
    diagram, system = _perception_scene(model_dir, "room", X_WO, known=False, fit=fit)
    simulator = Simulator(diagram)
    simulator.Initialize()
    assert system.fit_count == 1 and len(poses_from) == 2 and poses_from[0] == 0.0 and poses_from[1] > 0.5
    result = system.get_fit_result_output_port().Eval(system.GetMyContextFromRoot(simulator.get_context()))
    assert any("first look" in w for w in result.extra["warnings"])
    assert result.extra["object_pose"]["estimated"] is True


def test_an_estimated_pose_is_refined_and_the_port_gives_the_refined_one(model_dir):
    """Without X_WO the fit refines the masks' pose with the field; the result keeps the estimate
    and the refinement's report, and the X_WO port gives the estimate moved by the kept
    refinement's X_OP."""
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    fit = replace(TINY_FIT, pose_max_shift_m=0.5, pose_max_yaw_deg=45.0)  # the tiny model's move is kept
    diagram, system = _perception_scene(model_dir, "room", X_WO, known=False, fit=fit)
    simulator = Simulator(diagram)
    simulator.Initialize()
    context = system.GetMyContextFromRoot(simulator.get_context())
    pose = system.get_fit_result_output_port().Eval(context).extra["object_pose"]
    refinement = pose["refinement"]
    assert refinement is not None and refinement["steps"] == fit.pose_steps
    assert refinement["status"] == "kept", refinement["status"]
    expected = np.array(pose["X_WO_estimated"]) @ np.array(refinement["X_OP"])
    assert not np.allclose(expected, pose["X_WO_estimated"])  # it moved
    assert np.allclose(pose["X_WO"], expected, atol=1e-9)
    assert np.allclose(system.get_X_WO_output_port().Eval(context).GetAsMatrix4(), expected, atol=1e-9)


@pytest.mark.parametrize("carcass_gives_a_pose", [True, False])
def test_with_the_amodal_output_the_pose_comes_from_the_carcass(model_dir, monkeypatch, carcass_gives_a_pose):
    """A segmenter with the amodal carcass output, where the aimed look gives no pose: the pose is
    fitted to the carcass's masks from the whole photos (amodal=True, the box is the carcass), or,
    when those masks give none, to the visible masks; the fit gets the visible masks."""
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    carcass = []

    def amodal_net(folder):
        net = Segmenter(SegmenterConfig(channels=4, levels=2, bottleneck_dilations=(2,), amodal=True))
        net.carcass_amodal = lambda image: carcass.append(image.shape) or np.full(image.shape[:2], 0.75,
                                                                                    np.float32)
        return net, {}

    monkeypatch.setattr(perception_module, "load_segmenter", amodal_net)
    poses_from = []

    def estimate(masks, X_WCs, cameras, config, category, amodal=False):
        poses_from.append(([float(m.mean()) for m in masks], amodal))
        if amodal and not carcass_gives_a_pose:
            raise ObjectPoseError("object pose: the masks agree on no object")
        return ObjectPoseEstimate.from_box(np.array([1.0, 0.4, 0.6, 0.5, 0.6, 0.9]), 0.0, 1, np.zeros(6))

    monkeypatch.setattr(object_pose_module, "estimate_object_pose", estimate)
    monkeypatch.setattr(crop_module, "posed_close_look",
                        lambda net, images, *args: [np.full(i.shape[:2], 0.3, np.float32) for i in images])
    monkeypatch.setattr(crop_module, "posed_carcass_look",
                        lambda net, images, *args: [net.carcass_amodal(i) for i in images])
    monkeypatch.setattr(crop_module, "aimed_looks", lambda *args: None)  # it gives no pose
    calls = []

    class Stop(Exception):
        pass

    def infer(*args, **kwargs):
        calls.append(kwargs)
        raise Stop

    monkeypatch.setattr(infer_module, "infer", infer)
    diagram, _ = _perception_scene(model_dir, "room", X_WO, known=False)
    with pytest.raises(Stop):
        Simulator(diagram).Initialize()
    assert carcass == [(32, 32, 3)] * 3
    expected = [([0.75] * 3, True)] + ([] if carcass_gives_a_pose else [([pytest.approx(0.3)] * 3, False)])
    assert poses_from == expected
    assert [float(m.mean()) for m in calls[0]["masks"]] == pytest.approx([0.3] * 3)  # the fit's masks


@pytest.mark.parametrize("whole, aimed_look, expect_aimed", [
    ("holds the aim", "off-aim", False), ("off the aim", "off-aim", True), ("no pose", "off-aim", True),
    ("holds the aim", "always", True), ("off the aim", "never", False)])
def test_the_aimed_look_replaces_a_pose_off_the_cameras_aim(model_dir, monkeypatch, whole, aimed_look,
                                                             expect_aimed):
    """With an estimated pose and the crop stage, the whole photos' pose and masks are the fit's
    when their floor box holds the cameras' aim point; when it does not, or they give no pose,
    the aimed look's (`aimed_look` "off-aim"); "always" looks there first, "never" not at all."""
    _needs_segmenter()
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    box = np.array([1.1, 0.3, 0.5, 0.5, 0.6, 0.9])
    looked = []

    def aimed(net, images, X_WCs, cameras, category, hull):
        looked.append((len(images), category))
        masks = [np.full(i.shape[:2], 0.4, np.float32) for i in images]
        return masks, masks, ObjectPoseEstimate.from_box(box, 0.0, 1, np.zeros(6))

    def estimate(masks, X_WCs, cameras, config, category, amodal=False):
        if whole == "no pose":
            raise ObjectPoseError("object pose: the masks agree on no object")
        return ObjectPoseEstimate.from_box(box + [0.0 if whole == "holds the aim" else 0.8, 0, 0, 0, 0, 0],
                                           0.0, 1, np.zeros(6))

    monkeypatch.setattr(crop_module, "aimed_looks", aimed)
    monkeypatch.setattr(crop_module, "aimed_at", lambda b, X_WCs: bool(np.allclose(b, box)))
    monkeypatch.setattr(object_pose_module, "estimate_object_pose", estimate)
    monkeypatch.setattr(crop_module, "posed_close_look",
                        lambda net, images, *args: [np.full(i.shape[:2], 0.3, np.float32) for i in images])
    monkeypatch.setattr(crop_module, "posed_carcass_look",
                        lambda net, images, *args: [np.full(i.shape[:2], 0.3, np.float32) for i in images])
    fitted = []

    def infer(*args, **kwargs):
        fitted.append(kwargs)
        raise ObjectPoseError("stop here")  # not the pose's: raised by the fit

    monkeypatch.setattr(infer_module, "infer", infer)
    diagram, system = _perception_scene(model_dir, "room", X_WO, known=False, aimed_look=aimed_look)
    with pytest.raises(ObjectPoseError, match="stop here"):
        Simulator(diagram).Initialize()
    masks = [float(m.mean()) for m in fitted[0]["masks"]]
    if expect_aimed:
        assert looked == [(3, "closet")] and masks == pytest.approx([0.4] * 3)
    else:
        assert not looked and masks == pytest.approx([0.3] * 3)


@pytest.mark.parametrize("first_p, other_p, look_again, other_gives_a_pose, kept", [
    (0.3, 0.8, True, True, "other"), (0.3, 0.2, True, True, "first"), (0.9, 0.8, True, True, None),
    (0.3, 0.8, False, True, None), (0.3, 0.8, True, False, None)])
def test_a_refused_fit_looks_again(model_dir, monkeypatch, first_p, other_p, look_again,
                                   other_gives_a_pose, kept):
    """A fit its confidence refuses (P below the calibration's threshold) is followed, with
    `look_again`, by a fit at the other look's pose and masks; the more confident is kept, X_WO
    and the result with it, and the extra says so. A confident fit, `look_again` off or an other
    look without a pose: one fit."""
    _needs_segmenter()
    from nfr_drake.inference.result import FitResult
    from nfr_drake.perception.segmentation.crop import RoomLooks

    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.6), [1.0, 0.4, 0.0])
    boxes = {"first": np.array([1.0, 0.4, 0.6, 0.5, 0.6, 0.9]),
             "other": np.array([1.3, 0.2, 0.5, 0.5, 0.6, 0.9])}

    def looks(name: str, aimed: bool) -> RoomLooks:
        masks = [np.full((32, 32), 0.5, np.float32)] * 3
        return RoomLooks(masks, None, ObjectPoseEstimate.from_box(boxes[name], 0.0, 1, np.zeros(6)),
                         True, aimed)

    others = []

    def other_look(net, images, X_WCs, cameras, category, first, hull):
        others.append(first.aimed)
        return looks("other", True) if other_gives_a_pose else None

    def infer_painted(fitted, capture, fit_config, q_grid, images, masks, X_WCs, X_WO, *args, **kwargs):
        name = "first" if np.allclose(X_WO[:2, 3], boxes["first"][:2]) else "other"
        p = first_p if name == "first" else other_p
        confidence = {"p_handle_within_2cm": p, "threshold": 0.5, "weakest": None,
                      "calibration": "confidence_room.json",
                      "features": {"views": 3, "image_loss": 0.01, "image_loss_worst_view": 0.02,
                                   "room": True}}
        result = FitResult("closet", 0.0, {}, np.zeros(1), {}, 0.01, 1.0, confidence=confidence,
                           extra={"warnings": [], "fitted_at": name})
        return result, None

    monkeypatch.setattr(perception_module, "room_looks", lambda *args: looks("first", False))
    monkeypatch.setattr(perception_module, "other_look", other_look)
    monkeypatch.setattr(perception_module, "infer_painted", infer_painted)
    monkeypatch.setattr(perception_module, "refined_object_pose", lambda X, result, outcome: (X, {}))
    diagram, system = _perception_scene(model_dir, "room", X_WO, known=False, look_again=look_again)
    simulator = Simulator(diagram)
    simulator.Initialize()
    context = system.GetMyContextFromRoot(simulator.get_context())
    result = system.get_fit_result_output_port().Eval(context)
    X_WO_out = system.get_X_WO_output_port().Eval(context).translation()
    assert others == ([False] if kept or (first_p < 0.5 and look_again) else [])
    expect = kept or "first"
    assert result.extra["fitted_at"] == expect
    np.testing.assert_allclose(X_WO_out[:2], boxes[expect][:2])
    looked_again = result.extra["object_pose"].get("looked_again")
    if kept is None:
        assert looked_again is None
    else:
        assert looked_again == {"kept": kept, "p_handle_within_2cm": [first_p, other_p],
                                "aimed": [False, True]}
    assert any("look's fit is kept" in w for w in result.extra["warnings"]) == (kept == "other")


def test_a_pose_the_masks_do_not_give_is_refused_not_a_crash(monkeypatch, tmp_path):
    """An object the segmenter's masks miss: the pipeline plans nothing, its errors are inf, and
    eval-pipeline writes a refused row."""
    import csv

    from nfr_drake.eval import pipeline_eval
    from nfr_drake.systems import pipeline

    def no_object(scenario, obj, part=None, cloud=False):
        raise ObjectPoseError("object pose: the masks agree on no object in front of the cameras")

    monkeypatch.setattr(pipeline, "perceive_scene", no_object)
    monkeypatch.setattr(pipeline, "check_category", lambda *args: None)
    scenario = Scenario(category="drawer", object_pose="estimated", perceive="room")
    outcome = run_scenario(scenario)
    assert outcome.task is None and outcome.predicted is None
    assert outcome.refused.startswith("nothing planned: object pose:")
    assert math.isinf(outcome.keypoint_rmse_cm) and outcome.pose_error == (math.inf, math.inf)
    assert "nothing planned" in outcome.report()
    rows = pipeline_eval.evaluate_pipeline(scenario, 1, tmp_path / "rows.csv")
    assert rows[0]["refused"] == "True" and rows[0]["success"] == "False"
    assert float(rows[0]["pose_error_cm"]) == math.inf and float(rows[0]["handle_error_cm"]) == math.inf
    assert "1 with no object pose" in pipeline_eval.perception_summary(rows)
    assert list(csv.DictReader(open(tmp_path / "rows.csv")))[0]["failure"].startswith("nothing planned")


def test_an_unknown_aimed_look_is_refused():
    with pytest.raises(ConfigError, match="aimed_look must be one of off-aim, always, never"):
        Scenario(aimed_look="sometimes")


def test_an_unknown_perception_scene_is_refused():
    with pytest.raises(ConfigError, match="perceive must be one of alone, room"):
        Scenario(perceive="kitchen")


def test_visible_silhouettes_leave_out_what_the_room_hides():
    """The true visible mask: the pixels off the training background alone, less those where the
    room's depth is nearer than the object's (an arm in front), within `VISIBLE_DEPTH_M`."""
    background = np.round(255 * np.array(DEFAULT_BACKGROUND_RGB)).astype(np.uint8)
    alone = np.tile(background, (20, 30, 1))
    alone[5:15, 5:25] = (120, 60, 30)
    depth_alone = np.full((20, 30), np.inf, np.float32)
    depth_alone[5:15, 5:25] = 1.5
    depth_room = np.where(np.isinf(depth_alone), 3.0, depth_alone + 0.01).astype(np.float32)
    depth_room[5:15, 20:25] = 0.9  # something of the room in front of the object's right end
    (visible,) = visible_silhouettes([alone], [depth_alone], [depth_room])
    expected = np.zeros((20, 30), bool)
    expected[5:15, 5:20] = True
    np.testing.assert_array_equal(visible, expected)
