"""Contact sheet of the furniture category: each piece shut, half open and with one front open,
above its semantic classes and its part indices (one colour per front, in canonical order).

    python scripts/furniture_sheet.py --pieces 24 --seed 0 --size 160 \
        --out docs/images/contact_sheet_furniture.png

Pieces are drawn with `object_rng(SEED_DOMAIN_TRAIN, seed, i)`, i = 0..pieces-1 (as
`sample_object("furniture", ...)` draws them unless `--kinds` fixes the kinds); the lighting of
each piece is random (`sample_lighting`), the camera looks at it from the front-left or right.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import cv2
import numpy as np

from nfr_drake.data.camera import PinholeCamera
from nfr_drake.data.camera_placement import look_at
from nfr_drake.data.render import ObjectRenderer, sample_lighting
from nfr_drake.data.visualize import colorize_labels, colorize_parts
from nfr_drake.objects import SEED_DOMAIN_TRAIN, object_rng
from nfr_drake.objects.furniture import sample_furniture


def piece_views(obj, size: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Three renders (shut, all at q = 0.5, the middle front at q = 1) and their class and part images."""
    camera = PinholeCamera.from_fov(size, size, math.radians(45))
    lo, hi = obj.base_bounds()
    target = (lo + hi) / 2
    extent = float(np.linalg.norm(hi - lo))
    azimuth = math.radians(rng.choice([-1, 1]) * rng.uniform(20, 45))
    elevation = math.radians(rng.uniform(8, 25))
    distance = 0.75 * extent / math.tan(math.radians(22.5)) + 0.3
    eye = target + distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                        math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    X_OC = look_at(eye, target)
    renderer = ObjectRenderer(obj, camera, sample_lighting(rng))
    one = np.zeros(obj.num_fronts)
    one[obj.num_fronts // 2] = 1.0
    views = [renderer.render(q, X_OC) for q in (0.0, 0.5, one)]
    return ([v.rgb for v in views], colorize_labels(views[2].label), colorize_parts(views[2].part))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pieces", type=int, default=24)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--size", type=int, default=160)
    parser.add_argument("--per-row", type=int, default=3, help="pieces per row of the sheet")
    parser.add_argument("--kinds", nargs="*", default=None,
                        help="furniture kinds to cycle through (default: a random kind per piece)")
    parser.add_argument("--out", type=Path, default=Path("docs/images/contact_sheet_furniture.png"))
    args = parser.parse_args()
    cells = []
    for i in range(args.pieces):
        kind = args.kinds[i % len(args.kinds)] if args.kinds else None
        obj = sample_furniture(object_rng(SEED_DOMAIN_TRAIN, args.seed, i), name="furniture", kind=kind)
        rgbs, label, part = piece_views(obj, args.size, np.random.default_rng([args.seed, i]))
        cells.append(rgbs + [np.concatenate([label[::2, ::2], part[::2, ::2]], axis=0)
                             .repeat(1, 0)[:, :, :]])
        print(f"{i:3d} {obj.params['kind']:13s} {obj.num_fronts} fronts: {' '.join(obj.params['fronts'])}")
    rows = []
    for r in range(0, len(cells), args.per_row):
        row = []
        for cell in cells[r:r + args.per_row]:
            small = cell[3]
            pad = np.full((args.size, args.size // 2, 3), 255, np.uint8)
            pad[:small.shape[0], :small.shape[1]] = small
            row += cell[:3] + [pad]
        rows.append(row)
    width = max(sum(im.shape[1] for im in row) for row in rows)
    sheet = np.full((len(rows) * (args.size + 4), width + 4 * 4 * args.per_row, 3), 255, np.uint8)
    for i, row in enumerate(rows):
        x = 2
        for j, image in enumerate(row):
            y = 2 + i * (args.size + 4)
            sheet[y:y + image.shape[0], x:x + image.shape[1]] = image
            x += image.shape[1] + (8 if j % 4 == 3 else 2)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print("wrote", args.out)


if __name__ == "__main__":
    main()
