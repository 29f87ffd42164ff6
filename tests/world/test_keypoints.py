"""Keypoint trajectories: ground truth in the world frame, fit results, bad input."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from nfr_drake.errors import NfrDrakeError
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.world.keypoints import KeypointTrajectory

X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, 0.4), [0.3, -0.2, 0.0])


def _object(category, seed=0):
    return sample_object(category, object_rng(SEED_DOMAIN_TRAIN, seed, 0))


@pytest.mark.parametrize("category", ["closet", "drawer"])
def test_ground_truth_in_world(category):
    obj = _object(category)
    kt = KeypointTrajectory.from_articulated_object(obj, X_WO, 0.3, grid_size=21)
    assert kt.p_WK.shape == (21, len(obj.keypoint_names), 3)
    for q in (0.0, 0.35, 1.0):  # the door's arc is interpolated by chords: < 2 mm off at 21 points
        p_OK = obj.keypoint_array(q)
        expected = (X_WO.rotation().matrix() @ p_OK.T).T + X_WO.translation()
        np.testing.assert_allclose(kt.at(q), expected, atol=2e-3)
    assert kt.at(np.array([0.1, 0.2])).shape == (2, len(obj.keypoint_names), 3)
    assert kt.q_current == pytest.approx(0.3)


def test_fit_result_round_trip():
    obj = _object("closet")
    q = np.linspace(0, 1, 5)
    result = {"category": "closet", "q": 0.25, "trajectory": {
        "q": q.tolist(), "keypoints": {n: obj.keypoint_array(q)[:, i].tolist()
                                       for i, n in enumerate(obj.keypoint_names)}}}
    kt = KeypointTrajectory.from_fit_result(result, RigidTransform())
    np.testing.assert_allclose(kt.point("handle", 0.5), obj.keypoints(0.5)["handle"], atol=1e-9)
    with pytest.raises(NfrDrakeError, match="no usable keypoint trajectory"):
        KeypointTrajectory.from_fit_result({"category": "closet"}, RigidTransform())


def test_rejects_bad_input():
    with pytest.raises(NfrDrakeError, match="shape"):
        KeypointTrajectory("drawer", np.linspace(0, 1, 3), ("handle",), np.zeros((4, 1, 3)), 0.0)
    with pytest.raises(NfrDrakeError, match="lacks keypoints"):
        KeypointTrajectory("closet", np.linspace(0, 1, 3), ("handle",), np.zeros((3, 1, 3)), 0.0)


@pytest.mark.parametrize("category", ["closet", "drawer"])
def test_nearest_q_reads_the_articulation_off_a_handle_point(category):
    """The handle at a known articulation, moved 1.5 cm along the grip's depth (off the path),
    reads back within 0.01 of it; a point far off the path gives the nearest end."""
    obj = sample_object(category, np.random.default_rng(4))
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    for q in (0.0, 0.37, 0.6, 1.0):
        p = kt.point("handle", q)
        off = np.cross(kt.point("handle", min(q + 0.01, 1.0)) - kt.point("handle", max(q - 0.01, 0.0)),
                       [0.0, 0.0, 1.0])
        assert abs(kt.nearest_q("handle", p + 0.015 * off / np.linalg.norm(off)) - q) <= 0.01
    start = kt.point("handle", 0.0)
    assert kt.nearest_q("handle", start + 5.0 * (start - kt.point("handle", 1.0))) == 0.0
