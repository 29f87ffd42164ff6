"""`nfr-drake eval`: the neural field and the baseline on held-out capture sets."""

from __future__ import annotations

from pathlib import Path

from nfr_drake.cpu import set_torch_threads
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.evaluate import Method
from nfr_drake.eval.methods import baseline_method, neural_field_methods
from nfr_drake.eval.report import run_evaluation
from nfr_drake.inference.fit import FitConfig


def eval_command(
    sets: list[Path],
    out: Path,
    model: Path | None = None,
    baseline: Path | None = None,
    limit: int | None = None,
    fit: FitConfig = FitConfig(),
    example_plots: int = 2,
    threads: int | None = None,
) -> None:
    """Evaluate methods on held-out capture sets; resumable (rows already in OUT/results.csv stay).

    Writes OUT/results.csv (one row per capture and method), OUT/summary.md (medians and 90th
    percentiles per set and method), OUT/errors.png (error distributions) and handle-path plots
    of the first captures of each set.

    Args:
        sets: folders of capture sets (each a set; its folder name names it in the tables).
        out: output folder.
        model: neural-field model folder.
        baseline: image-encoder baseline folder.
        limit: use only the first n captures of each set.
        fit: options of the neural field's fit.
        example_plots: handle-path plots per set.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    methods: dict[str, Method] = {}
    if model is not None:
        methods.update(neural_field_methods(model, fit))
    if baseline is not None:
        methods["baseline"] = baseline_method(baseline)
    if not methods:
        raise NfrDrakeError("give --model and/or --baseline")
    print(run_evaluation(methods, sets, out, limit, example_plots))
