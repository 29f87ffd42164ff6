"""Grasp frames and obstacle boxes derived from keypoint trajectories alone."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw

from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng, sample_object
from nfr_drake.planning.grasp import (
    PANEL_SETBACK,
    carcass_box,
    door_panel_box,
    handle_tangent,
    handle_waypoints,
)
from nfr_drake.world.keypoints import KeypointTrajectory

X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, 0.4), [0.3, -0.2, 0.0])


def _object(category, seed=0):
    return sample_object(category, object_rng(SEED_DOMAIN_TRAIN, seed, 0))


def test_drawer_grasp_frame():
    kt = KeypointTrajectory.from_articulated_object(_object("drawer"), RigidTransform(), 0.0)
    (wp,) = handle_waypoints(kt, np.array([0.5]))
    np.testing.assert_allclose(wp.approach_W, [-1, 0, 0], atol=1e-9)  # minus the pull direction
    np.testing.assert_allclose(np.abs(wp.bar_W), [0, 1, 0], atol=1e-9)  # horizontal bar
    R = wp.X_WG().rotation().matrix()
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_closet_grasp_frame_and_box():
    obj = _object("closet")
    kt = KeypointTrajectory.from_articulated_object(obj, RigidTransform(), 0.0)
    wps = handle_waypoints(kt, np.linspace(0, 1, 5))
    for w in wps:
        np.testing.assert_allclose(w.bar_W, [0, 0, 1], atol=1e-9)  # the hinge axis
        # The approach points into the door: against the door's outward normal.
        n_O = obj.X_OM(w.q)[:3, :3] @ np.array([1.0, 0, 0])
        assert w.approach_W @ n_O < -np.cos(np.radians(20))
    box = carcass_box(kt)
    p_BH = box.X_WB.inverse() @ obj.keypoints(0.0)["handle"]
    assert np.any(np.abs(p_BH) > box.size / 2 + 0.04)  # the handle is well outside the box
    p_BG = box.X_WB.inverse() @ obj.keypoints(0.0)["goal"]
    assert np.all(np.abs(p_BG) <= box.size / 2 + 1e-9)  # the carcass centre is inside


def test_a_doors_approach_follows_its_hinge_not_a_bent_end_of_its_path():
    """A door's keypoints whose handle path is bent at its shut end (the first grid step's point
    moved 1 cm sideways, as a fitted path can be): the path's own direction there is several
    degrees off, the handle's tangent (about the hinge line) and so the approach within 0.1
    degree of the true door's."""
    obj = _object("closet")
    kt = KeypointTrajectory.from_articulated_object(obj, X_WO, 0.0)
    p_WK = kt.p_WK.copy()
    handle = kt.names.index("handle")
    lateral = np.cross([0.0, 0.0, 1.0], p_WK[1, handle] - p_WK[0, handle])
    p_WK[1, handle] += 0.01 * lateral / np.linalg.norm(lateral)
    bent = KeypointTrajectory(kt.category, kt.q_grid, kt.names, p_WK, 0.0)
    step = bent.point("handle", bent.q_grid[1]) - bent.point("handle", 0.0)
    true = handle_tangent(kt, 0.0)
    assert _degrees_between(step, true) > 3.0
    assert _degrees_between(handle_tangent(bent, 0.0), true) < 0.1
    (wp,) = handle_waypoints(bent, np.array([0.0]))
    assert _degrees_between(wp.approach_W, -true) < 0.1


def _degrees_between(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def test_open_door_panel_box():
    """An open door's approach obstacle: a thin box facing like the true door, its front face
    PANEL_SETBACK behind the handle; none for a shut door or a drawer."""
    obj = _object("closet")
    assert door_panel_box(KeypointTrajectory.from_articulated_object(obj, X_WO, 0.0)) is None
    drawer = KeypointTrajectory.from_articulated_object(_object("drawer"), X_WO, 0.8)
    assert door_panel_box(drawer) is None
    q = 0.8
    box = door_panel_box(KeypointTrajectory.from_articulated_object(obj, X_WO, q))
    n_W = X_WO.rotation() @ obj.X_OM(q)[:3, :3] @ np.array([1.0, 0, 0])  # the door's outward normal
    assert box.X_WB.rotation().col(0) @ n_W > np.cos(np.radians(20))
    p_BH = box.X_WB.inverse() @ (X_WO @ obj.keypoints(q)["handle"])
    assert p_BH[0] == pytest.approx(box.size[0] / 2 + PANEL_SETBACK, abs=1e-9)
    assert abs(p_BH[1]) < box.size[1] / 2 and abs(p_BH[2]) < box.size[2] / 2
    p_BA = box.X_WB.inverse() @ (X_WO @ obj.keypoints(q)["hinge_bottom"])
    assert abs(p_BA[1]) == pytest.approx(box.size[1] / 2, abs=1e-9)  # from the hinge line on
