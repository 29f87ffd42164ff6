"""`nfr-drake plan`: plan, simulate and replay opening or closing one articulated object."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Literal

import numpy as np
from pydrake.math import RigidTransform

from nfr_drake.errors import NfrDrakeError
from nfr_drake.jsonio import read_json
from nfr_drake.planning.planner import PlannerConfig, PlanningError, grasp_planner, plan_articulation
from nfr_drake.systems.articulation import SimulationConfig
from nfr_drake.systems.scene_objects import SceneObject, object_pose, sampled_part
from nfr_drake.systems.task import replay_plan, run_task, task_span
from nfr_drake.world.keypoints import KeypointTrajectory


def fitted_keypoints(path: Path, X_WO: RigidTransform) -> KeypointTrajectory:
    """The keypoint trajectory of a fit result JSON (`nfr-drake infer`) in W: a result whose pose was
    estimated (`infer --estimate-pose`, `extra.object_pose`) is in W already, any other is in O and
    placed at X_WO. Its present articulation is the fitted q."""
    result = read_json(path, NfrDrakeError, "fit result")
    in_W = isinstance(result, dict) and "object_pose" in (result.get("extra") or {})
    return KeypointTrajectory.from_fit_result(result, RigidTransform() if in_W else X_WO)


def plan_command(
    object: Path | None = None,
    joint: str | None = None,
    handle_body: str | None = None,
    category: Literal["closet", "drawer", "furniture"] | None = None,
    seed: int = 0,
    part: int | None = None,
    task: Literal["open", "close"] = "open",
    start_q: float | None = None,
    target_q: float | None = None,
    object_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0),
    object_yaw_deg: float = 0.0,
    object_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0),
    closed_at: Literal["lower", "upper"] | None = None,
    replay: Path = Path("out/plan/replay.html"),
    live: bool = False,
    keypoints: Path | None = None,
    grasp: Literal["constraint", "contact"] = "constraint",
) -> int:
    """Plan grasping the handle and opening (or closing) an object, simulate it, write a replay.

    Args:
        object: SDFormat or URDF file with one revolute or prismatic joint (finite limits).
        joint: the joint to articulate (with --object).
        handle_body: the body whose geometry's centre is the handle (with --object).
        category: instead of --object, plan on a sampled object of this category.
        seed: which sampled object (object_rng(SEED_DOMAIN_TRAIN, seed, 0)).
        part: which door or drawer of a sampled object (its index in canonical order,
            docs/FURNITURE.md); the others stay shut. Default: drawn from the object's stream.
        task: "open" (start_q -> target_q upward) or "close".
        start_q: articulation in [0, 1] at the start (default 0 to open, the open target to close).
        target_q: articulation to reach (default 0.6 for doors, 1.0 for drawers to open; 0 to
            close).
        object_xyz: position of the object's base in the world, m.
        object_yaw_deg: its rotation about the vertical, degrees.
        object_rpy_deg: roll, pitch, yaw of the object in the world, degrees, before the yaw above:
            stands up a model drawn lying on its side (e.g. exported Y-up: 90 0 0).
        closed_at: which limit of --joint is shut, "lower" or "upper" (with --object); default: the
            limit nearer the joint's zero, the position the model is drawn in.
        replay: where to write the self-contained HTML replay.
        live: keep the live meshcat view open after the run until Enter is pressed.
        keypoints: a fit result JSON (`nfr-drake infer`) to plan with instead of the object's own
            keypoints: in W when `infer --estimate-pose` estimated the object's pose (photos
            posed by `nfr-drake poses --world floor`), else in O and placed by --object-xyz and
            --object-yaw-deg. It plans from the fitted q (a door's, 90 degrees per unit, told in
            the joint's range: `SceneObject.in_joint_units`); the object (--object or --category) is
            the true one the motion is simulated on, shown in the replay beside the fitted
            keypoints with its own ("keypoints_true"). Without --object or --category (photos of
            a real object, no model of it) the motion is planned and replayed, not simulated.
        grasp: how the simulated hand holds the handle: "constraint" (a ball constraint switched
            on as the fingers close, the arm compliant while it pulls) or "contact" (the fingers
            squeeze the handle and friction holds it, the arm stiff; docs/SIMULATION.md).

    Returns 0 on success, 1 if the simulated motion failed; a planning failure exits 2.
    """
    X_WO = object_pose(object_xyz, object_yaw_deg, object_rpy_deg)
    if object is None and category is None and keypoints is not None:
        return _plan_only(fitted_keypoints(keypoints, X_WO), keypoints, task, start_q, target_q, replay,
                          grasp_planner(PlannerConfig(), grasp))
    if (object is None) == (category is None):
        raise NfrDrakeError("give either --object FILE --joint NAME --handle-body NAME or --category "
                            "(or --keypoints alone, to plan without simulating)")
    if object is None and (closed_at is not None or any(object_rpy_deg)):
        raise NfrDrakeError("--closed-at and --object-rpy-deg apply to a model file (--object)")
    if object is not None and part is not None:
        raise NfrDrakeError("--part chooses a front of a sampled object (--category); with --object "
                            "give --joint")
    if object is not None:
        if joint is None or handle_body is None:
            raise NfrDrakeError("--object needs --joint and --handle-body")
        scene_object = SceneObject.from_model_file(object, joint, handle_body, X_WO, 0.0, closed_at)
        for note in scene_object.notes:
            print(f"warning: {note}")
    else:
        obj, part, scene_object = sampled_part(category, seed, 0, X_WO, part)
        if obj.num_fronts > 1:
            print(f"{obj.params.get('kind', obj.category)} with {obj.num_fronts} parts; opening part "
                  f"{part} ({obj.front(part).kind})")
    q0, q1 = task_span(scene_object.category, task, start_q, target_q)
    scene_object = replace(scene_object, ground_truth=scene_object.ground_truth.with_current(q0))
    planned = None
    if keypoints is not None:
        planned = scene_object.in_joint_units(fitted_keypoints(keypoints, X_WO))
        if planned.category != scene_object.category:
            raise NfrDrakeError(f"{keypoints}: keypoints of a {planned.category}, but the object's joint "
                                f"makes it a {scene_object.category}")
        true = scene_object.ground_truth
        apart = np.linalg.norm(planned.point("handle", planned.q_current) - true.point("handle", q0))
        print(f"planning with the fitted keypoints of {keypoints} (q = {planned.q_current:.2f}; "
              f"handle {100 * apart:.1f} cm from the object's at q = {q0:g})")

    from pydrake.geometry import Meshcat

    meshcat = Meshcat()
    print(f"live view: {meshcat.web_url()}")
    outcome = run_task(scene_object, q1, keypoints=planned, meshcat=meshcat, replay=replay,
                       planner_config=grasp_planner(PlannerConfig(), grasp),
                       simulation_config=SimulationConfig(grasp=grasp),
                       reference=None if planned is None else scene_object.ground_truth)
    if outcome.plan is None:
        shorter = f" (a shorter motion, --target-q between {q0:g} and {q1:g}, may be reachable)" \
            if abs(q1 - q0) > 0.3 else ""
        raise PlanningError(outcome.planning_error + shorter)
    print(f"{outcome.summary()}; planning {outcome.planning_seconds:.2f} s; "
          f"replay {outcome.replay}")
    if live:
        input("press Enter to quit (the live view closes) ")
    return 0 if outcome.success else 1


def _plan_only(planned: KeypointTrajectory, source: Path, task: str, start_q: float | None,
               target_q: float | None, replay: Path, config: PlannerConfig) -> int:
    """Plan with fitted keypoints alone (no model of the object to simulate on) and write the
    planned motion's replay. Returns 0; a planning failure raises PlanningError (exit 2)."""
    q0, q1 = task_span(planned.category, task, planned.q_current if start_q is None else start_q, target_q)
    planned = planned.with_current(q0)
    plan = plan_articulation(planned, q1, config=config)
    path = replay_plan(planned, plan, q1, replay)
    p = plan.X_WB.translation()
    yaw = np.degrees(np.arctan2(plan.X_WB.rotation().matrix()[1, 0], plan.X_WB.rotation().matrix()[0, 0]))
    print(f"planned with the fitted keypoints of {source}: {planned.category} from q = {q0:.2f} to "
          f"{q1:.2f}, the robot's base at x {p[0]:.2f} m, y {p[1]:.2f} m, z {p[2]:.2f} m, yaw {yaw:.0f} deg, "
          f"{plan.duration:.1f} s of motion; planning {plan.seconds['total']:.2f} s; not simulated (no model "
          f"of the object: give --object or --category to simulate); replay {path}")
    return 0
