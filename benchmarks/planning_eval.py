"""Success rate and planning time of `nfr-drake plan` with ground-truth keypoints on sampled objects.

    python benchmarks/planning_eval.py --count 50 --csv out/planning_eval.csv

Resumable (rows already in the CSV are kept). Prints a markdown table for docs/EVALUATION.md.
"""

from __future__ import annotations

import datetime
import platform
import sys
from pathlib import Path

import tyro

from nfr_drake.eval.planning import PlanningEvalConfig, evaluate_planning, summarise


def main(count: int = 50, seed: int = 7, csv: Path = Path("out/planning_eval.csv")) -> None:
    rows = evaluate_planning(PlanningEvalConfig(count=count, seed=seed), csv)
    print(f"command: python benchmarks/planning_eval.py --count {count} --seed {seed} --csv {csv}")
    print(f"date: {datetime.date.today()}, machine: {platform.node()} {platform.machine()} "
          f"{platform.processor() or ''}, python {sys.version.split()[0]}")
    print("| category | objects | planned | success | median planning s | p90 planning s |")
    print("|---|---|---|---|---|---|")
    for name, s in summarise(rows).items():
        print(f"| {name} | {s['count']} | {s['planned']:.0%} | {s['success']:.0%} | "
              f"{s['median_s']:.2f} | {s['p90_s']:.2f} |")


if __name__ == "__main__":
    tyro.cli(main)
