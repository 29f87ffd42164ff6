"""Test-wide settings.

Network: nothing in nfr-drake may download (drake_models included), so the tests run with
DRAKE_ALLOW_NETWORK=meshcat, the strictest setting: package-map networking off. A bare `Parser()`
or `RobotDiagramBuilder()` fails under it (Drake's default package map registers the remote
`drake_models`); the package parses through `nfr_drake.parsing`, which works under any value.

Shared fixtures: a tiny rendered dataset, and a tiny closet model folder (random weights, fits in
seconds) for the inference and evaluation tests.
"""

import os

import pytest

os.environ.setdefault("DRAKE_ALLOW_NETWORK", "meshcat")
# oneDNN's AVX2 kernels crash torch's convolution backward on some virtual CPUs (segmentation
# fault, bus error or a hang in the baseline's training test on the project's AMD EPYC machine;
# README, "Troubleshooting"); the SSE4.1 ones do not. Set before
# torch is imported; a value set outside wins.
os.environ.setdefault("ONEDNN_MAX_CPU_ISA", "SSE41")


@pytest.fixture(scope="module")
def model_folder(tmp_path_factory):
    """A closet model folder: the tiny architecture, 3 training codes, random weights."""
    import torch

    from nfr_drake.nfr.checkpoint import write_model_folder
    from nfr_drake.nfr.config import NFRModelConfig
    from nfr_drake.nfr.model import NFRAutoDecoder

    small = NFRModelConfig(latent_obj_dim=8, hyper_hidden=16, field_width=16, feature_dim=16,
                           pe_frequencies=2, march_steps=3, lstm_hidden=8, pixel_hidden=16,
                           keypoint_hidden=16)
    folder = tmp_path_factory.mktemp("model") / "closet"
    torch.manual_seed(0)
    write_model_folder(folder, NFRAutoDecoder(small, num_objects=3),
                       {"category": "closet",
                        "keypoint_names": ["handle", "hinge_top", "hinge_bottom", "goal"]})
    return folder


FURNITURE_PARTS = ("door", "drawer", "door")
"""What the tiny furniture model says of every code: slots 0-2 exist with these types, 3-7 do not."""


@pytest.fixture(scope="module")
def furniture_model_folder(tmp_path_factory):
    """A furniture model folder: 8 slots, the tiny architecture, 3 training codes, random weights
    but for the keypoint head's slot logits, which say `FURNITURE_PARTS` whatever the code."""
    import torch

    from nfr_drake.data.slot_dataset import slot_keypoint_names
    from nfr_drake.nfr.checkpoint import write_model_folder
    from nfr_drake.nfr.config import NFRModelConfig
    from nfr_drake.nfr.model import NFRAutoDecoder

    S = 8
    small = NFRModelConfig(latent_obj_dim=8, hyper_hidden=16, field_width=16, feature_dim=16,
                           pe_frequencies=2, march_steps=3, lstm_hidden=8, pixel_hidden=16,
                           keypoint_hidden=16, num_slots=S, num_keypoints=4 * S,
                           bound_center=(0.35, 0.0, 1.0), bound_radius=1.6, min_depth=0.5)
    torch.manual_seed(0)
    module = NFRAutoDecoder(small, num_objects=3)
    last = module.model.keypoint_head.net[-1]
    logits = torch.full((S, 3), -5.0)
    for k, kind in enumerate(FURNITURE_PARTS):
        logits[k] = torch.tensor([5.0, 5.0 if kind == "door" else -5.0, 5.0 if kind == "drawer" else -5.0])
    with torch.no_grad():
        last.weight[3 * 4 * S:] = 0.0
        last.bias[3 * 4 * S:] = logits.flatten()
    folder = tmp_path_factory.mktemp("model") / "furniture"
    write_model_folder(folder, module, {"category": "furniture",
                                        "keypoint_names": list(slot_keypoint_names(S))})
    return folder


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """2 closets x 2 articulations x 4 views at 32 px, rendered by Drake (a few seconds)."""
    from nfr_drake.data.generate import generate_command

    out = tmp_path_factory.mktemp("nfr_data") / "closets"
    generate_command(category="closet", objects=2, out=out, articulations=2, views=4, size=32,
                     workers=1)
    return out


@pytest.fixture(scope="session")
def furniture_dataset(tmp_path_factory):
    """3 pieces of furniture x 2 articulations x 2 views at 24 px (a few seconds)."""
    from nfr_drake.data.generate import generate_command

    out = tmp_path_factory.mktemp("nfr_data") / "furniture"
    generate_command(category="furniture", objects=3, out=out, articulations=2, views=2, size=24,
                     workers=1)
    return out
