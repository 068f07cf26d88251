"""The 100 Hz block RMS, exactly as docs/PROTOCOL.md defines it (RMS frames, type 2).

One implementation for both sides: the simulated board computes its RMS frames
with it and the daemon computes the RMS of RAW blocks with it, so RMS mode and
RAW mode of the same signal give the same observations bit for bit:

    RMS = sqrt(mean(((count - offset) * scale)^2))   over the block_len samples,

in float64 from the float32 scale/offset of STATUS, then stored as float32.
Nothing else is removed (no block-mean subtraction, no filtering).  Both
functions reduce each block as one contiguous row, so the floating-point
summation is the same whichever way the blocks arrive.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rows_physical", "physical_rms", "rows_rms", "block_rms"]


def rows_physical(counts: np.ndarray, scale, offset) -> np.ndarray:
    """float64 (n, block_len) m/s²: ``(count - offset) * scale`` for n blocks of counts,
    row i calibrated with scale[i], offset[i] (float32 values, as STATUS carries them)."""
    scale = np.asarray(scale, dtype=np.float32).astype(np.float64)
    offset = np.asarray(offset, dtype=np.float32).astype(np.float64)
    if scale.size and (scale == scale[0]).all() and (offset == offset[0]).all():
        # one calibration for every row (one channel): the same numbers, by scalars, in flat
        # passes (a column broadcast over rows runs ~2.5x slower)
        x = np.asarray(counts).astype(np.float64)
        x -= offset[0]
        x *= scale[0]
        return x
    x = np.subtract(counts, offset[:, None], dtype=np.float64)   # counts to float64 inside: one pass
    x *= scale[:, None]
    return x


def physical_rms(x: np.ndarray) -> np.ndarray:
    """float32 (n,): the RMS of n blocks of physical values (n, block_len) from rows_physical."""
    ms = np.square(x).sum(axis=-1)         # np.mean's sum and division, without its wrapper
    ms /= x.shape[-1]
    return np.sqrt(ms).astype(np.float32)


def rows_rms(counts: np.ndarray, scale, offset) -> np.ndarray:
    """float32 (n,): the RMS of n blocks of counts (n, block_len) (see rows_physical)."""
    return physical_rms(rows_physical(counts, scale, offset))


def block_rms(counts: np.ndarray, scale, offset, block_len: int) -> np.ndarray:
    """float32 (C, n // block_len): the RMS frame values of whole blocks of counts (C, n)."""
    counts = np.asarray(counts)
    c, n = counts.shape
    if n % block_len:
        raise ValueError(f"counts must hold whole blocks of {block_len} samples, got {n} samples")
    nb = n // block_len
    rows = counts.reshape(c * nb, block_len)
    per_row = np.repeat(np.arange(c), nb)
    scale = np.asarray(scale, dtype=np.float32)[per_row]
    offset = np.asarray(offset, dtype=np.float32)[per_row]
    return rows_rms(rows, scale, offset).reshape(c, nb)
