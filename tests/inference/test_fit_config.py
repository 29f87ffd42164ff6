"""One fit configuration: every command that fits takes `fit: FitConfig` (flags `--fit.NAME`, the
old flags too), frozen and validated."""

import dataclasses
import functools
import importlib
import inspect

import pytest
import tyro

from nfr_drake.cli import SUBCOMMANDS
from nfr_drake.errors import ConfigError
from nfr_drake.inference.fit import FitConfig


@pytest.mark.parametrize("name", ["infer", "eval", "eval-pipeline", "demo", "tune-head"])
def test_fitting_commands_share_the_config(name):
    module, func = SUBCOMMANDS[name][0].split(":")
    parameters = inspect.signature(getattr(importlib.import_module(module), func)).parameters
    assert parameters["fit"].default == FitConfig()
    assert not {"max_steps", "restarts", "focus_steps", "handle_detector"} & set(parameters)


def _parse(args: list[str], default: FitConfig = FitConfig()) -> FitConfig:
    def command(fit: FitConfig = default) -> FitConfig:
        return fit

    return tyro.cli(command, args=args)


def test_new_and_old_flags():
    expected = FitConfig(max_steps=300, restarts=2, focus_steps=0, handle_detector=False)
    assert _parse(["--fit.max-steps", "300", "--fit.restarts", "2", "--fit.focus-steps", "0",
                   "--fit.no-handle-detector"]) == expected
    assert _parse(["--max-steps", "300", "--restarts", "2", "--focus-steps", "0",
                   "--no-handle-detector"]) == expected
    assert _parse(["--fit.sighting-codes", "4"]).sighting_codes == 4


def _parsed_by_the_cli(args: list[str]) -> FitConfig:
    """The FitConfig that `nfr-drake eval-pipeline ARGS` hands its command (parsed by
    `nfr_drake.cli.main` with tyro, the command itself not run)."""
    from nfr_drake import cli
    from nfr_drake.eval import pipeline_eval

    real, seen = pipeline_eval.eval_pipeline_command, {}

    @functools.wraps(real)
    def spy(*a, **k):
        seen["fit"] = inspect.signature(real).bind(*a, **k).arguments["fit"]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pipeline_eval, "eval_pipeline_command", spy)
        assert cli.main(["eval-pipeline", "--category", "closet", "--model", "m",
                         "--csv-path", "c.csv", *args]) in (0, None)
    return seen["fit"]


def test_a_field_set_on_the_command_line_beats_the_preset():
    """A field given on the command line keeps its value on top of either preset, also when
    that value is another preset's (the fast preset used to replace thorough's values)."""
    fast, thorough = FitConfig.PRESETS["fast"], FitConfig.PRESETS["thorough"]
    fit = _parsed_by_the_cli(["--fit.preset", "fast", "--fit.max_steps", "400"]).resolved()
    assert fit.preset == "fast" and fit.max_steps == 400 == thorough["max_steps"]
    assert (fit.focus_steps, fit.start) == (fast["focus_steps"], fast["start"])
    fit = _parsed_by_the_cli(["--fit.preset", "fast", "--fit.focus-steps", "150",
                              "--fit.start", "spread", "--fit.valley-first", "False"]).resolved()
    assert (fit.focus_steps, fit.start, fit.valley_first) == (150, "spread", False)
    assert fit.explore_steps == fast["explore_steps"]
    fit = _parsed_by_the_cli(["--fit.preset", "thorough", "--max-steps", "120"]).resolved()
    assert fit.max_steps == 120 and fit.focus_steps == thorough["focus_steps"]


def test_each_preset_from_the_command_line():
    for preset in ("fast", "thorough"):
        fit = _parsed_by_the_cli(["--fit.preset", preset]).resolved()
        assert {k: getattr(fit, k) for k in FitConfig.PRESETS[preset]} == FitConfig.PRESETS[preset]
    assert _parsed_by_the_cli([]) == FitConfig()


def test_another_preset_on_top_of_a_default_instance():
    """A command whose default is one preset's instance, given the other preset, runs with the
    other's values (tyro starts from the default instance's field values)."""
    for default, preset in ((FitConfig.fast(), "thorough"), (FitConfig(preset="thorough"), "fast")):
        fit = _parse(["--fit.preset", preset], default).resolved()
        assert {k: getattr(fit, k) for k in FitConfig.PRESETS[preset]} == FitConfig.PRESETS[preset]


def test_frozen_and_validated():
    with pytest.raises(dataclasses.FrozenInstanceError):
        FitConfig().max_steps = 3
    with pytest.raises(ConfigError, match="explore_steps"):
        FitConfig(explore_steps=100, max_steps=50)
    assert not FitConfig(handle_detector=False).uses_sightings
    assert not FitConfig(sighting_weight=0.0).uses_sightings and FitConfig().uses_sightings


def test_every_field_has_a_docstring():
    from nfr_drake.inference import fit

    source = inspect.getsource(fit.FitConfig)
    for f in dataclasses.fields(FitConfig):
        line = next(i for i, s in enumerate(source.splitlines()) if s.strip().startswith(f"{f.name}:"))
        assert source.splitlines()[line + 1].strip().startswith('"""'), f.name
