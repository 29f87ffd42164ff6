"""What a real camera adds to a clean render, applied in numpy: exposure and gain, white balance,
gamma, blur (defocus or motion) and sensor noise.

Drake's VTK renderer has no exposure control, so a photo's brightness changes are modelled here
after rendering, on the uint8 image. One `SensorEffects` holds the parameters of one image; its
noise comes from its own seed, so the same parameters always give the same image.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class SensorEffects:
    """Photometric changes of one image.

    gain: factor on linear intensity (exposure times analogue gain); gamma: exponent on the
    normalised image (> 1 darkens mid-tones); white_balance: factor per RGB channel;
    blur_sigma_px: Gaussian defocus blur, px (0 for none); motion_px, motion_angle_rad: length
    (px, 0 for none) and direction of a linear motion blur; noise_sigma: standard deviation of
    additive Gaussian noise on [0, 1] intensities, shot-noise-like (scaled by sqrt of the
    intensity); seed: the noise's random stream.
    """

    gain: float = 1.0
    gamma: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)
    blur_sigma_px: float = 0.0
    motion_px: float = 0.0
    motion_angle_rad: float = 0.0
    noise_sigma: float = 0.0
    seed: int = 0

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        """The image (uint8, (H, W, 3)) as this sensor would have taken it; same shape and dtype."""
        x = rgb.astype(np.float32) / 255.0
        x = np.clip(x * self.gain * np.asarray(self.white_balance, np.float32), 0.0, 1.0) ** self.gamma
        if self.blur_sigma_px > 0.0:
            x = cv2.GaussianBlur(x, (0, 0), self.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        if self.motion_px >= 1.0:
            x = cv2.filter2D(x, -1, _motion_kernel(self.motion_px, self.motion_angle_rad),
                             borderType=cv2.BORDER_REFLECT)
        if self.noise_sigma > 0.0:
            noise = np.random.default_rng(self.seed).normal(0.0, 1.0, x.shape).astype(np.float32)
            x = x + noise * self.noise_sigma * np.sqrt(np.clip(x, 0.02, 1.0))
        return (np.clip(x, 0.0, 1.0) * 255.0).round().astype(np.uint8)

    def to_json(self) -> dict:
        return asdict(self)


def _motion_kernel(length_px: float, angle_rad: float) -> np.ndarray:
    """A normalised line kernel of `length_px` along `angle_rad` (image x right, y down)."""
    size = int(np.ceil(length_px)) | 1
    kernel = np.zeros((size, size), np.float32)
    c, half = size // 2, (length_px - 1) / 2
    for t in np.linspace(-half, half, 4 * size):
        kernel[int(round(c + t * np.sin(angle_rad))), int(round(c + t * np.cos(angle_rad)))] = 1.0
    return kernel / kernel.sum()


def sample_sensor_effects(rng: np.random.Generator) -> SensorEffects:
    """Random effects of one photo: exposure -1 to +0.6 stops, gamma 0.8-1.25, white balance
    within 10% per channel, defocus blur in 1 of 3 photos (sigma up to 1.2 px), motion blur in 1
    of 5 (up to 5 px), noise sigma up to 0.05."""
    return SensorEffects(
        gain=float(2.0 ** rng.uniform(-1.0, 0.6)),
        gamma=float(rng.uniform(0.8, 1.25)),
        white_balance=tuple(float(w) for w in rng.uniform(0.9, 1.1, 3)),
        blur_sigma_px=float(rng.uniform(0.3, 1.2)) if rng.uniform() < 1 / 3 else 0.0,
        motion_px=float(rng.uniform(2.0, 5.0)) if rng.uniform() < 0.2 else 0.0,
        motion_angle_rad=float(rng.uniform(0, np.pi)),
        noise_sigma=float(rng.uniform(0.0, 0.05)),
        seed=int(rng.integers(2**31)),
    )
