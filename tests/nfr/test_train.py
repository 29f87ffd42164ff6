"""Training: the overfit test, the CLI with resume, and data-parallel training with torchrun."""

import csv
import os
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest
import torch

from nfr_drake.cli import main
from nfr_drake.data.dataset import RenderedDataset
from nfr_drake.nfr.config import LossConfig, NFRModelConfig, SamplerConfig
from nfr_drake.nfr.losses import nfr_loss
from nfr_drake.nfr.model import NFRAutoDecoder
from nfr_drake.nfr.rays import pixel_rays
from nfr_drake.nfr.sampling import RaySampler, stratified_pixels


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_stratified_pixels_draw_the_classes():
    label = np.zeros((32, 32), np.uint8)
    label[10:20, 10:20] = 1
    label[12:18, 12:14] = 2
    label[15, 15] = 3
    cfg = SamplerConfig(foreground_fraction=0.25, moving_fraction=0.25, handle_fraction=0.25)
    pix = stratified_pixels(label, 400, cfg, np.random.default_rng(0))
    assert pix.shape == (400,)
    drawn = label.reshape(-1)[pix]
    assert (drawn[:100] == 3).all() and (drawn[100:200] == 2).all() and (drawn[200:300] > 0).all()
    # A class missing from the image gives its share to uniform sampling.
    pix = stratified_pixels(np.zeros((8, 8), np.uint8), 50, cfg, np.random.default_rng(0))
    assert pix.shape == (50,)


def test_sampler_batches(tiny_dataset):
    data = RenderedDataset(tiny_dataset)
    s = RaySampler(data.records, data.camera.K, SamplerConfig(images_per_batch=3, rays_per_image=20), 0)
    b = s.sample()
    assert b.uv.shape == (3, 20, 2) and b.rgb.shape == (3, 20, 3) and b.labels.shape == (3, 20)
    assert b.K.shape == (3, 3, 3) and b.X_OC.shape == (3, 4, 4) and b.keypoints.shape == (3, 4, 3)
    # Sampled colours are the image's pixels at uv.
    rec = data.records[int(b.object_index[0])]
    a = int(np.flatnonzero(np.isclose(rec.q, float(b.q[0])))[0])
    imgs = [np.asarray(rec.rgb[a, v]) for v in range(rec.rgb.shape[1])]
    col, row = (b.uv[0, 0] - 0.5).long().tolist()
    assert any(np.allclose(img[row, col] / 255.0, b.rgb[0, 0].numpy(), atol=1e-6) for img in imgs)


def test_overfit_image_loss_falls_fivefold(tiny_dataset):
    """A few objects, a few views, 32 px: the image loss falls at least 5x within about a minute."""
    torch.manual_seed(0)
    data = RenderedDataset(tiny_dataset)
    cfg = NFRModelConfig(num_keypoints=len(data.keypoint_names))
    module = NFRAutoDecoder(cfg, data.num_objects)
    sampler = RaySampler(data.records, data.camera.K,
                         SamplerConfig(images_per_batch=4, rays_per_image=256), seed=0)
    opt = torch.optim.Adam([{"params": module.model.parameters(), "lr": 1e-3},
                            {"params": module.codes.parameters(), "lr": 1e-2}])
    losses, start = [], time.perf_counter()
    while time.perf_counter() - start < 60 and len(losses) < 400:
        b = sampler.sample()
        render, kp, z = module(b.object_index, b.q, pixel_rays(b.uv, b.K, b.X_OC))
        terms = nfr_loss(render, kp, z[:, 2:], b.rgb, b.labels, b.keypoints, LossConfig())
        opt.zero_grad()
        terms.total.backward()
        torch.nn.utils.clip_grad_norm_(module.parameters(), 1.0)
        opt.step()
        losses.append(terms.image.item())
        if len(losses) >= 40 and np.mean(losses[:10]) / np.mean(losses[-10:]) >= 8:
            break
    first, last = np.mean(losses[:10]), np.mean(losses[-10:])
    assert first / last >= 5, f"image loss fell only {first / last:.1f}x in {len(losses)} steps"


