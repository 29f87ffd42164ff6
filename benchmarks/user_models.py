"""`nfr-drake plan --object FILE` on realistic user models of furniture: opened or refused, and why.

    python benchmarks/user_models.py [--only NAME ...] [--out DIR] [--random N --seed S]
        [--grasp constraint|contact]

Writes the models of tests/fixtures/user_models.py (SDFormat, URDF, .obj meshes) into DIR (default
a temporary folder), runs `plan` on each as a user would (true keypoints, plan and simulation) and
prints one row per model: outcome (opened, failed: planned but the simulated motion failed,
refused: exit 2 with one line), the message, planning time, expected outcome, wall time.
`--random N` runs N random doors, drawers and sliding doors at random poses instead
(`random_models`: sizes, hinge sides, joint directions, handle kinds and heights drawn from seed S).
`--grasp` is `plan`'s: how the simulated hand holds the handle (the constraint grasp by default).
"""

from __future__ import annotations

import contextlib
import datetime
import io
import os
import platform
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Literal

import tyro

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fixtures.user_models import OPENS, random_models, write_models  # noqa: E402

from nfr_drake.cli import main as nfr_drake  # noqa: E402


def run(model, replay: Path, grasp: str) -> tuple[str, str, str, float]:
    """(outcome, message, planning seconds, wall seconds) of `plan --grasp GRASP` on one model."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = nfr_drake([*model.plan_args(), "--replay", str(replay), "--grasp", grasp])
        except Exception as exc:  # a traceback is an outcome here: the row says so
            status, err = -1, io.StringIO(f"traceback: {type(exc).__name__}: {exc}")
    wall = time.perf_counter() - t0
    lines = [line for line in (out.getvalue() + err.getvalue()).splitlines()
             if line and not line.startswith("live view")]
    planning = re.search(r"planning ([0-9.]+) s", out.getvalue())
    outcome = {0: "opened", 1: "failed", 2: "refused"}.get(status, "crashed")
    message = next((line for line in lines if line.startswith(("SUCCESS", "FAILURE", "nfr-drake plan: error",
                                                                "traceback"))), lines[-1] if lines else "")
    message = message.replace("nfr-drake plan: error: ", "").split("; planning ")[0]
    warnings = [line for line in lines if line.startswith("warning:")]
    if warnings:
        message = f"{message} [{len(warnings)} warning(s): {warnings[0][len('warning: '):]}]"
    return outcome, message, planning.group(1) if planning else "-", wall


def main(only: tuple[str, ...] = (), out: Path | None = None, random: int = 0, seed: int = 0,
         grasp: Literal["constraint", "contact"] = "constraint") -> None:
    """Print the table (markdown) with the date and machine."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    folder = Path(out) if out is not None else Path(tempfile.mkdtemp(prefix="user_models_"))
    models = random_models(folder, random, seed) if random else write_models(folder)
    models = [m for m in models if not only or m.name in only]
    print(f"{datetime.datetime.now():%Y-%m-%d %H:%M}, {platform.node()}, {os.cpu_count()} CPUs "
          f"({platform.processor() or platform.machine()}), load {os.getloadavg()[0]:.1f}; "
          f"{grasp} grasp; models in {folder}\n")
    print("| model | what | outcome | expected | planning (s) | wall (s) | message |")
    print("|---|---|---|---|---|---|---|")
    as_expected = 0
    for model in models:
        outcome, message, planning, wall = run(model, folder / f"{model.name}.html", grasp)
        expected = "opened" if model.expect == OPENS else "refused"
        ok = outcome == expected and (model.expect == OPENS or model.expect in message)
        as_expected += ok
        print(f"| {model.name} | {model.what} | {outcome} | {expected}{'' if ok else ' (NOT MET)'} | "
              f"{planning} | {wall:.0f} | {message} |", flush=True)
    print(f"\n{as_expected} of {len(models)} as expected")


if __name__ == "__main__":
    tyro.cli(main)
