"""Furniture of real kinds: cabinets, wardrobes, chests, desks, tables, kitchen runs, fridges.

`sample_furniture` draws a kind, a carcass (one or more boxes, a top, a plinth, legs or feet) and a
front layout: columns left to right, each a stack of cells top to bottom; a cell is a door, a door
pair, a drawer, two drawers side by side or an open shelf. Panels separate the cells, so every
door and drawer has its own compartment. Fronts overlay the carcass with gaps between them
(`FurnitureRanges.gap`). Each door and drawer becomes a `Front` (fronts.py) with its own joint;
they are ordered canonically (`canonical_order`) and at most `MAX_FRONTS` per piece.
docs/FURNITURE.md describes kinds, order, keypoints, labels and ranges.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from nfr_drake.objects.appearance import sample_handle_rgba, sample_rgba
from nfr_drake.objects.articulated import ArticulatedObject, Part, SemanticClass
from nfr_drake.objects.fronts import FrontLook, Rect, make_door, make_drawer
from nfr_drake.objects.handles import HandleSpec
from nfr_drake.objects.layouts import KINDS, Body, Cell, FurnitureRanges, Sampler, kind_params
from nfr_drake.objects.textures import texture_uri

_BACK = 0.008  # back panel thickness, m
_SHELF_SETBACK = 0.02  # shelves stand back from the front plane, m


# ---------------------------------------------------------------------------- materials
TEXTURE_POOL = 48
"""Texture seeds per kind are drawn from range(TEXTURE_POOL): files are shared between pieces."""


@dataclass(frozen=True)
class Material:
    rgba: tuple[float, float, float, float]
    texture: str | None = None


def _material(s: Sampler, kinds=("wood", "laminate", "paint"), plain_value=(0.3, 0.95)) -> Material:
    """An image texture (tinted) or a plain colour, white-ish or muted."""
    if s.u(0, 1) < s.ranges.texture_probability:
        kind = s.pick(kinds)
        tint = s.u(0.85, 1.0)
        return Material((tint, tint, tint, 1.0), texture_uri(kind, int(s.rng.integers(TEXTURE_POOL))))
    if s.u(0, 1) < 0.3:  # white and off-white
        v = s.u(0.85, 0.97)
        return Material((v, v, v * s.u(0.94, 1.0), 1.0))
    return Material(sample_rgba(s.rng, saturation=(0.0, 0.35), value=plain_value))


def _part(name, size, p, mat: Material, semantic=SemanticClass.CARCASS, shape="box", rpy=(0.0, 0.0, 0.0)):
    return Part(name, semantic, shape, tuple(float(v) for v in size), tuple(float(v) for v in p), mat.rgba,
                rpy, mat.texture)


# ---------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class _FrontSpec:
    """A front before it is numbered: kind, rectangle, and what its builder needs."""

    kind: Literal["door", "drawer"]
    rect: Rect
    hinge: str = ""
    compartment: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    goal: tuple[float, float, float] = (0.0, 0.0, 0.0)


def canonical_order(rects: list[Rect]) -> list[int]:
    """Indices of fronts in canonical order: by left edge (increasing y, to the mm), then top edge
    (decreasing z): columns left to right as seen from the front, top to bottom within each."""
    return sorted(range(len(rects)), key=lambda i: (round(rects[i].y0 * 1000), -round(rects[i].z1 * 1000)))


def _body_geometry(s: Sampler, body: Body, x_front: float, t: float, gap: float, mat: Material,
                   name: str) -> tuple[list[Part], list[_FrontSpec]]:
    """Panels of one carcass box and the fronts of its cells."""
    x_back = x_front - body.depth
    x_in = x_back + _BACK  # inner face of the back panel
    depth_in = x_front - x_in
    xc = (x_front + x_in) / 2
    W, H = body.y1 - body.y0, body.z1 - body.z0
    yc = (body.y0 + body.y1) / 2
    parts = [
        _part(f"{name}bottom", (body.depth, W, t), (x_front - body.depth / 2, yc, body.z0 + t / 2), mat),
        _part(f"{name}top", (body.depth, W, t), (x_front - body.depth / 2, yc, body.z1 - t / 2), mat),
        _part(f"{name}left", (body.depth, t, H - 2 * t), (x_front - body.depth / 2, body.y0 + t / 2,
                                                          body.z0 + H / 2), mat),
        _part(f"{name}right", (body.depth, t, H - 2 * t), (x_front - body.depth / 2, body.y1 - t / 2,
                                                           body.z0 + H / 2), mat),
        _part(f"{name}back", (_BACK, W - 2 * t, H - 2 * t), (x_back + _BACK / 2, yc, body.z0 + H / 2), mat),
    ]
    specs: list[_FrontSpec] = []
    Y = body.y0 + np.concatenate([[0.0], np.cumsum([c.width for c in body.columns])])
    Y[-1] = body.y1
    for j, col in enumerate(body.columns):
        last = j == len(body.columns) - 1
        iy0, iy1 = Y[j] + (t if j == 0 else t / 2), Y[j + 1] - (t if last else t / 2)
        if not last:
            parts.append(_part(f"{name}partition{j}", (depth_in, t, H - 2 * t),
                               (xc, Y[j + 1], body.z0 + H / 2), mat))
        Z = body.z1 - np.concatenate([[0.0], np.cumsum([c.height for c in col.cells])])
        Z[-1] = body.z0
        for i, cell in enumerate(col.cells):
            bottom = i == len(col.cells) - 1
            iz1, iz0 = Z[i] - (t if i == 0 else t / 2), Z[i + 1] + (t if bottom else t / 2)
            if not bottom:
                parts.append(_part(f"{name}divider{j}_{i}", (depth_in, iy1 - iy0, t),
                                   (xc, (iy0 + iy1) / 2, Z[i + 1]), mat))
            for k in range(cell.shelves):
                z = iz0 + (iz1 - iz0) * (k + 1) / (cell.shelves + 1)
                d = depth_in - _SHELF_SETBACK
                parts.append(_part(f"{name}shelf{j}_{i}_{k}", (d, iy1 - iy0, t),
                                   (x_in + d / 2, (iy0 + iy1) / 2, z), mat))
            rect = Rect(Y[j] + gap / 2, Y[j + 1] - gap / 2, Z[i + 1] + gap / 2, Z[i] - gap / 2)
            specs += _cell_fronts(s, cell, rect, gap, (xc, iy0, iy1, iz0, iz1), depth_in, t)
            if cell.kind == "drawers2":
                ym = (iy0 + iy1) / 2
                parts.append(_part(f"{name}split{j}_{i}", (depth_in, t, iz1 - iz0),
                                   (xc, ym, (iz0 + iz1) / 2), mat))
    return parts, specs


def _cell_fronts(s: Sampler, cell: Cell, rect: Rect, gap: float, interior, depth_in: float,
                 t: float) -> list[_FrontSpec]:
    """The fronts of one cell; `interior` = (x centre, y0, y1, z0, z1) of its compartment, in O."""
    xc, iy0, iy1, iz0, iz1 = interior
    if cell.kind == "open":
        return []
    if cell.kind == "drawer":
        return [_FrontSpec("drawer", rect, compartment=(depth_in, iy0, iy1, iz0, iz1))]
    half = (Rect(rect.y0, rect.yc - gap / 2, rect.z0, rect.z1),
            Rect(rect.yc + gap / 2, rect.y1, rect.z0, rect.z1))
    if cell.kind == "drawers2":
        ym = (iy0 + iy1) / 2
        return [_FrontSpec("drawer", half[0], compartment=(depth_in, iy0, ym - t / 2, iz0, iz1)),
                _FrontSpec("drawer", half[1], compartment=(depth_in, ym + t / 2, iy1, iz0, iz1))]

    def goal(r: Rect) -> tuple[float, float, float]:
        return (xc, float(np.clip(r.yc, iy0, iy1)), iz0)

    if cell.kind == "pair":
        return [_FrontSpec("door", half[0], "left", goal=goal(half[0])),
                _FrontSpec("door", half[1], "right", goal=goal(half[1]))]
    hinge = "left" if s.u(0, 1) < 0.5 else "right"
    return [_FrontSpec("door", rect, hinge, goal=goal(rect))]


# ---------------------------------------------------------------------------- handles
def _handle_style(s: Sampler, kind: str, overhang: bool) -> str:
    """One style per piece. No edge pulls under an overhanging top: it would cover the flange on
    the top edge of the drawers beneath it, leaving no room for fingers above it."""
    if kind == "fridge":
        return s.pick(("bar", "edge"), p=(0.7, 0.3))
    if overhang:
        return s.pick(("bar", "knob", "cup"), p=np.array([0.55, 0.15, 0.12]) / 0.82)
    return s.pick(("bar", "knob", "cup", "edge"), p=(0.55, 0.15, 0.12, 0.18))


def _handle_for(s: Sampler, style: str, front: _FrontSpec, length: float, radius: float,
                vertical_doors: bool) -> tuple[HandleSpec, float, float]:
    """Handle of one front: spec, grip height in O (m) and (doors) distance from the free edge (m)."""
    r = front.rect
    if front.kind == "drawer":
        if style == "knob" or (style == "cup" and r.width < 0.2):
            spec = HandleSpec("knob", False, 0.0, min(radius, 0.3 * r.height),
                              min(0.03, 0.3 * r.height + 0.01))
            return spec, (r.z0 + r.z1) / 2, 0.0
        if style == "edge":
            spec = HandleSpec("edge", False, min(length, 0.8 * r.width), 0.007, 0.015)
            return spec, r.z1 - 0.012, 0.0
        if style == "cup":
            return HandleSpec("cup", False, min(0.1, 0.6 * r.width), min(0.015, 0.2 * r.height), 0.009), \
                (r.z0 + r.z1) / 2, 0.0
        spec = HandleSpec("bar", False, min(length, 0.7 * r.width), radius * 0.6, 0.032)
        return spec, (r.z0 + r.z1) / 2, 0.0
    # Doors: grip at a reachable height (about 1 m above the floor) as far as the door allows.
    target = s.u(0.9, 1.1)
    if style in ("knob", "cup"):
        margin = 0.06
        spec = HandleSpec("knob", False, 0.0, radius, 0.03)
        return spec, float(np.clip(target, r.z0 + margin, r.z1 - margin)), 0.045
    vertical = vertical_doors or style == "edge"
    if vertical:
        L = min(length, r.height - 0.1)
        spec = HandleSpec(style, True, L, 0.007 if style == "edge" else radius * 0.6,
                          0.015 if style == "edge" else 0.032)
        margin = L / 2 + 0.04
        edge = 0.012 if style == "edge" else s.u(0.035, 0.06)
        return spec, float(np.clip(target, r.z0 + margin, r.z1 - margin)), edge
    L = min(length, 0.45 * r.width)
    spec = HandleSpec("bar", False, L, radius * 0.6, 0.032)
    return spec, float(np.clip(target, r.z0 + 0.06, r.z1 - 0.06)), L / 2 + s.u(0.03, 0.05)


# ---------------------------------------------------------------------------- the piece
def sample_furniture(rng: np.random.Generator, ranges: FurnitureRanges | None = None,
                     name: str = "furniture", kind: str | None = None) -> ArticulatedObject:
    """Draw one piece of furniture (of `kind`, else a random kind); all randomness comes from `rng`."""
    ranges = ranges or FurnitureRanges()
    s = Sampler(rng, ranges)
    kind = kind or s.pick(KINDS)
    p = kind_params(s, kind)
    t, gap = s.u(*ranges.panel_thickness), s.u(*ranges.gap)
    front_t = s.u(0.04, 0.07) if kind == "fridge" else s.u(*ranges.front_thickness)
    if kind == "fridge":
        # Brushed steel, or white, grey or black enamel.
        grey = s.pick((s.u(0.85, 0.96), s.u(0.55, 0.75), s.u(0.08, 0.2)), p=(0.6, 0.2, 0.2))
        carcass = (Material((1.0, 1.0, 1.0, 1.0), texture_uri("metal", int(s.rng.integers(TEXTURE_POOL))))
                   if s.u(0, 1) < 0.4 else Material((grey, grey, grey, 1.0)))
        front_mat, frame = carcass, 0.0
    else:
        carcass = _material(s)
        front_mat = carcass if s.u(0, 1) < 0.5 else _material(s)
        frame = s.u(0.04, 0.08) if s.u(0, 1) < ranges.frame_probability else 0.0
    look = FrontLook(front_t, frame, front_mat.rgba, front_mat.texture, sample_handle_rgba(s.rng),
                     box_rgba=sample_rgba(s.rng, saturation=(0.1, 0.4), value=(0.6, 0.9)))
    W, D, H = p["width"], p["depth"], p["height"]
    parts: list[Part] = []
    specs: list[_FrontSpec] = []
    top = p["top"]
    if kind in ("desk", "table"):
        x_front, body_depth = D / 2 - top["front"], D - 2 * top["front"]
        bodies = [Body(y0, y1, z0, H - top["t"], body_depth, cols) for y0, y1, z0, cols in p["bodies"]]
        parts += _table_parts(p, carcass)
    else:
        x_front, body_depth = D / 2, D
        z0 = p["mount"] or p["base_h"]
        bodies = [Body(-W / 2, W / 2, z0, H - (top["t"] if top else 0.0), D, p["columns"])]
        parts += _base_parts(p, carcass, s)
    for b, body in enumerate(bodies):
        body_parts, body_specs = _body_geometry(s, body, x_front, t, gap, carcass, f"b{b}_")
        parts += body_parts
        specs += body_specs
    if top and kind not in ("desk", "table"):
        worktop = _material(s, ("laminate", "wood"), (0.2, 0.9)) if top["worktop"] else carcass
        tw, td = W + 2 * top["side"], D + top["front"]
        parts.append(_part("top", (td, tw, top["t"]), (top["front"] / 2, 0.0, H - top["t"] / 2), worktop))

    style = _handle_style(s, kind, overhang=bool(top))
    length = s.u(*ranges.bar_length)
    radius = s.u(0.012, 0.022) if style in ("knob", "cup") else s.u(0.01, 0.02)
    vertical_doors = kind == "fridge" or s.u(0, 1) < 0.8
    order = canonical_order([f.rect for f in specs])
    fronts = []
    for k, i in enumerate(order):
        f = specs[i]
        handle, z_h, edge = _handle_for(s, style, f, length, radius, vertical_doors)
        if f.kind == "door":
            fronts.append(make_door(k, f.rect, x_front, f.hinge, look, handle, z_h, edge, f.goal))
        else:
            fronts.append(make_drawer(k, f.rect, x_front, look, handle, z_h, f.compartment))
    params = dict(kind=kind, width=W, depth=D, height=H, panel_thickness=t, gap=gap, front_thickness=front_t,
                  frame_width=frame, handle_style=style, fronts=[f.kind for f in fronts],
                  base=_base_name(p), top=("overhang" if top else "flush"), mount=p["mount"],
                  textured=carcass.texture is not None)
    return ArticulatedObject("furniture", name, tuple(parts), tuple(fronts), params)


def _base_name(p: dict) -> str:
    if "table_legs" in p:
        return "legs"
    return "plinth" if p["plinth"] else "legs" if p["legs"] else "feet" if p["feet"] else \
        "wall" if p["mount"] else "floor"


def _corners(x_half: float, y_half: float) -> list[tuple[float, float]]:
    return [(sx * x_half, sy * y_half) for sx in (-1, 1) for sy in (-1, 1)]


def _leg(name: str, x: float, y: float, z0: float, z1: float, r: float, square: bool, mat: Material) -> Part:
    if square:
        return _part(name, (2 * r, 2 * r, z1 - z0), (x, y, (z0 + z1) / 2), mat)
    return _part(name, (r, z1 - z0), (x, y, (z0 + z1) / 2), mat, shape="cylinder")


def _base_parts(p: dict, carcass: Material, s: Sampler) -> list[Part]:
    """Plinth, legs or feet under the body (none for a wall cabinet or a piece on the floor)."""
    W, D = p["width"], p["depth"]
    if p["plinth"]:
        dark = Material(sample_rgba(s.rng, saturation=(0.0, 0.2), value=(0.1, 0.35)))
        mat = carcass if s.u(0, 1) < 0.5 else dark
        depth = D - p["recess"] - 0.02
        return [_part("plinth", (depth, W - 0.02, p["plinth"]), (D / 2 - p["recess"] - depth / 2, 0.0,
                                                                  p["plinth"] / 2), mat)]
    metal = Material(sample_handle_rgba(s.rng))
    if p["legs"]:
        legs = p["legs"]
        mat = metal if s.u(0, 1) < 0.5 else carcass
        return [_leg(f"leg{i}", x, y, 0.0, p["base_h"], legs["r"], legs["square"], mat)
                for i, (x, y) in enumerate(_corners(D / 2 - legs["r"] - 0.02, W / 2 - legs["r"] - 0.02))]
    if p["feet"]:
        r = min(0.025, W / 10)
        return [_leg(f"foot{i}", x, y, 0.0, p["feet"], r, True, metal)
                for i, (x, y) in enumerate(_corners(D / 2 - r - 0.01, W / 2 - r - 0.01))]
    return []


def _table_parts(p: dict, mat: Material) -> list[Part]:
    """The top and the legs of a desk or table (a desk's pedestal replaces its legs on one side)."""
    W, D, H, top, legs = p["width"], p["depth"], p["height"], p["top"], p["table_legs"]
    parts = [_part("top", (D, W, top["t"]), (0.0, 0.0, H - top["t"] / 2), mat)]
    x_half, y_half = D / 2 - legs["inset"] - legs["r"], W / 2 - legs["inset"] - legs["r"]
    for i, (x, y) in enumerate(_corners(x_half, y_half)):
        if "pedestal_left" in p and (y < 0) == p["pedestal_left"]:
            continue
        parts.append(_leg(f"leg{i}", x, y, 0.0, H - top["t"], legs["r"], legs["square"], mat))
    return parts
