"""Random rooms around an object: labels of the target only, held-out textures and lights,
sensor effects, and the room dataset writer."""

import math

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.render import ObjectRenderer
from nfr_drake.data.room_dataset import (
    RoomDatasetSpec,
    generate_rooms,
    generate_rooms_command,
    read_room_spec,
    room_dirs,
)
from nfr_drake.data.room_lighting import sample_room_lighting
from nfr_drake.data.room_textures import FLOOR_KINDS, WALL_KINDS, room_texture_image
from nfr_drake.data.rooms import RoomDistribution, sample_room, sample_room_cameras
from nfr_drake.data.sensor_effects import SensorEffects, sample_sensor_effects
from nfr_drake.errors import ConfigError, DatasetError
from nfr_drake.objects import sample_object

CAMERA = PinholeCamera.from_fov(48, 48, math.radians(50))


@pytest.mark.parametrize("category", ["closet", "furniture"])
def test_the_room_mask_is_the_objects_own_labels_where_nothing_hides_it(category):
    rng = np.random.default_rng(4)
    obj = sample_object(category, rng)
    dist = RoomDistribution(neighbours=(2, 2), twin_probability=1.0, clutter=(8, 8), robot_probability=1.0,
                            cut_probability=0.0)
    X_WC = sample_room_cameras(rng, 3, obj, CAMERA, dist)
    room = sample_room(rng, obj, X_WC[:, :3, 3], dist)
    assert len(room.neighbours) == 3 and room.neighbours[0].twin and room.robot is not None
    in_room = ObjectRenderer(obj, CAMERA, room.lighting, add_scenery=room.add_to)
    alone = ObjectRenderer(obj, CAMERA)
    q = np.full(obj.num_fronts, 0.5)
    hidden = 0
    for X in X_WC:
        r, a = in_room.render(q, X), alone.render(q, X)
        mask, own = r.label > 0, a.label > 0
        assert mask.any() and np.all(own[mask])  # nothing but the object is labelled
        np.testing.assert_array_equal(r.label[mask], a.label[mask])
        np.testing.assert_array_equal(r.part[mask], a.part[mask])
        # Object pixels missing from the room's mask are hidden by something nearer the camera.
        gone = own & ~mask
        assert np.all(r.depth[gone] < a.depth[gone])
        hidden += gone.sum()
        assert np.isfinite(r.depth).all()  # walls, floor and ceiling close the room
    assert hidden > 0  # the twin, the clutter or the arm hides some of it in some view


def test_cameras_frame_the_object_and_cut_it_when_asked():
    rng = np.random.default_rng(0)
    obj = sample_object("drawer", rng)
    alone = ObjectRenderer(obj, CAMERA)

    def border_share(cut_probability: float) -> float:
        X = sample_room_cameras(rng, 8, obj, CAMERA, RoomDistribution(cut_probability=cut_probability))
        masks = [alone.render(0.0, x).label > 0 for x in X]
        assert all(m.any() for m in masks)
        return np.mean([m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any() for m in masks])

    assert border_share(0.0) == 0.0
    assert border_share(1.0) >= 0.5


def test_the_margin_sets_how_much_of_the_image_the_object_spans(tmp_path):
    rng = np.random.default_rng(1)
    obj = sample_object("drawer", rng)
    alone = ObjectRenderer(obj, CAMERA)

    def spans(margin: tuple[float, float]) -> np.ndarray:
        """The silhouette's bounding box's longer side over the image side, per view (shut fronts)."""
        dist = RoomDistribution(cut_probability=0.0, margin=margin)
        masks = [alone.render(0.0, x).label > 0 for x in sample_room_cameras(rng, 6, obj, CAMERA, dist)]
        return np.array([max(np.ptp(r), np.ptp(c)) + 1 for r, c in (np.nonzero(m) for m in masks)]) / 48

    far = spans((0.7, 0.7))
    assert np.all(far <= 0.3 + 2 / 48)  # the swept bounds fit in the middle 30 % of the image
    assert np.median(spans((0.05, 0.05))) > 2 * np.median(far)
    generate_rooms_command("drawer", 1, tmp_path / "wide", articulations=1, views=1, size=32,
                           margin=(0.05, 0.7))
    assert read_room_spec(tmp_path / "wide").room.margin == (0.05, 0.7)


def test_heldout_textures_and_lights_are_another_family():
    for kinds in (FLOOR_KINDS, WALL_KINDS):
        assert not set(kinds["train"]) & set(kinds["heldout"])
    np.testing.assert_array_equal(room_texture_image("tiles", 5), room_texture_image("tiles", 5))
    rng = np.random.default_rng(0)
    kinds = {s: {light.kind for _ in range(20)
                 for light in sample_room_lighting(rng, s, np.zeros(3), 2.5).lights}
             for s in ("train", "heldout")}
    assert kinds == {"train": {"directional"}, "heldout": {"directional", "point"}}


def test_sensor_effects():
    image = np.random.default_rng(0).integers(20, 200, (24, 32, 3), dtype=np.uint8)
    np.testing.assert_array_equal(SensorEffects().apply(image), image)
    assert SensorEffects(gain=2.0).apply(image).mean() > 1.5 * image.mean()
    effects = sample_sensor_effects(np.random.default_rng(1))
    np.testing.assert_array_equal(effects.apply(image), effects.apply(image))
    blurred = SensorEffects(blur_sigma_px=1.5).apply(image).astype(float)
    assert np.abs(np.diff(blurred, axis=1)).mean() < 0.5 * np.abs(np.diff(image.astype(float), axis=1)).mean()


def test_room_dataset_is_deterministic_resumes_and_refuses_other_options(tmp_path):
    room = RoomDistribution(clutter=(2, 4))
    spec = RoomDatasetSpec("closet", 2, articulations=1, views=2, size=32, room=room)
    assert generate_rooms(spec, tmp_path / "a", progress=False) == [0, 1]
    assert generate_rooms(spec, tmp_path / "a", progress=False) == []  # complete: nothing to do
    assert read_room_spec(tmp_path / "a") == spec
    generate_rooms(RoomDatasetSpec("closet", 1, articulations=1, views=2, size=32, room=room), tmp_path / "b",
                   progress=False)
    (a0, a1), (b0,) = room_dirs(tmp_path / "a"), room_dirs(tmp_path / "b")
    for name in ("rgb", "label", "part", "depth"):
        np.testing.assert_array_equal(np.load(a0 / f"{name}.npy"), np.load(b0 / f"{name}.npy"))
    label = np.load(a1 / "label.npy")
    assert label.shape == (1, 2, 32, 32) and set(np.unique(label)) <= {0, 1, 2, 3}
    with pytest.raises(DatasetError, match="other options"):
        generate_rooms(RoomDatasetSpec("closet", 3, articulations=1, views=2, size=32), tmp_path / "a",
                       progress=False)
    with pytest.raises(DatasetError, match="not found"):
        read_room_spec(tmp_path / "nothing")


def test_bad_room_options_are_one_line_errors():
    with pytest.raises(ConfigError, match="style"):
        RoomDistribution(style="kitchen")
    with pytest.raises(ConfigError, match="cut_probability"):
        RoomDistribution(cut_probability=1.5)
    with pytest.raises(DatasetError, match="unknown category"):
        RoomDatasetSpec("sofa", 1)
