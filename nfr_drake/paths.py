"""Output paths checked before the work that fills them, so a bad `--out` fails in a second."""

from __future__ import annotations

import os
from pathlib import Path

from nfr_drake.errors import ConfigError


def check_writable_file(path: Path, option: str) -> None:
    """ConfigError naming `option` when a file cannot be written at `path`: it is a folder, or
    its nearest existing parent is a file or not writable. Creates nothing."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder; give a file path")
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ConfigError(f"{option} {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{option} {path}: {parent} is not writable")
