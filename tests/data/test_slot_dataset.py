"""Furniture datasets read as slots: padded q, keypoints, existence and type per front."""

import numpy as np
import pytest
import torch

from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.data.slot_dataset import SLOT_KEYPOINTS, SlotDataset, open_dataset, slot_targets
from nfr_drake.errors import DatasetError
from nfr_drake.objects.articulated import MAX_FRONTS


def test_items_carry_padded_slots_with_existence(furniture_dataset):
    data = open_dataset(furniture_dataset)
    assert isinstance(data, SlotDataset) and data.num_slots == MAX_FRONTS
    assert len(data.keypoint_names) == 4 * MAX_FRONTS
    A, V = data.spec.articulations, data.spec.views
    for j, rec in enumerate(data.records):
        parts, F = rec.meta["parts"], len(rec.meta["parts"])
        for a in range(A):
            item = data[(j * A + a) * V]
            assert item.q.shape == (MAX_FRONTS,) and item.keypoints.shape == (4 * MAX_FRONTS, 3)
            np.testing.assert_array_equal(item.q[:F].numpy(), rec.q[a])
            assert (item.q[F:] == 0).all() and (item.keypoints[4 * F:] == 0).all()
            assert item.exists.tolist() == [True] * F + [False] * (MAX_FRONTS - F)
            assert item.types[:F].tolist() == [int(p["type"] == "drawer") for p in parts]
            np.testing.assert_array_equal(item.part.numpy(), rec.part[a, 0])
            kp = item.keypoints.view(MAX_FRONTS, 4, 3)
            for k, p in enumerate(parts):
                np.testing.assert_allclose(kp[k, 0], p["keypoints"]["handle"][a], atol=1e-6)
                np.testing.assert_allclose(kp[k, 1], p["keypoints"]["goal"][a], atol=1e-6)
    batch = torch.utils.data.default_collate([data[0], data[1]])
    assert batch.exists.shape == (2, MAX_FRONTS)


def _drawer_meta(q):
    handle0, pull, travel = np.array([0.5, 0.1, 0.4]), np.array([1.0, 0.0, 0.0]), 0.3
    handles = [handle0 + qi * travel * pull for qi in q]
    return {"q": [[qi] for qi in q], "parts": [{
        "index": 0, "type": "drawer", "q": list(q), "pull_axis": pull.tolist(), "travel": travel,
        "keypoints": {"handle": handles, "goal": handles}}]}


def test_drawer_axis_points_are_its_handle_shut_and_fully_open():
    t = slot_targets(_drawer_meta([0.0, 0.4, 1.0]), num_slots=2)
    assert SLOT_KEYPOINTS[2:] == ("axis_0", "axis_1")
    for a in range(3):
        np.testing.assert_allclose(t.keypoints[a, 0, 2], [0.5, 0.1, 0.4], atol=1e-6)
        np.testing.assert_allclose(t.keypoints[a, 0, 3], [0.8, 0.1, 0.4], atol=1e-6)
    assert t.exists.tolist() == [True, False] and t.types.tolist() == [1, 0]
    with pytest.raises(DatasetError, match="more than the 0 slots"):
        slot_targets(_drawer_meta([0.0]), num_slots=0)


def test_closet_datasets_stay_one_slot(tiny_dataset):
    assert type(open_dataset(tiny_dataset)) is RenderedDataset
    with pytest.raises(DatasetError, match="one front"):
        SlotDataset(tiny_dataset)
