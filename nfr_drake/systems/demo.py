"""`nfr-drake demo`: the main job, one command (systems/open_closet.yaml's scenario)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from nfr_drake.cpu import set_torch_threads
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import FitConfig
from nfr_drake.systems.pipeline import run_scenario
from nfr_drake.systems.scenario import Scenario
from nfr_drake.systems.task import OPEN_TARGET


def demo_command(model: Path | None = None, seed: int = 100, index: int = 0,
                 q_target: float | None = None, views: int = 10, image_size: int = Scenario.image_size,
                 fit: FitConfig = FitConfig(),
                 replay: Path = Path("out/demo/open_closet.html"),
                 min_confidence: float = -1.0, task: Literal["open", "open-and-place"] = "open",
                 grasp: Literal["constraint", "contact"] = "constraint",
                 object_pose: Literal["given", "estimated"] = "given",
                 perceive: Literal["alone", "room"] = "alone",
                 segmenter: Path = Path(Scenario.segmenter),
                 threads: int | None = None,
                 object: Path | None = None, joint: str | None = None, handle_body: str | None = None,
                 closed_at: Literal["lower", "upper"] | None = None,
                 object_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0), object_yaw_deg: float = 0.0,
                 object_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> int:
    """Open an unseen closet: Drake cameras photograph it, the neural field is fitted and
    forward-simulated, the planner opens the door with those keypoints in simulation (and, with
    `--task open-and-place`, then picks an item from a table beside the robot and places it at the
    goal keypoint inside). With `--object FILE --joint J --handle-body B` the same on your own
    SDFormat or URDF model: photographed alone, fitted with models/furniture (or `--model`: a
    closet or drawer model for a door or a drawer), opened with the fitted keypoints in
    simulation on your model (docs/PLANNING.md, "The neural field on your own model").

    Prints the estimated q, the keypoint error against ground truth, the fit's confidence, the
    planning time, a success line and the replay's path. Exit status 0 on success, 1 when the
    simulated task fails, 2 when the fit is refused: its P(handle within 2 cm) lies below the
    threshold (one line says why and what to do; nothing is planned).

    Args:
        model: neural-field model folder (default: models/closet; with --object
            models/furniture).
        seed: capture seed of the unseen closet.
        index: object index within the seed.
        q_target: articulation to open to (default 0.6 for a door, 1.0 for a drawer with --object;
            0.6 = 54 degrees, which a fixed-base Panda reaches for
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
        object: your SDFormat or URDF model to open instead of a generated closet (with --joint and
            --handle-body; checked and refused as `nfr-drake plan --object` does).
        joint: the joint of its door or drawer (with --object).
        handle_body: the body whose geometry's centre is the handle (with --object).
        closed_at: which limit of --joint is shut, "lower" or "upper" (default: the rule of
            `nfr-drake plan`).
        object_xyz: where the model's frame stands in the world, m (with --object).
        object_yaw_deg: its rotation about the vertical, degrees (with --object).
        object_rpy_deg: roll, pitch, yaw of the model, degrees, before the yaw (with --object:
            stands up a model drawn lying on its side, e.g. 90 0 0).
    """
    set_torch_threads(threads)
    model_file = {} if object is None else dict(
        object_file=str(object), joint=joint or "", handle_body=handle_body or "", closed_at=closed_at or "",
        object_xyz=list(object_xyz), object_yaw_deg=object_yaw_deg, object_rpy_deg=list(object_rpy_deg))
    if object is None and (joint or handle_body or closed_at or any(object_xyz) or object_yaw_deg
                           or any(object_rpy_deg)):
        raise ConfigError("--joint, --handle-body, --closed-at and --object-xyz/-yaw-deg/-rpy-deg apply to "
                          "--object FILE")
    if object is not None and not (joint and handle_body):
        raise ConfigError("--object needs --joint and --handle-body")
    default_model = "" if object is not None else "models/closet"
    if q_target is None:
        kind = Scenario(**model_file).model_file_object().category if object is not None else "closet"
        q_target = OPEN_TARGET[kind]
    scenario = Scenario(category="closet", model=str(model) if model is not None else default_model,
                        seed=seed, index=index, q_target=q_target, views=views,
                        image_size=image_size, fit=fit, replay=str(replay),
                        min_confidence=min_confidence, task=task, grasp=grasp,
                        object_pose=object_pose, perceive=perceive, segmenter=str(segmenter), **model_file)
    outcome = run_scenario(scenario)
    print(outcome.report())
    if outcome.refused:
        return 2
    return 0 if outcome.task.success else 1
