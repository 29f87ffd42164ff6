"""ResumableRun: a run stopped and resumed takes the steps it had left, with the state it had."""

import numpy as np
import pytest
import torch

from nfr_drake.errors import ConfigError
from nfr_drake.nfr.resumable import ResumableRun


def _run(folder, steps, options, resume=False):
    torch.manual_seed(0)
    net = torch.nn.Linear(3, 1)
    opt = torch.optim.Adam(net.parameters(), lr=0.1)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, 6)
    rng = np.random.default_rng(0)
    run = ResumableRun(folder, net, opt, sched, rng, options, resume)
    run.train(steps, 2, lambda: net(torch.as_tensor(rng.normal(size=(4, 3)), dtype=torch.float32))
              .square().mean(), "test")
    return run, net


def test_a_run_resumed_ends_as_one_never_stopped_and_refuses_other_options(tmp_path):
    once, net_once = _run(tmp_path / "once", 6, {"lr": 0.1})
    _run(tmp_path / "twice", 4, {"lr": 0.1})
    twice, net_twice = _run(tmp_path / "twice", 6, {"lr": 0.1}, resume=True)
    assert twice.step == 6 and len(twice.losses) == 6 and twice.losses[:4] == once.losses[:4]
    np.testing.assert_allclose(twice.losses, once.losses, rtol=1e-6)
    torch.testing.assert_close(net_twice.weight, net_once.weight)
    with pytest.raises(ConfigError, match=r"other options than the run's \(lr differ\)"):
        _run(tmp_path / "twice", 6, {"lr": 0.2}, resume=True)
