"""KeypointTrajectorySource reads the object's articulation from the plant state."""

import numpy as np
import pytest
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.objects.plant import add_articulated_object, set_articulation
from nfr_drake.systems.keypoints import AddKeypointTrajectorySource
from nfr_drake.world.keypoints import KeypointTrajectory


@pytest.mark.parametrize("category", ["closet", "drawer"])
def test_outputs_current_articulation(category):
    obj = sample_object(category, object_rng(SEED_DOMAIN_TRAIN, 1, 0))
    X_WO = RigidTransform([0.5, 0.0, 0.0])
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, 0.0)
    model = add_articulated_object(plant, obj, X_WO)
    plant.Finalize()
    truth = KeypointTrajectory.from_articulated_object(obj, X_WO, 0.0)
    source = AddKeypointTrajectorySource(builder, plant, plant.GetJointByName(obj.joint_name, model), truth)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    set_articulation(plant, plant.GetMyMutableContextFromRoot(context), obj, model, 0.7)
    kt = source.get_keypoint_trajectory_output_port().Eval(source.GetMyContextFromRoot(context))
    assert kt.q_current == pytest.approx(0.7, abs=1e-5)  # SDFormat stores limits to 6 digits
    np.testing.assert_array_equal(kt.p_WK, truth.p_WK)
    assert source.get_plant_state_input_port().size() == plant.num_multibody_states()
