"""The neural field on users' own model files: `nfr-drake demo --object FILE` on realistic furniture.

    python benchmarks/user_models_field.py [--only NAME ...] [--models closet-or-drawer furniture]
        [--random N --seed S] [--image-size 128]

Writes the models of tests/fixtures/user_models.py (SDFormat, URDF, .obj meshes) into a temporary
folder and, for each one that `plan --object` opens with its true keypoints (sliding doors left
out: no field models them), runs the pipeline of `demo --object` (`Scenario.object_file`: ten
128 px photos of the model alone, the fit in the frame its carcass gives, the plan with the fitted
keypoints, the simulation on the model) with the model of the joint's kind (models/closet or
models/drawer, "closet-or-drawer") and with models/furniture. Every fit is planned on (the
confidence's threshold is not applied, `min_confidence` 0), so that the table shows what a refusal
would have prevented. One row per model and field: what the fit read the part as (door or
drawer), the handle's error at the observed state, for a door read as one how far its hinge line
lies from the joint's axis (horizontally; both are upright), P(handle within 2 cm), whether the
calibrated threshold refuses it, the simulated outcome (a failure with how far the joint ended
from its target; where it went on from a second base, why: `systems.task.pull_on`, `turn_on`),
the fit's time.
"""

from __future__ import annotations

import contextlib
import datetime
import io
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import tyro

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fixtures.user_models import OPENS, random_models, write_models  # noqa: E402

from nfr_drake.cpu import set_torch_threads  # noqa: E402
from nfr_drake.errors import NfrDrakeError  # noqa: E402
from nfr_drake.inference.confidence import refusal  # noqa: E402
from nfr_drake.systems.articulation import joint_error_text  # noqa: E402
from nfr_drake.systems.pipeline import run_scenario  # noqa: E402
from nfr_drake.systems.scenario import Scenario  # noqa: E402
from nfr_drake.systems.task import OPEN_TARGET  # noqa: E402


def placement(args: tuple[str, ...]) -> dict:
    """The Scenario fields of a fixture's extra `plan` arguments (--object-xyz X Y Z,
    --object-yaw-deg D, --object-rpy-deg R P Y, --closed-at L)."""
    fields, values = {}, list(args)
    while values:
        flag = values.pop(0)
        if flag in ("--object-xyz", "--object-rpy-deg"):
            fields[flag[2:].replace("-", "_")] = [float(values.pop(0)) for _ in range(3)]
        elif flag in ("--object-yaw-deg", "--closed-at"):
            value = values.pop(0)
            fields[flag[2:].replace("-", "_")] = float(value) if flag == "--object-yaw-deg" else value
        else:
            raise ValueError(f"unknown fixture argument {flag}")
    return fields


def run(model, field: str, image_size: int) -> list[str]:
    """One row: the pipeline on `model` with the field "closet-or-drawer" or "furniture", its
    photos `image_size` px square."""
    scenario = Scenario(object_file=str(model.path), joint=model.joint, handle_body=model.handle_body,
                        model="models/furniture", min_confidence=0.0, image_size=image_size,
                        **placement(model.args))
    category = scenario.model_file_object().category
    scenario.q_target = OPEN_TARGET[category]
    if field == "closet-or-drawer":
        scenario.model = f"models/{category}"
    kind = {"closet": "door", "drawer": "drawer"}[category]
    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            outcome = run_scenario(scenario)
    except NfrDrakeError as err:  # refused in one line: the row says why
        wall = time.perf_counter() - t0
        return [model.name, kind, field, "-", "-", "-", "-", f"refused: {err}", "-", "-", f"{wall:.0f}"]
    wall = time.perf_counter() - t0
    p = (outcome.confidence or {}).get("p_handle_within_2cm", float("nan"))
    refused = "refused" if refusal(outcome.confidence) else "kept"
    task = outcome.task
    result = ("no plan" if task.plan is None else "opened" if task.success else "failed") if task else "-"
    if result == "failed" and task.final is not None:
        sim = task.final
        result += f" ({joint_error_text(sim.joint_type, sim.joint_error)} off the target)"
    if task is not None and task.pulled_on is not None:
        first = task.simulation
        result += (f", from a second base ({task.pulled_on.reason}; the first left it "
                   f"{joint_error_text(first.joint_type, first.joint_error)} off)")
    predicted = outcome.predicted
    read = {"closet": "door", "drawer": "drawer"}[predicted.category] if predicted else "-"
    hinge = "-"
    if predicted is not None and read == kind == "door":  # both hinge lines upright: their xy apart
        truth = outcome.truth
        apart = (predicted.point("hinge_bottom", predicted.q_current)
                 - truth.point("hinge_bottom", truth.q_current))
        hinge = f"{100 * np.linalg.norm(apart[:2]):.1f}"
    return [model.name, kind, field, read, f"{outcome.keypoint_rmse_cm:.1f}", hinge, f"{p:.2f}", refused,
            result, f"{outcome.perception_seconds:.1f}", f"{wall:.0f}"]


def main(only: tuple[str, ...] = (), models: tuple[str, ...] = ("closet-or-drawer", "furniture"),
         threads: int = 1, random: int = 0, seed: int = 0, image_size: int = Scenario.image_size) -> None:
    """Print the table (markdown) with the date and machine. `random`: that many random models
    (`random_models` of seed `seed`: doors, drawers and sliding doors in turn, the sliding doors
    left out) instead of the fixed ones; `image_size`: the photos' side, px."""
    set_torch_threads(threads)
    with tempfile.TemporaryDirectory() as folder:
        written = random_models(Path(folder), random, seed) if random else write_models(Path(folder))
        chosen = [m for m in written if m.expect == OPENS and "sliding" not in m.name
                  and (not only or m.name in only)]
        print(f"{datetime.date.today()}, {platform.node()}, {os.cpu_count()} cores, torch threads {threads}, "
              f"photos {image_size} px")
        print("| model | joint | field | fitted as | handle error (cm) | hinge line off (cm) "
              "| P(handle within 2 cm) | calibrated threshold | planned on the fit | fit (s) | wall (s) |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for model in chosen:
            for field in models:
                print("| " + " | ".join(run(model, field, image_size)) + " |", flush=True)


if __name__ == "__main__":
    tyro.cli(main)
