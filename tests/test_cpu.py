"""Default torch threads: the free cores, for every command with a --threads option."""

import importlib
import inspect

import pytest
import torch

from nfr_drake import cpu
from nfr_drake.cli import SUBCOMMANDS


@pytest.mark.parametrize("cores,load,expected", [(2, 2.1, 1), (2, 0.3, 2), (2, 9.0, 1),
                                                 (16, 3.4, 13), (16, 0.0, 16)])
def test_free_cores_are_the_affinity_less_the_load(monkeypatch, cores, load, expected):
    monkeypatch.setattr(cpu.os, "sched_getaffinity", lambda pid: set(range(cores)))
    monkeypatch.setattr(cpu.os, "getloadavg", lambda: (load, load, load))
    assert cpu.free_cores() == expected


def test_threads_given_win_and_processes_share_the_free_cores(monkeypatch):
    old = torch.get_num_threads()
    monkeypatch.setattr(cpu, "free_cores", lambda: 9)
    try:
        assert cpu.set_torch_threads(None, processes=2) == 4 == torch.get_num_threads()
        assert cpu.set_torch_threads(None, processes=20) == 1
        assert cpu.set_torch_threads(3) == 3 == torch.get_num_threads()
    finally:
        torch.set_num_threads(old)


def test_every_threads_option_defaults_to_the_free_cores():
    """A command's --threads (or its config's `threads`) defaults to None: `set_torch_threads`
    then picks the free cores, so `infer`, `eval`, `demo` ... agree."""
    from nfr_drake.baseline.train import BaselineTrainConfig
    from nfr_drake.nfr.config import TrainConfig
    from nfr_drake.perception.handle_detector.training import DetectorTrainConfig

    seen = []
    for name, (target, _) in SUBCOMMANDS.items():
        module, func = target.split(":")
        params = inspect.signature(getattr(importlib.import_module(module), func)).parameters
        if "threads" in params:
            seen.append(name)
            assert params["threads"].default is None, name
    assert {"infer", "eval", "demo", "eval-pipeline", "tune-head"} <= set(seen)
    for config in (TrainConfig(), BaselineTrainConfig(), DetectorTrainConfig()):
        assert config.threads is None, type(config).__name__
