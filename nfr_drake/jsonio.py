"""Reading JSON files with one clear error for a missing or malformed file."""

from __future__ import annotations

import json
from pathlib import Path

from nfr_drake.errors import NfrDrakeError


def read_json(path: str | Path, error: type[NfrDrakeError], what: str = "file"):
    """Parsed contents of `path`; `error` naming the path when it is missing or not valid JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except OSError as err:
        raise error(f"{path}: cannot read the {what} ({err.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise error(f"{path}: malformed JSON ({err})") from None
