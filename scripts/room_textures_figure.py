"""The room texture families, a few images of each kind (docs/ROOMS.md, "The rooms").

    python scripts/room_textures_figure.py --out docs/images/room_textures.png

One row per kind (`room_textures.ROOM_TEXTURE_KINDS`): its name, family ("train" or "held-out")
and `images` textures (seeds 0, 1, ...), each shrunk to `size` px.
"""

from pathlib import Path

import cv2
import numpy as np
import tyro

from nfr_drake.data.room_textures import FAMILY_KINDS, ROOM_TEXTURE_KINDS, room_texture_image
from nfr_drake.data.visualize import image_grid


def main(out: Path = Path("docs/images/room_textures.png"), images: int = 6, size: int = 96) -> None:
    rows = []
    for kind in ROOM_TEXTURE_KINDS:
        label = np.full((size, 2 * size, 3), 255, np.uint8)
        family = "held-out" if kind in FAMILY_KINDS["heldout"] else "train"
        cv2.putText(label, kind, (4, size // 2 - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(label, family, (4, size // 2 + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (200, 0, 0) if family == "held-out" else (0, 120, 0), 1, cv2.LINE_AA)
        tiles = [cv2.resize(room_texture_image(kind, s), (size, size), interpolation=cv2.INTER_AREA)
                 for s in range(images)]
        rows.append(np.concatenate([label, *tiles], 1))
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(image_grid([[r] for r in rows]), cv2.COLOR_RGB2BGR))
    print(f"wrote {out}")


if __name__ == "__main__":
    tyro.cli(main)
