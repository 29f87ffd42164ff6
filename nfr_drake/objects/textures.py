"""Image textures made in code (numpy), written once as PNG diffuse maps and reused.

Drake's VTK renderer reads PNG diffuse maps (`<drake:diffuse_map>` on an SDFormat visual; a box
face shows the whole image, stretched). A texture is named by its kind and an integer seed; the
same (kind, seed) always gives the same image, so objects stay deterministic from their seed and
files are shared between objects. Files go to `$NFR_DRAKE_TEXTURE_DIR`, by default
`~/.cache/nfr_drake/textures`.
"""

from __future__ import annotations

import colorsys
import os
from collections.abc import Callable
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

TextureKind = Literal["wood", "laminate", "paint", "metal"]
TEXTURE_KINDS: tuple[TextureKind, ...] = ("wood", "laminate", "paint", "metal")
_SIZE = 256


def texture_dir() -> Path:
    """Folder of the generated PNG files."""
    default = Path.home() / ".cache" / "nfr_drake" / "textures"
    return Path(os.environ.get("NFR_DRAKE_TEXTURE_DIR", default))


def smooth_noise(rng: np.random.Generator, shape: tuple[int, int], cells: tuple[int, int]) -> np.ndarray:
    """Value noise in [0, 1] of `shape`, with about `cells` features along (rows, columns)."""
    coarse = rng.uniform(0.0, 1.0, (cells[0] + 1, cells[1] + 1)).astype(np.float32)
    return cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC).clip(0, 1)


def _hsv(h: float, s: float, v: float) -> np.ndarray:
    return np.array(colorsys.hsv_to_rgb(h % 1.0, s, v), dtype=np.float32)


def texture_image(kind: TextureKind, seed: int) -> np.ndarray:
    """The texture of (kind, seed): uint8 RGB, shape (256, 256, 3); wood grain runs along the rows."""
    rng = np.random.default_rng([hash_kind(kind), seed])
    n = _SIZE
    if kind == "wood":
        base = _hsv(rng.uniform(0.05, 0.11), rng.uniform(0.35, 0.7), rng.uniform(0.35, 0.85))
        dark = base * rng.uniform(0.55, 0.8)
        # Growth rings: stripes along the rows, bent by low-frequency noise, with fine fibres.
        warp = smooth_noise(rng, (n, n), (3, 2)) * rng.uniform(4, 10)
        cols = np.arange(n, dtype=np.float32)[None, :] / n * rng.uniform(6, 16)
        rings = 0.5 + 0.5 * np.sin(2 * np.pi * (cols + warp))
        fibres = smooth_noise(rng, (n, n), (4, 96))
        t = (0.65 * rings**3 + 0.35 * fibres)[..., None]
        image = base * (1 - t) + dark * t
    elif kind == "laminate":
        base = _hsv(rng.uniform(0, 1), rng.uniform(0.0, 0.25), rng.uniform(0.45, 0.95))
        speckle = rng.normal(0.0, 0.025, (n, n, 1)).astype(np.float32)
        image = base * (1 + speckle + 0.04 * (smooth_noise(rng, (n, n), (6, 6))[..., None] - 0.5))
    elif kind == "paint":
        base = _hsv(rng.uniform(0, 1), rng.uniform(0.05, 0.6), rng.uniform(0.3, 0.95))
        image = base * (1 + 0.05 * (smooth_noise(rng, (n, n), (12, 12))[..., None] - 0.5))
    else:
        base = np.full(3, rng.uniform(0.55, 0.85), dtype=np.float32) * _hsv(0.6, 0.03, 1.0)
        streaks = cv2.blur(rng.normal(0.0, 1.0, (n, n)).astype(np.float32), (1, 41))
        image = base * (1 + 0.12 * streaks[..., None] / (streaks.std() + 1e-6) * 0.5)
    return (np.clip(image, 0, 1) * 255).round().astype(np.uint8)


def hash_kind(kind: TextureKind) -> int:
    """A stable integer of a texture kind (the random stream's first word)."""
    return TEXTURE_KINDS.index(kind) + 1


def texture_uri(kind: TextureKind, seed: int) -> str:
    """A file:// URI of the (kind, seed) texture, written on first use."""
    return cached_png_uri(f"{kind}_{seed:08d}", lambda: texture_image(kind, seed))


def cached_png_uri(stem: str, make_image: Callable[[], np.ndarray]) -> str:
    """A file:// URI of `texture_dir()/stem.png`; the uint8 RGB image `make_image()` is written
    there (atomically) when the file does not exist yet."""
    path = texture_dir() / f"{stem}.png"
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.png")
        cv2.imwrite(str(tmp), cv2.cvtColor(make_image(), cv2.COLOR_RGB2BGR))
        tmp.replace(path)
    return path.resolve().as_uri()
