"""Model folders and resumable training checkpoints, written atomically, read without unpickling.

Model folder (docs/CONVENTIONS.md): `model.safetensors` (weights of the networks, plus the training objects'
codes under `codes.weight`) and `config.json` (format, architecture, category, keypoint names,
training data and command). A resumable checkpoint adds `optimizer.safetensors` (Adam moments,
torch RNG state) and `trainer.json` (step, parameter groups, sampler RNG state); the same three
files hold the training state of any other module (`write_training_checkpoint`).

Folders are written under a temporary name and renamed into place, so a reader (or `--resume`
after a kill) never sees half a checkpoint. Tensors are read with safetensors only; `torch.load`
is never called.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch import nn

from nfr_drake.errors import ConfigError, NfrDrakeError
from nfr_drake.jsonio import read_json
from nfr_drake.nfr.config import NFRModelConfig
from nfr_drake.nfr.field import encoding_dim
from nfr_drake.nfr.model import NFRAutoDecoder, NFRModel

MODEL_FORMAT = "nfr-drake-model"
MODEL_VERSION = 1
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
OPTIMIZER_FILE = "optimizer.safetensors"
TRAINER_FILE = "trainer.json"
CODES_KEY = "codes.weight"


class CheckpointError(NfrDrakeError):
    """A model folder or checkpoint is missing, corrupt, or of another architecture."""


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def _replace_dir(tmp: Path, final: Path) -> None:
    """Move the complete folder tmp to final, replacing what was there."""
    old = final.with_name(final.name + ".old")
    if old.exists():
        shutil.rmtree(old)
    if final.exists():
        os.replace(final, old)
    os.replace(tmp, final)
    if old.exists():
        shutil.rmtree(old)


def model_state(module: NFRAutoDecoder) -> dict[str, torch.Tensor]:
    """Flat name -> tensor of the networks (`model.` prefix dropped) and the code table."""
    state = {k.removeprefix("model."): v for k, v in module.state_dict().items()}
    return {k: v.detach().cpu().contiguous() for k, v in state.items()}


def write_model_folder(folder: Path, module: NFRAutoDecoder, info: dict) -> None:
    """Write `model.safetensors` + `config.json` atomically. `info` adds category, keypoint_names,
    training data/command etc. to config.json."""
    folder = Path(folder)
    tmp = folder.with_name(folder.name + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    save_file(model_state(module), str(tmp / WEIGHTS_FILE))
    config = {"format": MODEL_FORMAT, "version": MODEL_VERSION,
              "architecture": module.model.config.to_json(),
              "num_objects": module.codes.num_objects, **info}
    _write_json(tmp / CONFIG_FILE, config)
    _replace_dir(tmp, folder)


def read_model_config(folder: Path) -> dict:
    """config.json of a model folder, checked for format and version."""
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise CheckpointError(f"{folder}: no {CONFIG_FILE}; not a model folder")
    config = read_json(path, CheckpointError)
    if not isinstance(config, dict):
        raise CheckpointError(f"{path}: not a JSON object")
    if config.get("format") != MODEL_FORMAT:
        raise CheckpointError(f"{path}: format is {config.get('format')!r}, expected {MODEL_FORMAT!r}")
    if config.get("version") != MODEL_VERSION:
        raise CheckpointError(f"{path}: version {config.get('version')} is not supported "
                              f"(this code reads version {MODEL_VERSION})")
    return config


def read_model_architecture(folder: Path) -> tuple[dict, NFRModelConfig]:
    """config.json of a model folder and the architecture it declares."""
    config = read_model_config(folder)
    try:
        return config, NFRModelConfig.from_json(config["architecture"])
    except (KeyError, TypeError, ConfigError) as err:
        raise CheckpointError(f"{Path(folder) / CONFIG_FILE}: bad architecture ({err})") from None


def read_tensors(path: Path) -> dict[str, torch.Tensor]:
    """The tensors of a safetensors file; CheckpointError naming it when missing or damaged."""
    if not Path(path).is_file():
        raise CheckpointError(f"{path}: missing")
    try:
        return load_file(str(path))
    except (SafetensorError, OSError, ValueError) as err:
        raise CheckpointError(f"{path}: not a readable safetensors file ({err})") from None


def load_strict(module: nn.Module, state: dict[str, torch.Tensor], where: Path) -> None:
    """Load `state` into `module`; CheckpointError naming `where` on missing, unexpected or
    misshapen tensors."""
    expected = module.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    wrong = sorted(k for k in set(expected) & set(state) if expected[k].shape != state[k].shape)
    if missing or unexpected or wrong:
        parts = []
        if missing:
            parts.append(f"missing {missing[:4]}{'...' if len(missing) > 4 else ''}")
        if unexpected:
            parts.append(f"unexpected {unexpected[:4]}{'...' if len(unexpected) > 4 else ''}")
        if wrong:
            parts.append("shape mismatch " + ", ".join(
                f"{k}: file {tuple(state[k].shape)} vs model {tuple(expected[k].shape)}"
                for k in wrong[:3]))
        raise CheckpointError(f"{where}: weights do not match the architecture in config.json "
                              f"({'; '.join(parts)})")
    module.load_state_dict(state, strict=True)


def load_model(folder: Path, device: torch.device | str = "cpu"
               ) -> tuple[NFRModel, torch.Tensor, dict]:
    """Read a model folder: (networks in eval mode, training codes z_obj (N, k), config.json)."""
    folder = Path(folder)
    config, arch = read_model_architecture(folder)
    state = read_tensors(folder / WEIGHTS_FILE)
    codes = state.pop(CODES_KEY, None)
    if codes is None:
        raise CheckpointError(f"{folder / WEIGHTS_FILE}: no {CODES_KEY}")
    model = NFRModel(arch)
    load_strict(model, state, folder / WEIGHTS_FILE)
    return model.to(device).eval(), codes.to(device), config


def _auto_decoder_state(folder: Path) -> dict[str, torch.Tensor]:
    """A model folder's tensors named as in `NFRAutoDecoder` (networks under `model.`)."""
    state = read_tensors(Path(folder) / WEIGHTS_FILE)
    if CODES_KEY not in state:
        raise CheckpointError(f"{Path(folder) / WEIGHTS_FILE}: no {CODES_KEY}")
    return {(k if k == CODES_KEY else "model." + k): v for k, v in state.items()}


