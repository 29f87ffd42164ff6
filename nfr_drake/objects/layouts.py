"""Front layouts of the furniture kinds: sizes, base, top and the cells of each column.

A piece's front is a row of columns (left to right), each a stack of cells (top to bottom); a
cell is a door, a door pair, a drawer, two drawers side by side or an open shelf. `kind_params`
draws one kind's sizes and layout within a budget of at most `MAX_FRONTS` fronts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from nfr_drake.objects.articulated import MAX_FRONTS

KINDS = ("base_cabinet", "wall_cabinet", "tall_cabinet", "chest", "desk", "table", "kitchen_run",
         "fridge", "sideboard")
CellKind = Literal["door", "pair", "drawer", "drawers2", "open"]
_FRONTS_OF = {"door": 1, "pair": 2, "drawer": 1, "drawers2": 2, "open": 0}


@dataclass(frozen=True)
class FurnitureRanges:
    """Sampling ranges of what all kinds share (min, max), metres unless stated."""

    height: tuple[float, float] = (0.3, 2.1)
    """Top of the piece above the floor (checked, not sampled: each kind has its own)."""
    width: tuple[float, float] = (0.3, 1.8)
    """Width of the carcass (checked; each kind samples its own)."""
    gap: tuple[float, float] = (0.002, 0.004)
    """Gap between neighbouring fronts."""
    panel_thickness: tuple[float, float] = (0.016, 0.022)
    front_thickness: tuple[float, float] = (0.016, 0.024)
    frame_probability: float = 0.3
    """Chance of frame-and-panel fronts (else flat)."""
    texture_probability: float = 0.65
    """Chance that a surface gets an image texture (else a plain colour)."""
    bar_length: tuple[float, float] = (0.06, 0.6)


@dataclass
class Cell:
    kind: CellKind
    height: float  # between the boundary lines (panel centres, or outer faces), m
    shelves: int = 0


@dataclass
class Column:
    width: float  # between the boundary lines, m
    cells: list[Cell] = field(default_factory=list)


@dataclass
class Body:
    """A carcass box: y in [y0, y1], z in [z0, z1] (outer faces), x from x_front back by depth."""

    y0: float
    y1: float
    z0: float
    z1: float
    depth: float
    columns: list[Column]


@dataclass
class Sampler:
    """One piece in the making: its random stream, materials and the budget of fronts."""

    rng: np.random.Generator
    ranges: FurnitureRanges
    budget: int = MAX_FRONTS

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def pick(self, options, p=None):
        return options[int(self.rng.choice(len(options), p=p))]


# ---------------------------------------------------------------------------- layouts of columns
def _stack(s: Sampler, height: float, n: int, graded: bool) -> list[Cell]:
    """n drawers filling `height`, equal or growing towards the bottom."""
    weights = np.linspace(1.0, s.u(1.3, 1.9), n) if graded else np.ones(n)
    return [Cell("drawer", height * w / weights.sum()) for w in weights]


def _column_cells(s: Sampler, width: float, height: float, options: tuple[str, ...],
                  columns_left: int) -> list[Cell]:
    """Cells of one column (top to bottom) by a layout picked from `options`, within the budget."""
    spare = s.budget - columns_left
    if columns_left == 0 and s.budget == MAX_FRONTS:  # the last column of a piece without fronts yet
        options = tuple(o for o in options if o != "open") or ("door",)
    feasible = [o for o in options if _layout_fronts(o, width, height) <= spare] or ["open"]
    layout = s.pick(feasible)
    if layout == "door":
        cells = [Cell("pair" if width > 0.62 else "door", height, shelves=int(height / 0.4))]
    elif layout == "stack":
        n = int(s.rng.integers(1 if height < 0.3 else 2, min(5, int(height / 0.11)) + 1))
        n = min(n, spare)
        cells = _stack(s, height, n, graded=s.u(0, 1) < 0.5)
    elif layout == "drawer_over_door":
        top = min(s.u(0.12, 0.2), 0.35 * height)
        cells = [Cell("drawer", top), Cell("pair" if width > 0.62 else "door", height - top,
                                          shelves=int((height - top) / 0.45))]
    elif layout == "door_over_drawers":
        n = int(s.rng.integers(1, 4))
        low = n * s.u(0.14, 0.24)
        cells = [Cell("pair" if width > 0.62 else "door", height - low, shelves=int((height - low) / 0.4)),
                 *_stack(s, low, n, graded=False)]
    elif layout == "two_doors":
        split = s.u(0.3, 0.42) * height
        cells = [Cell("door", height - split, shelves=2), Cell("door", split, shelves=1)]
    elif layout == "drawers2_over_stack":
        n = int(s.rng.integers(1, 4))
        top = s.u(0.12, 0.18)
        cells = [Cell("drawers2", top), *_stack(s, height - top, n, graded=s.u(0, 1) < 0.5)]
    else:
        cells = [Cell("open", height, shelves=max(1, int(height / 0.35)))]
    s.budget -= sum(_FRONTS_OF[c.kind] for c in cells)
    return cells


def _layout_fronts(layout: str, width: float, height: float) -> int:
    """The most fronts a column layout can make (to keep within the budget)."""
    doors = 2 if width > 0.62 else 1
    return {"door": doors, "stack": 5, "drawer_over_door": 1 + doors, "door_over_drawers": doors + 3,
            "two_doors": 2, "drawers2_over_stack": 5, "open": 0}[layout]


def _split_width(s: Sampler, width: float, n: int) -> list[float]:
    w = s.rng.uniform(0.8, 1.2, n)
    return list(width * w / w.sum())


# ---------------------------------------------------------------------------- kinds
def kind_params(s: Sampler, kind: str) -> dict:
    """Sizes, base, top and bodies of one kind (O frame: x_front = body depth / 2)."""
    u = s.u
    p: dict = dict(kind=kind, legs=None, top=None, plinth=None, feet=None, mount=0.0)
    if kind in ("base_cabinet", "kitchen_run"):
        W = u(0.3, 1.2) if kind == "base_cabinet" else u(0.9, 1.8)
        D, H = u(0.5, 0.62), u(0.86, 0.94)
        top_t = u(0.028, 0.04)
        p.update(width=W, depth=D, height=H, top=dict(t=top_t, front=u(0.015, 0.04), side=u(0.0, 0.015),
                                                       worktop=True),
                 plinth=u(0.08, 0.15), recess=u(0.04, 0.07))
        p["base_h"] = p["plinth"]
        n_units = 1 if kind == "base_cabinet" else int(s.rng.integers(2, 5))
        while kind == "kitchen_run" and W / n_units < 0.3:
            n_units -= 1
        widths = _split_width(s, W, n_units)
        options = ("door", "stack", "drawer_over_door")
        cols_h = H - top_t - p["plinth"]
        p["columns"] = [Column(w, _column_cells(s, w, cols_h, options, n_units - i - 1))
                        for i, w in enumerate(widths)]
    elif kind == "wall_cabinet":
        W, D = u(0.3, 1.2), u(0.28, 0.38)
        mount = u(1.3, 1.5)
        Hc = min(u(0.3, 0.75), 2.1 - mount)
        p.update(width=W, depth=D, height=mount + Hc, mount=mount, base_h=0.0)
        n_cols = 1 if W < 0.8 or u(0, 1) < 0.6 else 2
        widths = _split_width(s, W, n_cols)
        p["columns"] = [Column(w, _column_cells(s, w, Hc, ("door",) if n_cols == 1 or i == 0 else
                                                ("door", "open"), n_cols - i - 1))
                        for i, w in enumerate(widths)]
    elif kind == "tall_cabinet":
        W, D, H = u(0.4, 1.8), u(0.35, 0.62), u(1.6, 2.1)
        _base(s, p, allow_legs=False)
        _top(s, p)
        body_h = H - p["base_h"] - p["top_h"]
        n_cols = 1 if W < 0.7 else (int(s.rng.integers(1, 3)) if W < 1.2 else int(s.rng.integers(2, 4)))
        widths = _split_width(s, W, n_cols)
        open_col = int(s.rng.integers(0, n_cols)) if n_cols > 1 and u(0, 1) < 0.35 else -1
        p.update(width=W, depth=D, height=H)
        p["columns"] = [Column(w, _column_cells(
            s, w, body_h, ("open",) if i == open_col else ("door", "door_over_drawers", "two_doors"),
            n_cols - i - 1)) for i, w in enumerate(widths)]
    elif kind == "chest":
        W, D, H = u(0.4, 1.2), u(0.35, 0.55), u(0.5, 1.3)
        _base(s, p, allow_legs=True)
        _top(s, p)
        body_h = H - p["base_h"] - p["top_h"]
        p.update(width=W, depth=D, height=H)
        options = ("stack", "drawers2_over_stack") if W > 0.6 else ("stack",)
        if W > 0.9 and u(0, 1) < 0.3:
            p["columns"] = [Column(w, _column_cells(s, w, body_h, ("stack",), 1 - i))
                            for i, w in enumerate(_split_width(s, W, 2))]
        else:
            p["columns"] = [Column(W, _column_cells(s, W, body_h, options, 0))]
    elif kind == "sideboard":
        W, D, H = u(1.0, 1.8), u(0.38, 0.5), u(0.6, 0.95)
        _base(s, p, allow_legs=True)
        _top(s, p)
        body_h = H - p["base_h"] - p["top_h"]
        n_cols = int(s.rng.integers(2, 5))
        p.update(width=W, depth=D, height=H)
        opts = ("door", "stack", "drawer_over_door", "open")
        p["columns"] = [Column(w, _column_cells(s, w, body_h, opts, n_cols - i - 1))
                        for i, w in enumerate(_split_width(s, W, n_cols))]
    elif kind == "fridge":
        W, D, H = u(0.55, 0.75), u(0.58, 0.7), u(0.85, 2.0)
        p.update(width=W, depth=D, height=H, feet=u(0.01, 0.03), base_h=0.0, top_h=0.0)
        p["base_h"] = p["feet"]
        body_h = H - p["feet"]
        if H < 1.3:
            cells = [Cell("door", body_h, shelves=2)]
        else:
            low = s.u(0.3, 0.42) * body_h
            freezer_below = u(0, 1) < 0.7
            hi_cell, lo_cell = Cell("door", body_h - low, shelves=3), Cell("door", low, shelves=2)
            if not freezer_below:
                hi_cell, lo_cell = Cell("door", low, shelves=1), Cell("door", body_h - low, shelves=3)
            cells = [hi_cell, lo_cell]
        p["columns"] = [Column(W, cells)]
        s.budget -= len(cells)
    elif kind in ("desk", "table"):
        _desk_or_table(s, p, kind)
    return p


def _base(s: Sampler, p: dict, allow_legs: bool) -> None:
    style = s.pick(("plinth", "legs", "feet", "floor") if allow_legs else ("plinth", "feet", "floor"))
    p["plinth"] = s.u(0.06, 0.12) if style == "plinth" else None
    p["recess"] = s.u(0.02, 0.05)
    legs = dict(h=s.u(0.1, 0.3), r=s.u(0.012, 0.025), square=s.u(0, 1) < 0.4)
    p["legs"] = legs if style == "legs" else None
    p["feet"] = s.u(0.015, 0.04) if style == "feet" else None
    p["base_h"] = p["plinth"] or (p["legs"] and p["legs"]["h"]) or p["feet"] or 0.0


def _top(s: Sampler, p: dict) -> None:
    if s.u(0, 1) < 0.5:
        p["top"] = dict(t=s.u(0.018, 0.035), front=s.u(0.01, 0.03), side=s.u(0.0, 0.03), worktop=False)
    p["top_h"] = p["top"]["t"] if p["top"] else 0.0


def _desk_or_table(s: Sampler, p: dict, kind: str) -> None:
    u = s.u
    W, D, H = (u(1.0, 1.8), u(0.5, 0.8), u(0.72, 0.78)) if kind == "desk" else \
        (u(0.6, 1.6), u(0.5, 1.0), u(0.7, 0.8))
    top_t = u(0.02, 0.04)
    leg_r = u(0.018, 0.03)
    p.update(width=W, depth=D, height=H, top=dict(t=top_t, front=u(0.02, 0.05), side=u(0.02, 0.05),
                                                     worktop=False),
             table_legs=dict(r=leg_r, square=u(0, 1) < 0.5, inset=u(0.02, 0.06)))
    p["base_h"] = 0.0
    # Bodies hang under the top (aprons) or stand on the floor (a desk's pedestal): (y0, y1, z0, cols)
    under = H - top_t
    inner = W / 2 - p["table_legs"]["inset"] - 2 * leg_r - 0.01
    if kind == "table":
        apron = u(0.09, 0.15)
        width = 2 * inner
        n = 2 if width > 1.0 and u(0, 1) < 0.6 else 1
        p["bodies"] = [(-inner, inner, under - apron,
                        [Column(w, [Cell("drawer", apron)]) for w in _split_width(s, width, n)])]
        s.budget -= n
        return
    ped_w = u(0.38, 0.5)
    left = u(0, 1) < 0.5
    y0, y1 = (-inner, -inner + ped_w) if left else (inner - ped_w, inner)
    ped = [Column(ped_w, _column_cells(s, ped_w, under, ("stack", "drawer_over_door"), 1))]
    p["pedestal_left"] = left
    p["bodies"] = [(y0, y1, 0.0, ped)]
    if u(0, 1) < 0.6:
        apron = u(0.1, 0.14)
        a0, a1 = (y1 + 0.02, inner) if left else (-inner, y0 - 0.02)
        p["bodies"].append((a0, a1, under - apron, [Column(a1 - a0, [Cell("drawer", apron)])]))
        s.budget -= 1
