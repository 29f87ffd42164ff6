"""Room captures for the fit confidence: a room written as a capture set in the object's frame, and
its fits planned with the given and the estimated pose."""

import json
from pathlib import Path

import numpy as np
import pytest

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.room_dataset import RoomDatasetSpec, generate_rooms, room_dirs
from nfr_drake.eval.confidence_data import ROOM_VARIANTS, load_case, plan_cases
from nfr_drake.eval.confidence_rooms import room_capture
from nfr_drake.perception.handle_triangulation import project


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """One closet in a room, 3 views, 48 px."""
    root = tmp_path_factory.mktemp("rooms") / "closet_heldout"
    generate_rooms(RoomDatasetSpec("closet", 1, articulations=1, views=3, size=48, seed=5), root,
                   progress=False)
    return room_dirs(root)[0]


def test_a_room_is_a_capture_set_in_the_objects_frame(room, tmp_path):
    out = room_capture(room, tmp_path / "closet_heldout" / room.name)
    capture = read_capture_set(out)
    meta = json.loads((room / "meta.json").read_text())
    rgb, label = np.load(room / "rgb.npy")[0], np.load(room / "label.npy")[0]
    assert [f.load_rgb().tolist() for f in capture.frames] == rgb.tolist()
    assert capture.gt["category"] == "closet" and capture.gt["q"] == meta["q"][0][0]
    assert set(capture.gt["keypoints"]) == {"handle", "hinge_top", "hinge_bottom", "goal"}
    # The poses are the room's: the true handle projects onto the target where a view sees it.
    on_target = []
    for frame, labels in zip(capture.frames, label, strict=True):
        uv = project(frame, np.array(capture.gt["keypoints"]["handle"]))
        u, v = np.floor(uv).astype(int)
        on_target.append(bool((labels[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2] > 0).any()))
    assert any(on_target)
    assert room_capture(room, out) == out  # written once


def test_room_cases_fit_each_capture_with_the_given_and_the_estimated_pose(room, tmp_path):
    captures = {"closet_heldout": [room_capture(room, tmp_path / "closet_heldout" / room.name)],
                "drawer_heldout_cut": [Path("elsewhere/obj_000000")]}
    cases = plan_cases(tmp_path, 0, 0, 0, 0, 0, 0, captures)
    assert [(c.model, c.variant, c.split) for c in cases] == [
        ("models/closet", v, "rooms") for v in ROOM_VARIANTS] + [
        ("models/drawer", v, "rooms") for v in ROOM_VARIANTS]
    capture, images = load_case(cases[0])
    assert len(images) == len(capture.frames) == 3 and capture.gt["category"] == "closet"