def test_cli_train_and_resume(tiny_dataset, tmp_path):
    run = tmp_path / "run"
    small = ["--model.field-width", "16", "--model.feature-dim", "16", "--model.hyper-hidden", "16",
             "--model.march-steps", "4", "--sampler.images-per-batch", "2",
             "--sampler.rays-per-image", "32", "--log-every", "5", "--val-every", "10",
             "--ckpt-every", "10", "--val-images", "2", "--threads", "1"]
    assert main(["train", "--data", str(tiny_dataset), "--out", str(run), "--optim.steps", "10",
                 *small]) == 0
    assert (run / "best" / "model.safetensors").is_file() and (run / "best" / "config.json").is_file()
    assert (run / "checkpoints" / "step_0000010").is_dir()
    assert (run / "val" / "step_0000010.png").is_file() and (run / "curves.png").is_file()
    assert [r["step"] for r in _rows(run / "metrics.csv")] == ["5", "10"]
    # Starting again without --resume refuses to overwrite.
    assert main(["train", "--data", str(tiny_dataset), "--out", str(run), "--optim.steps", "20",
                 *small]) == 2
    # Resume continues from step 10 to 20.
    assert main(["train", "--data", str(tiny_dataset), "--out", str(run), "--optim.steps", "20",
                 "--resume", *small]) == 0
    assert [r["step"] for r in _rows(run / "metrics.csv")] == ["5", "10", "15", "20"]
    assert (run / "checkpoints" / "step_0000020").is_dir()
    # Resuming with another architecture is a clear error.
    other = [a if a != "16" else "24" for a in small]
    assert main(["train", "--data", str(tiny_dataset), "--out", str(run), "--optim.steps", "30",
                 "--resume", *other]) == 2


def test_init_from_carries_codes_to_another_image_size_but_not_to_other_objects(tiny_dataset,
                                                                                tmp_path):
    from nfr_drake.data.generate import generate_command

    small = ["--model.field-width", "16", "--model.feature-dim", "16", "--model.hyper-hidden", "16",
             "--model.march-steps", "4", "--sampler.images-per-batch", "2",
             "--sampler.rays-per-image", "32", "--log-every", "5", "--val-every", "5",
             "--ckpt-every", "5", "--val-images", "2", "--threads", "1", "--optim.steps", "5"]
    assert main(["train", "--data", str(tiny_dataset), "--out", str(tmp_path / "a"), *small]) == 0
    start = str(tmp_path / "a" / "best")
    for name, size, seed in (("same_objects_24px", 24, 0), ("other_objects", 32, 1)):
        generate_command(category="closet", objects=2, out=tmp_path / name, articulations=2,
                         views=4, size=size, seed=seed, workers=1)
    assert main(["train", "--data", str(tmp_path / "same_objects_24px"), "--out",
                 str(tmp_path / "b"), "--init-from", start, *small]) == 0
    assert main(["train", "--data", str(tmp_path / "other_objects"), "--out",
                 str(tmp_path / "c"), "--init-from", start, *small]) == 2


def test_bad_data_folder_is_a_user_error(tmp_path):
    assert main(["train", "--data", str(tmp_path / "nothing"), "--out", str(tmp_path / "r")]) == 2


@pytest.mark.slow
def test_ddp_two_cpu_processes(tiny_dataset, tmp_path):
    """torchrun with 2 CPU processes (gloo): both ranks train, rank 0 writes the run."""
    run = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
           "--master_port", "29533", "-m", "nfr_drake.cli", "train", "--data", str(tiny_dataset),
           "--out", str(run), "--optim.steps", "10", "--threads", "1", "--log-every", "5",
           "--val-every", "10", "--ckpt-every", "10", "--val-images", "2",
           "--sampler.images-per-batch", "2", "--sampler.rays-per-image", "32",
           "--device", "cpu"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = _rows(run / "metrics.csv")
    assert [r["step"] for r in rows] == ["5", "10"]
    # rays/s counts both ranks' rays: 2 ranks x 2 images x 32 rays per step.
    assert (run / "best" / "model.safetensors").is_file()


def test_loss_weights_scale_terms():
    cfg = replace(LossConfig(), seg_weight=0.0, keypoint_weight=0.0, latent_weight=0.0,
                  depth_weight=0.0)
    B, R = 2, 4
    from nfr_drake.nfr.model import RenderOutput

    render = RenderOutput(torch.zeros(B, R, 3), torch.zeros(B, R, 4), torch.zeros(B, R, 3),
                          torch.ones(B, R), -torch.ones(B, R, 3))
    terms = nfr_loss(render, torch.zeros(B, 4, 3), torch.ones(B, 5), torch.ones(B, R, 3),
                     torch.zeros(B, R, dtype=torch.long), torch.ones(B, 4, 3), cfg)
    assert float(terms.total) == pytest.approx(1.0)  # only the image term
    assert float(terms.keypoint) == pytest.approx(3.0) and float(terms.depth) == pytest.approx(1.0)
    assert float(terms.seg) == pytest.approx(np.log(4)) and float(terms.latent) == 1.0
