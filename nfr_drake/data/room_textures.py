"""Floor and wall textures of random rooms, made in code (numpy) and cached as PNG diffuse maps.

Two disjoint families: the training family (floors of tiles or planks, walls of plaster or paint)
and a held-out family for evaluation (floors of checkerboard or carpet, walls of brick or
wallpaper), so that a segmenter's score on held-out rooms measures surfaces it never saw. A face
of a box shows the whole image once, so the repeats (tiles, planks, bricks) are drawn into the
image: about `REPEAT_M` metres of surface per image.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from nfr_drake.objects.textures import cached_png_uri, smooth_noise

RoomTextureKind = Literal["tiles", "planks", "plaster", "paint", "checker", "carpet", "brick", "wallpaper"]
TextureFamily = Literal["train", "heldout"]
FLOOR_KINDS: dict[str, tuple[RoomTextureKind, ...]] = {"train": ("tiles", "planks"),
                                                       "heldout": ("checker", "carpet")}
WALL_KINDS: dict[str, tuple[RoomTextureKind, ...]] = {"train": ("plaster", "paint"),
                                                      "heldout": ("brick", "wallpaper")}
ROOM_TEXTURE_KINDS: tuple[RoomTextureKind, ...] = (
    "tiles", "planks", "plaster", "paint", "checker", "carpet", "brick", "wallpaper")
REPEAT_M = 4.0
"""Metres of floor or wall one texture image covers; a face this many metres across shows it once."""
_SIZE = 512


def _colour(rng: np.random.Generator, saturation: tuple[float, float], value: tuple[float, float]
            ) -> np.ndarray:
    import colorsys

    return np.array(colorsys.hsv_to_rgb(rng.uniform(), rng.uniform(*saturation), rng.uniform(*value)),
                    np.float32)


def _grid_cells(n: int, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column cell index and position within the cell (0..1) of each pixel, (n, n) each."""
    t = np.arange(n, dtype=np.float32)[:, None] / n * cells
    return np.broadcast_to(t, (n, n)), np.broadcast_to(t.T, (n, n))


def room_texture_image(kind: RoomTextureKind, seed: int) -> np.ndarray:
    """The texture of (kind, seed): uint8 RGB, shape (512, 512, 3); same inputs, same image."""
    rng = np.random.default_rng([ROOM_TEXTURE_KINDS.index(kind) + 100, seed])
    n = _SIZE
    grain = smooth_noise(rng, (n, n), (24, 24))[..., None] - 0.5
    rows, cols = _grid_cells(n, 1)
    if kind == "tiles":
        cells = int(rng.integers(6, 17))
        r, c = rows * cells, cols * cells
        base = _colour(rng, (0.0, 0.35), (0.45, 0.95))
        tone = rng.normal(0, 0.04, (cells, cells, 1)).astype(np.float32)[r.astype(int), c.astype(int)]
        grout = (np.minimum(r % 1, c % 1) < rng.uniform(0.03, 0.08))[..., None]
        image = np.where(grout, base * rng.uniform(0.4, 0.8), base * (1 + tone + 0.05 * grain))
    elif kind == "planks":
        planks = int(rng.integers(10, 25))
        r = rows * planks
        base = _colour(rng, (0.3, 0.7), (0.3, 0.85)) * np.array([1.0, 0.8, 0.6], np.float32)
        tone = rng.normal(0, 0.08, (planks, 1)).astype(np.float32)[r.astype(int)]
        fibres = smooth_noise(rng, (n, n), (planks * 3, 8))[..., None] - 0.5
        seam = ((r % 1) < 0.06)[..., None]
        image = np.where(seam, base * 0.45, base * (1 + tone + 0.25 * fibres))
    elif kind == "plaster":
        base = _colour(rng, (0.0, 0.12), (0.75, 0.97))
        image = base * (1 + 0.08 * grain + rng.normal(0, 0.02, (n, n, 1)).astype(np.float32))
    elif kind == "paint":
        base = _colour(rng, (0.1, 0.6), (0.35, 0.95))
        image = base * (1 + 0.03 * grain)
    elif kind == "checker":
        cells = int(rng.integers(6, 17))
        a, b = _colour(rng, (0.0, 0.8), (0.1, 0.5)), _colour(rng, (0.0, 0.5), (0.6, 1.0))
        odd = ((rows * cells).astype(int) + (cols * cells).astype(int)) % 2 == 1
        image = np.where(odd[..., None], a, b) * (1 + 0.04 * grain)
    elif kind == "carpet":
        base = _colour(rng, (0.2, 0.9), (0.2, 0.8))
        fleck = rng.normal(0, 0.12, (n, n, 1)).astype(np.float32)
        image = base * (1 + fleck + 0.3 * grain)
    elif kind == "brick":
        courses = int(rng.integers(20, 40))
        r = rows * courses
        offset = (r.astype(int) % 2) * 0.5
        c = cols * courses / 3 + offset
        base = _colour(rng, (0.4, 0.8), (0.35, 0.7)) * np.array([1.0, 0.6, 0.45], np.float32)
        tone = rng.normal(0, 0.1, (courses + 1, courses + 1, 1)).astype(np.float32)
        tone = tone[r.astype(int), c.astype(int) % (courses + 1)]
        mortar = (((r % 1) < 0.12) | ((c % 1) < 0.05))[..., None]
        image = np.where(mortar, np.float32(rng.uniform(0.6, 0.85)), base * (1 + tone + 0.1 * grain))
    else:  # wallpaper: stripes or dots on a ground
        ground, ink = _colour(rng, (0.0, 0.4), (0.6, 1.0)), _colour(rng, (0.2, 0.9), (0.2, 0.8))
        period = int(rng.integers(6, 20))
        if rng.uniform() < 0.5:
            on = ((cols * period) % 1 < rng.uniform(0.2, 0.5))
        else:
            r, c = (rows * period * 2) % 1 - 0.5, (cols * period) % 1 - 0.5
            on = r**2 + c**2 < rng.uniform(0.03, 0.12)
        image = np.where(on[..., None], ink, ground) * (1 + 0.03 * grain)
    return (np.clip(image, 0, 1) * 255).round().astype(np.uint8)


def room_texture_uri(kind: RoomTextureKind, seed: int) -> str:
    """A file:// URI of the (kind, seed) room texture, written on first use."""
    return cached_png_uri(f"room_{kind}_{seed:08d}", lambda: room_texture_image(kind, seed))
