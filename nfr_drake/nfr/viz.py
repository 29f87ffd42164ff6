"""Pictures of training: validation grids (ground truth | render | segmentation) and loss curves."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nfr_drake.data.visualize import SEMANTIC_PALETTE  # noqa: E402

CLASS_COLORS = SEMANTIC_PALETTE.astype(np.float32) / 255.0
"""Display colours of classes 0 background, 1 carcass, 2 door/drawer, 3 handle: the project's
one palette (`nfr_drake.data.visualize.SEMANTIC_PALETTE`), as floats."""


def colorize_labels(labels: np.ndarray) -> np.ndarray:
    """int (..., H, W) classes -> float RGB (..., H, W, 3)."""
    return CLASS_COLORS[np.clip(labels, 0, len(CLASS_COLORS) - 1)]


def image_grid(rows: list[list[np.ndarray]], scale: int = 2, pad: int = 2) -> np.ndarray:
    """Tile equally sized float RGB images (H, W, 3) in [0, 1]: rows of columns, white gaps."""
    H, W = rows[0][0].shape[:2]
    n_c = max(len(r) for r in rows)
    h, w = H * scale, W * scale
    grid = np.ones((len(rows) * (h + pad) + pad, n_c * (w + pad) + pad, 3), np.float32)
    for i, row in enumerate(rows):
        for j, img in enumerate(row):
            big = np.repeat(np.repeat(np.asarray(img, np.float32), scale, 0), scale, 1)
            y, x = pad + i * (h + pad), pad + j * (w + pad)
            grid[y:y + h, x:x + w] = big[..., :3]
    return grid


def save_png(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    mpimg.imsave(str(path), np.clip(image, 0, 1))


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


def q_sweep_figure(model, codes, data, objects: list[int], out: Path, steps: int = 5,
                   view: int = 0) -> None:
    """For each training object: its true image at q = 0 and the model's RGB and segmentation at
    `steps` values of q in [0, 1], from the camera of articulation 0, `view`. One PNG."""
    import torch

    from nfr_drake.nfr.latent import q_to_z_art
    from nfr_drake.nfr.render import render_images

    S = data.spec.size
    qs = torch.linspace(0, 1, steps)
    K = torch.from_numpy(data.camera.K.astype(np.float32)).expand(steps, 3, 3)
    rows = []
    for j in objects:
        rec = data.records[j]
        X = torch.from_numpy(np.asarray(rec.X_OC[0, view])).expand(steps, 4, 4)
        z = torch.cat([q_to_z_art(qs), codes[j].expand(steps, -1)], dim=-1)
        with torch.no_grad():
            img = render_images(model, z, K, X, S, S)
        gt = np.asarray(rec.rgb[0, view], np.float32) / 255.0
        rows.append([gt] + list(img.rgb.numpy()))
        rows.append([colorize_labels(np.asarray(rec.label[0, view]))]
                    + list(colorize_labels(img.labels.numpy())))
    save_png(Path(out), image_grid(rows))
