"""Lights of random rooms: a training set (a headlight, a key light from above and a fill light,
near-white) and a held-out set for evaluation (coloured lamps: point lights in the room, a dim
headlight), so that a segmenter's score on held-out rooms measures lighting it never saw.

Frames: "world" lights are in the room's frame W (= the target object's frame O), "camera" lights
move with the camera (a direction (0, 0, 1) shines along its optical axis).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Literal

import numpy as np

LightingSet = Literal["train", "heldout"]


@dataclass(frozen=True)
class Light:
    """One VTK light. kind: "directional" (shines along `direction`) or "point" (at `position`,
    m, in `frame`); intensity: VTK intensity; rgb: colour, each channel in [0, 1]."""

    kind: Literal["directional", "point"]
    frame: Literal["world", "camera"]
    intensity: float
    rgb: tuple[float, float, float] = (1.0, 1.0, 1.0)
    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def drake_light(self):
        from pydrake.geometry import LightParameter, Rgba

        d = np.asarray(self.direction, float)
        return LightParameter(type=self.kind, frame=self.frame, intensity=self.intensity,
                              color=Rgba(*self.rgb, 1.0), direction=d / np.linalg.norm(d),
                              position=list(self.position))


@dataclass(frozen=True)
class RoomLighting:
    """The lights of one room; `drake_lights()` is what `ObjectRenderer` takes."""

    lights: tuple[Light, ...]

    def drake_lights(self) -> list:
        return [light.drake_light() for light in self.lights]

    def to_json(self) -> list[dict]:
        return [asdict(light) for light in self.lights]

    def moved(self, X_PW: np.ndarray) -> RoomLighting:
        """The same lights with the room's frame W at X_PW (4, 4) in another frame P: world
        lights' directions and positions in P; camera lights unchanged."""
        R, t = np.asarray(X_PW, float)[:3, :3], np.asarray(X_PW, float)[:3, 3]
        return RoomLighting(tuple(
            light if light.frame == "camera" else replace(
                light, direction=tuple(float(c) for c in R @ light.direction),
                position=tuple(float(c) for c in R @ light.position + t))
            for light in self.lights))


def _tint(rng: np.random.Generator, strength: float) -> tuple[float, float, float]:
    """A colour near white: each channel lowered by up to `strength`, at least one channel 1."""
    rgb = 1.0 - rng.uniform(0.0, strength, 3)
    return tuple(float(c) for c in rgb / rgb.max())


def _from_above(rng: np.random.Generator, elevation_deg: tuple[float, float]) -> tuple[float, ...]:
    """Direction of travel of light from a random azimuth and elevation above the horizon."""
    az, el = rng.uniform(-np.pi, np.pi), np.deg2rad(rng.uniform(*elevation_deg))
    return tuple(float(-c) for c in (np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)))


def sample_room_lighting(rng: np.random.Generator, lighting_set: LightingSet,
                         p_centre_W: np.ndarray, ceiling_m: float) -> RoomLighting:
    """Lights of one room around an object whose centre is p_centre_W (m).

    "train": headlight 0.25-0.6, a key light from 25-85 degrees above (0.3-0.9, tinted up to 15%)
    and a fill light from 10-40 degrees (0-0.35). "heldout": 1-3 point lamps under the ceiling
    (`ceiling_m`) 1-3 m from the object, coloured up to 45% (amber to blue), 0.25-0.7 each, and a
    headlight 0.05-0.3.
    """
    if lighting_set == "train":
        return RoomLighting((
            Light("directional", "camera", float(rng.uniform(0.25, 0.6))),
            Light("directional", "world", float(rng.uniform(0.3, 0.9)), _tint(rng, 0.15),
                  _from_above(rng, (25.0, 85.0))),
            Light("directional", "world", float(rng.uniform(0.0, 0.35)), _tint(rng, 0.15),
                  _from_above(rng, (10.0, 40.0))),
        ))
    lamps = []
    for _ in range(int(rng.integers(1, 4))):
        az, r = rng.uniform(-np.pi / 2, np.pi / 2), rng.uniform(1.0, 3.0)
        p = np.asarray(p_centre_W, float) + [r * np.cos(az), r * np.sin(az), 0.0]
        p[2] = ceiling_m - rng.uniform(0.1, 0.6)
        lamps.append(Light("point", "world", float(rng.uniform(0.25, 0.7)), _tint(rng, 0.45),
                           position=tuple(float(x) for x in p)))
    return RoomLighting((Light("directional", "camera", float(rng.uniform(0.05, 0.3))), *lamps))
