"""Success rate and planning time of `nfr-drake plan` with ground-truth keypoints on sampled objects.

    python benchmarks/planning_eval.py --count 50 --csv out/planning_eval.csv
    python benchmarks/planning_eval.py --count 100 --grasp contact --csv out/planning_eval_contact.csv
    python benchmarks/planning_eval.py --categories furniture --count 100 --csv out/planning_furniture.csv

Furniture: piece i opened at one random part (drawn from the piece's stream), the others shut.
Resumable (rows already in the CSV are kept). Prints markdown tables for docs/EVALUATION.md: by
category, and for furniture by part type and by kind.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
from pathlib import Path

import tyro

from nfr_drake.eval.planning import PlanningEvalConfig, evaluate_planning, summarise


def _cpu() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").is_file() else []:
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def main(count: int = 50, seed: int = 7, csv: Path = Path("out/planning_eval.csv"),
         categories: tuple[str, ...] = ("closet", "drawer"), closet_target: float = 0.6,
         drawer_target: float = 1.0, grasp: str = "constraint") -> None:
    """Evaluate (resuming from `csv`) and print the command, date, machine and a markdown table.
    `grasp`: the simulated grasp, "constraint" or "contact" (give each its own CSV)."""
    config = PlanningEvalConfig(count=count, seed=seed, categories=categories,
                                closet_target=closet_target, drawer_target=drawer_target, grasp=grasp)
    rows = evaluate_planning(config, csv)
    print(f"command: python benchmarks/planning_eval.py --count {count} --seed {seed} --csv {csv} "
          f"--categories {' '.join(categories)} --closet-target {closet_target} "
          f"--drawer-target {drawer_target} --grasp {grasp}")
    print(f"date: {datetime.date.today()}, machine: {_cpu()}, {os.cpu_count()} cores, "
          f"python {sys.version.split()[0]}")
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    tables = [("category", rows)]
    furniture = [r for r in rows if r["category"] == "furniture"]
    if furniture:
        tables += [("part_type", furniture), ("kind", furniture)]
    for by, selected in tables:
        print(f"\n| {by} | objects | planned | success | median planning s | p90 planning s "
              "| median planning CPU s |")
        print("|---|---|---|---|---|---|---|")
        for name, s in summarise(selected, by).items():
            print(f"| {name} | {s['count']} | {s['planned']:.0%} | {s['success']:.0%} | "
                  f"{s['median_s']:.2f} | {s['p90_s']:.2f} | {s['median_cpu_s']:.2f} |")
    failed = [r for r in furniture if r["success"] != "True"]
    if failed:
        print("\nfailed furniture parts (index, kind, part, type, handle height m, error):")
        for r in failed:
            print(f"  {r['index']} {r['kind']} part {r['part']} {r['part_type']} {r['handle_height']} "
                  f"{r['error'][:160] or 'simulated motion failed'}")


if __name__ == "__main__":
    tyro.cli(main)
