"""NfrPerceptionSystem: fits once per trigger, sees the object alone, outputs keypoints in W."""

import math

import numpy as np
import pytest
import torch
from pydrake.geometry import Box
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.inference.forward import semantic_point_cloud
from nfr_drake.inference.infer import FittedModel
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.objects.plant import add_articulated_object
from nfr_drake.systems.perception import AddNfrPerception
from tests.systems.conftest import TINY_FIT


def _scene(model_dir, obj, X_WO, X_OCs, camera, known_pose=True):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_articulated_object(plant, obj, X_WO)
    # A distractor that the perception cameras must not see: a red box in front of the object.
    distractor = plant.AddRigidBody("distractor", plant.AddModelInstance("distractor"),
                                    SpatialInertia.SolidBoxWithMass(1, 0.3, 0.3, 0.3))
    plant.RegisterVisualGeometry(distractor, RigidTransform(), Box(0.3, 0.3, 0.3), "box",
                                 np.array([1.0, 0.0, 0.0, 1.0]))
    plant.WeldFrames(plant.world_frame(), distractor.body_frame(),
                     X_WO @ RigidTransform([0.9, 0.0, 0.5]))
    plant.Finalize()
    X_WCs = [X_WO @ RigidTransform(X) for X in X_OCs]
    system = AddNfrPerception(builder, plant, scene_graph, model_dir, model,
                              X_WO if known_pose else None, X_WCs, camera, TINY_FIT)
    return builder.Build(), system


def test_fits_once_at_initialisation_and_once_per_refit(model_dir):
    obj = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 5, 0))
    camera = PinholeCamera.from_fov(24, 24, math.radians(50))
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.7), [1.0, -0.5, 0.0])
    X_OCs = CameraDistribution().sample(np.random.default_rng(0), 3, obj.look_at_target())
    diagram, system = _scene(model_dir, obj, X_WO, X_OCs, camera)
    simulator = Simulator(diagram)
    simulator.Initialize()
    assert system.fit_count == 1
    simulator.AdvanceTo(0.05)  # 50 discrete plant steps
    assert system.fit_count == 1
    context = system.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    result = system.refit(context)
    assert system.fit_count == 2
    kt = system.get_keypoint_trajectory_output_port().Eval(context)
    assert system.fit_count == 2  # reading outputs never fits
    q = system.get_q_estimate_output_port().Eval(context)[0]
    assert q == pytest.approx(result.q) and kt.q_current == pytest.approx(result.q)
    # Keypoints come out in W: the fit result (in O) moved by X_WO.
    p_O = result.trajectory["goal"][3]
    np.testing.assert_allclose(kt.point("goal", kt.q_grid[3]), X_WO.multiply(p_O), atol=1e-9)
    # The fitted field's points come out in W too, at the fitted q, from the cameras at 48 px.
    cloud = system.get_semantic_cloud_output_port().Eval(context)
    assert system.fit_count == 2 and cloud.q == pytest.approx(result.q)
    views = [(camera.scaled(48, 48), X) for X in X_OCs]
    field = FittedModel(model_dir).model
    points_O, classes = semantic_point_cloud(field, torch.as_tensor(result.z), result.q, views)
    assert len(points_O) > 100
    np.testing.assert_array_equal(cloud.classes, classes)
    np.testing.assert_allclose(cloud.points, X_WO.multiply(points_O.T.astype(float)).T, atol=1e-5)


def test_perception_cameras_see_the_object_as_the_training_renderer_does(model_dir):
    obj = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 5, 1))
    camera = PinholeCamera.from_fov(48, 48, math.radians(50))
    X_WO = RigidTransform(RollPitchYaw(0, 0, -0.4), [0.5, 0.8, 0.0])
    X_OCs = CameraDistribution().sample(np.random.default_rng(1), 2, obj.look_at_target())
    diagram, system = _scene(model_dir, obj, X_WO, X_OCs, camera)
    context = diagram.CreateDefaultContext()
    reference = ObjectRenderer(obj, camera)
    for i, X_OC in enumerate(X_OCs):
        sensor = diagram.GetSubsystemByName(f"nfr_camera_{i}")
        image = sensor.color_image_output_port().Eval(sensor.GetMyContextFromRoot(context))
        seen = image.data[..., :3].astype(int)
        expected = reference.render_rgb(0.0, X_OC).astype(int)
        # Same object, pose, background and lights; the red distractor box is not seen.
        assert np.abs(seen - expected).mean() < 2.0


def test_object_pose_is_estimated_from_the_views_when_not_given(model_dir):
    obj = sample_object("closet", object_rng(SEED_DOMAIN_CAPTURE, 5, 2))
    camera = PinholeCamera.from_fov(96, 96, math.radians(50))
    X_WO = RigidTransform(RollPitchYaw(0, 0, 2.2), [-0.7, 1.1, 0.0])
    X_OCs = CameraDistribution().sample(np.random.default_rng(2), 8, obj.look_at_target())
    diagram, system = _scene(model_dir, obj, X_WO, X_OCs, camera, known_pose=False)
    simulator = Simulator(diagram)
    simulator.Initialize()
    context = system.GetMyContextFromRoot(simulator.get_context())
    X_WO_hat = system.get_X_WO_output_port().Eval(context)
    error = X_WO.inverse() @ X_WO_hat
    assert np.linalg.norm(error.translation()) < 0.02
    assert abs(RollPitchYaw(error.rotation()).yaw_angle()) < math.radians(2.0)
    result = system.get_fit_result_output_port().Eval(context)
    assert result.extra["object_pose"]["estimated"] is True
    # Keypoints come out in W through the estimate: the fit result (in O) moved by X_WO_hat.
    kt = system.get_keypoint_trajectory_output_port().Eval(context)
    p_O = result.trajectory["goal"][3]
    np.testing.assert_allclose(kt.point("goal", kt.q_grid[3]), X_WO_hat.multiply(p_O), atol=1e-9)
