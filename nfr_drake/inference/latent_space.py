"""The space of codes z = [z_art, z_obj]: paths between two objects and new objects drawn from the
distribution of the training codes (the paper's interpolation and generation of new representations).

An object is a point (z_obj, q): the code the networks see is z = [(cos(pi q), sin(pi q)), z_obj]
(`nfr_drake.inference.forward.code_at`); with several part slots (furniture) q is one per slot
and z_art one such pair per slot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nfr_drake.errors import ConfigError


def interpolate_codes(z_obj_a: torch.Tensor, q_a: float | np.ndarray, z_obj_b: torch.Tensor,
                      q_b: float | np.ndarray, t: np.ndarray) -> tuple[torch.Tensor, np.ndarray]:
    """Codes along the path from object a to object b at fractions t (T,) in [0, 1].

    z_obj (k,) moves on the straight line; z_art moves on the unit circle at constant angular
    speed (slerp), each part slot's on its own circle when q_a and q_b are one q per slot (S,).
    Both ends lie on the upper half circle, angle pi q, where the slerp's angle, and so q, changes
    linearly. Returns z_obj (T, k) and q (T,) (per slot: (T, S)); t = 0 gives exactly (z_obj_a,
    q_a), t = 1 exactly (z_obj_b, q_b).
    """
    t = np.asarray(t, float)
    if t.ndim != 1 or t.min(initial=0.0) < 0.0 or t.max(initial=1.0) > 1.0:
        raise ConfigError("interpolation fractions must be a 1-D array in [0, 1]")
    w = torch.as_tensor(t, dtype=z_obj_a.dtype, device=z_obj_a.device)[:, None]
    z_obj = (1.0 - w) * z_obj_a + w * z_obj_b
    q_a, q_b = np.asarray(q_a, float), np.asarray(q_b, float)
    if q_a.shape != q_b.shape:
        raise ConfigError(f"interpolation ends of different slot counts: q {q_a.shape} and {q_b.shape}")
    tq = t.reshape(-1, *[1] * q_a.ndim)
    return z_obj, (1.0 - tq) * q_a + tq * q_b


def farthest_code(codes: torch.Tensor, z_obj: torch.Tensor) -> int:
    """Index of the code among `codes` (N, k) farthest from z_obj (k,) (Euclidean)."""
    return int((codes - z_obj).norm(dim=-1).argmax())


@dataclass(frozen=True)
class CodeGaussian:
    """A Gaussian over object codes z_obj: mean (k,) and covariance (k, k) (diagonal when fitted
    to fewer codes than `CodeGaussian.fit`'s `full_from` times k)."""

    mean: np.ndarray
    cov: np.ndarray

    @classmethod
    def fit(cls, codes: torch.Tensor, full_from: float = 2.0) -> CodeGaussian:
        """Mean and covariance of codes (N, k), N >= 2; the covariance is full when N >= full_from
        * k, diagonal (the per-dimension variances) otherwise, where a full one would be singular
        or too noisy."""
        x = codes.detach().double().cpu().numpy()
        n, k = x.shape
        if n < 2:
            raise ConfigError(f"a Gaussian over codes needs at least 2 codes, got {n}")
        cov = np.cov(x, rowvar=False).reshape(k, k)
        if n < full_from * k:
            cov = np.diag(np.diag(cov))
        return cls(x.mean(0), cov)

    @property
    def is_diagonal(self) -> bool:
        return bool(np.count_nonzero(self.cov - np.diag(np.diag(self.cov))) == 0)

    def sample(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """`count` codes (count, k) drawn from the Gaussian."""
        k = len(self.mean)
        L = np.linalg.cholesky(self.cov + 1e-12 * np.trace(self.cov) / k * np.eye(k))
        return self.mean + rng.standard_normal((count, k)) @ L.T
