"""Streams of blocks for the acoustic filters: the observed sound energy and the per-block outputs.

Shared by :class:`~cmsensord.dsp.acoustic.estimator.AcousticEstimator` and
:class:`~cmsensord.dsp.acoustic.ekf.AcousticEKF`: both take z as (T, C) (blocks, microphone
channels) and return an :class:`AcousticBlock`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["block_energy", "AcousticBlock", "stream_input", "empty_block", "fill_channel"]

#: the per-block outputs, in the order of a row of :func:`fill_channel`
OUTPUTS = ("x_hat", "P_x", "a_hat", "P_a", "y_hat", "P_y", "z_pred")


def block_energy(samples: np.ndarray, block_len: int) -> np.ndarray:
    """z_k: the mean square of each whole block of ``block_len`` samples (last axis).

    ``samples`` (..., n) in physical units (Pa); returns (..., n // block_len).
    """
    samples = np.asarray(samples, dtype=np.float64)
    n = samples.shape[-1]
    if block_len < 1 or n % block_len:
        raise ValueError(f"samples must hold whole blocks of {block_len} samples, got {n}")
    b = samples.reshape(samples.shape[:-1] + (n // block_len, block_len))
    return np.mean(b * b, axis=-1)


@dataclass
class AcousticBlock:
    """Per-block outputs, shape (T, C); NaN where a channel has no estimate yet."""

    x_hat: np.ndarray
    P_x: np.ndarray
    a_hat: np.ndarray
    P_a: np.ndarray
    y_hat: np.ndarray
    P_y: np.ndarray
    z_pred: np.ndarray     # z*_k, the predicted observation
    valid: np.ndarray      # bool: an observation was used (else prediction only)


def stream_input(z: np.ndarray, C: int, valid) -> tuple[np.ndarray, np.ndarray]:
    """z as float64 (T, C) (a 1-D z for one channel) and the mask of the blocks to use: finite
    and, when ``valid`` (T, C) is given, valid.  Raises ValueError for a wrong shape."""
    z = np.asarray(z, dtype=np.float64)
    if z.ndim == 1 and C == 1:
        z = z[:, None]
    if z.ndim != 2 or z.shape[1] != C:
        raise ValueError(f"z: expected shape (T, {C}), got {z.shape}")
    ok = np.isfinite(z)
    if valid is not None:
        valid = np.asarray(valid, dtype=bool)
        if valid.shape != z.shape:
            raise ValueError(f"valid: expected shape {z.shape}, got {valid.shape}")
        ok &= valid
    return z, ok


def empty_block(T: int, C: int, valid: np.ndarray) -> AcousticBlock:
    """T blocks of C channels, every output NaN."""
    def nan() -> np.ndarray:
        return np.full((T, C), np.nan)

    return AcousticBlock(x_hat=nan(), P_x=nan(), a_hat=nan(), P_a=nan(), y_hat=nan(), P_y=nan(),
                         z_pred=nan(), valid=valid)


def fill_channel(out: AcousticBlock, c: int, rows: list) -> None:
    """Write channel ``c`` of ``out`` from one row per block, the values in the order of OUTPUTS."""
    if rows:
        arr = np.array(rows)
        for j, name in enumerate(OUTPUTS):
            getattr(out, name)[:, c] = arr[:, j]
