"""The neural field of articulated objects (NFR): structured latent code, hypernetwork, field Phi,
LSTM raymarcher, pixel generators, keypoint head, losses, checkpoints and auto-decoder training.

Modules, one role each: `config` (dataclasses), `latent` (z = [z_art, z_obj]), `hyper` (H(z)),
`field` (Phi), `rays` (camera rays), `raymarcher` (LSTM marcher), `heads` (psi_1, psi_2, Gamma),
`model` (NFRModel taking z explicitly; NFRAutoDecoder with the code table), `render` (whole
images), `losses`, `sampling` (training rays), `checkpoint` (safetensors model folders), `viz`,
`train` (the loop and `nfr-drake train`), `resumable` (the resumable loop of the small 2D
networks: handle detector, segmenter). See docs/NEURAL_FIELD.md.
"""

from nfr_drake.nfr.checkpoint import CheckpointError, load_model, write_model_folder
from nfr_drake.nfr.config import LossConfig, NFRModelConfig, OptimConfig, SamplerConfig, TrainConfig
from nfr_drake.nfr.latent import compose_z, normalize_z_art, q_to_z_art, z_art_to_q
from nfr_drake.nfr.model import NFRAutoDecoder, NFRModel, RenderOutput
from nfr_drake.nfr.rays import Rays, pixel_centers, pixel_rays
from nfr_drake.nfr.render import Images, render_images

__all__ = [
    "CheckpointError", "Images", "LossConfig", "NFRAutoDecoder", "NFRModel", "NFRModelConfig",
    "OptimConfig", "Rays", "RenderOutput", "SamplerConfig", "TrainConfig", "compose_z",
    "load_model", "normalize_z_art", "pixel_centers", "pixel_rays", "q_to_z_art", "render_images",
    "write_model_folder", "z_art_to_q",
]
