"""`nfr-drake validate`: check a capture set and summarise it."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import tyro

from nfr_drake.data.capture import read_capture_set


def validate_command(capture: Annotated[Path, tyro.conf.Positional]) -> None:
    """Validate the capture set in CAPTURE (transforms.json and its images); exit 2 if invalid.

    Args:
        capture: capture-set folder.
    """
    cap = read_capture_set(capture)
    centres = np.array([f.X_OC[:3, 3] for f in cap.frames])
    sizes = sorted({(f.camera.width, f.camera.height) for f in cap.frames})
    fovs = sorted({round(np.degrees(f.camera.fov_y), 1) for f in cap.frames})
    print(f"{capture}: {len(cap.frames)} frames, image sizes {sizes}, vertical FOV {fovs} deg, "
          f"camera distance to origin {np.linalg.norm(centres, axis=1).min():.2f}-"
          f"{np.linalg.norm(centres, axis=1).max():.2f} m, ground truth: "
          f"{'yes' if cap.gt else 'no'}")
