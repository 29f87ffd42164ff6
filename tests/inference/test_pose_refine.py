"""The refinement of an estimated object pose by the fitted field (`inference.pose_refine`)."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from nfr_drake.data.capture import CaptureSet, read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.inference.fit import FitConfig, observed_rays
from nfr_drake.inference.infer import FittedModel, infer
from nfr_drake.inference.pose_refine import delta_transform, in_P, refine_object_pose, repose

CLOSET = Path(__file__).parents[2] / "models" / "closet"


def planar(dx: float, dy: float, yaw_deg: float) -> np.ndarray:
    """(4, 4): a turn by yaw_deg about z and a shift (dx, dy, 0) m."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    X = np.eye(4)
    X[:2, :2] = [[c, -s], [s, c]]
    X[:2, 3] = dx, dy
    return X


def pose_error(X: np.ndarray) -> tuple[float, float]:
    """Distance on the floor (cm) and yaw (degrees) of X (4, 4) from the identity."""
    return 100.0 * float(np.linalg.norm(X[:2, 3])), abs(math.degrees(math.atan2(X[1, 0], X[0, 0])))


def test_reposed_rays_have_the_gradient_of_finite_differences():
    generator = torch.Generator().manual_seed(0)
    origins = torch.randn(5, 3, dtype=torch.float64, generator=generator)
    directions = torch.randn(5, 3, dtype=torch.float64, generator=generator)
    directions = directions / directions.norm(dim=-1, keepdim=True)
    pivot = torch.tensor([0.3, -0.1, 0.0], dtype=torch.float64)
    delta = torch.tensor([0.02, -0.03, 0.07], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda d: repose(origins, directions, d, pivot), (delta,))


def test_the_refined_frame_is_the_one_the_rays_are_reposed_into():
    delta, pivot = np.array([0.03, -0.02, math.radians(4.0)]), np.array([0.3, 0.0, 0.45])
    X_OP = delta_transform(delta, pivot)
    p_P = np.array([[0.1, 0.2, 0.3], [0.6, -0.4, 1.0]])
    p_O = p_P @ X_OP[:3, :3].T + X_OP[:3, 3]
    back = in_P(torch.from_numpy(p_O), torch.from_numpy(delta), torch.from_numpy(pivot)).numpy()
    np.testing.assert_allclose(back, p_P, atol=1e-12)
    np.testing.assert_allclose(X_OP[:3, :3] @ [0.3, 0.0, 0.0] + X_OP[:3, 3], [0.33, -0.02, 0.0],
                               atol=1e-12)  # the turn is about the pivot's vertical line


@pytest.fixture(scope="module")
def misplaced_closet(tmp_path_factory):
    """The shipped closet model, a shut closet alone in 8 views of 64 px, and the capture with
    its poses in a frame 3 cm and 4 degrees off the closet's (X_OO': that frame in the true O)."""
    if not (CLOSET / "model.safetensors").is_file():
        pytest.skip("no shipped closet model")
    root = tmp_path_factory.mktemp("closet")
    captures_command("closet", n=1, out=root, views=8, size=64, seed=3, q=0.0)
    capture = read_capture_set(root / "closet_000")
    X_OO = planar(0.02, -0.0224, 4.0)
    X_OO_inv = np.linalg.inv(X_OO)
    moved = CaptureSet(capture.root, [replace(f, X_OC=X_OO_inv @ f.X_OC) for f in capture.frames],
                       capture.gt, capture.extra)
    torch.set_num_threads(1)
    return FittedModel(CLOSET), moved, X_OO


def test_a_pose_3_cm_and_4_degrees_off_is_refined_to_within_1_cm_and_1_degree(misplaced_closet):
    fitted, capture, X_OO = misplaced_closet
    assert pose_error(X_OO) == pytest.approx((3.0, 4.0), abs=0.01)
    result, outcome = infer(fitted, capture, FitConfig(), np.linspace(0, 1, 5), refine_pose=True)
    report = result.extra["pose_refinement"]
    assert report["status"] == "kept" and report["loss_after"] < report["loss_before"]
    cm, deg = pose_error(X_OO @ outcome.X_OP)
    assert cm < 1.0 and deg < 1.0, f"refined pose {cm:.2f} cm, {deg:.2f} deg off"
    assert outcome.q < 0.1  # still shut


def test_a_move_beyond_the_bounds_is_refused_and_a_given_pose_stays(misplaced_closet):
    fitted, capture, _ = misplaced_closet
    config = FitConfig(max_steps=40, focus_steps=0)
    result, outcome = infer(fitted, capture, config, np.linspace(0, 1, 5))
    assert "pose_refinement" not in result.extra and outcome.X_OP is None  # a given pose
    rays = observed_rays(capture)
    refused = refine_object_pose(fitted.model, outcome.z, rays, replace(config, pose_max_shift_m=0.002,
                                                                        pose_max_yaw_deg=0.2))
    assert refused.status.startswith("refused: a move of") and not refused.kept
    np.testing.assert_array_equal(refused.X_OP, np.eye(4))
    assert torch.equal(refused.z, outcome.z)

