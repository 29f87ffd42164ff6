"""Fit time and accuracy of the neural field per capture set: fit presets side by side, or a profile.

Usage: python benchmarks/fit_time.py --model models/closet --captures data/eval/closet_train_cams
       [--n 20] [--first 0] [--threads 1] [--variants thorough fast] [--variant NAME:FIELD=VALUE,...]
       [--profile K] [--step-costs] [--csv FILE] [--halves] [--bootstrap]
       python benchmarks/fit_time.py --captures DIR --from-csv FILE [FILE ...] [--halves] [--bootstrap]
Create the captures with `nfr-drake captures --category closet --n 20 --out DIR --size 64`.

Side by side (default): every capture is fitted (`nfr_drake.inference.infer.infer`: the fit and the
forward simulation of gt.json's q grid) once per variant, the variants interleaved on each capture
(their order alternating from one capture to the next) so that the machine's load hits them
alike. A variant is a fit preset (`FitConfig(preset=...)`: "fast", the default, or "thorough")
or one named with `--variant NAME:FIELD=VALUE,...` (FitConfig fields on top of a preset's
values, the default's unless `preset=...` names one; a field named keeps its value). Per fit: CPU seconds of
the process (`time.process_time`, the measure that another job's load hardly changes with one
torch thread), wall seconds, steps, and the errors against gt.json
(`nfr_drake.eval.evaluate.score`: articulation, keypoint RMSE at the observed state, handle
error, handle trajectory RMSE). Prints one markdown row per variant: medians and 90th
percentiles, and the ratio of the medians to the first variant's; with `--halves`, the same
for the first and the second half of the captures too (a choice tuned on the first half is
checked on the second). `--from-csv FILE ...` prints the tables of CSVs written by `--csv` (e.g. of
two halves fitted in parallel with `--first`) without fitting.

`--step-costs`: CPU milliseconds of one Adam step of one code (forward, backward, update) on 64
to 512 rays of the first capture.
`--profile K`: where the CPU time of K fits of the first variant goes, under cProfile timed by
`time.process_time` (cProfile adds its own overhead to every Python call, so shares, not
seconds, are what to read).
"""

from __future__ import annotations

import argparse
import cProfile
import csv
import os
import platform
import pstats
import time
from dataclasses import fields
from datetime import datetime
from pathlib import Path

import numpy as np
import torch

from nfr_drake.data.capture import capture_dirs, read_capture_set
from nfr_drake.eval.evaluate import Prediction, score
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.infer import FittedModel, infer

METRICS = (("cpu_s", "CPU s"), ("wall_s", "wall s"), ("steps", "steps"),
           ("articulation_error", "articulation error"), ("keypoint_rmse_cm", "keypoint RMSE cm"),
           ("handle_error_cm", "handle error cm"),
           ("handle_trajectory_rmse_cm", "handle trajectory RMSE cm"))


def parse_value(text: str, example) -> object:
    """A FitConfig field's value from text, by the type of an example value of the field."""
    if isinstance(example, bool):
        return text.lower() in ("1", "true", "yes")
    return type(example)(text)


def variant_config(spec: str) -> tuple[str, FitConfig]:
    """"fast" / "thorough" (a preset) or "NAME:FIELD=VALUE,..." -> (name, FitConfig); the fields
    not named keep their preset's values (`FitConfig.resolved`)."""
    if ":" not in spec:
        return spec, FitConfig(preset=spec)
    name, assignments = spec.split(":", 1)
    defaults = {f.name: getattr(FitConfig().resolved(), f.name) for f in fields(FitConfig)}
    values = {}
    for item in filter(None, assignments.split(",")):
        key, value = item.split("=", 1)
        values[key] = parse_value(value, defaults[key])
    return name, FitConfig(**values)


def fit_once(fitted: FittedModel, capture, config: FitConfig) -> dict:
    """One `infer` of the capture: times, steps and the errors against gt.json."""
    cpu, wall = time.process_time(), time.perf_counter()
    result, outcome = infer(fitted, capture, config, np.asarray(capture.gt["trajectory"]["q"]))
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    metrics = score(capture, Prediction(result.q, result.keypoints, result.trajectory, wall),
                    capture.root.parent.name, "")
    return {"cpu_s": cpu, "wall_s": wall, "steps": outcome.steps,
            **{key: getattr(metrics, key) for key, _ in METRICS[3:]}}


