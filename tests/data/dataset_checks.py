"""Checks shared by the dataset tests: arrays on disk, bit-identical data, a run killed with -9."""

import os
import signal
import subprocess
import time

import numpy as np

from nfr_drake.data.shards import OBJECTS_DIR, completed_objects

ARRAYS = ("rgb", "label", "depth")


def object_arrays(root, index, names=ARRAYS):
    """The arrays of object `index` in the dataset folder `root`, name -> array."""
    folder = root / OBJECTS_DIR / f"obj_{index:06d}"
    return {n: np.load(folder / f"{n}.npy") for n in names}


def assert_same_data(a, b, objects, names=ARRAYS):
    """Both dataset folders hold objects 0..objects-1 with bit-identical arrays."""
    assert completed_objects(a) == completed_objects(b) == list(range(objects))
    for i in range(objects):
        x, y = object_arrays(a, i, names), object_arrays(b, i, names)
        for name in x:
            np.testing.assert_array_equal(x[name], y[name], err_msg=f"object {i} {name}")


def kill_when(cmd, done, timeout_s=120):
    """Start `cmd`, wait until `done()` is true, then kill -9 it and its workers."""
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    deadline = time.time() + timeout_s
    while time.time() < deadline and not done():
        time.sleep(0.01)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def kill_after_first_object(cmd, root, timeout_s=120):
    """Start `cmd` (a generate run into `root`), kill -9 it and its workers once one object is
    complete, and return how many objects were complete."""
    kill_when(cmd, lambda: (root / OBJECTS_DIR).is_dir() and len(completed_objects(root)) >= 1, timeout_s)
    return len(completed_objects(root))


def dead_pid():
    """The id of a process that has ended (for temporary folders left by a killed writer)."""
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def files_of(root):
    """Every file under `root`: relative path -> bytes."""
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}
