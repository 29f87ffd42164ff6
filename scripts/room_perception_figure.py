"""What the pipeline's perception cameras see, alone and in a room, and what the fit gets in a room.

    python scripts/room_perception_figure.py --category closet --seed 200 --index 0 \
        --out docs/images/pipeline_room_views.png

Builds the perception diagram of `nfr-drake eval-pipeline --perceive room --object-pose estimated`
for one unseen object (`pipeline.perception_simulator`; nothing is fitted) and draws, for the first
`views` cameras: the photo of the object alone (the paper's setting), the photo in the room, the
segmenter's mask over it (magenta) and the room photo painted in the training background off the
mask (`paint_background`: what the fit sees).
"""

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import tyro

from nfr_drake.data.render import DEFAULT_BACKGROUND_RGB
from nfr_drake.data.visualize import image_grid
from nfr_drake.inference.infer import paint_background
from nfr_drake.perception.segmentation.model import load_segmenter
from nfr_drake.systems.pipeline import perception_simulator
from nfr_drake.systems.scenario import Scenario


def photos(scenario: Scenario, views: int) -> list[np.ndarray]:
    """uint8 RGB photos of the scenario's first `views` perception cameras."""
    simulator, _ = perception_simulator(scenario, scenario.sample_object())
    diagram, context = simulator.get_system(), simulator.get_context()
    sensors = [diagram.GetSubsystemByName(f"nfr_camera_{i}") for i in range(views)]
    return [s.color_image_output_port().Eval(s.GetMyContextFromRoot(context)).data[..., :3].copy()
            for s in sensors]


def main(category: str = "closet", seed: int = 200, index: int = 0, views: int = 5,
         out: Path = Path("docs/images/pipeline_room_views.png"),
         segmenter: Path = Path(Scenario.segmenter)) -> None:
    scenario = Scenario(category=category, model=f"models/{category}", seed=seed, index=index,
                        object_pose="estimated", perceive="room", segmenter=str(segmenter))
    room = photos(scenario, views)
    alone = photos(replace(scenario, perceive="alone"), views)
    net, _ = load_segmenter(segmenter)
    masks = [net.object_mask(image) for image in room]
    overlay = [np.clip(image * (1 - 0.5 * m[..., None]) + 0.5 * m[..., None] * [255, 0, 255], 0, 255)
               .astype(np.uint8) for image, m in zip(room, masks, strict=True)]
    painted = paint_background(room, masks, DEFAULT_BACKGROUND_RGB)
    figure = image_grid([alone, room, overlay, painted])
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(figure, cv2.COLOR_RGB2BGR))
    print(f"{out}: rows alone, room, segmenter mask, painted; {category} {seed}/{index}")


if __name__ == "__main__":
    tyro.cli(main)