def side_by_side(fitted: FittedModel, dirs: list[Path], variants: dict[str, FitConfig],
                 csv_path: Path | None) -> dict[str, list[dict]]:
    """Rows per variant, the variants interleaved per capture (alternating order)."""
    rows: dict[str, list[dict]] = {name: [] for name in variants}
    names = list(variants)
    writer = None
    if csv_path is not None:
        csv_path.parent.mkdir(parents=True, exist_ok=True)
        out = open(csv_path, "w", newline="")  # noqa: SIM115 (closed at the end)
        writer = csv.DictWriter(out, ["capture", "variant"] + [k for k, _ in METRICS])
        writer.writeheader()
    for i, d in enumerate(dirs):
        capture = read_capture_set(d)
        for name in (names if i % 2 == 0 else names[::-1]):
            row = fit_once(fitted, capture, variants[name])
            rows[name].append(row)
            print(f"{d.name} {name}: " + ", ".join(f"{k} {row[k]:.3g}" for k, _ in METRICS),
                  flush=True)
            if writer is not None:
                writer.writerow({"capture": d.name, "variant": name, **row})
                out.flush()
    return rows


def summary(rows: dict[str, list[dict]], unit: str) -> str:
    """Markdown table: per variant the median (p90) of each metric, the median ratios of CPU
    and wall time to the first variant's."""
    first = next(iter(rows.values()))
    heads = [h.replace("articulation error", f"articulation error ({unit})") for _, h in METRICS]
    lines = ["| variant | fits | " + " | ".join(heads) + " | CPU / first | wall / first |",
             "|---" * (len(METRICS) + 4) + "|"]
    for name, rs in rows.items():
        cells = []
        for key, _ in METRICS:
            v = np.array([r[key] for r in rs], float)
            cells.append(f"{np.median(v):.3g} (p90 {np.percentile(v, 90):.3g})")
        ratios = [np.median([r[k] for r in rs]) / np.median([r[k] for r in first])
                  for k in ("cpu_s", "wall_s")]
        lines.append(f"| {name} | {len(rs)} | " + " | ".join(cells)
                     + f" | {ratios[0]:.2f} | {ratios[1]:.2f} |")
    return "\n".join(lines)


ERRORS = ("articulation_error", "keypoint_rmse_cm", "handle_error_cm", "handle_trajectory_rmse_cm")


