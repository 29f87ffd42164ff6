"""Pictures of training: PNG writing for the validation grids (`data.visualize.image_grid`) and loss
curves."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def save_png(path: Path, image: np.ndarray) -> None:
    """Write a uint8 RGB image (H, W, 3) as a PNG, making its folder."""
    path.parent.mkdir(parents=True, exist_ok=True)
    mpimg.imsave(str(path), image)


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        return {}
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    return {k: np.array([float(r[k]) if r[k] not in ("", None) else np.nan for r in rows])
            for k in rows[0]}


def plot_curves(run_dir: Path, out: Path) -> None:
    """Loss curves of a run (metrics.csv, val.csv) as one PNG with four panels."""
    train = _read_csv(Path(run_dir) / "metrics.csv")
    val = _read_csv(Path(run_dir) / "val.csv")
    if not train:
        return
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.6))
    s = train["step"]
    for key in ("image", "seg", "keypoint", "total"):
        axes[0].semilogy(s, train[key], label=key, lw=0.8)
    axes[0].set_title("training loss terms (unweighted)")
    axes[0].legend(fontsize=7)
    axes[1].plot(s, train["psnr"], lw=0.8, label="train rays (object-weighted)")
    if val:
        axes[1].plot(val["step"], val["psnr"], "o-", label="val images")
    axes[1].set_title("PSNR (dB)")
    axes[1].legend(fontsize=7)
    if val:
        axes[2].plot(val["step"], val["miou"], "o-", label="mIoU")
        axes[2].plot(val["step"], val["handle_iou"], "o-", label="handle IoU")
        axes[2].set_title("validation segmentation")
        axes[2].legend(fontsize=7)
        axes[3].plot(val["step"], val["kp_mean_cm"], "o-", label="all keypoints")
        axes[3].plot(val["step"], val["kp_handle_cm"], "o-", label="handle")
        axes[3].set_title("keypoint error, training objects (cm)")
        axes[3].set_yscale("log")
        axes[3].legend(fontsize=7)
    for ax in axes:
        ax.set_xlabel("step")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
