"""How many torch threads a command uses when `--threads` is not given: the free cores.

More threads than free cores slows torch on CPU many times over (a thread that waits for a core
held by another process stalls the others at every parallel region: 20 fit steps took 25 s with 2
threads and 2.5 s with 1 on a busy 2-core machine), so the default is the cores this process may
run on less the recent load, at least 1.
"""

from __future__ import annotations

import os


def free_cores() -> int:
    """Cores of this process's CPU affinity mask less the 1-minute load average, rounded, >= 1."""
    cores = len(os.sched_getaffinity(0))
    return max(1, min(cores, round(cores - os.getloadavg()[0])))


def set_torch_threads(threads: int | None = None, processes: int = 1) -> int:
    """Set torch's intra-op threads to `threads`, or (None) to the free cores shared by
    `processes` processes that run at once; returns the number set."""
    import torch

    n = threads if threads is not None else max(1, free_cores() // processes)
    torch.set_num_threads(n)
    return n
