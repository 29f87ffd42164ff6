"""NfrPerceptionSystem with a furniture model: the part asked for (a parameter), the others held."""

import math

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import CameraDistribution
from nfr_drake.errors import NfrDrakeError
from nfr_drake.inference.furniture_fit import FurnitureFitConfig
from nfr_drake.inference.infer import FittedModel
from nfr_drake.objects import SEED_DOMAIN_CAPTURE, object_rng, sample_object
from nfr_drake.objects.plant import add_articulated_object
from nfr_drake.systems.perception import AddNfrPerception, NfrPerceptionSystem

QUICK = FurnitureFitConfig(starts=2, keep=1, steps=2, rays_per_step=32, lookup_rays=32)


def test_outputs_the_part_asked_for_without_fitting_again(furniture_model_folder):
    obj = sample_object("furniture", object_rng(SEED_DOMAIN_CAPTURE, 5, 0))
    camera = PinholeCamera.from_fov(24, 24, math.radians(50))
    cameras = CameraDistribution(framing="bounds")
    X_OCs = cameras.sample(np.random.default_rng(0), 3, *cameras.target_of(obj), camera)
    X_WO = RigidTransform(RollPitchYaw(0, 0, 0.5), [1.0, -0.5, 0.0])
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_articulated_object(plant, obj, X_WO)
    plant.Finalize()
    system = AddNfrPerception(builder, plant, scene_graph, furniture_model_folder, model, X_WO,
                              [X_WO @ RigidTransform(X) for X in X_OCs], camera, part=1,
                              furniture_config=QUICK)
    simulator = Simulator(builder.Build())
    simulator.Initialize()
    context = system.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    result = system.get_fit_result_output_port().Eval(context)
    kt = system.get_keypoint_trajectory_output_port().Eval(context)
    # Slot 1 of the tiny model is a drawer: a drawer's trajectory, in W.
    assert result.part == {"index": 1, "type": "drawer", "found": True} and kt.category == "drawer"
    assert system.get_q_estimate_output_port().Eval(context)[0] == pytest.approx(result.q)
    handle_W = [X_WO.multiply(p) for p in result.trajectory["handle"]]
    np.testing.assert_allclose(kt.point("handle", kt.q_grid), handle_W, atol=1e-9)
    # The confidence of the part asked for (no calibration in the tiny model: features, no p).
    confidence = system.get_confidence_output_port().Eval(context)
    assert confidence["features"] == result.parts[1]["confidence"]["features"]
    assert confidence["p_handle_within_2cm"] is None and len(confidence["per_view"]) == 3
    system.set_part(context, 0)
    door = system.get_keypoint_trajectory_output_port().Eval(context)
    assert door.category == "closet" and system.fit_count == 1
    assert (system.get_confidence_output_port().Eval(context)["features"]
            == result.parts[0]["confidence"]["features"])
    assert system.get_fit_result_output_port().Eval(context).part["index"] == 0
    hinge_O = result.parts[0]["trajectory"]["keypoints"]["axis_0"][2]
    np.testing.assert_allclose(door.point("hinge_top", door.q_grid[2]), X_WO.multiply(hinge_O), atol=1e-9)
    system.set_part(context, 5)
    with pytest.raises(NfrDrakeError, match="finds no part 5"):
        system.get_keypoint_trajectory_output_port().Eval(context)


def test_a_part_is_refused_for_a_one_part_model(model_folder):
    camera = PinholeCamera.from_fov(16, 16, math.radians(50))
    with pytest.raises(ValueError, match="has one part"):
        NfrPerceptionSystem(FittedModel(model_folder), [camera], [RigidTransform()], part=0)
