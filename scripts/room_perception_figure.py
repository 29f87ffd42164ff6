"""What the pipeline's perception cameras see, alone and in a room, and what the fit gets in a room.

    python scripts/room_perception_figure.py --category closet --seed 200 --index 0 \
        --out docs/images/pipeline_room_views.png

Builds the perception diagram of `nfr-drake eval-pipeline --perceive room --object-pose estimated`
for one unseen object (`pipeline.perception_simulator`; nothing is fitted) and draws, for the first
`views` cameras: the photo of the object alone (the paper's setting), the photo in the room, the
segmenter's first mask over it (magenta), the crop stage's mask (magenta, its crop in yellow:
`segmentation.crop`, around the box of the pose from the first masks) and the room photo painted in
the training background off that mask (`paint_background`: what the fit sees).
"""

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import tyro

from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.visualize import image_grid
from nfr_drake.inference.infer import paint_background
from nfr_drake.perception.object_pose import estimate_object_pose
from nfr_drake.perception.segmentation.crop import view_boxes
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
    first = [net.object_mask(image) for image in room]
    # the crop stage (`posed_close_look`), step by step to draw its crops
    box = estimate_object_pose(first, X_WCs, cameras, category=category).box
    crops = view_boxes(box, X_WCs, cameras, [image.shape[:2] for image in room])
    masks = [net.close_look(image, crop) for image, crop in zip(room, crops, strict=True)]
    cropped = [_overlay(image, m) for image, m in zip(room[:views], masks, strict=False)]
    for image, crop in zip(cropped, crops, strict=False):
        if crop is not None:
            cv2.rectangle(image, crop[:2], (crop[2] - 1, crop[3] - 1), (255, 255, 0), 1)
    painted = paint_background(room[:views], masks[:views], DEFAULT_BACKGROUND_RGB)
    overlay = [_overlay(image, m) for image, m in zip(room[:views], first, strict=False)]
    figure = image_grid([alone, room[:views], overlay, cropped, painted])
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
    print(f"{out}: rows alone, room, first mask, crop stage mask, painted; {category} {seed}/{index}")


if __name__ == "__main__":
    tyro.cli(main)
