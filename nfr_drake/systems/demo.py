"""`nfr-drake demo`: the main job, one command (systems/open_closet.yaml's scenario)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from nfr_drake.cpu import set_torch_threads
from nfr_drake.inference.fit import FitConfig
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario


def demo_command(model: Path = Path("models/closet"), seed: int = 100, index: int = 0,
                 q_target: float = 0.6, views: int = 10, image_size: int = Scenario.image_size,
                 fit: FitConfig = FitConfig(),
                 replay: Path = Path("out/demo/open_closet.html"),
                 min_confidence: float = -1.0, task: Literal["open", "open-and-place"] = "open",
                 grasp: Literal["constraint", "contact"] = "constraint",
                 object_pose: Literal["given", "estimated"] = "given",
                 perceive: Literal["alone", "room"] = "alone",
                 segmenter: Path = Path(Scenario.segmenter),
                 threads: int | None = None) -> int:
    """Open an unseen closet: Drake cameras photograph it, the neural field is fitted and
    forward-simulated, the planner opens the door with those keypoints in simulation (and, with
    `--task open-and-place`, then picks an item from a table beside the robot and places it at the
    goal keypoint inside).

    Prints the estimated q, the keypoint error against ground truth, the fit's confidence, the
    planning time, a success line and the replay's path. Exit status 0 on success, 1 when the
    simulated task fails, 2 when the fit is refused: its P(handle within 2 cm) lies below the
    threshold (one line says why and what to do; nothing is planned).

    Args:
        model: closet model folder.
        seed: capture seed of the unseen closet.
        index: object index within the seed.
        q_target: articulation to open to (0.6 = 54 degrees, which a fixed-base Panda reaches for
            every closet size; see docs/EVALUATION.md).
        views: perception cameras.
        image_size: their square image size, pixels.
        fit: options of the fit.
        replay: HTML replay to write.
        min_confidence: refuse to plan below this P(handle within 2 cm) (below 0: the model's
            calibrated threshold, `confidence.json`; 0: never refuse).
        task: "open", or "open-and-place" (the paper's last step, Place).
        grasp: open-and-place: how the simulated hand holds the handle and the item,
            "constraint" (constraints switched on as the fingers close) or "contact" (the fingers
            squeeze, friction holds).
        object_pose: "given" (the closet's true pose, the paper's setting) or "estimated" (from
            the views, cameras placed around a coarse look at the scene; the error is printed).
        perceive: what the cameras see: the closet "alone" before the training background (the
            paper's setting) or in a "room" (floor, walls, other furniture, clutter, the arm, under
            textures and lights the segmenter never saw; its masks pick the closet out).
        segmenter: the segmenter's model folder (with `--perceive room`).
        threads: torch CPU threads for the fit (default: the free cores,
            `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    scenario = Scenario(category="closet", model=str(model), seed=seed, index=index,
                        q_target=q_target, views=views,
                        image_size=image_size, fit=fit, replay=str(replay),
                        min_confidence=min_confidence, task=task, grasp=grasp,
                        object_pose=object_pose, perceive=perceive, segmenter=str(segmenter))
    outcome = run_scenario(scenario)
    print(outcome.report())
    if outcome.refused:
        return 2
    return 0 if outcome.task.success else 1
