"""Training throughput of the neural field: rays/s, steps/s and peak memory, with sweeps.

Each configuration runs in a fresh process (so its peak RSS is its own and the thread count is set
before torch starts): a few warm-up steps, then timed full training steps (ray sampling from the
dataset, forward, loss, backward, Adam step).

    python benchmarks/nfr_training_throughput.py --data data/closet_train            # all sweeps
    python benchmarks/nfr_training_throughput.py --data data/closet_train --sweep threads
    python benchmarks/nfr_training_throughput.py --data data/closet_train --device cuda

Prints a markdown table (one row per configuration) to paste into docs/BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time

DEFAULT = {"threads": 1, "images": 12, "rays": 384, "width": 64, "steps": 12, "warmup": 3}

SWEEPS = {
    "default": [{}],
    "threads": [{"threads": 1}, {"threads": 2}],
    "rays": [{"images": 6, "rays": 384}, {"images": 12, "rays": 192}, {"images": 12, "rays": 768},
             {"images": 24, "rays": 384}],
    "width": [{"width": 32}, {"width": 128}],
    "srn": [{"srn": True, "images": 4, "rays": 384, "steps": 5}],
}


def run_one(data: str, params: dict, device: str) -> dict:
    """Time training steps of one configuration in this process."""
    import torch

    from nfr_drake.data.dataset import RenderedDataset
    from nfr_drake.nfr.config import LossConfig, NFRModelConfig, SamplerConfig
    from nfr_drake.nfr.losses import nfr_loss
    from nfr_drake.nfr.model import NFRAutoDecoder
    from nfr_drake.nfr.rays import pixel_rays
    from nfr_drake.nfr.sampling import RaySampler

    torch.set_num_threads(params["threads"])
    dev = torch.device(device)
    ds = RenderedDataset(data)
    w = params["width"]
    if params.get("srn"):
        cfg = NFRModelConfig.srn_reference(num_keypoints=len(ds.keypoint_names))
    else:
        cfg = NFRModelConfig(field_width=w, feature_dim=w, hyper_hidden=w, pixel_hidden=w,
                             num_keypoints=len(ds.keypoint_names))
    torch.manual_seed(0)
    module = NFRAutoDecoder(cfg, ds.num_objects).to(dev)
    opt = torch.optim.Adam(module.parameters(), 4e-4)
    sampler = RaySampler(ds.records, ds.camera.K,
                         SamplerConfig(images_per_batch=params["images"],
                                       rays_per_image=params["rays"]), seed=0)
    times = []
    for i in range(params["warmup"] + params["steps"]):
        t0 = time.perf_counter()
        b = sampler.sample().to(dev)
        render, kp, z = module(b.object_index, b.q, pixel_rays(b.uv, b.K, b.X_OC))
        loss = nfr_loss(render, kp, z[:, 2:], b.rgb, b.labels, b.keypoints, LossConfig()).total
        opt.zero_grad()
        loss.backward()
        opt.step()
        if dev.type == "cuda":
            torch.cuda.synchronize()
        if i >= params["warmup"]:
            times.append(time.perf_counter() - t0)
    step = sorted(times)[len(times) // 2]  # median: robust to other processes' bursts
    out = {**params, "steps_per_s": 1.0 / step, "rays_per_s": params["images"] * params["rays"] / step,
           "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
           "params_m": sum(p.numel() for p in module.model.parameters()) / 1e6}
    if dev.type == "cuda":
        out["peak_cuda_mb"] = torch.cuda.max_memory_allocated() / 2**20
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--data", required=True, help="dataset folder (nfr-drake generate)")
    ap.add_argument("--sweep", action="append", choices=sorted(SWEEPS),
                    help="sweeps to run (default: all)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--single", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.single:
        print(json.dumps(run_one(args.data, json.loads(args.single), args.device)))
        return
    rows = []
    for name in args.sweep or list(SWEEPS):
        for change in SWEEPS[name]:
            params = {**DEFAULT, **change}
            env = {**os.environ, "OMP_NUM_THREADS": str(params["threads"])}
            done = subprocess.run([sys.executable, __file__, "--data", args.data, "--device",
                                   args.device, "--single", json.dumps(params)],
                                  env=env, capture_output=True, text=True, check=True)
            row = json.loads(done.stdout.strip().splitlines()[-1])
            row["sweep"] = name
            rows.append(row)
            print(f"{name}: {row}", file=sys.stderr)
    load = os.getloadavg()
    print(f"\n{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {platform.machine()}, "
          f"{os.cpu_count()} CPUs, device {args.device}, load average before the last run "
          f"{load[0]:.2f}\n")
    print("| sweep | threads | images x rays | width | steps/s | rays/s | peak RSS (MB) | params (M) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        width = "SRN ref. (256)" if r.get("srn") else r["width"]
        print(f"| {r['sweep']} | {r['threads']} | {r['images']} x {r['rays']} | {width} | "
              f"{r['steps_per_s']:.2f} | {r['rays_per_s']:,.0f} | {r['peak_rss_mb']:.0f} | "
              f"{r['params_m']:.2f} |")


if __name__ == "__main__":
    main()
