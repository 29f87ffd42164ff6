"""Each object's latest row over several `eval-pipeline` CSVs, summarised as the evaluation prints it.

    python scripts/latest_rows.py --files docs/results/A.csv docs/results/B.csv \
        [--columns C ...] [--out merged.csv]

Files are read in the order given; a later file's row for an object index replaces an earlier
one's. Prints the summary row (`SUMMARY_HEADER`), the place line for open-and-place rows, how
many rows each file gave, and the indices of the objects that did not succeed with their
`failure`. `--columns` prints those columns of every row as well (index first); `--out` writes the
merged rows (by index) as one CSV.
"""

from __future__ import annotations

import csv
from pathlib import Path

import tyro

from nfr_drake.eval.pipeline_eval import SUMMARY_HEADER, place_summary, summary_row


def latest_rows(files: list[Path]) -> tuple[dict[int, dict], dict[int, Path]]:
    """(rows by object index, the file each came from): the last file that has an index wins."""
    rows, sources = {}, {}
    missing = [str(path) for path in files if not path.is_file()]
    if missing:
        raise SystemExit(f"latest_rows: no such file: {', '.join(missing)}")
    for path in files:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                rows[int(row["index"])], sources[int(row["index"])] = row, path
    return rows, sources


def main(files: list[Path], columns: tuple[str, ...] = (), out: Path | None = None) -> None:
    """Print the merged rows' summary (and `columns` of each); write them to `out` when given."""
    rows, sources = latest_rows(files)
    ordered = [rows[i] for i in sorted(rows)]
    print(SUMMARY_HEADER)
    print(summary_row(ordered))
    if "item_error_cm" in ordered[0]:
        print(place_summary(ordered))
    for path in files:
        print(f"{path}: {sum(s == path for s in sources.values())} rows kept")
    for i in sorted(rows):
        if rows[i]["success"] != "True":
            state = "refused" if rows[i]["refused"] == "True" else "failed"
            print(f"  {i}: {state}: {rows[i]['failure']}")
    for i in sorted(rows) if columns else ():
        print(i, *(rows[i][c] for c in columns))
    if out is not None:
        with open(out, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(ordered[0]))
            writer.writeheader()
            writer.writerows(ordered)


if __name__ == "__main__":
    tyro.cli(main)
