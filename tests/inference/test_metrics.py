"""Metrics against hand-computed values."""

import numpy as np
import pytest

from nfr_drake.inference.metrics import articulation_error, keypoint_rmse_cm, mean_iou, psnr


def test_articulation_error_units():
    assert articulation_error(0.5, 0.4, "revolute", np.pi / 2) == pytest.approx(9.0)
    assert articulation_error(0.2, 0.7, "prismatic", 0.3) == pytest.approx(15.0)


def test_keypoint_rmse():
    true = np.zeros((2, 3))
    pred = np.array([[0.03, 0.0, 0.04], [0.0, 0.0, 0.0]])  # 5 cm and 0 cm
    assert keypoint_rmse_cm(pred, true) == pytest.approx(np.sqrt(25 / 2))


def test_psnr_and_miou():
    a = np.zeros((4, 4, 3))
    assert psnr(a + 0.1, a) == pytest.approx(20.0)
    assert psnr(a, a) == float("inf")
    true = np.array([[0, 0], [1, 2]])
    pred = np.array([[0, 1], [1, 2]])
    # class 0: 1/2, class 1: 1/2, class 2: 1; class 3 absent
    assert mean_iou(pred, true) == pytest.approx((0.5 + 0.5 + 1.0) / 3)
