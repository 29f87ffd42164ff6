"""Room textures: every kind renders, the training and held-out families are disjoint, and
held-out rooms show no training texture."""

import math
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pytest

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.room_textures import (
    FAMILY_KINDS,
    FLOOR_KINDS,
    ROOM_TEXTURE_KINDS,
    WALL_KINDS,
    room_texture_image,
)
from nfr_drake.data.rooms import RoomDistribution, sample_room, sample_room_cameras
from nfr_drake.objects import sample_object


@pytest.mark.parametrize("kind", ROOM_TEXTURE_KINDS)
def test_every_kind_renders_deterministically_and_varies_with_the_seed(kind):
    a, b = room_texture_image(kind, 3), room_texture_image(kind, 4)
    assert a.shape == (512, 512, 3) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, room_texture_image(kind, 3))
    assert not np.array_equal(a, b)
    assert a.std() > 1.0  # not a flat colour: some pattern or grain


def test_the_families_are_disjoint_and_cover_every_kind():
    train, heldout = set(FAMILY_KINDS["train"]), set(FAMILY_KINDS["heldout"])
    assert not train & heldout
    assert train | heldout == set(ROOM_TEXTURE_KINDS)
    for kinds in (FLOOR_KINDS, WALL_KINDS):
        assert set(kinds["train"]) <= train and set(kinds["heldout"]) <= heldout
    assert len(train) >= 12  # domain randomisation: many families, not two floors and two walls


def test_training_stripes_are_never_vertical_or_horizontal():
    """The held-out wallpaper has vertical stripes; the training stripes keep 15 degrees off both axes."""
    for seed in range(6):
        gray = room_texture_image("stripes", seed).astype(np.float32).mean(-1)
        gy, gx = np.gradient(gray)
        # Dominant gradient direction from the structure tensor, folded into [0, 90) degrees.
        jxx, jyy, jxy = (gx * gx).sum(), (gy * gy).sum(), (gx * gy).sum()
        angle = math.degrees(0.5 * math.atan2(2 * jxy, jxx - jyy)) % 90
        assert 10 < angle < 80, (seed, angle)


def _texture_names(room) -> set[str]:
    parts = [*room.surfaces, *room.clutter]
    for nb in room.neighbours:
        parts += [*nb.obj.base_parts, *(p for f in nb.obj.fronts for p in f.parts)]
    return {Path(unquote(urlparse(p.texture).path)).name for p in parts if p.texture}


def test_training_rooms_wear_the_training_family_and_heldout_rooms_never_do():
    camera = PinholeCamera.from_fov(48, 48, math.radians(50))
    seen = {"train": set(), "heldout": set()}
    retextured = 0
    for style in ("train", "heldout"):
        dist = RoomDistribution(style=style, neighbours=(3, 3), clutter=(12, 12))
        for i in range(8):
            rng = np.random.default_rng([7, i])
            obj = sample_object("drawer", rng)
            X_WC = sample_room_cameras(rng, 2, obj, camera, dist)
            room = sample_room(rng, obj, X_WC[:, :3, 3], dist)
            seen[style] |= {n.split("_")[1] for n in _texture_names(room) if n.startswith("room_")}
            retextured += sum(nb.texture is not None for nb in room.neighbours)
            assert all(nb.texture is None for nb in room.neighbours) or style == "train"
    assert seen["train"] <= set(FAMILY_KINDS["train"]) and len(seen["train"]) >= 6
    assert seen["heldout"] <= set(FAMILY_KINDS["heldout"])
    assert retextured > 0  # some neighbours in training rooms wear room textures
