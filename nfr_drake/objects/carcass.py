"""The open-front box that closets and drawers share."""

from __future__ import annotations

from nfr_drake.objects.articulated import Part, SemanticClass


def carcass_parts(
    width: float, depth: float, height: float, thickness: float, rgba, shelf_heights=()
) -> tuple[Part, ...]:
    """Bottom, top, sides, back and shelves of a carcass standing on the floor, in O.

    The carcass spans x in [-depth/2, depth/2] (front at +x, open), y in [-width/2, width/2] and
    z in [0, height]; panels are `thickness` thick (m). Shelves are at the given heights (centre
    of the shelf board, m), set 1 cm back from the front.
    """
    t, W, D, H = thickness, width, depth, height
    c = SemanticClass.CARCASS
    parts = [
        Part("bottom", c, "box", (D, W, t), (0.0, 0.0, t / 2), rgba),
        Part("top", c, "box", (D, W, t), (0.0, 0.0, H - t / 2), rgba),
        Part("left", c, "box", (D, t, H - 2 * t), (0.0, -W / 2 + t / 2, H / 2), rgba),
        Part("right", c, "box", (D, t, H - 2 * t), (0.0, W / 2 - t / 2, H / 2), rgba),
        Part("back", c, "box", (t, W - 2 * t, H - 2 * t), (-D / 2 + t / 2, 0.0, H / 2), rgba),
    ]
    shelf_depth = D - t - 0.01
    for i, z in enumerate(shelf_heights):
        x = -D / 2 + t + shelf_depth / 2
        parts.append(Part(f"shelf{i}", c, "box", (shelf_depth, W - 2 * t, t), (x, 0.0, z), rgba))
    return tuple(parts)
