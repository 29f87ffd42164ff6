"""Reading JSON files with one clear error for a missing or malformed file; writing result rows as CSV."""

from __future__ import annotations

import csv
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


def write_rows_csv(path: str | Path, rows: list[dict]) -> None:
    """Rows (dicts with the same keys, in the first row's order) as a CSV file with a header; the
    parent folder is made."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