def load_auto_decoder(folder: Path, module: NFRAutoDecoder) -> dict:
    """Load a model folder's weights and codes into an existing training module (strict)."""
    config = read_model_config(folder)
    load_strict(module, _auto_decoder_state(folder), Path(folder) / WEIGHTS_FILE)
    return config


def optimizer_tensors(optimizer: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], dict]:
    """Split an optimizer's state_dict into tensors (for safetensors) and JSON (groups, scalars)."""
    sd = optimizer.state_dict()
    tensors, scalars = {}, {}
    for idx, st in sd["state"].items():
        for key, value in st.items():
            if torch.is_tensor(value):
                tensors[f"state.{idx}.{key}"] = value.detach().cpu().contiguous()
            else:
                scalars[f"{idx}.{key}"] = value
    return tensors, {"param_groups": sd["param_groups"], "scalars": scalars}


def load_optimizer_tensors(optimizer: torch.optim.Optimizer, tensors: dict[str, torch.Tensor],
                           meta: dict) -> None:
    state: dict[int, dict] = {}
    for name, value in tensors.items():
        _, idx, key = name.split(".", 2)
        state.setdefault(int(idx), {})[key] = value
    for name, value in meta["scalars"].items():
        idx, key = name.split(".", 1)
        state.setdefault(int(idx), {})[key] = value
    optimizer.load_state_dict({"state": state, "param_groups": meta["param_groups"]})


def _write_trainer_state(folder: Path, optimizer: torch.optim.Optimizer, trainer: dict) -> None:
    """optimizer.safetensors (optimizer tensors, torch RNG) and trainer.json (`trainer` + the
    optimizer's parameter groups and scalars) into `folder`."""
    tensors, meta = optimizer_tensors(optimizer)
    tensors["rng.torch"] = torch.get_rng_state()
    save_file(tensors, str(folder / OPTIMIZER_FILE))
    _write_json(folder / TRAINER_FILE, {**trainer, "optimizer": meta})


def _read_trainer_state(folder: Path, optimizer: torch.optim.Optimizer) -> dict:
    """Restore optimizer and torch RNG from `_write_trainer_state`; returns trainer.json."""
    tensors = read_tensors(folder / OPTIMIZER_FILE)
    trainer = read_json(folder / TRAINER_FILE, CheckpointError)
    try:
        torch.set_rng_state(tensors.pop("rng.torch"))
        load_optimizer_tensors(optimizer, tensors, trainer["optimizer"])
    except (KeyError, ValueError, RuntimeError) as err:
        raise CheckpointError(f"{folder}: optimizer state does not match ({err})") from None
    return trainer


def write_checkpoint(folder: Path, module: NFRAutoDecoder, optimizer: torch.optim.Optimizer,
                     info: dict, trainer: dict) -> None:
    """A resumable checkpoint: model folder + optimizer moments + trainer state, atomically."""
    folder = Path(folder)
    tmp = folder.with_name(folder.name + ".tmp")
    write_model_folder(tmp, module, info)
    _write_trainer_state(tmp, optimizer, trainer)
    _replace_dir(tmp, folder)


