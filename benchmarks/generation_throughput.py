"""Dataset generation throughput: images per second with RGB, labels and depth written to disk.

Usage: python benchmarks/generation_throughput.py [--category closet] [--objects 8]
    [--articulations 10] [--views 10]
Prints a markdown table for docs/BENCHMARKS.md and the projected time of the paper-scale set
(1000 objects x 100 articulations x 10 views at 128 px). Furniture is rendered as `nfr-drake
generate --category furniture` renders it: cameras framed by each piece's bounds, a part-index
image per view, textures copied beside object.sdf.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import tempfile
import time
from datetime import date
from pathlib import Path

from nfr_drake.data.camera_placement import CameraDistribution, resolve_framing
from nfr_drake.data.generate import generate_dataset
from nfr_drake.data.shards import DatasetSpec
from nfr_drake.objects import CATEGORIES

PAPER_IMAGES = 1000 * 100 * 10


def measure(category: str, size: int, workers: int, objects: int, articulations: int, views: int) -> float:
    """Images per second of one generation run into a fresh temporary folder."""
    out = Path(tempfile.mkdtemp(prefix="nfr_bench_"))
    try:
        cameras = CameraDistribution(framing=resolve_framing("auto", category))
        spec = DatasetSpec(category, objects, articulations, views, size, seed=123, cameras=cameras)
        start = time.perf_counter()
        generate_dataset(spec, out, workers=workers, progress=False)
        seconds = time.perf_counter() - start
    finally:
        shutil.rmtree(out)
    return objects * articulations * views / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--category", choices=sorted(CATEGORIES), default="closet")
    parser.add_argument("--objects", type=int, default=8)
    parser.add_argument("--articulations", type=int, default=10)
    parser.add_argument("--views", type=int, default=10)
    args = parser.parse_args()
    print(f"{args.category}, {date.today()}, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, load average before: {os.getloadavg()[0]:.2f}")
    print("| size | workers | images/s | paper-scale set (1e6 images at 128 px) |")
    print("|---|---|---|---|")
    for size in (64, 128):
        for workers in (1, 2):
            rate = measure(args.category, size, workers, args.objects, args.articulations, args.views)
            projected = f"{PAPER_IMAGES / rate / 3600:.1f} h" if size == 128 else ""
            print(f"| {size} | {workers} | {rate:.0f} | {projected} |", flush=True)


if __name__ == "__main__":
    main()
