"""One fit configuration: every command that fits takes `fit: FitConfig` (flags `--fit.NAME`, the
old flags too), frozen and validated."""

import dataclasses
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


def _parse(args: list[str]) -> FitConfig:
    def command(fit: FitConfig = FitConfig()) -> FitConfig:
        return fit

    return tyro.cli(command, args=args)


def test_new_and_old_flags():
    expected = FitConfig(max_steps=300, restarts=2, focus_steps=0, handle_detector=False)
    assert _parse(["--fit.max-steps", "300", "--fit.restarts", "2", "--fit.focus-steps", "0",
                   "--fit.no-handle-detector"]) == expected
    assert _parse(["--max-steps", "300", "--restarts", "2", "--focus-steps", "0",
                   "--no-handle-detector"]) == expected
    assert _parse(["--fit.sighting-codes", "4"]).sighting_codes == 4


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