def median_differences(rows: dict[str, list[dict]], unit: str, reps: int = 2000) -> str:
    """Markdown table: per variant after the first, the difference of its median from the first
    variant's for each error, with the 90 % interval of a paired bootstrap (`reps` resamplings
    of the captures, the variants' rows of one capture drawn together; rows in capture order)."""
    names = list(rows)
    n = min(len(rs) for rs in rows.values())
    values = {name: {k: np.array([r[k] for r in rows[name][:n]], float) for k in ERRORS}
              for name in names}
    draws = np.random.default_rng(0).integers(0, n, size=(reps, n))
    heads = [k.replace("articulation_error", f"articulation_error ({unit})") for k in ERRORS]
    lines = [f"paired bootstrap over {n} captures: median of the variant minus the first's "
             "[90 % interval]", "", "| variant | " + " | ".join(heads) + " |",
             "|---" * (len(ERRORS) + 1) + "|"]
    for name in names[1:]:
        cells = []
        for key in ERRORS:
            a, b = values[name][key], values[names[0]][key]
            boot = np.median(a[draws], axis=1) - np.median(b[draws], axis=1)
            low, high = np.percentile(boot, [5, 95])
            cells.append(f"{np.median(a) - np.median(b):+.3g} [{low:+.3g}, {high:+.3g}]")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def tables(rows: dict[str, list[dict]], unit: str, halves: bool, bootstrap: bool = False) -> str:
    """`summary` of all rows, and with `halves` of the first and second half of each variant's
    rows (captures in order) too; with `bootstrap`, `median_differences` of all rows."""
    text = summary(rows, unit)
    if bootstrap:
        text += "\n\n" + median_differences(rows, unit)
    if halves:
        n = min(len(rs) for rs in rows.values())
        for first, last in ((0, n // 2), (n // 2, n)):
            text += (f"\n\ncaptures {first}-{last - 1}:\n"
                     + summary({name: rs[first:last] for name, rs in rows.items()}, unit))
    return text


def read_rows(csv_paths: list[Path]) -> dict[str, list[dict]]:
    """The rows per variant of CSVs written by `side_by_side`, in their order."""
    rows: dict[str, list[dict]] = {}
    for path in csv_paths:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                rows.setdefault(row["variant"], []).append({k: float(row[k]) for k, _ in METRICS})
    return rows


def profile_parts() -> list[tuple[str, list]]:
    """(label, functions) of the parts a profile reports; a str names a builtin method."""
    from torch.nn import LSTMCell

    from nfr_drake.inference import fit, forward
    from nfr_drake.nfr.field import Field
    from nfr_drake.nfr.heads import KeypointHead, PixelGenerator
    from nfr_drake.nfr.hyper import HyperNetwork
    from nfr_drake.perception import handle_triangulation
    from nfr_drake.perception.handle_detector.model import HandleDetector

    return [
        ("photos to rays and edge map", [fit.observed_rays]),
        ("handle detector on the photos", [HandleDetector.detect]),
        ("handle triangulation", [handle_triangulation.locate_handle]),
        ("hypernetwork H(z)", [HyperNetwork.forward]),
        ("field Phi (encoding, generated MLP)", [Field.forward]),
        ("LSTM cell of the marcher", [LSTMCell.forward]),
        ("pixel generators psi_1, psi_2", [PixelGenerator.forward]),
        ("keypoint head Gamma", [KeypointHead.forward]),
        ("backward (autograd)", ["<method 'run_backward' of 'torch._C._EngineBase' objects>"]),
        ("Adam step", [torch.optim.Adam.step]),
        ("ray sampling", [fit.ObservedRays.sample, fit.ObservedRays.take]),
        ("forward simulation (keypoint trajectory)", [forward.keypoint_trajectory]),
    ]


def _key(function) -> tuple:
    """cProfile's key of a Python function (file, first line, name), or of a builtin."""
    if isinstance(function, str):
        return ("~", 0, function)
    code = getattr(function, "__wrapped__", function).__code__
    return (code.co_filename, code.co_firstlineno, code.co_name)


def profile(fitted: FittedModel, dirs: list[Path], config: FitConfig) -> str:
    """Markdown table of where the time of fits of the captures goes (cProfile cumulative time
    per part; the marcher's own share is its forward less the field and the LSTM cell)."""
    from nfr_drake.nfr.raymarcher import LSTMRaymarcher

    captures = [read_capture_set(d) for d in dirs]
    profiler = cProfile.Profile(time.process_time)  # CPU time: load does not count
    cpu, wall = time.process_time(), time.perf_counter()
    profiler.enable()
    for capture in captures:
        infer(fitted, capture, config, np.asarray(capture.gt["trajectory"]["q"]))
    profiler.disable()
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    stats = pstats.Stats(profiler).stats
    total = sum(entry[2] for entry in stats.values())  # sum of the functions' own times

    def cumulative(function) -> float:
        key = _key(function)
        return stats[key][3] if key in stats else 0.0

    parts = {label: sum(cumulative(f) for f in functions) for label, functions in profile_parts()}
    parts["marcher's own steps (points, step head, clamps)"] = (
        cumulative(LSTMRaymarcher.forward) - parts["field Phi (encoding, generated MLP)"]
        - parts["LSTM cell of the marcher"])
    parts["the rest (Python of the fit loop, losses, lookups)"] = total - sum(parts.values())
    lines = [f"{len(captures)} fits under cProfile: {cpu:.1f} s CPU, {wall:.1f} s wall, "
             f"{total:.1f} s CPU profiled", "", "| part | s | share |", "|---|---|---|"]
    for label, seconds in sorted(parts.items(), key=lambda kv: -kv[1]):
        lines.append(f"| {label} | {seconds:.2f} | {100 * seconds / total:.0f} % |")
    return "\n".join(lines)


def step_costs(fitted: FittedModel, capture, counts=(64, 128, 256, 512), steps: int = 20) -> str:
    """Markdown table: CPU ms of one Adam step (forward, backward, update) of one code on each
    number of the capture's rays, median of `steps` steps."""
    from nfr_drake.inference.fit import _adam, observed_rays

    rays = observed_rays(capture)
    for parameter in fitted.model.parameters():  # frozen, as in the fit
        parameter.requires_grad_(False)
    z0 = torch.cat([torch.tensor([0.0, 1.0]), fitted.z_obj_mean])[None]
    lines = ["| rays per step | CPU ms per step |", "|---|---|"]
    for count in counts:
        times = []
        for _ in range(steps):
            z = z0.clone()
            cpu = time.process_time()
            _adam(fitted.model, z, rays, FitConfig().resolved(), torch.Generator().manual_seed(0), 1, count,
                  stop_early=False)
            times.append(time.process_time() - cpu)
        lines.append(f"| {count} | {1000 * np.median(times):.1f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, help="the model folder to fit (not with --from-csv)")
    parser.add_argument("--captures", type=Path, required=True)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--first", type=int, default=0,
                        help="index of the first capture used (captures FIRST to FIRST + n - 1)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--variants", nargs="*", default=["thorough", "fast"],
                        help="presets to compare, in this order (the first is the reference)")
    parser.add_argument("--variant", action="append", default=[],
                        help="NAME:FIELD=VALUE,... another variant (FitConfig fields)")
    parser.add_argument("--profile", type=int, default=0,
                        help="profile this many fits of the first variant instead")
    parser.add_argument("--csv", type=Path, default=None, help="per-fit rows to write")
    parser.add_argument("--step-costs", action="store_true",
                        help="CPU time of one Adam step by rays per step instead")
    parser.add_argument("--halves", action="store_true",
                        help="the tables of the first and the second half of the captures too")
    parser.add_argument("--bootstrap", action="store_true",
                        help="the differences of the error medians from the first variant's, "
                             "with 90 %% paired bootstrap intervals")
    parser.add_argument("--from-csv", type=Path, nargs="+", default=None,
                        help="print the tables of the rows of --csv files (joined in this order) "
                             "instead of fitting")
    args = parser.parse_args()
    dirs = capture_dirs(args.captures)[args.first:args.first + args.n]
    warm = read_capture_set(dirs[0])  # the first fit of a process pays for lazy set-up
    unit = "deg" if warm.gt["object"]["joint_type"] == "revolute" else "cm"
    if args.from_csv is not None:
        print(tables(read_rows(args.from_csv), unit, args.halves, args.bootstrap))
        return
    if args.model is None:
        parser.error("--model is needed to fit")
    torch.set_num_threads(args.threads)
    fitted = FittedModel(args.model)
    variants = dict(variant_config(s) for s in args.variants + args.variant)
    infer(fitted, warm, next(iter(variants.values())), np.linspace(0.0, 1.0, 3))
    print(f"{datetime.now():%Y-%m-%d %H:%M}, {platform.machine()}, {os.cpu_count()} CPUs, "
          f"{args.threads} torch thread(s), load average {os.getloadavg()[0]:.2f}, model "
          f"{args.model}, {args.captures} ({len(dirs)} captures)", flush=True)
    if args.step_costs:
        print(step_costs(fitted, warm))
        return
    if args.profile:
        print(profile(fitted, dirs[:args.profile], next(iter(variants.values()))))
        return
    rows = side_by_side(fitted, dirs, variants, args.csv)
    print(f"\nload average at the end {os.getloadavg()[0]:.2f}\n")
    print(tables(rows, unit, args.halves, args.bootstrap))


if __name__ == "__main__":
    main()
