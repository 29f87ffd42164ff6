"""What the pipeline's perception cameras see, alone and in a room, and what the fits get in a room.

    python scripts/room_perception_figure.py --category closet --seed 200 --index 0 \
        --out docs/images/pipeline_room_views.png

Builds the perception photos of `nfr-drake eval-pipeline --perceive room --object-pose estimated`
for one unseen object (`pipeline.perception_photos`; nothing is fitted) and draws, for the first
`views` cameras, one row each: the photo of the object alone (the paper's setting), the photo in
the room, the object's masks as the pipeline finds them (`segmentation.crop.room_looks`: the crop
stage or the aimed look; magenta), and the room photo painted in the training background off those
masks each way the pipeline paints it (`inference.infer.paint_off_object`, one fit each: "region",
"fronts", "sure").
"""

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import tyro

from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.visualize import image_grid
from nfr_drake.inference.infer import PAINTINGS, paint_off_object
from nfr_drake.perception.segmentation.crop import room_looks
from nfr_drake.perception.segmentation.model import load_segmenter
from nfr_drake.systems.pipeline import perception_photos
from nfr_drake.systems.scenario import Scenario


def _overlay(image: np.ndarray, mask: np.ndarray) -> np.ndarray:
    return np.clip(image * (1 - 0.5 * mask[..., None]) + 0.5 * mask[..., None] * [255, 0, 255], 0, 255
                   ).astype(np.uint8)


def main(category: str = "closet", seed: int = 200, index: int = 0, views: int = 5,
         out: Path = Path("docs/images/pipeline_room_views.png"),
         segmenter: Path = Path(Scenario.segmenter)) -> None:
    scenario = Scenario(category=category, model=f"models/{category}", seed=seed, index=index,
                        object_pose="estimated", perceive="room", segmenter=str(segmenter))
    room, X_WCs, cameras = perception_photos(scenario)
    alone = perception_photos(replace(scenario, perceive="alone"))[0][:views]
    net, _ = load_segmenter(segmenter)
    looks = room_looks(net, room, X_WCs, cameras, category, aimed_look=scenario.aimed_look)
    masks = [_overlay(image, m) for image, m in zip(room[:views], looks.masks, strict=False)]
    painted = [paint_off_object(room, looks.masks, X_WCs, cameras, looks.estimate.X_WO, looks.estimate.size,
                                DEFAULT_BACKGROUND_RGB, painting)[0][:views] for painting in PAINTINGS]
    figure = image_grid([alone, room[:views], masks, *painted])
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
    look = "aimed look" if looks.aimed else "whole photos"
    print(f"{out}: rows alone, room, the pipeline's masks ({look}), painted {', '.join(PAINTINGS)}; "
          f"{category} {seed}/{index}")


if __name__ == "__main__":
    tyro.cli(main)
