"""Floor and wall textures of random rooms, made in code (numpy) and cached as PNG diffuse maps.

Two disjoint families of kinds (`FAMILY_KINDS`):
- *train*: tiles, planks, plaster, paint, and, for domain randomisation, parquet (chevron
  planks), stone (irregular flagstones), mosaic (irregular cells of random colours), terrazzo
  (irregular chips on a ground), marble (veined noise), concrete (noise with pores and seams),
  twill (woven fabric), noise (multi-scale noise through a random palette), blotches (flat
  regions of 2-4 colours with irregular edges), stripes (bands of random widths at 15-75
  degrees off the image axes) and mixtures of two of these through a smooth mask;
- *held-out*, for evaluation only: checkerboard and carpet floors, brick and wallpaper walls.
No training kind is a held-out kind or a near-copy of one: no regular two-colour grid (the
checkerboard; the twill's diagonal is one thread wide), no single-hue per-pixel flecks (carpet),
no rows of offset rectangles with mortar (brick; the stone's cells are irregular), no regular
dots and no vertical or horizontal stripes (wallpaper; plank seams run along the rows as they
did before). A segmenter's score on held-out rooms thus measures surfaces it never saw. Training
rooms draw floors and walls from all the training kinds; held-out rooms as before (`FLOOR_KINDS`,
`WALL_KINDS`). A face of a box shows the whole image once, so the repeats are drawn into the
image: about `REPEAT_M` metres of surface per image.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from nfr_drake.objects.textures import cached_png_uri, smooth_noise

RoomTextureKind = Literal["tiles", "planks", "plaster", "paint", "checker", "carpet", "brick", "wallpaper",
                          "parquet", "stone", "mosaic", "terrazzo", "marble", "concrete", "twill", "noise",
                          "blotches", "stripes", "mixture"]
TextureFamily = Literal["train", "heldout"]
ROOM_TEXTURE_KINDS: tuple[RoomTextureKind, ...] = (
    "tiles", "planks", "plaster", "paint", "checker", "carpet", "brick", "wallpaper",
    "parquet", "stone", "mosaic", "terrazzo", "marble", "concrete", "twill", "noise", "blotches",
    "stripes", "mixture")
"""Every kind; new kinds go at the end (a kind's index seeds its images)."""
FAMILY_KINDS: dict[str, tuple[RoomTextureKind, ...]] = {
    "train": ("tiles", "planks", "plaster", "paint", "parquet", "stone", "mosaic", "terrazzo", "marble",
              "concrete", "twill", "noise", "blotches", "stripes", "mixture"),
    "heldout": ("checker", "carpet", "brick", "wallpaper")}
FLOOR_KINDS: dict[str, tuple[RoomTextureKind, ...]] = {"train": FAMILY_KINDS["train"],
                                                       "heldout": ("checker", "carpet")}
WALL_KINDS: dict[str, tuple[RoomTextureKind, ...]] = {"train": FAMILY_KINDS["train"],
                                                      "heldout": ("brick", "wallpaper")}
_MIXABLE = tuple(k for k in FAMILY_KINDS["train"] if k != "mixture")
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


def _turbulence(rng: np.random.Generator, n: int, base_cells: int, octaves: int) -> np.ndarray:
    """Sum of `octaves` value-noise layers, cells doubling, amplitudes halving; (n, n) in about [0, 1]."""
    out, total = np.zeros((n, n), np.float32), 0.0
    for o in range(octaves):
        c = min(base_cells * 2**o, n // 2)
        out += 0.5**o * smooth_noise(rng, (n, n), (c, c))
        total += 0.5**o
    return out / total


def _cells(rng: np.random.Generator, n: int, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Voronoi cells of one jittered seed point per grid cell: each pixel's cell id (n, n) int and
    the gap to the second-nearest seed, d2 - d1 (n, n), in pixels (small on cell borders); ids
    lie in [0, (cells + 2)**2)."""
    m = cells + 2  # a ring of seeds outside the image, so that border pixels have all 9 neighbours
    pts = (np.stack(np.meshgrid(np.arange(m), np.arange(m), indexing="ij"), -1) - 1
           + rng.uniform(0.1, 0.9, (m, m, 2))) * (n / cells)
    ys, xs = np.mgrid[0:n, 0:n].astype(np.float32)
    ci, cj = (ys * cells / n).astype(int) + 1, (xs * cells / n).astype(int) + 1
    dists, ids = [], []
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            i, j = ci + di, cj + dj
            p = pts[i, j]
            dists.append(np.hypot(p[..., 0] - ys, p[..., 1] - xs))
            ids.append(i * m + j)
    dists, ids = np.stack(dists), np.stack(ids)
    order = np.argsort(dists, axis=0)
    d = np.take_along_axis(dists, order[:2], 0)
    return np.take_along_axis(ids, order[:1], 0)[0], d[1] - d[0]


def _palette(rng: np.random.Generator, k: int) -> np.ndarray:
    """k random colours, (k, 3) float32."""
    return np.stack([_colour(rng, (0.0, 0.9), (0.15, 0.95)) for _ in range(k)])


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
    elif kind == "wallpaper":  # stripes or dots on a ground
        ground, ink = _colour(rng, (0.0, 0.4), (0.6, 1.0)), _colour(rng, (0.2, 0.9), (0.2, 0.8))
        period = int(rng.integers(6, 20))
        if rng.uniform() < 0.5:
            on = ((cols * period) % 1 < rng.uniform(0.2, 0.5))
        else:
            r, c = (rows * period * 2) % 1 - 0.5, (cols * period) % 1 - 0.5
            on = r**2 + c**2 < rng.uniform(0.03, 0.12)
        image = np.where(on[..., None], ink, ground) * (1 + 0.03 * grain)
    else:
        image = _training_kind(kind, rng, n, grain, seed)
    return (np.clip(image, 0, 1) * 255).round().astype(np.uint8)


def _training_kind(kind: RoomTextureKind, rng: np.random.Generator, n: int, grain: np.ndarray,
                   seed: int) -> np.ndarray:
    """The float RGB image (n, n, 3) of one of the domain-randomisation kinds."""
    ys, xs = np.mgrid[0:n, 0:n].astype(np.float32) / n
    if kind == "parquet":  # chevron: bands of planks at +-45 degrees, seams and per-plank tones
        bands, planks = int(rng.integers(3, 9)), float(rng.uniform(20, 45))
        length = rng.uniform(2.5, 6.0)
        band = (ys * bands).astype(int)
        sign = np.where(band % 2 == 0, 1.0, -1.0).astype(np.float32)
        u = (xs + sign * ys) / np.sqrt(2) * planks
        idx = np.floor(u).astype(int)
        t = (xs - sign * ys) / np.sqrt(2) * planks / length + (idx * 0.37) % 1
        piece = np.floor(t).astype(int)
        base = _colour(rng, (0.3, 0.75), (0.25, 0.85)) * np.array([1.0, 0.78, 0.55], np.float32)
        tone = rng.normal(0, 0.1, 997).astype(np.float32)[(idx * 31 + piece * 17 + band * 7) % 997]
        seam = ((u % 1) < 0.07) | ((t % 1) < 0.02) | ((ys * bands) % 1 < 0.01)
        image = np.where(seam[..., None], base * 0.4, base * (1 + tone[..., None] + 0.2 * grain))
    elif kind in ("stone", "mosaic", "terrazzo"):
        cells = int(rng.integers(*{"stone": (5, 14), "mosaic": (8, 30), "terrazzo": (25, 60)}[kind]))
        ids, gap = _cells(rng, n, cells)
        if kind == "stone":
            base = _colour(rng, (0.0, 0.35), (0.35, 0.8))
            tone = 1 + rng.normal(0, 0.15, ((cells + 2) ** 2, 1)).astype(np.float32) + rng.normal(
                0, 0.04, ((cells + 2) ** 2, 3)).astype(np.float32)
            face = base * tone[ids] * (1 + 0.25 * grain)
            joint = rng.uniform(0.4, 0.9) * np.ones(3, np.float32)
            image = np.where((gap < rng.uniform(2, 6))[..., None], joint, face)
        elif kind == "mosaic":
            colours = _palette(rng, 6)[rng.integers(6, size=(cells + 2) ** 2)]
            image = np.where((gap < rng.uniform(1.5, 4))[..., None], _colour(rng, (0, 0.2), (0.1, 0.9)),
                             colours[ids] * (1 + 0.1 * grain))
        else:
            ground = _colour(rng, (0.0, 0.3), (0.4, 0.95))
            chips = _palette(rng, 4)[rng.integers(4, size=(cells + 2) ** 2)]
            share = rng.uniform(size=(cells + 2) ** 2) < rng.uniform(0.2, 0.5)
            chip = share[ids] & (gap > rng.uniform(2, 5))
            image = np.where(chip[..., None], chips[ids], ground * (1 + 0.1 * grain))
    elif kind == "marble":
        base = _colour(rng, (0.0, 0.25), (0.55, 0.97))
        vein = _colour(rng, (0.0, 0.6), (0.05, 0.5))
        a = rng.uniform(0, np.pi)
        turb = _turbulence(rng, n, 3, 5)
        phase = (xs * np.cos(a) + ys * np.sin(a)) * rng.uniform(2, 8) + turb * rng.uniform(3, 8)
        v = np.abs(np.sin(np.pi * phase)) ** rng.uniform(0.15, 0.5)
        image = vein + (base - vein) * v[..., None] * (1 + 0.05 * grain)
    elif kind == "concrete":
        base = _colour(rng, (0.0, 0.12), (0.35, 0.8))
        turb = _turbulence(rng, n, 4, 6)[..., None] - 0.5
        pores = (rng.uniform(size=(n, n)) < rng.uniform(0.001, 0.01))[..., None]
        image = base * (1 + rng.uniform(0.2, 0.5) * turb) * np.where(pores, 0.5, 1.0)
        if rng.uniform() < 0.5:  # formwork seams, a slab grid at a random angle
            a, cells = rng.uniform(0, np.pi / 2), rng.uniform(1.5, 4)
            u, v = (xs * np.cos(a) + ys * np.sin(a)) * cells, (-xs * np.sin(a) + ys * np.cos(a)) * cells
            seam = ((u % 1) < 0.006) | ((v % 1) < 0.006)
            image = np.where(seam[..., None], image * 0.55, image)
    elif kind == "twill":  # woven: warp and weft threads, over-2-under-2 diagonal, at a random angle
        a, threads = rng.uniform(0, np.pi), float(rng.integers(60, 160))
        u, v = (xs * np.cos(a) + ys * np.sin(a)) * threads, (-xs * np.sin(a) + ys * np.cos(a)) * threads
        iu, iv = np.floor(u).astype(int), np.floor(v).astype(int)
        warp_up = ((iu + iv) % 4) < 2
        warp, weft = _colour(rng, (0.1, 0.9), (0.15, 0.9)), _colour(rng, (0.0, 0.9), (0.15, 0.9))
        shade = np.where(warp_up, np.sin(np.pi * (u % 1)), np.sin(np.pi * (v % 1)))[..., None]
        image = np.where(warp_up[..., None], warp, weft) * (0.75 + 0.25 * shade) * (1 + 0.1 * grain)
    elif kind == "noise":  # two multi-scale noise fields through a random palette
        k = int(rng.integers(3, 6))
        pal = _palette(rng, k)
        t = _turbulence(rng, n, int(rng.integers(2, 12)), int(rng.integers(2, 6)))
        t = (t - t.min()) / (np.ptp(t) + 1e-6) * (k - 1)
        lo = np.clip(np.floor(t).astype(int), 0, k - 2)
        image = pal[lo] + (pal[lo + 1] - pal[lo]) * (t - lo)[..., None]
        image = image * (1 + 0.4 * (_turbulence(rng, n, 32, 3)[..., None] - 0.5))
    elif kind == "blotches":  # flat regions with irregular edges (camouflage)
        k = int(rng.integers(2, 5))
        pal = _palette(rng, k)
        fields = np.stack([_turbulence(rng, n, int(rng.integers(3, 10)), 3) for _ in range(k)])
        image = pal[np.argmax(fields, 0)] * (1 + 0.05 * grain)
    elif kind == "stripes":  # bands of random widths and 2-4 colours, 15-75 degrees off the axes
        a = np.deg2rad(rng.uniform(15, 75) + 90 * rng.integers(2))
        widths = rng.uniform(0.005, 0.08, 200)
        edges = np.cumsum(widths)
        u = (xs * np.cos(a) + ys * np.sin(a)) + 2.0
        band = np.searchsorted(edges, u % edges[-1])
        pal = _palette(rng, int(rng.integers(2, 5)))
        image = pal[band % len(pal)] * (1 + 0.08 * grain)
    elif kind == "mixture":  # two other training kinds through a smooth mask
        a, b = rng.choice(len(_MIXABLE), 2, replace=False)
        mask = _turbulence(rng, n, int(rng.integers(2, 8)), 4)
        edge = rng.uniform(0.02, 0.15)
        w = np.clip((mask - np.median(mask)) / edge + 0.5, 0, 1)[..., None]
        ia = room_texture_image(_MIXABLE[a], seed + 10_000).astype(np.float32) / 255
        ib = room_texture_image(_MIXABLE[b], seed + 20_000).astype(np.float32) / 255
        image = ia * (1 - w) + ib * w
    else:
        raise ValueError(f"unknown room texture kind {kind!r}")
    return image


def room_texture_uri(kind: RoomTextureKind, seed: int) -> str:
    """A file:// URI of the (kind, seed) room texture, written on first use."""
    return cached_png_uri(f"room_{kind}_{seed:08d}", lambda: room_texture_image(kind, seed))
