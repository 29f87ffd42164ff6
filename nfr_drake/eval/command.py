"""`nfr-drake eval`: the neural field and the baseline on held-out capture sets."""

from __future__ import annotations

from pathlib import Path

from nfr_drake.cpu import set_torch_threads
from nfr_drake.errors import NfrDrakeError
from nfr_drake.eval.evaluate import Method
from nfr_drake.eval.methods import baseline_method, neural_field_methods
from nfr_drake.eval.report import run_evaluation, set_categories
from nfr_drake.inference.fit import FitConfig
from nfr_drake.inference.furniture_fit import FurnitureFitConfig


def eval_command(
    sets: list[Path],
    out: Path,
    model: Path | None = None,
    baseline: Path | None = None,
    category: str | None = None,
    limit: int | None = None,
    fit: FitConfig = FitConfig(),
    furniture_fit: FurnitureFitConfig = FurnitureFitConfig(),
    example_plots: int = 2,
    threads: int | None = None,
) -> None:
    """Evaluate methods on held-out capture sets; resumable (rows already in OUT/results.csv stay).

    Writes OUT/results.csv (one row per capture and method; furniture: per true part),
    OUT/summary.md (medians and 90th percentiles per set and method; furniture: per-part errors,
    part count right, fit time), OUT/errors.png (error distributions) and handle-path plots of the
    first captures of each set.

    Args:
        sets: folders of capture sets (each a set; its folder name names it in the tables).
        out: output folder.
        model: neural-field model folder.
        baseline: image-encoder baseline folder, of the sets' category.
        category: the sets' category, checked against their gt.json (default: theirs).
        limit: use only the first n captures of each set.
        fit: options of the neural field's fit.
        furniture_fit: options of the fit of a model with several parts (furniture).
        example_plots: handle-path plots per set.
        threads: torch CPU threads (default: the free cores, `nfr_drake.cpu.free_cores`).
    """
    set_torch_threads(threads)
    categories = set_categories(sets)
    if category is not None and categories != {category}:
        raise NfrDrakeError(f"--category {category}, but the sets hold {', '.join(sorted(categories))}")
    methods: dict[str, Method] = {}
    if model is not None:
        methods.update(neural_field_methods(model, fit, furniture_fit))
    if baseline is not None:
        baseline_category, methods["baseline"] = baseline_method(baseline)
        if categories != {baseline_category}:
            raise NfrDrakeError(f"--baseline {baseline} is a {baseline_category} baseline, but the sets "
                                f"hold {', '.join(sorted(categories))}")
    if not methods:
        raise NfrDrakeError("give --model and/or --baseline")
    print(run_evaluation(methods, sets, out, limit, example_plots))
