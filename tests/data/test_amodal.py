"""Amodal carcass labels: the carcass alone as if nothing hid it, rendered from object.sdf, in
rooms where clutter, furniture and the arm hide parts of it; the post-pass over a dataset."""

import math

import numpy as np
import pytest

from nfr_drake.data.amodal import (
    AMODAL_FILE,
    amodal_labels,
    amodal_mask,
    carcass_solids,
    label_amodal_command,
)
from nfr_drake.data.camera import PinholeCamera

CAMERA = PinholeCamera.from_fov(64, 64, math.radians(50))


def test_the_label_covers_the_carcass_where_clutter_hides_it():
    pytest.importorskip("pydrake")
    from nfr_drake.data.object_records import portable_sdformat
    from nfr_drake.data.render import ObjectRenderer
    from nfr_drake.data.rooms import RoomDistribution, sample_room, sample_room_cameras
    from nfr_drake.objects import sample_object

    rng = np.random.default_rng(11)
    obj = sample_object("drawer", rng)
    dist = RoomDistribution(neighbours=(2, 2), clutter=(12, 12), robot_probability=1.0, cut_probability=0.0)
    X_OC = sample_room_cameras(rng, 4, obj, CAMERA, dist)
    room = sample_room(rng, obj, X_OC[:, :3, 3], dist)
    in_room = ObjectRenderer(obj, CAMERA, room.lighting, add_scenery=room.add_to)
    alone = ObjectRenderer(obj, CAMERA)
    labels = amodal_labels(portable_sdformat(obj)[0], X_OC[None], CAMERA)[0]
    assert labels.shape == (4, 64, 64) and labels.dtype == np.uint8
    q = np.zeros(obj.num_fronts)  # shut: the front hides the carcass's front face
    hidden = 0
    for X, label in zip(X_OC, labels, strict=True):
        r, a = in_room.render(q, X), alone.render(q, X)
        carcass_alone = a.label == 1
        assert np.all(label[carcass_alone] == 1)  # every carcass pixel the object alone shows
        covered = (label == 1) & carcass_alone & (r.label == 0)  # carcass hidden in the room
        assert np.all(r.depth[covered] < a.depth[covered])  # ... by something nearer the camera
        hidden += covered.sum()
        # the label also covers the carcass behind the shut front: the object alone's pixels
        assert (label == 1).sum() <= (a.label > 0).sum() + 0.03 * label.size
    assert hidden > 0


def test_a_box_carcass_renders_as_its_box():
    sdf = ("<sdf version='1.9'><model name='m'><link name='carcass'>"
           "<visual name='b'><pose>0 0 0.3 0 0 0</pose><geometry><box><size>0.4 0.5 0.6</size></box>"
           "</geometry></visual></link><link name='front0'><visual name='f'><geometry><box><size>1 1 1"
           "</size></box></geometry></visual></link></model></sdf>")
    from nfr_drake.data.camera_placement import look_at

    X = look_at(np.array([1.5, 0.4, 0.9]), np.array([0.0, 0.0, 0.3]))
    mask = amodal_mask(carcass_solids(sdf), X, CAMERA)
    corners = np.array([[x, y, z] for x in (-0.2, 0.2) for y in (-0.25, 0.25) for z in (0.0, 0.6)])
    X_CO = np.linalg.inv(X)
    p = corners @ X_CO[:3, :3].T + X_CO[:3, 3]
    uv = p[:, :2] / p[:, 2:] * CAMERA.fx + CAMERA.cx
    assert mask[int(uv[:, 1].mean()), int(uv[:, 0].mean())] == 1
    rows, cols = np.nonzero(mask)
    # the silhouette spans the projected corners (pixel centres inside), not the front link's box
    assert abs(cols.min() + 0.5 - uv[:, 0].min()) <= 1 and abs(cols.max() + 0.5 - uv[:, 0].max()) <= 1
    assert abs(rows.min() + 0.5 - uv[:, 1].min()) <= 1 and abs(rows.max() + 0.5 - uv[:, 1].max()) <= 1


def test_the_post_pass_writes_what_generation_writes_and_resumes(tmp_path, capsys):
    pytest.importorskip("pydrake")
    from nfr_drake.data.room_dataset import RoomDatasetSpec, generate_rooms, room_dirs

    root = tmp_path / "rooms"
    generate_rooms(RoomDatasetSpec("closet", 2, articulations=1, views=2, size=32), root, progress=False)
    folders = room_dirs(root)
    generated = [np.load(f / AMODAL_FILE) for f in folders]
    assert all(g.shape == (1, 2, 32, 32) and g.any() for g in generated)
    (folders[1] / AMODAL_FILE).unlink()
    label_amodal_command([root])
    assert "written for 1 of 2 rooms" in capsys.readouterr().out
    np.testing.assert_array_equal(np.load(folders[1] / AMODAL_FILE), generated[1])
