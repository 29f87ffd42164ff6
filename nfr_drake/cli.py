"""The `nfr-drake` command: one subcommand per job, each a typed function turned into a CLI by tyro.

Subcommands are imported only when they run, so `nfr-drake generate` does not pay for torch and
`nfr-drake train` does not pay for pycolmap. To add one, add a line to `SUBCOMMANDS`.
"""

from __future__ import annotations

import importlib
import sys

from nfr_drake.errors import NfrDrakeError

# name -> ("module:function", one-line description). The function's signature is the CLI.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("nfr_drake.systems.demo:demo_command",
             "the main job: photograph an unseen closet, fit, plan and open it in simulation"),
    "generate": ("nfr_drake.data.generate:generate_command",
                 "render a training dataset of one category with Drake"),
    "generate-rooms": ("nfr_drake.data.room_dataset:generate_rooms_command",
                       "render objects in random rooms (furniture, clutter, the arm) for segmentation"),
    "label-amodal": ("nfr_drake.data.amodal:label_amodal_command",
                     "add amodal carcass labels (the carcass as if nothing hid it) to room datasets"),
    "captures": ("nfr_drake.data.captures:captures_command",
                 "render capture sets (transforms.json + gt.json) of unseen objects"),
    "validate": ("nfr_drake.data.validate:validate_command",
                 "check a capture set (transforms.json, images, ground truth) or a dataset"),
    "infer": ("nfr_drake.inference.infer:infer_command",
              "fit a model to a capture set and forward-simulate the object's motion"),
    "eval": ("nfr_drake.eval.command:eval_command",
             "evaluate the neural field and the baseline on held-out capture sets"),
    "eval-pipeline": ("nfr_drake.eval.pipeline_eval:eval_pipeline_command",
                      "success rate of perception + planning + simulation on unseen objects"),
    "calibrate-confidence": ("nfr_drake.eval.confidence_calibration:calibrate_confidence_command",
                             "calibrate the fit confidence and check it on out-of-distribution captures"),
    "explore": ("nfr_drake.eval.explore:explore_command",
                "what a model has learned: interpolations, new articulations, new objects, a 3D page"),
    "train-baseline": ("nfr_drake.baseline.train:train_baseline_command",
                       "train the paper's image-encoder baseline on a dataset"),
    "train-handle-detector": ("nfr_drake.perception.handle_detector.command:train_detector_command",
                              "train the 2D handle detector on rendered datasets"),
    "train-segmenter": ("nfr_drake.perception.segmentation.command:train_segmenter_command",
                        "train the 2D object segmenter on room datasets"),
    "eval-segmenter": ("nfr_drake.perception.segmentation.command:eval_segmenter_command",
                       "mask IoU of a segmenter on room datasets, and a figure of its masks"),
    "tune-head": ("nfr_drake.inference.head_tuning:tune_head_command",
                  "tune a model's keypoint head on the codes the fit finds for unseen objects"),
    "poses": ("nfr_drake.perception.poses:poses_command",
              "camera poses of a folder of photos (pycolmap SfM, metric alignment) as a capture set"),
    "train": ("nfr_drake.nfr.train:train_command", "train the neural field (auto-decoder) on a dataset"),
    "sheet": ("nfr_drake.data.contact_sheet:contact_sheet_command",
              "write a contact sheet PNG of a dataset's renders"),
    "plan": ("nfr_drake.systems.plan_command:plan_command", "plan, simulate and replay opening an object"),
}


def _usage() -> str:
    width = max(len(n) for n in SUBCOMMANDS)
    lines = ["usage: nfr-drake SUBCOMMAND [--help] [ARGS...]", "", "subcommands:"]
    lines += [f"  {name:<{width}}  {desc}" for name, (_, desc) in SUBCOMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit status."""
    import tyro

    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in SUBCOMMANDS:
        print(f"nfr-drake: unknown subcommand {name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    module_name, func_name = SUBCOMMANDS[name][0].split(":")
    func = getattr(importlib.import_module(module_name), func_name)
    try:
        result = tyro.cli(func, args=rest, prog=f"nfr-drake {name}")
    except NfrDrakeError as err:
        print(f"nfr-drake {name}: error: {err}", file=sys.stderr)
        return err.exit_status
    except KeyboardInterrupt:
        print(f"nfr-drake {name}: interrupted", file=sys.stderr)
        return 130
    return int(result) if isinstance(result, int) else 0


if __name__ == "__main__":
    sys.exit(main())