def read_checkpoint(folder: Path, module: NFRAutoDecoder,
                    optimizer: torch.optim.Optimizer) -> dict:
    """Restore module, optimizer and torch RNG from `write_checkpoint`; returns trainer.json."""
    folder = Path(folder)
    load_auto_decoder(folder, module)
    return _read_trainer_state(folder, optimizer)


def write_training_checkpoint(folder: Path, module: nn.Module, optimizer: torch.optim.Optimizer,
                              trainer: dict) -> None:
    """A resumable checkpoint of any module, atomically: its state_dict in model.safetensors,
    optimizer.safetensors and trainer.json (`trainer`: JSON values only)."""
    folder = Path(folder)
    tmp = folder.with_name(folder.name + ".tmp")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    save_file({k: v.detach().cpu().contiguous() for k, v in module.state_dict().items()},
              str(tmp / WEIGHTS_FILE))
    _write_trainer_state(tmp, optimizer, trainer)
    _replace_dir(tmp, folder)


def read_training_checkpoint(folder: Path, module: nn.Module,
                             optimizer: torch.optim.Optimizer) -> dict:
    """Restore module, optimizer and torch RNG from `write_training_checkpoint`; returns
    trainer.json."""
    folder = Path(folder)
    load_strict(module, read_tensors(folder / WEIGHTS_FILE), folder / WEIGHTS_FILE)
    return _read_trainer_state(folder, optimizer)


def _widen_first_layer(state: dict[str, torch.Tensor], old_frequencies: int,
                       new_frequencies: int) -> dict[str, torch.Tensor]:
    """Remap the field's first generated layer from `old_frequencies` to `new_frequencies`
    octaves of `positional_encoding`: the old inputs keep their weights, the new octaves get zero
    weights in the base weight and in the hypernetwork's output, so the function is unchanged."""
    new_in = encoding_dim(new_frequencies)
    # Input index map: [x (3), sin (3 F), cos (3 F)] in both encodings.
    old_to_new = torch.cat([torch.arange(3), 3 + torch.arange(3 * old_frequencies),
                            3 + 3 * new_frequencies + torch.arange(3 * old_frequencies)])
    prefix = "model.hyper.layers.0."
    state = dict(state)
    base = state[prefix + "base_weight"]  # (out, old_in)
    out_features = base.shape[0]
    widened = base.new_zeros(out_features, new_in)
    widened[:, old_to_new] = base
    state[prefix + "base_weight"] = widened
    # Hypernetwork output: out * in weight entries (row-major), then out biases.
    rows = (torch.arange(out_features)[:, None] * new_in + old_to_new[None, :]).flatten()
    rows = torch.cat([rows, out_features * new_in + torch.arange(out_features)])
    for name in ("net.2.weight", "net.2.bias"):
        old = state[prefix + name]
        new = old.new_zeros((out_features * new_in + out_features, *old.shape[1:]))
        new[rows] = old
        state[prefix + name] = new
    return state


def init_from_model_folder(folder: Path, module: NFRAutoDecoder) -> dict:
    """Start a training module from a model folder's weights and codes (fine-tuning).

    The architectures must match, except that `module` may use more positional-encoding octaves:
    the new octaves start with zero weights (see `_widen_first_layer`). `module` may have more
    objects than the model (a grown dataset whose first objects are the model's): their codes
    start at the model's mean code plus `module`'s initial noise. Returns config.json.
    """
    folder = Path(folder)
    config, arch = read_model_architecture(folder)
    target = module.model.config
    if replace(arch, pe_frequencies=target.pe_frequencies) != target \
            or arch.pe_frequencies > target.pe_frequencies:
        raise CheckpointError(f"{folder}: cannot start from this model: its architecture differs "
                              "from the run's in more than added positional-encoding octaves")
    state = _auto_decoder_state(folder)
    codes, n_new = state[CODES_KEY], module.codes.num_objects
    if len(codes) > n_new:
        raise CheckpointError(f"{folder}: {len(codes)} object codes, the run has only {n_new} "
                              "objects")
    with torch.no_grad():
        grown = module.codes.weight.detach().clone() + codes.mean(0)
    grown[:len(codes)] = codes
    state[CODES_KEY] = grown
    if arch.pe_frequencies < target.pe_frequencies:
        state = _widen_first_layer(state, arch.pe_frequencies, target.pe_frequencies)
    load_strict(module, state, folder / WEIGHTS_FILE)
    return config
