"""Every tutorial runs as plain Python (smoke test), writing its figures into a temporary folder;
`NFR_TUTORIAL_QUICK=1` asks those that render and fit (03) for their small sizes."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

TUTORIALS = sorted((Path(__file__).parents[1] / "tutorials").glob("[0-9]*.py"))


@pytest.mark.parametrize("path", TUTORIALS, ids=lambda p: p.name)
def test_tutorial_runs(path, tmp_path):
    env = {**os.environ, "NFR_TUTORIAL_OUT": str(tmp_path), "MPLBACKEND": "Agg", "NFR_TUTORIAL_QUICK": "1"}
    result = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert any(tmp_path.glob("*.png")), "the tutorial wrote no figure"
