"""Colour sampling shared by the categories."""

from __future__ import annotations

import colorsys

import numpy as np


def sample_rgba(
    rng: np.random.Generator,
    saturation: tuple[float, float] = (0.0, 0.6),
    value: tuple[float, float] = (0.25, 0.95),
) -> tuple[float, float, float, float]:
    """An opaque colour drawn uniformly in HSV within the given saturation and value ranges."""
    h = rng.uniform(0.0, 1.0)
    s = rng.uniform(*saturation)
    v = rng.uniform(*value)
    r, g, b = colorsys.hsv_to_rgb(h, s, v)
    return (r, g, b, 1.0)


def sample_front_rgba(rng: np.random.Generator, carcass_rgba) -> tuple[float, float, float, float]:
    """Colour of a door or drawer front: often the carcass colour, otherwise its own."""
    if rng.uniform() < 0.4:
        return tuple(carcass_rgba)
    return sample_rgba(rng)


def sample_handle_rgba(rng: np.random.Generator) -> tuple[float, float, float, float]:
    """Handle colour: metallic greys, dark or brass-like tones, sometimes a free colour."""
    kind = rng.integers(0, 4)
    if kind == 0:
        g = rng.uniform(0.55, 0.85)
        return (g, g, g * rng.uniform(0.95, 1.05), 1.0)
    if kind == 1:
        g = rng.uniform(0.05, 0.2)
        return (g, g, g, 1.0)
    if kind == 2:
        return (rng.uniform(0.6, 0.8), rng.uniform(0.45, 0.6), rng.uniform(0.15, 0.3), 1.0)
    return sample_rgba(rng, saturation=(0.3, 0.9), value=(0.3, 0.9))
